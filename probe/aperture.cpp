#include "probe/aperture.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "probe/array_geometry.h"
#include "tissue/base/fast_math.h"

#include <vector>

namespace sonotrace::probe {

LineArray line_array(const Transducer& t, int l, double snap_along) {
    const ScanGeometry geometry(t);
    const ArrayGeometry& array = geometry.array();
    const ScanLine line = geometry.line(l);
    LineArray a;
    a.pitch_mm = t.pitch_mm;
    const double length = t.array_length_mm(), half = 0.5 * length;
    // The line's centre on the array (mm along it); steered lines use the whole array.
    const std::optional<double> aperture_centre = array.aperture_centre(line);
    double centre = aperture_centre.value_or(0.0);
    if (snap_along > 0.0 && aperture_centre) {
        const double first = -half + 0.5 * t.pitch_mm;  // the first element's centre
        centre = first + std::round((centre - first) / snap_along) * snap_along;
    }
    for (int e = 0; e < t.elements; ++e) {
        const double s = -half + (e + 0.5) * t.pitch_mm;  // along the array
        double along = s - centre;
        if (array.closed()) along -= length * std::floor((along + half) / length);  // [-L/2, L/2)
        const ArrayPoint p = array.seen_from_line(s, along, line);
        a.position.push_back(p.position);
        a.normal.push_back(p.normal);
        a.along.push_back(along);
    }
    return a;
}

std::vector<double> aperture_weights(const LineArray& array, double width_mm, Apodization a) {
    const std::size_t n = array.along.size();
    std::vector<double> w(n, 0.0);
    if (n == 0) return w;
    // At least two pitches, so that the aperture holds an element wherever it sits.
    const double half = 0.5 * std::max(width_mm, 2.0 * array.pitch_mm);
    // The array's ends (a ring's elements are numbered from anywhere along it).
    const auto [lowest, highest] = std::minmax_element(array.along.begin(), array.along.end());
    const double first = *lowest - 0.5 * array.pitch_mm, last = *highest + 0.5 * array.pitch_mm;
    const double lo = std::max(-half, first), hi = std::min(half, last);
    double total = 0.0;
    for (std::size_t e = 0; e < n; ++e) {
        const double s = array.along[e];
        if (s < lo || s > hi) continue;
        w[e] = apodization_weight(a, (s - lo) / std::max(hi - lo, 1e-12));
        total += w[e];
    }
    if (!(total > 0.0)) {  // a window whose only elements sit on its zero edges
        std::size_t nearest = 0;
        for (std::size_t e = 1; e < n; ++e)
            if (std::abs(array.along[e]) < std::abs(array.along[nearest])) nearest = e;
        w[nearest] = 1.0;
    }
    return w;
}

LineFields::LineFields(const Transducer& t, LineArray array) : t_(t), array_(std::move(array)) {
    tx_weights_ = aperture_weights(array_, t.active_aperture_mm(), t.tx_apodization);
    double sum2 = 0.0;
    for (double w : tx_weights_) sum2 += w * w;
    tx_norm_ = 1.0 / std::sqrt(t.wavelength_mm() / t.pitch_mm * sum2);
    k_ = 2.0 * std::numbers::pi / t.wavelength_mm();
    element_width_ = t.element_width_mm;
    for (std::size_t e = 0; e < array_.position.size(); ++e) {
        x_.push_back(float(array_.position[e].x)), y_.push_back(float(array_.position[e].y));
        nx_.push_back(float(array_.normal[e].x)), ny_.push_back(float(array_.normal[e].y));
    }
}

namespace {

// An element of width w seen at angle theta from its normal: sinc(pi w sin theta /
// lambda) cos theta, 0 behind it. The sinc as sin(2 pi u) / (2 pi u) at u = (w / 2 lambda)
// |sin theta| + 1e-9 (even, and defined at 0 without a branch: loops over it vectorise).
inline float directivity(float sin_theta, float cos_theta, float half_width_in_lambdas) {
    const float u = half_width_in_lambdas * std::abs(sin_theta) + 1e-9f;
    float s, c;
    base::sincos_turns(u, s, c);
    return s / (6.28318531f * u) * std::max(cos_theta, 0.0f);
}

// The terms of a field sum (LineFields::sum), element by element: re + i im =
// w D exp(-i 2 pi path / lambda) / sqrt(r). Float and branch-free (an element behind q
// gets D = 0) so that the loop vectorises; built for AVX2 and the baseline, with no FMA
// in either, so both give the same numbers.
[[gnu::target_clones("avx2", "default")]] void field_terms(
    std::size_t n, const float* __restrict x, const float* __restrict y, const float* __restrict nx,
    const float* __restrict ny, const float* __restrict weight, float qx, float qy, float fx,
    float fy, float inverse_lambda, float half_width, float* __restrict re, float* __restrict im) {
    for (std::size_t e = 0; e < n; ++e) {
        const float dx = qx - x[e], dy = qy - y[e];
        const float r = std::max(std::sqrt(dx * dx + dy * dy), 1e-6f), inverse = 1.0f / r;
        const float cos_theta = (dx * nx[e] + dy * ny[e]) * inverse;
        const float sin_theta = (dx * ny[e] - dy * nx[e]) * inverse;
        float s, c;
        const float gain = weight[e] *
                           directivity(sin_theta, cos_theta, half_width * inverse_lambda) /
                           std::sqrt(r);
        const float fdx = fx - x[e], fdy = fy - y[e];
        const float path = r - std::sqrt(fdx * fdx + fdy * fdy) + fy - qy;
        base::sincos_turns(path * inverse_lambda, s, c);
        re[e] = gain * c, im[e] = -gain * s;  // exp(-i k path)
    }
}

}  // namespace

std::complex<double> LineFields::sum(const glm::dvec2& q, const std::vector<double>& weights,
                                     const glm::dvec2& focus) const {
    // An aperture narrower than the array (F-number, the dynamic receive's growth) leaves
    // zero weights at its ends, whose terms are +-0 and change no sum: the span between
    // them is all that is summed. The PSF table's build was half these sums, over every
    // element. Scratch per thread: a call per table sample allocated three vectors.
    std::size_t first = 0, last = weights.size();
    while (first < last && weights[first] == 0.0) ++first;
    while (last > first && weights[last - 1] == 0.0) --last;
    const std::size_t n = last - first;
    thread_local std::vector<float> w, re, im;
    w.resize(n), re.resize(n), im.resize(n);
    for (std::size_t e = 0; e < n; ++e) w[e] = float(weights[first + e]);
    field_terms(n, x_.data() + first, y_.data() + first, nx_.data() + first, ny_.data() + first,
                w.data(), float(q.x), float(q.y), float(focus.x), float(focus.y),
                float(1.0 / t_.wavelength_mm()), float(0.5 * element_width_), re.data(), im.data());
    double sum_re = 0.0, sum_im = 0.0;  // in order, in double: the same on every build
    for (std::size_t e = 0; e < n; ++e) sum_re += re[e], sum_im += im[e];
    return {sum_re, sum_im};
}

std::complex<double> LineFields::transmit(const glm::dvec2& q) const {
    return tx_norm_ * sum(q, tx_weights_, {0.0, t_.focus_mm});
}

LineFields::Receive LineFields::receive_aperture(double focus_mm) const {
    Receive r;
    r.focus_mm = focus_mm;
    r.weights = aperture_weights(array_, t_.receive_aperture_mm(focus_mm), t_.rx_apodization);
    double sum2 = 0.0;
    for (double v : r.weights) sum2 += v * v;
    r.norm = 1.0 / std::sqrt(t_.wavelength_mm() / t_.pitch_mm * sum2);
    return r;
}

std::complex<double> LineFields::receive(const glm::dvec2& q, const Receive& aperture) const {
    return aperture.norm * sum(q, aperture.weights, {0.0, aperture.focus_mm});
}

namespace {

// The receive elements of a plane echo (LineFields::plane_echo), in float arrays relative
// to the plane's point.
struct ReceiveElements {
    const float *x, *y, *nx, *ny, *image_x, *image_y, *weight, *delay;
};

// One transmit element's terms over the receive elements: re + i im = the element pair's
// D_e D_r w_r / (sqrt(L) cos beta) exp(-i 2 pi (L - delay_r) / lambda - offset). The hot
// loop of the plane echoes: built for AVX2 and the baseline, picked at load time (no FMA
// in either: the same numbers).
[[gnu::target_clones("avx2", "default")]] void image_source_terms(
    const ReceiveElements& rx, std::size_t n, float ex, float ey, float px, float py, float enx,
    float eny, float mx, float my, float inverse_lambda, float half_width, float offset,
    float* __restrict re, float* __restrict im) {
    const float* __restrict rx_x = rx.x;
    const float* __restrict rx_y = rx.y;
    const float* __restrict rx_nx = rx.nx;
    const float* __restrict rx_ny = rx.ny;
    const float* __restrict image_x = rx.image_x;
    const float* __restrict image_y = rx.image_y;
    const float* __restrict weight = rx.weight;
    const float* __restrict delay = rx.delay;
    for (std::size_t r = 0; r < n; ++r) {
        // Mirrored path e' -> r; the same length from e to r's mirror image.
        const float dx = rx_x[r] - ex, dy = rx_y[r] - ey;
        const float length = std::sqrt(dx * dx + dy * dy), inverse = 1.0f / length;
        // Arrival at r from e' and departure from e towards r', against each normal.
        const float cos_r = -(dx * rx_nx[r] + dy * rx_ny[r]) * inverse;
        const float sin_r = (dx * rx_ny[r] - dy * rx_nx[r]) * inverse;
        const float ux = image_x[r] - px, uy = image_y[r] - py;
        const float cos_e = (ux * enx + uy * eny) * inverse;
        const float sin_e = (ux * eny - uy * enx) * inverse;
        const float cos_beta = std::max(std::abs(dx * mx + dy * my) * inverse, 0.05f);
        float s, co;
        const float half_width_in_lambdas = half_width * inverse_lambda;
        const float gain = directivity(sin_e, cos_e, half_width_in_lambdas) *
                           directivity(sin_r, cos_r, half_width_in_lambdas) * weight[r] /
                           (std::sqrt(length) * cos_beta);
        base::sincos_turns(length * inverse_lambda - delay[r] * inverse_lambda - offset, s, co);
        re[r] = gain * co, im[r] = -gain * s;  // exp(-i 2 pi phase)
    }
}

}  // namespace

std::complex<double> LineFields::plane_echo(double z, double sin_tilt) const {
    const Receive aperture = receive_aperture(z);
    sin_tilt = std::clamp(sin_tilt, -1.0, 1.0);
    const glm::dvec2 m(sin_tilt, std::sqrt(1.0 - sin_tilt * sin_tilt)), c(0.0, z);
    auto mirror = [&](const glm::dvec2& p) { return p - 2.0 * glm::dot(p - c, m) * m; };
    // Receive elements in float arrays (positions relative to the plane's point c, so
    // that float keeps a ~1e-6 mm path resolution), the inner loop over them vectorises.
    const double lambda = t_.wavelength_mm();
    std::vector<float> rx_x, rx_y, rx_nx, rx_ny, image_x, image_y, weight, delay;
    for (std::size_t r = 0; r < aperture.weights.size(); ++r) {
        if (aperture.weights[r] == 0.0) continue;
        const glm::dvec2 p = array_.position[r];
        const glm::dvec2 image = mirror(p);
        rx_x.push_back(float(p.x - c.x)), rx_y.push_back(float(p.y - c.y));
        rx_nx.push_back(float(array_.normal[r].x)), rx_ny.push_back(float(array_.normal[r].y));
        image_x.push_back(float(image.x - c.x)), image_y.push_back(float(image.y - c.y));
        weight.push_back(float(aperture.weights[r]));
        delay.push_back(float(glm::length(c - p) - z));  // dynamic receive focus at z
    }
    const std::size_t n = weight.size();
    const ReceiveElements rx{rx_x.data(),    rx_y.data(),    rx_nx.data(),  rx_ny.data(),
                             image_x.data(), image_y.data(), weight.data(), delay.data()};
    const float inverse_lambda = float(1.0 / lambda), half_width = float(0.5 * element_width_);
    const float mx = float(m.x), my = float(m.y);
    std::complex<double> total = 0.0;
    std::vector<float> re(n), im(n);
    for (std::size_t e = 0; e < tx_weights_.size(); ++e) {
        if (tx_weights_[e] == 0.0) continue;
        const glm::dvec2 p = array_.position[e];
        const glm::dvec2 image = mirror(p) - c, from = p - c;
        const float ex = float(image.x), ey = float(image.y), px = float(from.x),
                    py = float(from.y);
        const float enx = float(array_.normal[e].x), eny = float(array_.normal[e].y);
        // Transmit delay and the reference 2z, in wavelengths.
        const float offset =
            float((glm::length(glm::dvec2(0.0, t_.focus_mm) - p) - t_.focus_mm + 2.0 * z) / lambda);
        image_source_terms(rx, n, ex, ey, px, py, enx, eny, mx, my, inverse_lambda, half_width,
                           offset, re.data(), im.data());
        double sum_re = 0.0, sum_im = 0.0;
        for (std::size_t r = 0; r < n; ++r) sum_re += re[r], sum_im += im[r];
        total += tx_weights_[e] * std::complex<double>(sum_re, sum_im);
    }
    return total * tx_norm_ * aperture.norm * std::sqrt(lambda) *
           std::polar(1.0, -0.25 * std::numbers::pi);
}

}  // namespace sonotrace::probe
