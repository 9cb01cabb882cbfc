#pragma once
// The half-maximum crossings of a sampled peak: the one measuring helper behind every full
// width at half maximum the code and the tests take (the pulse's envelope, a line's echo,
// a target's lateral profile).
#include <algorithm>
#include <cmath>
#include <limits>

namespace sonotrace::base {

// Fractional sample positions, either side of `peak`, where the samples value(0 ..
// count - 1) first fall to half of value(peak) or below, by linear interpolation between
// the last sample above half and the first at or below it. NaN on a side whose samples
// stay above half.
struct HalfMaximum {
    double left = std::numeric_limits<double>::quiet_NaN();
    double right = std::numeric_limits<double>::quiet_NaN();
    double width() const { return right - left; }  // in samples
};

template <class Value>  // double value(int i)
HalfMaximum half_maximum(int count, int peak, Value&& value) {
    const double half = 0.5 * double(value(peak));
    auto crossing = [&](int step) {
        for (int i = peak; i + step >= 0 && i + step < count; i += step) {
            const double a = double(value(i)), b = double(value(i + step));
            if (!(b > half)) return i + step * (a - half) / (a - b);
        }
        return std::numeric_limits<double>::quiet_NaN();
    };
    return {crossing(-1), crossing(1)};
}

// The same on samples at positions x (ascending): the crossings' positions, interpolated
// between the samples' x as between their indices.
template <class Value, class Position>  // double value(int i), double x(int i)
HalfMaximum half_maximum_at(int count, int peak, Value&& value, Position&& x) {
    const HalfMaximum h = half_maximum(count, peak, value);
    auto at = [&](double u) {
        if (std::isnan(u)) return u;
        const int i = std::clamp(int(std::floor(u)), 0, count - 2);
        return x(i) + (x(i + 1) - x(i)) * (u - i);
    };
    return {at(h.left), at(h.right)};
}

}  // namespace sonotrace::base
