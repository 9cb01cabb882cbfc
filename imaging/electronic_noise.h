#pragma once
// Electronic (receiver) noise on the RF lines: the thermal noise of the receive chain,
// which a real frame shows where TGC lifts the echoes to its level (the bottom of a deep
// frame, behind a shadow).
//
//   n = (w (*) h) s,  w white Gaussian (unit variance, one value per RF sample),
//   h[m] = p(m / fs)  the pulse-echo waveform's in-phase part (probe/pulse.h),
//   s^2 = P / (10^(SNR/10) sum_m h[m]^2),  P = the frame's mean RF power (all lines and
//   samples, before the noise),
//
// so the noise has the receive band's spectrum (a receiver filters to it) and its power
// is exactly P / 10^(SNR/10): the SNR is the ratio of the frame's mean echo power to the
// noise power, in dB. A frame with no echo (P = 0) stays silent. Values come from a
// counter-based stream keyed by (seed, line, sample): the same on any thread count.
#include <cstdint>

#include "imaging/bmode.h"

namespace sonotrace::imaging {

// The shaping taps h (centred: h[half + m] = p(m / fs)) and their power sum.
struct NoiseShape {
    std::vector<float> taps;
    double power = 0.0;  // sum of taps^2
};
NoiseShape noise_shape(const probe::Transducer& t, double fs_hz);

// Adds the noise to `rf` at `snr_db`; returns the noise's variance per sample (s^2 sum h^2).
double add_electronic_noise(LineData& rf, const probe::Transducer& t, double snr_db, uint64_t seed);

}  // namespace sonotrace::imaging
