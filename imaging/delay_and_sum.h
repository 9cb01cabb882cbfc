#pragma once
// Delay-and-sum beamforming of channel data (imaging/channel_data.h) on a grid of pixels,
// coherently compounded over the transmits:
//
//   b(r) = sum_w sum_e a_e(r) s_we(tau_w(r) + |r - p_e| / c0)
//
// with s_we the analytic signal of element e's channel under transmit w, tau_w(r) the
// transmit's arrival at r (probe/transmit.h), p_e element e's place and a_e(r) the
// receive apodization over the elements within d / (2 F) of o along the face (F the
// receive F-number; at least a pitch), where o is where r's scan line leaves the face and
// d the depth along it: the focused mode's receive aperture (a linear array: o = x, d =
// z; a phased one: o = 0, d = |r|; a convex one: the foot of the normal through r). The
// analytic signal is taken by the discrete Hilbert transform (the spectrum's negative
// half removed), brought to baseband at f0 and interpolated there (Catmull-Rom), then
// carried back to the carrier at the delay: the carrier's phase is exact at any delay.
// |b| is the envelope the image shows (TGC and log compression follow as for focused
// frames).
#include <complex>
#include <vector>

#include "imaging/channel_data.h"
#include "probe/transducer.h"

namespace sonotrace::imaging {

// Pixels at (x_i, z_j) = (x0 + i dx, z0 + j dz), probe plane, mm.
struct PixelGrid {
    double x0_mm = 0.0, z0_mm = 0.0, dx_mm = 0.1, dz_mm = 0.1;
    int nx = 0, nz = 0;
    double x(int i) const { return x0_mm + i * dx_mm; }
    double z(int j) const { return z0_mm + j * dz_mm; }
};
// A grid over the array's width from `from_mm` to `to_mm` deep at `pixel_mm`.
PixelGrid pixel_grid(const probe::Transducer& t, double from_mm, double to_mm, double pixel_mm);

// Receive of the beamformer:
//   f_number     (default 1.75): receive aperture width d / f_number about o (above)
//   apodization  (default hann): weighting across that aperture
struct DasSettings {
    double f_number = 1.75;
    probe::Apodization apodization = probe::Apodization::hann;
};

struct BeamformedImage {
    PixelGrid grid;
    std::vector<std::complex<float>> values;  // [j * nx + i]: analytic pixel values
    std::vector<float> weights;               // [j * nx + i]: sum of the weights a_e used
    std::complex<float> at(int i, int j) const {
        return values[std::size_t(j) * std::size_t(grid.nx) + std::size_t(i)];
    }
    float weight_sum(int i, int j) const {
        return weights[std::size_t(j) * std::size_t(grid.nx) + std::size_t(i)];
    }
};

// The compounded image of the transmits [first, last) of `channels` (all by default).
BeamformedImage delay_and_sum(const ChannelData& channels, const probe::Transducer& t,
                              const PixelGrid& grid, const DasSettings& settings, int first = 0,
                              int last = -1);

// The analytic signal of n real samples (discrete Hilbert transform, zero-padded to the
// next fast length): out[k] = x[k] + i H{x}[k].
std::vector<std::complex<float>> analytic_signal(const float* x, int n);

}  // namespace sonotrace::imaging
