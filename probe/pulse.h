#pragma once
// The pulse-echo waveform of a transducer: an excitation of n cycles of a sine at the
// centre frequency, convolved with the transducer's two-way (transmit x receive) impulse
// response. The response's amplitude spectrum is a generalized Gaussian about f0,
//
//   |H(f)| = exp(-ln 2 |(f - f0) / (B6 f0 / 2)|^p),  p = ln(ln 10 / ln 2) / ln(B20 / B6),
//
// through a datasheet's two points: -6 dB at the fractional bandwidth B6, -20 dB at B20.
// The shape is the ratio B20 / B6 (Transducer::band_shape): sqrt(ln 10 / ln 2) = 1.82 is
// the Gaussian (p = 2); real transducers are flatter-topped (a smaller ratio, p > 2),
// which lengthens the echo for the same B6. The response has zero phase and passes no DC.
//
// The axial point-spread function is this waveform's envelope: nothing is chosen for it.
// One cycle (the default of the presets, as a scanner's B-mode pulse) barely lengthens
// the impulse response; more cycles narrow the spectrum and lengthen the echo.
//
// The waveform is tabulated once, finely (64 samples per period), together with its
// quadrature (Hilbert transform): echoes with a phase (the complex two-way field of the
// aperture) are Re{a (p + i q)}. Time zero is the envelope's peak, so an echo placed at
// time t peaks there.
#include <complex>
#include <vector>

namespace sonotrace::probe {

struct Transducer;

class PulseEcho {
  public:
    // frequency_hz: centre frequency f0; bandwidth: fractional -6 dB width B6 of the
    // two-way response's spectrum; band_shape: B20 / B6 (> 1); cycles: excitation length
    // in periods (> 0, fractional allowed).
    PulseEcho(double frequency_hz, double bandwidth, double band_shape, double cycles);
    explicit PulseEcho(const Transducer& t);

    double frequency_hz() const { return f0_; }
    // In-phase and quadrature parts at time t (s) from the envelope peak; 0 outside
    // [-half_length, half_length].
    double in_phase(double t) const { return sample(in_phase_, t); }
    double quadrature(double t) const { return sample(quadrature_, t); }
    // Both at once: in_phase(t) + i quadrature(t), the table position found once.
    std::complex<double> analytic(double t) const;
    double envelope(double t) const {
        return std::abs(std::complex<double>(in_phase(t), quadrature(t)));
    }
    // Half the support kept (s): where the envelope has fallen below 1e-4 of its peak.
    double half_length_s() const { return half_length_; }
    // FWHM of the envelope (s) and the axial resolution it gives, c0/2 times it (mm).
    double envelope_fwhm_s() const { return fwhm_; }
    double axial_fwhm_mm() const;
    // Peak of the envelope: 1 (the waveform is scaled to it).

    // The waveform's spectrum S on uniform frequencies f_m = first + m step (m < count):
    // weights s_m = S(f_m) step, so that analytic(t) = sum_m s_m exp(i 2 pi f_m t) for
    // |t| < 1 / (2 step). Sampling a spectrum at steps of `step` repeats its waveform every
    // 1 / step (Poisson's summation), so a broadband field summed over these frequencies
    // (probe/aperture.h) is exact for echoes that stay within that window; the step
    // leaves `spread_s` on either side of the waveform's support (where its envelope
    // exceeds `floor`), and frequencies where |S| is below `floor` times its peak are
    // dropped.
    struct Band {
        double centre_hz = 0.0;  // f0, one of the frequencies
        double first_hz = 0.0, step_hz = 0.0;
        std::vector<std::complex<double>> weight;  // s_m
        double power = 0.0;                        // sum |s_m|^2
        // The grid an echo's envelope peak is searched on (probe::broadband_echo): times
        // t_k = k search_dt for |k| <= search_half across the window 1 / step, a quarter
        // of the band's inverse span apart, and their baseband phasors exp(i 2 pi m step
        // t_k) at [(k + search_half) count + m].
        double search_dt = 0.0;
        int search_half = 0;
        std::vector<std::complex<double>> search;
        int count() const { return int(weight.size()); }
        double frequency_hz(int m) const { return first_hz + m * step_hz; }
        // sum_m s_m exp(i 2 pi f_m t): the waveform (analytic) as the band sums it.
        std::complex<double> waveform(double t) const;
    };
    Band band(double spread_s, double floor = 1e-3) const;

    // |H(f)| of the two-way response (header), 1 at f0; 0 at f <= 0.
    static double transducer_response(double f, double frequency_hz, double bandwidth,
                                      double band_shape);

  private:
    double sample(const std::vector<double>& table, double t) const;
    double f0_;
    double dt_ = 0.0;                            // table spacing (s)
    double half_length_ = 0.0;                   // s
    double fwhm_ = 0.0;                          // s
    std::vector<double> in_phase_, quadrature_;  // sample k at t = (k - centre) dt
    int centre_ = 0;
};

}  // namespace sonotrace::probe
