#pragma once
// Pre-integration of a transfer function's extinction and the opacity CDF along a ray
// segment (Sakamoto & Koyamada, sec. 3.4 and 4; Engel's pre-integration).
//
// T(s) = integral_0^s sigma(lambda) dlambda (eq. 19), exact for the piecewise-linear
// table of ColourTransferFunction (T is piecewise quadratic). Along a segment of length
// l whose scalar goes linearly from s_f to s_b (eq. 20), the opacity is
//     alpha(s_f, s_b, l) = 1 - exp(-l / (s_b - s_f) (T(s_b) - T(s_f)))   (eq. 18)
// or 1 - exp(-sigma(s_f) l) when s_f = s_b (eq. 23), and the opacity up to the fraction
// w of the segment, alpha(w) (eqs. 21-22), is the CDF of the depth of the first particle.
// Inverting it (eqs. 24-25) places a particle at w = alpha^-1(R), R uniform in
// [0, alpha(s_f, s_b, l)).
#include <cstddef>
#include <cstdint>
#include <utility>
#include <vector>

#include "imaging/pbvr/colour_tf.h"

namespace sonotrace::imaging::pbvr {

class PreIntegration {
  public:
    explicit PreIntegration(const ColourTransferFunction& tf);

    // T(s), s in 0..1 (clamped); 1/mm.
    double integral(double s) const;
    // The optical depth and opacity of a segment (eq. 18 / 23).
    double optical_depth(double s_front, double s_back, double length_mm) const;
    double opacity(double s_front, double s_back, double length_mm) const;
    // The opacity up to the fraction w of the segment (eqs. 21 / 22).
    double opacity_to(double w, double s_front, double s_back, double length_mm) const;
    // w = alpha^-1(R) for R in [0, opacity(s_front, s_back, length)) (eqs. 24 / 25): the
    // first point along the segment where the opacity reaches R.
    double inverse(double r, double s_front, double s_back, double length_mm) const;

  private:
    // The smallest s with T(s) >= y, and the largest s with T(s) <= y.
    double inverse_rising(double y) const;
    double inverse_falling(double y) const;
    double segment_value(int e, double y) const;  // T^-1 inside table segment e

    const ColourTransferFunction* tf_;
    int entries_;
    double step_;                // table spacing in s
    std::vector<double> sigma_;  // at the entries, 1/mm
    std::vector<double> table_;  // T at the entries
    // T^-1 precomputed (eq. 19's inverse): for y_k = k T(1) / (K - 1), the first table
    // entry whose T reaches y_k. A search for T^-1(y) then runs between the entries of two
    // neighbouring y_k, and stays exact within the piecewise-quadratic T.
    std::vector<int32_t> inverse_table_;
    double inverse_scale_ = 0.0;  // (K - 1) / T(1)
    // The table entries [first, last] between which T^-1(y) lies.
    std::pair<std::ptrdiff_t, std::ptrdiff_t> bracket(double y) const;
};

}  // namespace sonotrace::imaging::pbvr
