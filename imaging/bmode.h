#pragma once
// B-mode image formation: from the tracer's echoes to a scan-converted frame, by linear
// acoustics.
//
//   reflection events      --plane response of the line's two-way PSF-->  echo per line
//   scatter echo profile   --x tissue-fixed speckle field, PSF-weighted sum across-->
//   point targets          --each line's exact two-way field H at the target-->
//   complex pre-RF --(*) pulse-echo waveform--> RF --analytic signal--> baseband, banded
//   to the pixels --scan conversion (coherent between lines), TGC, log compression--> image
//   (imaging/scan_conversion.h)
//
// The tracer carries where the energy goes (refraction, shadowing, multiple reflections,
// attenuation); the aperture's two-way field H = T R (probe/aperture.h, tabulated per
// depth in imaging/psf.h) carries the lateral resolution, its side lobes and the focal
// gain; the pulse-echo waveform (probe/pulse.h: n-cycle excitation (*) impulse response)
// carries the axial resolution. Each is applied once.
// Amplitudes: an echo of intensity I (energy units: the particle's energy at the event x
// the fraction sent back x its two-way loss E/E0) from a reflector whose normal is tilted
// by theta from the line has amplitude sqrt(I) times the plane response sum H(x)
// exp(-2ik x sin theta) dx at its apparent depth (the range of the particle's path: a
// mirrored path images where the mirror puts it). Reflections of one line add as
// intensities within an RF sample (particles of one beam meeting one interface are one
// wavefront). Speckle: sub-resolution scatterers are a white random field fixed in world
// (tissue) coordinates, sampled on sub-lines between the lines' mean scattering positions
// (so mirrored or refracted beams sample the tissue where they really went), each lit by
// the lines' illumination times the map's backscatter^2 at the sub-line's own point (so
// an anechoic region between lines whose beams graze tissue stays dark); each line
// sums them weighted by its complex H, so the mean level follows the lateral power
// integral |H|^2 dx (brightest at the focus) and the grain grows away from it.
#include <array>
#include <cmath>
#include <complex>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <vector>

#include <glm/glm.hpp>
#include <opencv2/core.hpp>

#include "probe/source_particle.h"
#include "probe/transducer.h"
#include "simulator/records.h"
#include "simulator/trace_settings.h"
#include "tissue/acoustic_map.h"
#include "tissue/base/fast_math.h"
#include "tissue/base/hash.h"

