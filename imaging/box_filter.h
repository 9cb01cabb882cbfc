#pragma once
// A Gaussian smoothing as three passes of a box (O(n) whatever the width), of the four
// moments a detected sample carries: the speckle's scatter profile (speckle_lines.cpp)
// and the envelope's low-pass to the pixel (envelope.cpp) share it.
#include <array>

namespace sonotrace::imaging {

// Three passes of a centred box of odd width b = 2r + 1 approximate a Gaussian of
// variance (b^2 - 1) / 4 to within a few per cent (zero outside, sum 1), in O(n)
// whatever the width. The r of a Gaussian of `sigma` samples:
int box3_radius(double sigma);

// The four moments of a sample (speckle_lines), smoothed together.
using Moments = std::array<double, 4>;

// The three passes over n samples of the interleaved moments (one pass serves all four).
// `v` and `scratch` each hold r zero samples, the n samples, r zero samples: the windows
// read the padding beyond the ends, with no branch per sample. Returns where the
// result's sample 0 is. Built for AVX2 too (a sample's four moments in one register; no
// FMA, so the same numbers either way).
const Moments* smooth_box3(Moments* v, Moments* scratch, int n, int r);

}  // namespace sonotrace::imaging
