#pragma once
// The array seen from one scan line, and its narrowband (centre-frequency) fields: the
// transmit field T of the line's focused, apodized transmit aperture and the receive
// sensitivity R of its dynamically focused, expanding receive aperture. Their product is
// the two-way point-spread function H = T R of the line (linear acoustics, 2D).
//
// In the line's own frame (x across the line, z along it, origin where the line leaves
// the face), each element e at p_e with weight a_e contributes
//
//   a_e D_e(q) exp(-i k (|q - p_e| - |f - p_e| + z_f - q.z)) / sqrt(|q - p_e|)
//
// to T at q: cylindrical spreading (2D), the element's directivity D_e = sinc(pi w sin
// theta / lambda) cos theta (w the element's width, the pitch less the kerf; soft baffle;
// theta from its normal), and the transmit delays that bring every element's wave to the focus
// f = (0, z_f) at once. The phase is measured against the echo time 2 q.z / c0 at which
// an image places q, so H at a point on the axis at the focus is real and positive. R is
// the same sum over the receive aperture with its focus at the depth of q itself (dynamic
// receive). Each field is normalised to unit lateral power: the main grating order of
// the aperture carries (lambda / pitch) sum a_e^2 (Parseval, far field), so
// integral |T|^2 dx = 1 at every depth as energy conservation wants. With T so
// normalised, |T(x)|^2 is the fraction of the beam's power per mm at x; the same for R
// by reciprocity. The echo of a point of 2D backscatter width sigma (mm) lit by beam power
// P then has amplitude sqrt(P sigma lambda / (2 pi)) |T R| and a perpendicular plane
// reflector of reflection coefficient r has r sqrt(P) |integral T R dx| (<= 1: all of
// the beam's power comes back when R matches T).
#include <complex>
#include <memory>
#include <vector>

#include <glm/glm.hpp>

#include "probe/pulse.h"
#include "probe/transducer.h"