namespace sonotrace::imaging {

// A point of the TGC curve: gain (dB) at a depth (mm); linear in between, constant beyond.
struct TgcPoint {
    double depth_mm = 0.0;
    double gain_db = 0.0;
};

// The automatic TGC at a depth (dB): the two-way attenuation of brain, 0.6 dB/(cm MHz),
// at the probe's centre frequency (`simulate --tgc auto`, the GUI's base curve, the
// dataset's frames).
inline double automatic_tgc_db(double frequency_mhz, double depth_mm) {
    return 2.0 * 0.6 * frequency_mhz * depth_mm / 10.0;
}

// Gain of a TGC curve at a depth (dB).
double tgc_gain_db(const std::vector<TgcPoint>& curve, double depth_mm);

// Log compression to [0, 1]: 20 log10(envelope) + gain mapped from -range..0 dB to 0..1.
float log_compress(float envelope, double gain_db, double dynamic_range_db);

struct ImagingSettings {
    double sampling_mhz = 0.0;  // RF sampling rate; 0 = 4 x the centre frequency
    bool speckle = true;
    double speckle_cell_mm = 0.0;    // lattice of the scatterer field; 0 = wavelength / 8
    double profile_smoothing = 1.0;  // smoothing of the scatter profile, in pulse FWHMs
    // Spacing of the speckle's sub-lines between scan lines, in units of the narrowest
    // beam sigma (the receive PSF at the F-number); larger is faster and coarser.
    double sub_line_sigmas = 1.0;
    std::vector<TgcPoint> tgc;  // empty = none
    double gain_db = 0.0;
    double dynamic_range_db = 60.0;
    double pixel_mm = 0.2;  // scan-converted pixel size
    uint64_t seed = 1;      // of the scatterer field
    // Receiver noise at this SNR (dB, imaging/electronic_noise.h); unset: none.
    std::optional<double> noise_snr_db;
};

// The depth (mm) of sample i at fs_hz: c0 t / 2.
double sample_depth_mm(int i, double fs_hz);

// Lines x samples of one quantity (RF, envelope, log-compressed), sample i at echo time
// i / fs (0 = the face).
struct LineData {
    int lines = 0, samples = 0;
    double fs_hz = 0.0;
    std::vector<float> values;  // [line * samples + i]
    float at(int l, int i) const {
        return values[std::size_t(l) * std::size_t(samples) + std::size_t(i)];
    }
    float& at(int l, int i) {
        return values[std::size_t(l) * std::size_t(samples) + std::size_t(i)];
    }
    double depth_mm(int i) const;  // c0 * t / 2
};

// Sampling of the RF lines for a transducer: rate and sample count covering its depth.
LineData rf_layout(const probe::Transducer& t, const ImagingSettings& settings);

// Fraction of the energy an interface reflects that heads back along the incident path
// into a receiver subtending +-half_acceptance (rad): the reflected lobe cos^c about the
// mirror direction, which lies 2 theta_i from the way back, approximated in 2D by a
// Gaussian of sigma 1/sqrt(c), integrated over the acceptance. A smooth interface echoes
// only near normal incidence; a rough one (bone, c ~ 3) from most angles.
double reflection_back_fraction(double cos_incidence, double lobe_exponent,
                                double half_acceptance_rad);

// The receive beam's lateral sigma at a range, in lines: lambda x range / the receive
// aperture there (the FWHM, lambda times the receive F-number) over kFwhmPerSigma, divided
// by the line spacing at that range. Speckle and whatever lights it vary across lines on
// this scale.
double receive_beam_sigma_lines(const probe::Transducer& t, const probe::ScanGeometry& geometry,
                                double range_mm);

// Maps a point of the tracer's map frame (mm) to world coordinates (mm), for the speckle
// field: the plane's origin and axes in the world; and where the probe plane's origin
// (the face centre, ScanGeometry's frame) lies in the map frame.
struct MapToWorld {
    glm::dvec3 origin{0.0}, x_axis{1.0, 0.0, 0.0}, y_axis{0.0, 1.0, 0.0};
    glm::dvec2 face_in_map{0.0};
    glm::dvec3 operator()(const glm::dvec2& map) const {
        return origin + x_axis * map.x + y_axis * map.y;
    }
};

// A point target as the image sees it: where it is (mm, map frame) and its echo's
// amplitude factor sqrt(P sigma lambda / (2 pi)) (probe/aperture.h), the two-way losses
// of its path included; each line's two-way field H at its position scales it.
struct PointEcho {
    glm::dvec2 position{0.0};
    double amplitude = 0.0;
    double core_radius_mm = 0.0;  // traced echoes this close are the target's own (dropped)
    // The one-way travel time of the straight path from the face, less c0's, times c0
    // (mm): the echo comes from that much deeper (integral of (c0 / c - 1) ds).
    double delay_mm = 0.0;
};

// The RF lines of a frame. `events` and `profile` come from one trace of `sources`
// (profile bins must equal the layout's samples at bin width 1/fs); `points` are imaged
// through each line's two-way field without being traced. `receive`: the receive
// weights the trace's profile was made with (imaging/psf.h; made here if null). `map`:
// the traced map, whose backscatter lights the speckle point by point (with the
// profile's illumination); without it, or without illumination, each sub-line is lit by
// the lines' scattered intensity.
LineData synthesize_rf(const probe::Transducer& t, const probe::Sources<2>& sources,
                       const std::vector<simulator::EchoEvent<2>>& events,
                       const simulator::EchoProfile<2>& profile, const MapToWorld& to_world,
                       const ImagingSettings& settings, const std::vector<PointEcho>& points = {},
                       std::shared_ptr<const simulator::ReceiveWeights> receive = nullptr,
                       const tissue::AcousticMap<2>* map = nullptr);

// What an image of `pixel_mm` pixels can show of a transducer's line data without
// aliasing: the analytic signal taken to baseband at the carrier and low-passed there
// (three running boxes of 2 box_radius + 1 samples, close to a Gaussian) so that the
// axial resolution (the pulse's envelope, as a Gaussian's sigma) reaches kPixelSigmas
// pixels where it is finer; where the pulse is already as long, no filter (box_radius 0:
// no resolution is lost where the pixel is smaller than the PSF). Coherent, before
// detection, so that speckle stays Rayleigh (SNR 1.91) with grains as large as the pixels
// can show, rather than averaged into a smoother texture; `gain` restores speckle's
// mean power, sum_m |s_m|^2 / sum_m |s_m B(f_m - f0)|^2 over the pulse-echo spectrum s
// and the boxes' response B.
struct PixelBand {
    double carrier_hz = 0.0;
    int box_radius = 0;
    double gain = 1.0;
    double sigma_samples = 0.0;  // the displayed axial resolution, a Gaussian's sigma
};
// sigma of the displayed axial resolution, in pixels: the detected intensity's spectrum at
// the pixels' Nyquist frequency exp(-pi^2 sigma^2 / 2) = -15 dB.
inline constexpr double kPixelSigmas = 0.85;
PixelBand pixel_band(const probe::Transducer& t, const LineData& layout, double pixel_mm);

// Lines x samples of a detected signal at baseband: the analytic signal times exp(-i 2 pi
// f0 t), low-passed to the display's pixels (PixelBand), whose magnitude is the displayed
// envelope. What the display's scan conversion interpolates, coherently, between lines.
struct BasebandLines {
    int lines = 0, samples = 0;
    double fs_hz = 0.0;
    double sigma_samples = 0.0;               // axial resolution, a Gaussian's sigma (PixelBand)
    std::vector<std::complex<float>> values;  // [line * samples + i]
};

// Envelope of every line: magnitude of the analytic signal (a finite Hilbert transformer,
// accurate across the RF band; nothing of an echo reaches farther than 48 samples), with
// a pixel band low-passed to it first; with `unbanded`, the plain envelope too, from the
// same analytic signal.
LineData envelope(const LineData& rf, const PixelBand& band = {}, LineData* unbanded = nullptr);
// The same signal banded, at baseband (what the display's scan conversion takes; `band`
// from pixel_band, whose carrier it is taken down from), and the plain envelope.
BasebandLines baseband(const LineData& rf, const PixelBand& band, LineData* unbanded = nullptr);

// Spreads each of `n` samples' four values over the `period` samples from it on (itself
// first, the last one fractional), by a running sum: a track-length profile whose steps
// deposit what they scatter along their length at their start
// (simulator::EchoProfile::step_mm) is a comb of the steps' echo-time period
// 2 step / c0 fs, which this turns into what the steps scatter, constant where they are
// equal. Sums are kept (but for what spreads past the end). period <= 1: nothing changes.
void spread_over_step(std::array<double, 4>* values, int n, double period);

// TGC and log compression as the display applies them: 20 log10(envelope) + gain + TGC(depth)
// mapped from -range..0 dB to 0..1 and clamped, folded into scale ln(envelope) +
// offset(depth); the offsets by sample of a layout (`samples` at `fs_hz`).
class Compression {
  public:
    Compression(int samples, double fs_hz, const ImagingSettings& settings);
    float offset(int i) const { return offset_[std::size_t(i)]; }
    const float* offsets() const { return offset_.data(); }  // by sample
    float scale() const { return scale_; }
    // base::log_float rather than std::log: loops over pixels or samples vectorise (the
    // call was most of the stage). Infinite envelopes clamp to the largest float first.
    float operator()(float envelope, float offset) const {
        const float level = scale_ * base::log_float(std::min(envelope, 3.4e38f)) + offset;
        return envelope > 0.0f ? std::clamp(level, 0.0f, 1.0f) : 0.0f;
    }

