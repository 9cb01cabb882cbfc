// Channel data (imaging/channel_data.h) against the physics it approximates: the echo of a
// point target at every element, summed here element by element over the whole transmit
// aperture (each element's delay, 1 / sqrt(R) spreading and directivity at every
// frequency) and over a fine frequency grid of the pulse's spectrum, which this file
// computes from the pulse's waveform by its own Fourier sum. Nothing of the model's
// stationary phase, quadratic directivity or sample splitting is in that reference.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <complex>
#include <limits>
#include <numbers>

#include <opencv2/core.hpp>

#include "imaging/channel_data.h"
#include "imaging/channel_scatterers.h"
#include "imaging/delay_and_sum.h"
#include "probe/pulse.h"
#include "probe/transducer.h"
#include "probe/transmit.h"
#include "tests/pulse_spectrum_reference.h"
#include "tissue/base/error.h"

namespace sonotrace::imaging {
namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kC0 = 1540e3;  // mm/s

double sinc(double x) {
    return std::abs(x) < 1e-12 ? 1.0 : std::sin(x) / x;
}

using test::pulse_spectrum;
using test::Spectrum;

// An element: its centre and the unit normal of its face, written here from the arrays'
// definitions (a flat array's elements at (s, 0) facing +y; a convex one's on the arc of
// radius R about (0, -R), at angle s / R: (R sin, R (cos - 1)), facing (sin, cos)).
struct Element {
    glm::dvec2 position, normal;
};
std::vector<Element> elements_of(const probe::Transducer& t) {
    std::vector<Element> out;
    for (int i = 0; i < t.elements; ++i) {
        const double s = (i - 0.5 * (t.elements - 1)) * t.pitch_mm;
        if (t.type == probe::TransducerType::convex) {
            const double phi = s / t.radius_mm;
            out.push_back({{t.radius_mm * std::sin(phi), t.radius_mm * (std::cos(phi) - 1.0)},
                           {std::sin(phi), std::cos(phi)}});
        } else {
            out.push_back({{s, 0.0}, {0.0, 1.0}});
        }
    }
    return out;
}

// One element's radiation at frequency f towards r: D exp(-i k R) / sqrt(R), D = sinc(pi w
// f sin theta / c0) cos theta from its normal (nothing behind it).
std::complex<double> element_wave(const probe::Transducer& t, const Element& e, const glm::dvec2& r,
                                  double f) {
    const glm::dvec2 d = r - e.position;
    const double R = glm::length(d);
    const double sin_theta = (d.x * e.normal.y - d.y * e.normal.x) / R,
                 cos_theta = glm::dot(d, e.normal) / R;
    if (!(cos_theta > 0.0)) return 0.0;
    const double directivity = sinc(kPi * t.element_width_mm * f * sin_theta / kC0) * cos_theta;
    return directivity * std::polar(1.0 / std::sqrt(R), -2.0 * kPi * f * R / kC0);
}

// The transmit's wave (the ideal one) reaches p at this time, written from the wave's
// definition (not TransmitField's): the firing times, and the arrivals at targets.
double wave_time(const probe::TransmitWave& w, const glm::dvec2& p) {
    if (w.kind == probe::TransmitWave::Kind::plane)
        return (p.x * std::sin(w.angle_rad) + p.y * std::cos(w.angle_rad)) / kC0;
    const double b = w.source_distance_mm;
    const glm::dvec2 v(-b * std::sin(w.angle_rad), -b * std::cos(w.angle_rad));
    return (glm::length(p - v) - b) / kC0;
}

// The analytic signal's envelope peak of samples [from, from + count): position (samples,
// by a parabola through the largest and its neighbours) and height.
struct Peak {
    double position = 0.0, height = 0.0;
    double phase = 0.0;  // of the analytic signal at the largest sample
};
Peak envelope_peak(const std::vector<float>& rf) {
    const std::vector<std::complex<float>> a = analytic_signal(rf.data(), int(rf.size()));
    int best = 1;
    for (int n = 1; n + 1 < int(a.size()); ++n)
        if (std::abs(a[std::size_t(n)]) > std::abs(a[std::size_t(best)])) best = n;
    const double l = std::abs(a[std::size_t(best - 1)]), m = std::abs(a[std::size_t(best)]),
                 r = std::abs(a[std::size_t(best + 1)]);
    const double shift = 0.5 * (l - r) / (l - 2.0 * m + r);
    return {best + shift, m - 0.25 * (l - r) * shift, std::arg(a[std::size_t(best)])};
}

TEST(ChannelData, PointEchoesMatchTheElementByElementSum) {
    // The PICMUS probe (flat) and the convex preset (an arc of radius 49.57 mm spanning 75
    // degrees): its diverging wave from the centre of curvature, one steered from a source
    // nearer the face, and a plane wave, which only the strip in front of the arc's chord
    // receives.
    struct Case {
        const char* probe;
        std::vector<std::string> schemes;
        std::vector<glm::dvec2> targets;
    };
    const std::vector<Case> cases{
        {"picmus",
         {"plane:0", "plane:10", "diverging:15", "diverging:50"},
         {{0.0, 20.0}, {-6.0, 30.0}, {4.0, 12.0}}},
        {"convex",
         {"diverging:49.57", "diverging:30:8", "plane:0"},
         {{0.0, 30.0}, {-12.0, 40.0}, {10.0, 20.0}}},
    };
    for (const Case& test_case : cases) {
        probe::Transducer t = probe::find_transducer(test_case.probe, "test");
        t.depth_mm = 45.0;
        const std::vector<Element> elements = elements_of(t);
        // df: the reference repeats every 1 / df = 100 us, longer than any channel here, so
        // the transmit's edge waves (not modelled) cannot fold onto the echo compared.
        const Spectrum spectrum = pulse_spectrum(t, 1e4);
        for (const std::string& scheme_text : test_case.schemes) {
            const probe::TransmitScheme scheme =
                probe::parse_transmit_scheme(scheme_text, "test", "transmit");
            const probe::TransmitWave& wave = scheme.waves[0];
            for (const glm::dvec2& target : test_case.targets) {
                SCOPED_TRACE(std::string(test_case.probe) + " " + scheme_text + " target (" +
                             std::to_string(target.x) + ", " + std::to_string(target.y) + ")");
                const ChannelData model =
                    channel_data(t, scheme, {{target, 1.0, 0.0, std::nullopt}}, {});
                // The element sum of the transmit at the target, at every frequency.
                std::vector<std::complex<double>> transmit(spectrum.f.size(), 0.0);
                for (std::size_t k = 0; k < spectrum.f.size(); ++k)
                    for (const Element& element : elements)
                        transmit[k] += element_wave(t, element, target, spectrum.f[k]) *
                                       std::polar(1.0, -2.0 * kPi * spectrum.f[k] *
                                                           wave_time(wave, element.position));
                // Each element's echo at the samples around its arrival.
                struct Measured {
                    Peak reference, simulated;
                    double residual;  // rms(simulated - reference) / rms(reference)
                };
                std::vector<Measured> measured;
                double strongest = 0.0;
                const int window = 64;
                const int pulse_reach =
                    int(std::ceil(probe::PulseEcho(t).half_length_s() * model.fs_hz));
                for (int e = 0; e < t.elements; ++e) {
                    const Element& element = elements[std::size_t(e)];
                    // Expected from geometry, only to place the window.
                    const double arrival =
                        wave_time(wave, target) + glm::length(target - element.position) / kC0;
                    const int centre = int(std::lround((arrival - model.start_s) * model.fs_hz));
                    const int from = centre - window;
                    ASSERT_GE(from, 0);
                    ASSERT_LT(centre + window, model.samples);
                    std::vector<std::complex<double>> receive(spectrum.f.size());
                    for (std::size_t k = 0; k < spectrum.f.size(); ++k)
                        receive[k] = spectrum.s[k] * transmit[k] *
                                     element_wave(t, element, target, spectrum.f[k]);
                    std::vector<float> reference(2 * window + 1), simulated(2 * window + 1);
                    for (int n = 0; n <= 2 * window; ++n) {
                        const double time = model.time_s(from + n);
                        std::complex<double> sum = 0.0;
                        for (std::size_t k = 0; k < spectrum.f.size(); ++k)
                            sum += receive[k] * std::polar(1.0, 2.0 * kPi * spectrum.f[k] * time);
                        reference[std::size_t(n)] = float(sum.real());
                        simulated[std::size_t(n)] = model.at(0, e, from + n);
                    }
                    double difference = 0.0, power = 0.0;
                    for (std::size_t n = std::size_t(window - pulse_reach);
                         n <= std::size_t(window + pulse_reach); ++n) {
                        difference += std::pow(double(simulated[n]) - reference[n], 2);
                        power += std::pow(double(reference[n]), 2);
                    }
                    measured.push_back({envelope_peak(reference), envelope_peak(simulated),
                                        std::sqrt(difference / power)});
                    strongest = std::max(strongest, measured.back().reference.height);
                }
                // Elements whose echo is within 12 dB of the strongest (beyond, the
                // directivity's nulls make a level in dB meaningless).
                int compared = 0;
                double worst_time = 0.0, worst_db = 0.0, worst_phase = 0.0, worst_residual = 0.0;
                for (const Measured& m : measured) {
                    if (m.reference.height < 0.25 * strongest) continue;
                    ++compared;
                    worst_time =
                        std::max(worst_time, std::abs(m.simulated.position - m.reference.position));
                    worst_db = std::max(worst_db, std::abs(20.0 * std::log10(m.simulated.height /
                                                                             m.reference.height)));
                    worst_residual = std::max(worst_residual, m.residual);
                    worst_phase = std::max(
                        worst_phase,
                        std::abs(std::arg(std::polar(1.0, m.simulated.phase - m.reference.phase))));
                }
                EXPECT_GE(compared, 32);
                EXPECT_LT(worst_time, 0.1) << "samples";
                EXPECT_LT(worst_db, 1.0) << "dB";
                // The waveform, sample by sample over the pulse's support (its shape, not only
                // its peak). The model leaves out the transmit's grating lobes (pitch 0.30 mm
                // against a wavelength of 0.296 mm at f0): their echo comes a few samples
                // after the main one where the scheme steers rays past the grating-lobe limit,
                // which validate_transmit_scheme warns of (diverging:15: residual up to 0.66
                // over 64 samples either side, 0.08 over the pulse); within the limit the
                // upper band's lobes still leave up to 0.06 (plane:10 at (-6, 30)).
                const bool past_limit =
                    !probe::validate_transmit_scheme(scheme, t, "test", "transmit").empty();
                if (!past_limit) {
                    EXPECT_LT(worst_residual, 0.1);
                }
                // The carrier too: a tenth of a sample's worth of its phase.
                EXPECT_LT(worst_phase, 2.0 * kPi * t.frequency_mhz * 1e6 * 0.1 / model.fs_hz)
                    << "rad";
                std::printf(
                    "%-7s %-16s (%5.1f, %5.1f): %3d elements, worst arrival %.3f samples, "
                    "worst level %.2f dB, worst phase %.3f rad, worst residual %.3f\n",
                    test_case.probe, scheme_text.c_str(), target.x, target.y, compared, worst_time,
                    worst_db, worst_phase, worst_residual);
            }
        }
    }
}

TEST(ChannelData, TransmitSchemesParseAndRefuseBadInput) {
    const auto plane = probe::parse_transmit_scheme("plane:-16:16:75", "--transmit", "");
    ASSERT_EQ(plane.waves.size(), 75u);
    EXPECT_NEAR(plane.waves.front().angle_rad, -16.0 * kPi / 180.0, 1e-12);
    EXPECT_NEAR(plane.waves[37].angle_rad, 0.0, 1e-12);
    EXPECT_EQ(probe::parse_transmit_scheme("plane:0,10", "--transmit", "").waves.size(), 2u);
    const auto diverging = probe::parse_transmit_scheme("diverging:15:-10:10:3", "--transmit", "");
    ASSERT_EQ(diverging.waves.size(), 3u);
    EXPECT_EQ(diverging.waves[2].source_distance_mm, 15.0);
    for (const char* bad :
         {"plane", "plane:", "plane:95", "plane:-90", "plane:0:10:0", "plane:0:10:2.5", "plane:nan",
          "plane:1,,2", "diverging:-5", "diverging:0", "diverging:x", "focused:3", "plane:0:1",
          "plane:0:10:1e9"}) {
        SCOPED_TRACE(bad);
        EXPECT_THROW(probe::parse_transmit_scheme(bad, "--transmit", ""), base::InputError);
    }
    const probe::Transducer picmus = probe::find_transducer("picmus", "test");
    EXPECT_TRUE(probe::validate_transmit_scheme(plane, picmus, "--transmit", "").empty());
    EXPECT_FALSE(
        probe::validate_transmit_scheme(probe::parse_transmit_scheme("plane:30", "--transmit", ""),
                                        picmus, "--transmit", "")
            .empty());
    // A convex array takes them where every element's ray heads into the tissue: not a
    // plane wave 60 degrees from the axis (97.5 degrees from the normal of the arc's end),
    // nor a source beside the array, in front of its end elements' faces.
    const probe::Transducer convex = probe::find_transducer("convex", "test");
    for (const char* good : {"plane:0", "diverging:49.57:-10:10:5", "diverging:5:85"}) {
        SCOPED_TRACE(good);
        EXPECT_NO_THROW(probe::validate_transmit_scheme(
            probe::parse_transmit_scheme(good, "--transmit", ""), convex, "--transmit", ""));
    }
    for (const char* bad : {"plane:60", "plane:-60", "diverging:40.3:83"}) {
        SCOPED_TRACE(bad);
        EXPECT_THROW(
            probe::validate_transmit_scheme(probe::parse_transmit_scheme(bad, "--transmit", ""),
                                            convex, "--transmit", ""),
            base::InputError);
    }
    // A ring has no side to send a wave from.
    EXPECT_THROW(probe::validate_transmit_scheme(plane, probe::find_transducer("radial", "test"),
                                                 "--transmit", ""),
                 base::InputError);
}

// Point targets under 1 plane wave and under 75 compounded over +-16 degrees: the lateral
// FWHM of the beamformer's image against an independent delay-and-sum written here (the
// channels' analytic signal upsampled 16 times by zero-padding their spectrum, nearest
// upsampled sample), and the narrowing against what the synthetic transmit aperture
// predicts: the broadband lateral response sum_f |S(f)| sum_w sum_e exp(i 2 pi f / c0 dx
// (sin theta_w + sin phi_e)) of the transmit angles theta_w and the directions phi_e from
// the target to the receiving elements, each way's lateral spatial frequencies added.
namespace compounding {

struct Profile {
    std::vector<double> x, value;
};
double fwhm(const Profile& p) {
    const int peak = int(std::max_element(p.value.begin(), p.value.end()) - p.value.begin());
    const double half = 0.5 * p.value[std::size_t(peak)];
    auto crossing = [&](int step) {
        for (int i = peak; i + step >= 0 && i + step < int(p.value.size()); i += step) {
            const double a = p.value[std::size_t(i)], b = p.value[std::size_t(i + step)];
            if (b <= half)
                return p.x[std::size_t(i)] +
                       (p.x[std::size_t(i + step)] - p.x[std::size_t(i)]) * (a - half) / (a - b);
        }
        return std::numeric_limits<double>::quiet_NaN();
    };
    return crossing(1) - crossing(-1);
}

}  // namespace compounding

TEST(ChannelData, CompoundingNarrowsPointsAsTheSyntheticApertureDoes) {
    using compounding::fwhm;
    using compounding::Profile;
    probe::Transducer t = probe::find_transducer("picmus", "test");
    t.depth_mm = 40.0;
    const std::vector<double> depths{15.0, 25.0, 35.0};
    std::vector<ChannelEcho> echoes;
    for (double z : depths) echoes.push_back({{0.0, z}, 1.0, 0.0, std::nullopt});
    const probe::TransmitScheme scheme = probe::parse_transmit_scheme("plane:-16:16:75", "t", "");
    const ChannelData channels = channel_data(t, scheme, echoes, {});
    const int single = 37;  // 0 degrees
    ASSERT_NEAR(scheme.waves[single].angle_rad, 0.0, 1e-12);
    DasSettings das;
    das.f_number = 1.75;
    das.apodization = probe::Apodization::rectangular;
    const double dx = 0.02;

    // The independent beamformer's channels: upsampled analytic signals, per transmit.
    const int up = 16, S = channels.samples;
    const int padded = cv::getOptimalDFTSize(S + 64);
    auto upsampled = [&](int w) {
        std::vector<std::vector<std::complex<float>>> out(std::size_t(channels.elements));
        for (int e = 0; e < channels.elements; ++e) {
            cv::Mat spectrum(1, padded, CV_32FC2, cv::Scalar::all(0));
            for (int n = 0; n < S; ++n) spectrum.at<cv::Vec2f>(0, n)[0] = channels.at(w, e, n);
            cv::dft(spectrum, spectrum);
            cv::Mat wide(1, padded * up, CV_32FC2, cv::Scalar::all(0));
            for (int k = 1; k < padded / 2; ++k)  // positive frequencies, doubled
                wide.at<cv::Vec2f>(0, k) = 2.0f * spectrum.at<cv::Vec2f>(0, k);
            cv::dft(wide, wide, cv::DFT_INVERSE);
            auto& v = out[std::size_t(e)];
            v.resize(std::size_t(padded * up));
            for (int n = 0; n < padded * up; ++n) {
                const cv::Vec2f& s = wide.at<cv::Vec2f>(0, n);
                v[std::size_t(n)] = std::complex<float>(s[0], s[1]) / float(padded);
            }
        }
        return out;
    };
    // The test's own delays: pixel (x_i, z) under transmit w, added to `sum`.
    auto add_transmit = [&](int w, const std::vector<std::vector<std::complex<float>>>& channel,
                            double z, const std::vector<double>& xs,
                            std::vector<std::complex<double>>& sum) {
        const double a = scheme.waves[std::size_t(w)].angle_rad;
        for (std::size_t i = 0; i < xs.size(); ++i) {
            const double transmit = (xs[i] * std::sin(a) + z * std::cos(a)) / kC0;
            for (int e = 0; e < channels.elements; ++e) {
                const double xe = channels.element_s_mm[std::size_t(e)];
                if (std::abs(xe - xs[i]) > 0.5 * z / das.f_number) continue;
                const double delay = transmit + std::hypot(xs[i] - xe, z) / kC0;
                const long n = std::lround((delay - channels.start_s) * channels.fs_hz * up);
                if (n >= 0 && n < long(channel[std::size_t(e)].size()))
                    sum[i] += std::complex<double>(channel[std::size_t(e)][std::size_t(n)]);
            }
        }
    };
    // The synthetic aperture's prediction (header), on the pulse's band.
    const Spectrum spectrum = pulse_spectrum(t, 2e5);
    auto predicted = [&](int first, int last, double z, const std::vector<double>& xs) {
        Profile p;
        for (double x : xs) {
            std::complex<double> sum = 0.0;
            for (std::size_t k = 0; k < spectrum.f.size(); ++k) {
                const double kx = 2.0 * kPi * spectrum.f[k] / kC0 * x;
                std::complex<double> transmit = 0.0, receive = 0.0;
                for (int w = first; w < last; ++w)
                    transmit +=
                        std::polar(1.0, kx * std::sin(scheme.waves[std::size_t(w)].angle_rad));
                for (double xe : channels.element_s_mm)
                    if (std::abs(xe) <= 0.5 * z / das.f_number)
                        receive += std::polar(1.0, kx * -xe / std::hypot(xe, z));
                sum += std::abs(spectrum.s[k]) * transmit * receive;
            }
            p.x.push_back(x);
            p.value.push_back(std::abs(sum));
        }
        return fwhm(p);
    };

    std::vector<double> xs;
    for (double x = -2.0; x <= 2.0 + 1e-9; x += dx) xs.push_back(x);
    // The beamformer's image around each target (the row of its brightest pixel), 1 and
    // 75 waves; then the independent sums on those rows, one pass over the transmits.
    const std::size_t D = depths.size();
    std::vector<std::array<double, 2>> width(D), row_depth(D), prediction(D);
    for (std::size_t d = 0; d < D; ++d) {
        for (int mode = 0; mode < 2; ++mode) {
            const int first = mode == 0 ? single : 0, last = mode == 0 ? single + 1 : 75;
            PixelGrid grid;
            grid.x0_mm = xs.front(), grid.dx_mm = dx, grid.nx = int(xs.size());
            grid.z0_mm = depths[d] - 0.3, grid.dz_mm = 0.02, grid.nz = 31;
            const BeamformedImage image = delay_and_sum(channels, t, grid, das, first, last);
            int best = 0;
            for (int k = 0; k < int(image.values.size()); ++k)
                if (std::abs(image.values[std::size_t(k)]) >
                    std::abs(image.values[std::size_t(best)]))
                    best = k;
            const int row = best / grid.nx;
            Profile p{xs, {}};
            for (int i = 0; i < grid.nx; ++i) p.value.push_back(std::abs(image.at(i, row)));
            width[d][std::size_t(mode)] = fwhm(p);
            row_depth[d][std::size_t(mode)] = grid.z(row);
            prediction[d][std::size_t(mode)] = predicted(first, last, depths[d], xs);
        }
    }
    std::vector<std::array<std::vector<std::complex<double>>, 2>> sums(D);
    for (auto& s : sums) s[0].assign(xs.size(), 0.0), s[1].assign(xs.size(), 0.0);
    for (int w = 0; w < 75; ++w) {
        const auto channel = upsampled(w);
        for (std::size_t d = 0; d < D; ++d) {
            add_transmit(w, channel, row_depth[d][1], xs, sums[d][1]);
            if (w == single) add_transmit(w, channel, row_depth[d][0], xs, sums[d][0]);
        }
    }
    for (std::size_t d = 0; d < D; ++d) {
        const double z = depths[d];
        std::array<double, 2> independent;
        for (int mode = 0; mode < 2; ++mode) {
            Profile p{xs, {}};
            for (const auto& v : sums[d][std::size_t(mode)]) p.value.push_back(std::abs(v));
            independent[std::size_t(mode)] = fwhm(p);
            EXPECT_NEAR(width[d][std::size_t(mode)], independent[std::size_t(mode)],
                        0.10 * independent[std::size_t(mode)])
                << "z " << z << (mode ? ", 75 waves" : ", 1 wave");
        }
        const double ratio = width[d][1] / width[d][0],
                     predicted_ratio = prediction[d][1] / prediction[d][0];
        std::printf(
            "z %.0f mm: FWHM 1 wave %.3f mm (independent %.3f, predicted %.3f), 75 "
            "waves %.3f mm (independent %.3f, predicted %.3f); ratio %.3f, predicted "
            "%.3f\n",
            z, width[d][0], independent[0], prediction[d][0], width[d][1], independent[1],
            prediction[d][1], ratio, predicted_ratio);
        EXPECT_NEAR(ratio, predicted_ratio, 0.15 * predicted_ratio) << "z " << z;
        EXPECT_LT(ratio, 0.9);
    }
}

// An anechoic cyst in speckle, under 1 plane wave and 75 compounded: the PICMUS
// measures by their definitions (contrast 20 log10 of the mean envelopes, gCNR one minus
// the overlap of the envelopes' histograms, speckle SNR mean over standard deviation of
// the envelope). Compounding lowers the clutter the unfocused transmit leaves in the cyst,
// so contrast and gCNR rise; the speckle stays Rayleigh (SNR 4 / sqrt(4 pi - pi^2) = 1.91
// for a fully developed speckle: Wagner et al. 1983), within 0.15.
TEST(ChannelData, CompoundingRaisesCystContrastAndKeepsSpeckleRayleigh) {
    probe::Transducer t = probe::find_transducer("picmus", "test");
    t.depth_mm = 40.0;
    const glm::dvec2 cyst(0.0, 25.0);
    const double radius = 3.0;
    const std::vector<ChannelEcho> echoes = channel_scatterers(
        t, {-9.0, 12.0}, {9.0, 38.0}, {},
        [&](const glm::dvec2& r) { return glm::length(r - cyst) < radius ? 0.0 : 1.0; });
    const probe::TransmitScheme scheme = probe::parse_transmit_scheme("plane:-16:16:75", "t", "");
    const ChannelData channels = channel_data(t, scheme, echoes, {});
    PixelGrid grid;
    grid.x0_mm = -7.0, grid.z0_mm = 14.0, grid.dx_mm = grid.dz_mm = 0.1;
    grid.nx = 141, grid.nz = 221;
    struct Measures {
        double contrast_db, gcnr, snr;
    };
    auto measure = [&](int first, int last) {
        const BeamformedImage image = delay_and_sum(channels, t, grid, DasSettings{}, first, last);
        std::vector<double> inside, outside;
        // Speckle SNR in depth bands of 4 mm (the receive aperture grows with depth, and
        // with it the level), averaged.
        std::vector<std::vector<double>> bands(std::size_t(grid.nz / 40 + 1));
        for (int j = 0; j < grid.nz; ++j)
            for (int i = 0; i < grid.nx; ++i) {
                const glm::dvec2 r(grid.x(i), grid.z(j));
                const double d = glm::length(r - cyst), v = std::abs(image.at(i, j));
                if (d < radius - 0.5) inside.push_back(v);
                if (d > radius + 0.5 && d < radius + 2.5) outside.push_back(v);
                if (d > radius + 1.0) bands[std::size_t(j / 40)].push_back(v);
            }
        auto mean = [](const std::vector<double>& v) {
            double s = 0.0;
            for (double x : v) s += x;
            return s / double(v.size());
        };
        double snr = 0.0, weight = 0.0;
        for (const auto& band : bands) {
            if (band.size() < 1000) continue;
            const double m = mean(band);
            double var = 0.0;
            for (double x : band) var += (x - m) * (x - m);
            snr += double(band.size()) * m / std::sqrt(var / double(band.size() - 1));
            weight += double(band.size());
        }
        // gCNR: 1 - sum of min of the two normalised histograms (100 bins over the range).
        const double top = std::max(*std::max_element(inside.begin(), inside.end()),
                                    *std::max_element(outside.begin(), outside.end()));
        std::vector<double> hi(100, 0.0), ho(100, 0.0);
        for (double v : inside)
            hi[std::min(std::size_t(99), std::size_t(v / top * 100.0))] +=
                1.0 / double(inside.size());
        for (double v : outside)
            ho[std::min(std::size_t(99), std::size_t(v / top * 100.0))] +=
                1.0 / double(outside.size());
        double overlap = 0.0;
        for (int k = 0; k < 100; ++k) overlap += std::min(hi[std::size_t(k)], ho[std::size_t(k)]);
        return Measures{20.0 * std::log10(mean(inside) / mean(outside)), 1.0 - overlap,
                        snr / weight};
    };
    const Measures one = measure(37, 38), all = measure(0, 75);
    std::printf(
        "1 wave: contrast %.1f dB, gCNR %.3f, speckle SNR %.3f; 75 waves: contrast %.1f "
        "dB, gCNR %.3f, speckle SNR %.3f (%zu scatterers)\n",
        one.contrast_db, one.gcnr, one.snr, all.contrast_db, all.gcnr, all.snr, echoes.size());
    EXPECT_LT(all.contrast_db, one.contrast_db - 3.0);
    EXPECT_GT(all.gcnr, one.gcnr + 0.02);
    EXPECT_NEAR(all.snr, 1.91, 0.15);
}

}  // namespace
}  // namespace sonotrace::imaging