namespace sonotrace::probe {

// The array in one line's frame.
struct LineArray {
    std::vector<glm::dvec2> position;    // element centres (mm, line frame)
    std::vector<glm::dvec2> normal;      // unit, into the tissue
    std::vector<double> along;           // mm along the array, relative to the line's centre on it
    double lowest = 0.0, highest = 0.0;  // the least and the greatest `along`
    double pitch_mm = 0.0;
};

// Elements of `t` as seen from line `l`. Linear and convex lines are centred on the
// array at their own position; `snap_along` (mm, 0 = none) rounds that centre to a grid
// of the pitch, so lines at the same offset share one geometry (the beam does not change
// with a sub-element shift). Phased lines all see the whole array, steered.
LineArray line_array(const Transducer& t, int l, double snap_along = 0.0);

// Active aperture of a line: elements with |along| <= half_width (clipped by the array)
// weighted by the apodization across the span they occupy.
std::vector<double> aperture_weights(const LineArray& array, double width_mm, Apodization a);
// The elements [first, last) between the first and the last with a weight: the same as
// aperture_weights' nonzero span, without computing the weights between.
std::pair<int, int> aperture_span(const LineArray& array, double width_mm, Apodization a);

// The frequencies the broadband fields sum over (PulseEcho::Band), kept per pulse
// (centre frequency, bandwidth, band shape, cycles). For echoes (`echo`): the pulse-echo
// waveform's band with room for echoes spread kBandSpreadPeriods periods either side of
// the pulse (the arrivals of the elements at a point off the focus, which is what lowers
// a broadband beam's side lobes; 1.5 periods left a -24 dB ghost lobe at 10 mm on the
// linear preset where the element sum has none). For energies (`energy`): the waveform's
// support alone, where |S| exceeds kEnergyFloor of its peak: the energy sum_m |s_m H_m|^2
// is a quadrature over frequency of |S H|^2, which the main lobe dominates (the test
// BroadbandFields.SpeckleTableEnergyFollowsTheFullBand bounds what the coarser band
// misses).
constexpr double kBandSpreadPeriods = 3.0;
constexpr double kEnergyFloor = 3e-2;
enum class BandUse { echo, energy };
std::shared_ptr<const PulseEcho::Band> pulse_band(const Transducer& t, BandUse use);

// What an image shows of a broadband two-way response with spectrum H_m at the band's
// frequencies (LineFields::broadband): the echo e(t) = sum_m s_m H_m exp(i 2 pi f_m t)
// relative to the pulse p(t) = sum_m s_m exp(i 2 pi f_m t) that the image places at the
// echo time.
struct BroadbandEcho {
    // The envelope's peak |e(t*)| over the pulse's (1), with the carrier's phase there
    // against the pulse's (arg e(t*) - arg p(t*)): the echo an image of the separable
    // form echo x pulse shows at its brightest. Off the main lobe the true echo is
    // longer and lower than the pulse (the elements' arrivals spread); its peak is what
    // a lateral profile of the image reads.
    std::complex<double> echo;
    // sum_m |s_m H_m|^2 / sum_m |s_m|^2: the echo's energy over the pulse's (Parseval),
    // which sets the mean level of speckle.
    double power = 0.0;
};
BroadbandEcho broadband_echo(const PulseEcho::Band& band, const std::complex<double>* h);

// Narrowband fields at the centre frequency (see the header), each normalised to unit
// lateral power, and the broadband two-way response summed over the pulse's band.
class LineFields {
  public:
    LineFields(const Transducer& t, LineArray array);
    // T at q (line frame, mm).
    std::complex<double> transmit(const glm::dvec2& q) const;
    // The receive aperture focused at depth `focus_mm` on the axis (width focus / rx
    // F-number, at most the array): weights and their normalisation.
    // The elements of an aperture with a weight, in float and padded with weightless
    // elements to a multiple of eight (the vectorised sums' lanes): packed once per
    // aperture, not per point.
    struct Elements {
        std::vector<float> w, x, y, nx, ny;
    };
    struct Receive {
        std::vector<double> weights;
        double norm = 1.0, focus_mm = 0.0;
        Elements elements;
    };
    Receive receive_aperture(double focus_mm) const;
    // The same without `elements` (ApertureTerms sums from the weights).
    Receive receive_weights(double focus_mm) const;
    std::complex<double> receive(const glm::dvec2& q, const Receive& aperture) const;
    std::complex<double> receive(const glm::dvec2& q, double focus_mm) const {
        return receive(q, receive_aperture(focus_mm));
    }
    // H = T R at the centre frequency with the receive focused at q's own depth.
    std::complex<double> two_way_narrowband(const glm::dvec2& q) const {
        return transmit(q) * receive(q, q.y);
    }
    // The broadband two-way response at q: T_m R_m at each frequency f_m of the band,
    // each field normalised to unit lateral power at its own frequency (the 2D Green's
    // function's 1 / sqrt(k) and the normalisation's sqrt(k) cancel), the element
    // directivity at f_m. echo is what images take (BroadbandEcho), receive_power the
    // energy-weighted |R_m|^2 (sum_m |s_m R_m|^2 / sum_m |s_m|^2).
    struct Broadband {
        BroadbandEcho two_way;
        double receive_power = 0.0;
    };
    Broadband broadband(const glm::dvec2& q, const Receive& aperture) const;
    Broadband broadband(const glm::dvec2& q) const { return broadband(q, receive_aperture(q.y)); }
    // What the speckle takes of the broadband response at q, on the energy band: the
    // echo's energy power = sum_m |s_m H_m|^2 / sum_m |s_m|^2 and the same of R alone,
    // and a weight of that energy with the phase of H at f0.
    struct Speckle {
        std::complex<double> weight;
        double power = 0.0, receive_power = 0.0;
    };
    Speckle speckle(const glm::dvec2& q, const Receive& aperture) const;
    // The same from the transmit and the receive sums at each frequency of the energy
    // band (unnormalised, `sum` at each f_m) and the apertures' norms.
    Speckle speckle_of_sums(const std::complex<double>* transmit_sums,
                            const std::complex<double>* receive_sums, double transmit_norm,
                            double receive_norm) const;
    // The broadband echo at q (what a point target's image shows).
    std::complex<double> two_way(const glm::dvec2& q) const { return broadband(q).two_way.echo; }
    // The echo of an infinite planar reflector through (0, z) whose normal, pointing away
    // from the probe, is (sin_tilt, cos theta) in the line frame: integral of T R over the
    // plane, phase against the echo time 2 z / c0, receive focused at z. By image
    // sources: the plane mirrors transmit element e to e', and stationary phase turns the
    // integral over the plane into
    //   sum_e sum_r a_e b_r D_e D_r sqrt(lambda) exp(-i pi/4) exp(-ik (L - tau_e - tau_r -
    //   2z)) / (sqrt(L) cos beta)
    // with L = |r - e'| the mirrored path, D the directivities along it, tau the focusing
    // delays and beta the path's angle from the plane's normal (error O(1/(kL))). Exact
    // for every depth and tilt with no lateral window: a defocused beam's plane echo
    // gathers from the whole width that both apertures light.
    // Broadband: the sum at each frequency of the band, reduced as BroadbandEcho.echo.
    std::complex<double> plane_echo(double z, double sin_tilt) const;
    const LineArray& array() const { return array_; }
    // sum_e w_e D_e exp(-i k (|q - e| - |f - e| + f_y - q_y)) / sqrt(|q - e|), unnormalised:
    // the sum transmit and receive take, over the elements of `weights` (one per element).
    // Elements of zero weight at either end add nothing and are skipped.
    std::complex<double> sum(const glm::dvec2& q, const std::vector<double>& weights,
                             const glm::dvec2& focus) const;
    const PulseEcho::Band& band() const { return *echo_->band; }
    const std::vector<double>& transmit_weights() const { return tx_weights_; }
    double transmit_norm() const { return tx_norm_; }

  private:
    friend class ApertureTerms;
    Transducer t_;
    LineArray array_;
    std::vector<double> tx_weights_;
    std::vector<float> x_, y_, nx_, ny_;  // the elements in float, for the vectorised sums
    double tx_norm_ = 1.0;
    double k_ = 0.0, element_width_ = 0.0;
    struct Spectrum {
        std::shared_ptr<const PulseEcho::Band> band;
        std::vector<float> inverse_ratio;  // f0 / f_m
        std::vector<double> root_ratio;    // sqrt(f_m / f0): a field's norm at f_m over f0's
        int centre = 0;                    // m of f0
    };
    std::shared_ptr<const Spectrum> echo_, energy_;
    static std::shared_ptr<const Spectrum> line_spectrum(const Transducer& t, BandUse use);
    // The sum at every frequency f_m of a band (out: its count values), the directivity
    // and the phase at f_m.
    void sum_spectrum(const glm::dvec2& q, const Elements& elements, const glm::dvec2& focus,
                      const Spectrum& spectrum, std::complex<double>* out) const;
    Elements pack(const std::vector<double>& weights) const;
    Elements tx_elements_;
    // T_m R_m on a band, each normalised at f_m (the norms scale as sqrt(f_m / f0)), into
    // out, and sum_m |s_m R_m|^2 / sum_m |s_m|^2.
    double two_way_spectrum(const glm::dvec2& q, const Receive& aperture, const Spectrum& spectrum,
                            std::complex<double>* out) const;
};

}  // namespace sonotrace::probe