  private:
    float scale_ = 1.0f;
    std::vector<float> offset_;
};

// The white scatterer field fixed in world coordinates: trilinear interpolation of
// independent zero-mean values on a lattice of `cell_mm`, scaled to unit mean square at
// every point.
class ScattererField {
  public:
    ScattererField(uint64_t seed, double cell_mm);
    float operator()(const glm::dvec3& world_mm) const {
        return at_lattice(world_mm * inverse_cell_);
    }
    // The same at a point given in lattice cells (world_mm / cell_mm).
    float at_lattice(const glm::dvec3& p) const {
        const glm::dvec3 base = glm::floor(p);
        const glm::vec3 f(p - base);
        return blend(key(base), f.x, f.y, f.z);
    }
    // Lattice key of a cell: one 32-bit sum of the indices spread by odd constants, so
    // that neighbours differ by a constant and only the finaliser runs per corner.
    uint32_t key(const glm::dvec3& base) const {
        return seed_ + uint32_t(int64_t(base.x)) * kSpreadI + uint32_t(int64_t(base.y)) * kSpreadJ +
               uint32_t(int64_t(base.z)) * kSpreadK;
    }
    // The same in single precision, for batches (cells up to 2^24 from the origin: the
    // lattice spans at most a few thousand cells).
    static float at_lattice_float(uint32_t seed, float x, float y, float z) {
        const int32_t ix = base::floor_to_int(x), iy = base::floor_to_int(y),
                      iz = base::floor_to_int(z);
        const uint32_t key =
            seed + uint32_t(ix) * kSpreadI + uint32_t(iy) * kSpreadJ + uint32_t(iz) * kSpreadK;
        return blend(key, x - float(ix), y - float(iy), z - float(iz));
    }
    uint32_t seed() const { return seed_; }
    // Trilinear blend of the cell's 8 corner values at fractions (fx, fy, fz). Plain
    // integer and float arithmetic: loops over it vectorise.
    static float blend(uint32_t key, float fx, float fy, float fz) {
        float v = 0.0f;
        for (int c = 0; c < 8; ++c) {
            const int di = c & 1, dj = (c >> 1) & 1, dk = c >> 2;
            const float w = (di ? fx : 1.0f - fx) * (dj ? fy : 1.0f - fy) * (dk ? fz : 1.0f - fz);
            v += w * value(key + uint32_t(di) * kSpreadI + uint32_t(dj) * kSpreadJ +
                           uint32_t(dk) * kSpreadK);
        }
        // Trilinear blending of independent values has mean square prod((1-f)^2 + f^2):
        // rescaled to 1 at every point. (Scaled by its average over a cell, 8/27, the
        // field's level rose and fell with the lattice's phase, and lines sampling the
        // lattice at a phase that drifts from line to line showed as stripes of +-1 dB.)
        const float gx = (1.0f - fx) * (1.0f - fx) + fx * fx,
                    gy = (1.0f - fy) * (1.0f - fy) + fy * fy,
                    gz = (1.0f - fz) * (1.0f - fz) + fz * fz;
        return v / std::sqrt(gx * gy * gz);
    }

