#include "imaging/bmode.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <opencv2/core.hpp>

#include "tissue/acoustic_map.h"
#include "tissue/hash.h"

namespace sonotrace::imaging {

namespace {

constexpr double kFwhmPerSigma = 2.3548200450309493;  // 2 sqrt(2 ln 2)
constexpr double kC0 = tissue::kReferenceSpeed;       // m/s

using probe::ScanLine;
using tissue::mix64;

// Gaussian kernel of `sigma` samples, sum 1.
std::vector<float> gaussian_kernel(double sigma) {
    const int half = std::max(1, int(std::ceil(3.0 * sigma)));
    std::vector<float> k(std::size_t(2 * half + 1));
    double sum = 0.0;
    for (int i = -half; i <= half; ++i)
        sum += k[std::size_t(i + half)] = float(std::exp(-0.5 * i * i / (sigma * sigma)));
    for (float& v : k) v = float(v / sum);
    return k;
}

// out = in (*) kernel (centred), zero outside.
template <typename T>
void convolve(const T* in, int n, const std::vector<float>& kernel, T* out) {
    const int half = int(kernel.size() / 2);
    for (int i = 0; i < n; ++i) {
        const int lo = std::max(0, i - half), hi = std::min(n - 1, i + half);
        T sum = 0;
        for (int j = lo; j <= hi; ++j) sum += in[j] * kernel[std::size_t(j - i + half)];
        out[i] = sum;
    }
}

// Sum over k of the correlation of the scatterer field between points k u cells apart
// along a lattice axis: linear interpolation of white values has the cubic B-spline
// autocorrelation B3(x) (phase-averaged), normalised by B3(0) = 2/3.
double lattice_correlation_sum(double u) {
    auto rho = [](double x) {
        x = std::abs(x);
        const double b = x < 1.0 ? 2.0 / 3.0 - x * x + 0.5 * x * x * x
                                 : (x < 2.0 ? (2.0 - x) * (2.0 - x) * (2.0 - x) / 6.0 : 0.0);
        return b * 1.5;
    };
    double sum = 1.0;
    for (int k = 1; k * u < 2.0; ++k) sum += 2.0 * rho(k * u);
    return sum;
}

}  // namespace

double Pulse::sigma_s() const {
    const double sigma_f = bandwidth * frequency_hz / kFwhmPerSigma;
    return 1.0 / (2.0 * std::numbers::pi * sigma_f);
}
double Pulse::envelope_fwhm_s() const {
    return kFwhmPerSigma * sigma_s();
}
double Pulse::axial_fwhm_mm() const {
    return 0.5 * kC0 * envelope_fwhm_s() * 1e3;
}
double Pulse::operator()(double t) const {
    const double s = sigma_s();
    return std::exp(-0.5 * t * t / (s * s)) * std::cos(2.0 * std::numbers::pi * frequency_hz * t);
}

double tgc_gain_db(const std::vector<TgcPoint>& curve, double depth_mm) {
    if (curve.empty()) return 0.0;
    if (depth_mm <= curve.front().depth_mm) return curve.front().gain_db;
    for (std::size_t i = 1; i < curve.size(); ++i) {
        if (depth_mm <= curve[i].depth_mm) {
            const TgcPoint &a = curve[i - 1], &b = curve[i];
            const double t = (depth_mm - a.depth_mm) / std::max(b.depth_mm - a.depth_mm, 1e-12);
            return a.gain_db + t * (b.gain_db - a.gain_db);
        }
    }
    return curve.back().gain_db;
}

float log_compress(float envelope, double gain_db, double dynamic_range_db) {
    if (!(envelope > 0.0f)) return 0.0f;
    const double db = 20.0 * std::log10(double(envelope)) + gain_db;
    return float(std::clamp((db + dynamic_range_db) / dynamic_range_db, 0.0, 1.0));
}

double LineData::depth_mm(int i) const {
    return 0.5 * kC0 * (double(i) / fs_hz) * 1e3;
}

LineData rf_layout(const probe::Transducer& t, const ImagingSettings& settings) {
    LineData d;
    d.lines = t.lines;
    d.fs_hz = (settings.sampling_mhz > 0.0 ? settings.sampling_mhz : 8.0 * t.frequency_mhz) * 1e6;
    d.samples = int(std::ceil(2.0 * t.depth_mm * 1e-3 / kC0 * d.fs_hz)) + 1;
    return d;
}

ScattererField::ScattererField(uint64_t seed, double cell_mm)
    : seed_(mix64(seed ^ 0x73636174ull)), inverse_cell_(1.0 / cell_mm) {}

float ScattererField::lattice(int64_t i, int64_t j, int64_t k) const {
    // One mix of the three indices, each spread by an odd 64-bit constant.
    const uint64_t h =
        mix64(seed_ + uint64_t(i) * 0x9E3779B97F4A7C15ull + uint64_t(j) * 0xC2B2AE3D27D4EB4Full +
              uint64_t(k) * 0x165667B19E3779F9ull);
    // Uniform on [-sqrt 3, sqrt 3]: zero mean, unit variance.
    return float((double(h >> 11) * 0x1.0p-53 * 2.0 - 1.0) * std::numbers::sqrt3);
}

float ScattererField::operator()(const glm::dvec3& world_mm) const {
    const glm::dvec3 p = world_mm * inverse_cell_;
    const glm::dvec3 base = glm::floor(p);
    const glm::dvec3 f = p - base;
    const int64_t i = int64_t(base.x), j = int64_t(base.y), k = int64_t(base.z);
    float v = 0.0f;
    for (int c = 0; c < 8; ++c) {
        const int di = c & 1, dj = (c >> 1) & 1, dk = c >> 2;
        const double w = (di ? f.x : 1.0 - f.x) * (dj ? f.y : 1.0 - f.y) * (dk ? f.z : 1.0 - f.z);
        v += float(w) * lattice(i + di, j + dj, k + dk);
    }
    // Trilinear blending of independent values has mean square prod((1-f)^2 + f^2),
    // 8/27 on average over a cell: rescale to 1.
    return v * float(std::sqrt(27.0 / 8.0));
}

double reflection_back_fraction(double cos_incidence, double lobe_exponent,
                                double half_acceptance_rad) {
    const double off_axis = 2.0 * std::acos(std::clamp(cos_incidence, -1.0, 1.0));
    const double sigma = 1.0 / std::sqrt(std::max(lobe_exponent, 1.0));
    auto cdf = [](double z) { return 0.5 * std::erfc(-z / std::numbers::sqrt2); };
    return cdf((half_acceptance_rad - off_axis) / sigma) -
           cdf((-half_acceptance_rad - off_axis) / sigma);
}

LineData synthesize_rf(const probe::Transducer& t, const probe::Sources<2>& sources,
                       const std::vector<simulator::EchoEvent<2>>& events,
                       const simulator::EchoProfile<2>& profile, const MapToWorld& to_world,
                       const ImagingSettings& settings) {
    LineData rf = rf_layout(t, settings);
    const int L = rf.lines, N = rf.samples;
    const double fs = rf.fs_hz;
    const Pulse pulse{t.frequency_mhz * 1e6, t.bandwidth};

    // Particle (line, index within line) -> source, for energies and receive weights.
    std::vector<std::vector<uint32_t>> of_line(static_cast<std::size_t>(L));
    for (std::size_t s = 0; s < sources.size(); ++s) {
        if (sources[s].line < uint32_t(L)) of_line[sources[s].line].push_back(uint32_t(s));
    }

    // -- reflections: intensity per line and sample, split linearly between samples
    std::vector<float> reflected(std::size_t(L) * std::size_t(N), 0.0f);
    for (const auto& e : events) {
        if (e.kind == simulator::EchoKind::scatter || e.line >= uint32_t(L)) continue;
        const auto& line = of_line[e.line];
        if (e.particle >= line.size()) continue;
        const auto& source = sources[line[e.particle]];
        double intensity = double(e.energy) * e.weight * source.receive_weight;
        double echo_time = e.time_s;  // the particle came back itself: the full round trip
        if (e.kind != simulator::EchoKind::returned_to_probe) {
            echo_time = 2.0 * e.time_s;  // monostatic estimate: twice the one-way time
            intensity *= double(e.energy) / std::max(double(source.energy), 1e-30);
            // Of the reflected energy, the share that returns into the receive aperture
            // (dynamic receive at the F-number, at most the array) seen from the event.
            const double range_mm = std::max(e.time_s * kC0 * 1e3, 1e-3);
            const double aperture = std::min(t.array_length_mm(), range_mm / t.f_number);
            intensity *= reflection_back_fraction(e.cos_incidence, e.lobe_exponent,
                                                  std::atan(0.5 * aperture / range_mm));
        }
        const double position = echo_time * fs;
        if (!(position >= 0.0) || position >= double(N - 1)) continue;
        const int i = int(position);
        const float frac = float(position - i);
        float* row = reflected.data() + std::size_t(e.line) * std::size_t(N);
        row[i] += float(intensity) * (1.0f - frac);
        row[i + 1] += float(intensity) * frac;
    }

    // -- speckle (header): the beam's intensity at each echo time, its mean position and
    // lateral spread, from the smoothed profile
    const probe::ScanGeometry geometry(t);
    std::vector<float> speckle(std::size_t(L) * std::size_t(N), 0.0f);
    const bool with_profile = settings.speckle && profile.lines > 0 && profile.bins == N &&
                              profile.covariance.size() == profile.intensity.size();
    if (with_profile) {
        const double cell =
            settings.speckle_cell_mm > 0.0 ? settings.speckle_cell_mm : t.wavelength_mm() / 8.0;
        const ScattererField field(settings.seed, cell);
        const double fwhm_samples = pulse.envelope_fwhm_s() * fs;
        const auto smooth = gaussian_kernel(
            std::max(0.5, settings.profile_smoothing * fwhm_samples / kFwhmPerSigma));
        const int profile_lines = std::min(L, profile.lines);
        std::vector<double> w(std::size_t(L) * std::size_t(N), 0.0);
        std::vector<glm::dvec2> mean(w.size(), glm::dvec2(0.0));
        std::vector<glm::dmat2> spread(w.size(), glm::dmat2(0.0));
        tbb::parallel_for(0, profile_lines, [&](int l) {
            // Moments S0 = w, S1 = w m, S2 = w (C + m m^T), smoothed, then back.
            const std::size_t row = std::size_t(l) * std::size_t(N);
            std::vector<double> in(static_cast<std::size_t>(N)), moments[6];
            for (int c = 0; c < 6; ++c) {
                for (int i = 0; i < N; ++i) {
                    const std::size_t at = row + std::size_t(i);
                    const double wi = profile.intensity[at];
                    const glm::dvec2 m(profile.position[at]);
                    const glm::dmat2 s2 =
                        glm::dmat2(profile.covariance[at]) + glm::outerProduct(m, m);
                    const double values[6] = {1.0, m.x, m.y, s2[0][0], s2[1][0], s2[1][1]};
                    in[std::size_t(i)] = wi > 0.0 ? wi * values[c] : 0.0;
                }
                moments[c].resize(std::size_t(N));
                convolve(in.data(), N, smooth, moments[c].data());
            }
            for (int i = 0; i < N; ++i) {
                const double s0 = moments[0][std::size_t(i)];
                if (!(s0 > 0.0)) continue;
                const std::size_t at = row + std::size_t(i);
                w[at] = s0;
                mean[at] = glm::dvec2(moments[1][std::size_t(i)], moments[2][std::size_t(i)]) / s0;
                const double xy = moments[4][std::size_t(i)] / s0 - mean[at].x * mean[at].y;
                spread[at] =
                    glm::dmat2(moments[3][std::size_t(i)] / s0 - mean[at].x * mean[at].x, xy, xy,
                               moments[5][std::size_t(i)] / s0 - mean[at].y * mean[at].y);
            }
        });

        // The scatterer field on K sub-lines per gap between lines, interpolated between
        // the lines' mean positions (the nominal line spacing where a line has no echo),
        // so neighbouring lines see overlapping scatterers as their beams overlap; each
        // scaled by the square root of the intensity that lights it.
        double widest_gap = 0.0;
        for (double d : {0.0, 0.5 * t.depth_mm, t.depth_mm})
            widest_gap = std::max(widest_gap, geometry.line_spacing_mm(d));
        const int K = std::clamp(int(std::ceil(widest_gap / cell)), 1, 32);
        const int sub_lines = (L - 1) * K + 1;
        auto gap_ends = [&](int l, int i, glm::dvec2* a, glm::dvec2* b) {
            const std::size_t at = std::size_t(l) * std::size_t(N) + std::size_t(i);
            const std::size_t next = at + std::size_t(N);
            *a = mean[at], *b = mean[next];
            if (w[at] > 0.0 && w[next] > 0.0) return;
            const double depth = rf.depth_mm(i);  // a line without echo: nominal spacing
            const glm::dvec2 nominal = geometry.point(l + 1, depth) - geometry.point(l, depth);
            if (!(w[at] > 0.0)) *a = mean[next] - nominal;
            if (!(w[next] > 0.0)) *b = mean[at] + nominal;
        };
        std::vector<float> sub(std::size_t(sub_lines) * std::size_t(N), 0.0f);
        tbb::parallel_for(0, sub_lines, [&](int s) {
            const int l = std::min(s / K, L - 2), k = s - l * K;
            const double f = double(k) / K;
            for (int i = 0; i < N; ++i) {
                const std::size_t at = std::size_t(l) * std::size_t(N) + std::size_t(i);
                if (L == 1) {
                    if (w[at] > 0.0)
                        sub[std::size_t(i)] =
                            float(std::sqrt(w[at])) * field(to_world(glm::vec2(mean[at])));
                    continue;
                }
                const double lit = (1.0 - f) * w[at] + f * w[at + std::size_t(N)];
                if (!(lit > 0.0)) continue;
                glm::dvec2 a, b;
                gap_ends(l, i, &a, &b);
                // Scatterers lit by the intensity there (interpolated between the lines).
                sub[std::size_t(s) * std::size_t(N) + std::size_t(i)] =
                    float(std::sqrt(lit)) * field(to_world(glm::vec2(a + f * (b - a))));
            }
        });

        // Each line sums the sub-lines under its two-way beam, amplitude weights g. The
        // particles give the transmit beam (intensity variance v, so amplitude variance
        // 2v; at the focus already two-way through the receive weights); dynamic receive
        // focusing bounds it by the receive PSF, FWHM lambda * max(F, depth / array).
        // Normalised by the field's mean square over the sum (lattice correlation along
        // the sub-lines included), the mean speckle intensity is the profile's, averaged
        // over the beam.
        tbb::parallel_for(0, L, [&](int l) {
            const ScanLine line = geometry.line(l);
            const glm::dvec2 across(-line.direction.y, line.direction.x);
            for (int i = 0; i < N; ++i) {
                const std::size_t at = std::size_t(l) * std::size_t(N) + std::size_t(i);
                if (!(w[at] > 0.0)) continue;
                const double depth = rf.depth_mm(i);
                const double transmit_var = std::max(0.0, glm::dot(across, spread[at] * across));
                const double receive_sigma = t.wavelength_mm() *
                                             std::max(t.f_number, depth / t.array_length_mm()) /
                                             kFwhmPerSigma;
                const double sigma_g =
                    std::max(std::min(std::sqrt(2.0 * transmit_var), receive_sigma), cell);
                const double d_sub = std::max(geometry.line_spacing_mm(depth), 1e-6) / K;
                int reach = int(std::min(std::ceil(3.0 * sigma_g / d_sub), 1e6));
                const int stride = std::max(1, (reach + 63) / 64);
                reach = reach / stride * stride;
                // Gaussian weights by recurrence: g(j) = exp(-alpha j^2), g(j+1) = g(j) q_j,
                // q_j = exp(-alpha (2j + 1)).
                const double alpha =
                    0.5 * (stride * d_sub) * (stride * d_sub) / (sigma_g * sigma_g);
                const int centre = l * K;
                double sum = 0.0, norm = 0.0, g = 1.0, q = std::exp(-alpha);
                const double q_step = q * q;
                for (int j = 0; j * stride <= reach; ++j, g *= q, q *= q_step) {
                    for (int side = 0; side < (j == 0 ? 1 : 2); ++side) {
                        const int s = centre + (side == 0 ? j : -j) * stride;
                        if (s < 0 || s >= sub_lines) continue;
                        sum += g * sub[std::size_t(s) * std::size_t(N) + std::size_t(i)];
                        norm += g * g;
                    }
                }
                const double u = stride * d_sub / cell;
                // The axial samples see the same lattice correlation.
                const double u_axial = (rf.depth_mm(1) - rf.depth_mm(0)) / cell;
                speckle[at] = float(sum / std::sqrt(norm * lattice_correlation_sum(u) *
                                                    lattice_correlation_sum(u_axial)));
            }
        });
    }

    // -- pre-RF: reflection amplitudes + speckle
    std::vector<float> pre(std::size_t(L) * std::size_t(N), 0.0f);
    for (std::size_t at = 0; at < pre.size(); ++at)
        pre[at] = std::sqrt(reflected[at]) + speckle[at];

    // -- RF: pre-RF (*) pulse
    const int half = int(std::ceil(4.0 * pulse.sigma_s() * fs));
    std::vector<float> taps(std::size_t(2 * half + 1));
    for (int i = -half; i <= half; ++i) taps[std::size_t(i + half)] = float(pulse(i / fs));
    rf.values.assign(std::size_t(L) * std::size_t(N), 0.0f);
    tbb::parallel_for(0, L, [&](int l) {
        convolve(pre.data() + std::size_t(l) * std::size_t(N), N, taps,
                 rf.values.data() + std::size_t(l) * std::size_t(N));
    });
    return rf;
}

LineData envelope(const LineData& rf) {
    LineData env = rf;
    const int n = cv::getOptimalDFTSize(rf.samples + 64);  // padding: no wrap-around
    cv::Mat lines(rf.lines, n, CV_32F, cv::Scalar(0));
    for (int l = 0; l < rf.lines; ++l)
        std::copy_n(rf.values.data() + std::size_t(l) * std::size_t(rf.samples), rf.samples,
                    lines.ptr<float>(l));
    cv::Mat spectrum;
    cv::dft(lines, spectrum, cv::DFT_ROWS | cv::DFT_COMPLEX_OUTPUT);
    // Analytic signal: keep DC (and Nyquist), double positive, drop negative frequencies.
    for (int l = 0; l < rf.lines; ++l) {
        auto* s = spectrum.ptr<cv::Vec2f>(l);
        for (int k = 1; k < (n + 1) / 2; ++k) s[k] *= 2.0f;
        for (int k = n / 2 + 1; k < n; ++k) s[k] = cv::Vec2f(0.0f, 0.0f);
    }
    cv::Mat analytic;
    cv::dft(spectrum, analytic, cv::DFT_ROWS | cv::DFT_INVERSE | cv::DFT_SCALE);
    for (int l = 0; l < rf.lines; ++l) {
        const auto* a = analytic.ptr<cv::Vec2f>(l);
        for (int i = 0; i < rf.samples; ++i) env.at(l, i) = std::hypot(a[i][0], a[i][1]);
    }
    return env;
}

LineData compress(const LineData& envelope, const ImagingSettings& settings) {
    LineData out = envelope;
    for (int i = 0; i < envelope.samples; ++i) {
        const double gain = settings.gain_db + tgc_gain_db(settings.tgc, envelope.depth_mm(i));
        for (int l = 0; l < envelope.lines; ++l)
            out.at(l, i) = log_compress(envelope.at(l, i), gain, settings.dynamic_range_db);
    }
    return out;
}

ScanConverted scan_convert(const LineData& data, const probe::Transducer& t, double pixel_mm,
                           float outside) {
    const probe::ScanGeometry geometry(t);
    const auto [lo, hi] = geometry.bounds();
    ScanConverted out;
    out.pixel_mm = pixel_mm;
    out.origin = lo;
    const int cols = int(std::floor((hi.x - lo.x) / pixel_mm)) + 1;
    const int rows = int(std::floor((hi.y - lo.y) / pixel_mm)) + 1;
    out.image = cv::Mat(rows, cols, CV_32F, cv::Scalar(outside));
    out.inside = cv::Mat(rows, cols, CV_8U, cv::Scalar(0));
    const double samples_per_mm = 2.0 * 1e-3 / kC0 * data.fs_hz;
    tbb::parallel_for(0, rows, [&](int r) {
        for (int c = 0; c < cols; ++c) {
            const glm::dvec2 p = lo + glm::dvec2(c, r) * pixel_mm;
            const glm::dvec2 ld = geometry.line_and_depth(p);
            if (!(ld.x >= -0.5 && ld.x <= data.lines - 0.5 && ld.y >= 0.0 && ld.y <= t.depth_mm))
                continue;
            const double l = std::clamp(ld.x, 0.0, double(data.lines - 1));
            const double s = std::clamp(ld.y * samples_per_mm, 0.0, double(data.samples - 1));
            const int l0 = std::min(int(l), std::max(data.lines - 2, 0)),
                      s0 = std::min(int(s), data.samples - 2);
            const int l1 = std::min(l0 + 1, data.lines - 1);
            const float fl = float(l - l0), fsm = float(s - s0);
            const float a = data.at(l0, s0) * (1 - fsm) + data.at(l0, s0 + 1) * fsm;
            const float b = data.at(l1, s0) * (1 - fsm) + data.at(l1, s0 + 1) * fsm;
            out.image.at<float>(r, c) = a * (1 - fl) + b * fl;
            out.inside.at<uint8_t>(r, c) = 255;
        }
    });
    return out;
}

}  // namespace sonotrace::imaging
