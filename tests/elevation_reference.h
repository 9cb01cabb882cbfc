#pragma once
// The two-way elevation response of a lens-focused element row, written out independently
// of probe/elevation.h: a Rayleigh-Sommerfeld sum over the element height (2D Green's
// function e^{ikr}/sqrt(r), exact distances, the lens taking sqrt(x^2 + F^2) - F off each
// path), which makes no Fresnel approximation. Returns |U|^2 (transmit times receive) up to
// a constant; `width_at` measures its -6 dB width.
#include <cmath>
#include <complex>
#include <numbers>

#include "probe/transducer.h"

namespace sonotrace::test {

inline double rayleigh_elevation_two_way(const probe::Transducer& t, double e, double z) {
    const double H = t.elevation_aperture_mm(), F = t.elevation_focus_mm;
    const double k = 2.0 * std::numbers::pi / t.wavelength_mm();
    std::complex<double> sum = 0.0;
    const int n = 1000;
    for (int m = 0; m < n; ++m) {
        const double x = -0.5 * H + (m + 0.5) * H / n;
        const double r = std::hypot(e - x, z);
        sum += std::polar(1.0 / std::sqrt(r), k * (r - (std::hypot(x, F) - F)));
    }
    return std::norm(sum);
}

// The full width (mm) at half the on-axis value of a profile symmetric in e, from the
// outermost e on a grid of `step` where it still reaches half.
template <class Profile>
double half_amplitude_width(Profile&& amplitude, double reach, double step) {
    const double peak = amplitude(0.0);
    double high = 0.0;
    for (double e = 0.0; e <= reach; e += step)
        if (amplitude(e) >= 0.5 * peak) high = e;
    return 2.0 * high;
}

}  // namespace sonotrace::test