  private:
    static constexpr uint32_t kSpreadI = 0x9E3779B1u, kSpreadJ = 0x85EBCA77u,
                              kSpreadK = 0xC2B2AE3Du;
    // Uniform on [-sqrt 3, sqrt 3): zero mean, unit variance (lowbias32 finaliser).
    static float value(uint32_t h) {
        return float(int32_t(base::mix32(h))) * 8.0654901e-10f;  // sqrt(3) / 2^31
    }
    uint32_t seed_;
    double inverse_cell_;
};

class PsfTable;

namespace detail {
// One line's speckle sums over the samples [begin, end) between two PSF table rows: for
// each sub-line j in [j_first, j_last] (first_sub_line + j N), sum += (h0_j + f (h1_j -
// h0_j)) v_j, in-phase into sum_i and quadrature into sum_q, in the order of j (speckle_lines.cpp).
void add_weighted_sub_lines(const std::complex<float>* w0, const std::complex<float>* w1,
                            int j_first, int j_last, const float* first_sub_line, int N,
                            const float* f, int begin, int end, float* sum_i, float* sum_q);
// The illumination across lines (lines x samples, row-major, in place): a line's light at
// a sample is an estimate from its own few particles of what lights its beam, which varies
// across lines on the beam's scale. Each line's light is spread over the lines by a
// Gaussian normalised over the frame's lines (so kept whole), of sigma_lines[sample] (the
// receive beam's sigma, in lines) times d, d the fewest lines either side within which the
// other lines hold at least its light: 1 in an even field, so the beam's width; more for a
// line that one heavy particle lit among faint ones, up to widest_lines[sample] (the sample
// point estimator of kernel density estimation, with the kernel set by mass rather than
// by count). Lines without light take their shares: left dark, such a line stood as a
// black radial bar in the skull's shadow, and a line of one heavy particle as a bright
// one. Samples with sigma under 0.3 lines are left as they are. With line_spacing_samples
// (the line spacing at each sample, in samples of depth), what a line pooled with d > 1
// (heavier than the lines around it) is also spread in depth, as wide as across the lines
// (the estimator's kernel is round in the image plane): spread across the lines only, a
// few heavy paths lit zones 20-40 mm wide that ended in depth as sharply as the paths, 15-20
// dB above the brain beyond. The beam's own pooling (d = 1) stays sharp in depth, as a
// shadow's onset is.
void pool_across_lines(double* light, int lines, int samples, const double* sigma_lines,
                       const double* widest_lines, const double* line_spacing_samples = nullptr);
// The speckle term of every line into speckle_i, speckle_q (rf's lines x samples):
// synthesize_rf's first stage (imaging/speckle_lines.cpp).
void speckle_lines(const probe::Transducer& t, const PsfTable& psf,
                   const simulator::EchoProfile<2>& profile, const MapToWorld& to_world,
                   const ImagingSettings& settings, const LineData& rf,
                   const tissue::AcousticMap<2>* map, float* speckle_i, float* speckle_q);
}  // namespace detail

}  // namespace sonotrace::imaging
