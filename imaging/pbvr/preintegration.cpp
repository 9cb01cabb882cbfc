#include "imaging/pbvr/preintegration.h"

#include <algorithm>
#include <cmath>

namespace sonotrace::imaging::pbvr {

namespace {
// Below this difference of the end values, a segment is treated as constant (eqs. 23 and
// 25): eq. 18's quotient would divide rounding noise by it.
constexpr double kEqualValues = 1e-7;
}  // namespace

PreIntegration::PreIntegration(const ColourTransferFunction& tf)
    : tf_(&tf), entries_(ColourTransferFunction::kEntries), step_(1.0 / (entries_ - 1)) {
    sigma_.resize(std::size_t(entries_));
    table_.resize(std::size_t(entries_));
    for (int e = 0; e < entries_; ++e) sigma_[std::size_t(e)] = tf.extinction(float(e * step_));
    table_[0] = 0.0;
    for (int e = 1; e < entries_; ++e)  // trapezoids: exact for the linear pieces
        table_[std::size_t(e)] =
            table_[std::size_t(e - 1)] +
            0.5 * step_ * (sigma_[std::size_t(e - 1)] + sigma_[std::size_t(e)]);
    inverse_table_.resize(std::size_t(entries_));
    const double total = table_.back();
    inverse_scale_ = total > 0.0 ? (entries_ - 1) / total : 0.0;
    for (int k = 0; k < entries_; ++k) {
        const double y = total * k / (entries_ - 1);
        inverse_table_[std::size_t(k)] =
            int32_t(std::lower_bound(table_.begin(), table_.end(), y) - table_.begin());
    }
}

// Entries before inverse_table_[k] have T < y_k <= y, entries from inverse_table_[k + 1]
// on have T >= y_(k+1) > y: both T^-1 searches end between them.
std::pair<std::ptrdiff_t, std::ptrdiff_t> PreIntegration::bracket(double y) const {
    if (!(inverse_scale_ > 0.0)) return {0, entries_ - 1};
    const double x = std::clamp(y * inverse_scale_, 0.0, double(entries_ - 1));
    const auto k = std::size_t(x);
    const std::ptrdiff_t first = std::max<std::ptrdiff_t>(inverse_table_[k] - 1, 0);
    const std::ptrdiff_t last =
        k + 1 < inverse_table_.size() ? std::ptrdiff_t(inverse_table_[k + 1]) : entries_ - 1;
    return {first, std::min<std::ptrdiff_t>(last + 1, entries_ - 1)};
}

double PreIntegration::integral(double s) const {
    s = std::clamp(s, 0.0, 1.0);
    const int e = std::min(int(s / step_), entries_ - 2);
    const double d = s - e * step_;
    const double a = sigma_[std::size_t(e)], b = sigma_[std::size_t(e + 1)];
    return table_[std::size_t(e)] + a * d + (b - a) * d * d / (2.0 * step_);
}

double PreIntegration::segment_value(int e, double y) const {
    // solve a d + (b - a) d^2 / (2 step) = y - T_e for d in [0, step], stably
    const double a = sigma_[std::size_t(e)], slope = (sigma_[std::size_t(e + 1)] - a) / step_;
    const double rest = std::max(y - table_[std::size_t(e)], 0.0);
    const double root = std::sqrt(std::max(a * a + 2.0 * slope * rest, 0.0));
    const double d = a + root > 0.0 ? 2.0 * rest / (a + root) : 0.0;
    return e * step_ + std::clamp(d, 0.0, step_);
}

double PreIntegration::inverse_rising(double y) const {
    const auto [first, last] = bracket(y);
    const auto k =
        std::lower_bound(table_.begin() + first, table_.begin() + last + 1, y) - table_.begin();
    if (k == 0) return 0.0;
    if (k >= entries_) return 1.0;
    return segment_value(int(k) - 1, y);
}

double PreIntegration::inverse_falling(double y) const {
    const auto [first, last] = bracket(y);
    const auto k =
        std::upper_bound(table_.begin() + first, table_.begin() + last + 1, y) - table_.begin() - 1;
    if (k < 0) return 0.0;
    if (k >= entries_ - 1) return 1.0;
    return segment_value(int(k), y);
}

double PreIntegration::optical_depth(double s_front, double s_back, double length_mm) const {
    if (std::abs(s_back - s_front) < kEqualValues)  // eq. 23
        return double(tf_->extinction(float(0.5 * (s_front + s_back)))) * length_mm;
    return length_mm / (s_back - s_front) * (integral(s_back) - integral(s_front));  // eq. 18
}

double PreIntegration::opacity(double s_front, double s_back, double length_mm) const {
    return 1.0 - std::exp(-optical_depth(s_front, s_back, length_mm));
}

double PreIntegration::opacity_to(double w, double s_front, double s_back, double length_mm) const {
    const double s = (1.0 - w) * s_front + w * s_back;  // eq. 20
    return opacity(s_front, s, w * length_mm);          // eqs. 21 / 22
}

double PreIntegration::inverse(double r, double s_front, double s_back, double length_mm) const {
    const double tau = -std::log1p(-std::clamp(r, 0.0, 1.0 - 1e-16));
    const double ds = s_back - s_front;
    if (std::abs(ds) < kEqualValues) {  // eq. 25
        const double sigma = tf_->extinction(float(0.5 * (s_front + s_back)));
        return sigma > 0.0 ? std::clamp(tau / (sigma * length_mm), 0.0, 1.0) : 1.0;
    }
    // eq. 24: T(s) = T(s_f) + tau (s_b - s_f) / l, then w from eq. 20
    const double target = integral(s_front) + tau * ds / length_mm;
    const double s = ds > 0.0 ? inverse_rising(target) : inverse_falling(target);
    return std::clamp((s - s_front) / ds, 0.0, 1.0);
}

}  // namespace sonotrace::imaging::pbvr
