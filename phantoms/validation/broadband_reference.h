#pragma once
// The fuller physics the broadband aperture model (probe/aperture.h) is held to, written
// out independently of it: the pulse-echo spectrum from first principles and the envelope
// of an echo summed over it. Shared by the resolution case of `sonotrace validate` and
// the tests of the broadband fields.
#include <complex>
#include <vector>

#include "probe/transducer.h"

namespace sonotrace::validation {

// The pulse-echo spectrum S(f) of a transducer: n cycles of a sine at f0 integrated
// directly (midpoint rule, 400 points per cycle), times the stated two-way response, the
// generalized Gaussian exp(-ln 2 |(f - f0) / (B6 f0 / 2)|^p) through -6 dB at B6 and
// -20 dB at B20 = band_shape B6; on a grid df = f0 / periods from df to 3 f0 (a window
// of `periods` periods: nothing wraps within it), dropping |S| below 1e-7 of f0's scale.
class PulseSpectrum {
  public:
    // reach_periods: the echo's envelope is searched over +-reach periods, f0 / 32 apart.
    PulseSpectrum(const probe::Transducer& t, double periods, double reach_periods);
    const std::vector<double>& frequency() const { return frequency_; }
    // S(f) df at each frequency.
    const std::vector<std::complex<double>>& weight() const { return weight_; }
    // The envelope's peak over time of sum_f S(f) h(f) exp(i 2 pi f t) df, over the same of
    // the pulse itself (h = 1): what an image's lateral profile reads of an echo.
    double peak(const std::vector<std::complex<double>>& h) const;
    // The echo's energy over the pulse's: sum |S h|^2 / sum |S|^2 (Parseval).
    double energy(const std::vector<std::complex<double>>& h) const;

  private:
    double envelope_peak(const std::vector<std::complex<double>>& h) const;
    std::vector<double> frequency_;
    std::vector<std::complex<double>> weight_, carrier_;  // carrier_: [time][frequency]
    double pulse_peak_ = 1.0;
};

// The first side lobe of a lateral profile: the highest local maximum beyond the first
// minimum on either side of the peak, relative to the peak (dB). A skirt without a lobe
// above kNoSideLobeDb (a broadband beam's usual case off the focus) gives kNoSideLobeDb:
// below it a "lobe" is numerical ripple.
constexpr double kNoSideLobeDb = -50.0;
double first_side_lobe_db(const std::vector<double>& profile);

}  // namespace sonotrace::validation
