// Image formation from linear acoustics: the pulse-echo waveform and the two-way
// point-spread function of a point target, measured on the simulated image (RF lines ->
// envelope) and compared with predictions computed here, independently of the image
// pipeline: the excitation convolved with the impulse response by direct summation and its
// envelope by a brute-force discrete Fourier transform. (The lateral resolution against an
// element sum written out there and against sinc^2: the validation case `resolution`.)
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <complex>
#include <cstdio>
#include <cstring>
#include <numbers>
#include <random>
#include <vector>

#include "imaging/bmode.h"
#include "imaging/psf.h"
#include "imaging/receive_weights.h"
#include "imaging/simulation.h"
#include "probe/aperture.h"
#include "probe/beam.h"
#include "probe/elevation.h"
#include "probe/pulse.h"
#include "probe/transducer.h"
#include "tests/elevation_reference.h"
#include "tests/test_util.h"

namespace sonotrace {
namespace {

constexpr double kC0 = 1540.0;  // m/s
constexpr double kPi = std::numbers::pi;

// The pulse-echo envelope's FWHM (s) of a Gaussian band from first principles: n cycles
// of a sine convolved with the Gaussian-modulated cosine of -6 dB bandwidth B (its DC
// removed), summed directly; the envelope through the analytic signal of a brute-force DFT.
double gaussian_pulse_fwhm_s(double f0, double bandwidth, double cycles) {
    const double dt = 1.0 / (40.0 * f0);
    const double sigma_t = 2.0 * std::sqrt(2.0 * std::log(2.0)) / (2.0 * kPi * bandwidth * f0);
    const double w = 2.0 * kPi * f0;
    const int h_half = int(8.0 * sigma_t / dt), e_len = int(std::lround(cycles * 40.0));
    const int n = 2 * h_half + e_len + 200;
    std::vector<double> p(std::size_t(n), 0.0);
    for (int i = 0; i < e_len; ++i) {
        for (int k = -h_half; k <= h_half; ++k) {
            const double t = k * dt;
            const double h = std::exp(-0.5 * t * t / (sigma_t * sigma_t)) *
                             (std::cos(w * t) - std::exp(-0.5 * w * w * sigma_t * sigma_t));
            p[std::size_t(100 + i + k + h_half)] += std::sin(w * (i + 0.5) * dt) * h;
        }
    }
    // Analytic signal: keep the positive frequencies (doubled), drop the negative ones.
    std::vector<std::complex<double>> spectrum(static_cast<std::size_t>(n));
    for (int k = 0; k < n; ++k)
        for (int i = 0; i < n; ++i)
            spectrum[std::size_t(k)] += p[std::size_t(i)] * std::polar(1.0, -2.0 * kPi * k * i / n);
    std::vector<double> envelope(static_cast<std::size_t>(n));
    for (int i = 0; i < n; ++i) {
        std::complex<double> a = 0.0;
        for (int k = 1; 2 * k < n; ++k)
            a += 2.0 * spectrum[std::size_t(k)] * std::polar(1.0, 2.0 * kPi * k * i / n);
        envelope[std::size_t(i)] = std::abs(a) / n;
    }
    return test::peak_width_samples(envelope) * dt;
}

// The same for any band shape, from the band's definition: |H(f)| the generalized
// Gaussian through -6 dB at f0 (1 +- B6 / 2) and -20 dB at f0 (1 +- B20 / 2). The analytic
// impulse response h(t) = integral over f > 0 of 2 |H(f)| exp(i 2 pi f t) df by the
// midpoint rule (no FFT), convolved in time with the n sine cycles; FWHM of its modulus.
double reference_pulse_fwhm_s(double f0, double b6, double b20, double cycles) {
    const double p = std::log(std::log(10.0) / std::log(2.0)) / std::log(b20 / b6);
    auto band = [&](double f) {
        return std::exp(-std::log(2.0) * std::pow(std::abs(f - f0) / (0.5 * b6 * f0), p));
    };
    const double df = f0 / 400.0, dt = 1.0 / (40.0 * f0);
    const double support = 8.0 / (b6 * f0);  // the response has rung down (checked below)
    const int h_half = int(support / dt), e_len = int(std::lround(cycles * 40.0));
    std::vector<std::complex<double>> h(std::size_t(2 * h_half + 1));
    for (int k = -h_half; k <= h_half; ++k) {
        std::complex<double> sum = 0.0;
        for (double f = 0.5 * df; f < f0 * (1.0 + 2.0 * b20); f += df)
            sum += 2.0 * band(f) * std::polar(1.0, 2.0 * kPi * f * k * dt);
        h[std::size_t(k + h_half)] = sum * df;
    }
    EXPECT_LT(std::abs(h.front()), 1e-3 * std::abs(h[std::size_t(h_half)]));
    const int n = 2 * h_half + e_len;
    std::vector<std::complex<double>> a(static_cast<std::size_t>(n));
    for (int i = 0; i < e_len; ++i)
        for (int k = 0; k <= 2 * h_half; ++k)
            a[std::size_t(i + k)] += std::sin(2.0 * kPi * f0 * (i + 0.5) * dt) * h[std::size_t(k)];
    std::vector<double> envelope(static_cast<std::size_t>(n));
    for (int i = 0; i < n; ++i) envelope[std::size_t(i)] = std::abs(a[std::size_t(i)]);
    return test::peak_width_samples(envelope) * dt;
}

// LineFields::sum skips the zero weights at an aperture's ends (they add +-0). The same
// sum with those weights replaced by 1e-300, which is non-zero in double (so nothing is
// skipped) and 0 in float (so each term is the same zero), runs the whole loop: the two
// must be the same bits, for transmit- and receive-like apertures at many points.
TEST(Psf, SkippingAnAperturesZeroWeightsChangesNoBit) {
    std::mt19937 random(5);
    std::uniform_real_distribution<double> across(-15.0, 15.0), depth(1.0, 80.0);
    for (const char* preset : {"linear", "convex", "phased"}) {
        const probe::Transducer t = probe::find_transducer(preset, "test");
        for (const int line : {0, t.lines / 3, t.lines - 1}) {
            const probe::LineFields fields(t, probe::line_array(t, line));
            for (const double focus : {10.0, 25.0, 60.0}) {
                const std::vector<double> weights = fields.receive_aperture(focus).weights;
                std::vector<double> padded = weights;
                int zeros = 0;
                for (double& w : padded)
                    if (w == 0.0) w = 1e-300, ++zeros;
                for (int k = 0; k < 50; ++k) {
                    const glm::dvec2 q(across(random), depth(random));
                    const std::complex<double> skipped = fields.sum(q, weights, {0.0, focus});
                    const std::complex<double> whole = fields.sum(q, padded, {0.0, focus});
                    ASSERT_EQ(std::memcmp(&skipped, &whole, sizeof skipped), 0)
                        << preset << " line " << line << " focus " << focus << " zeros " << zeros;
                }
            }
        }
    }
}

TEST(Psf, PulseEnvelopeMatchesTheExcitationConvolvedWithTheImpulseResponse) {
    // The band's definition: -6 dB and -20 dB at the stated widths.
    for (const double shape : {1.3, 1.5, 2.2}) {
        const double f0 = 5e6, b6 = 0.7, b20 = shape * b6;
        for (const double side : {-1.0, 1.0}) {
            EXPECT_NEAR(
                probe::PulseEcho::transducer_response(f0 * (1 + side * b6 / 2), f0, b6, shape), 0.5,
                1e-12);
            EXPECT_NEAR(
                probe::PulseEcho::transducer_response(f0 * (1 + side * b20 / 2), f0, b6, shape),
                0.1, 1e-12);
        }
    }
    for (const auto& [f0, b, shape, cycles] :
         std::vector<std::tuple<double, double, double, double>>{{7.6e6, 0.79, 1.5, 1.0},
                                                                 {3.5e6, 0.86, 1.5, 1.0},
                                                                 {2.7e6, 0.74, 1.3, 3.0},
                                                                 {5.0e6, 0.5, 2.2, 2.0}}) {
        const probe::PulseEcho pulse(f0, b, shape, cycles);
        const double expected = reference_pulse_fwhm_s(f0, b, shape * b, cycles);
        EXPECT_NEAR(pulse.envelope_fwhm_s(), expected, 0.02 * expected) << f0 << " " << cycles;
    }
    // The Gaussian band (B20 / B6 = sqrt(ln 10 / ln 2)) is the Gaussian-modulated cosine.
    const double gaussian = std::sqrt(std::log(10.0) / std::log(2.0));
    for (const auto& [f0, b, cycles] :
         std::vector<std::tuple<double, double, double>>{{7.6e6, 0.79, 1.0}, {2.7e6, 0.74, 3.0}}) {
        const double expected = gaussian_pulse_fwhm_s(f0, b, cycles);
        EXPECT_NEAR(probe::PulseEcho(f0, b, gaussian, cycles).envelope_fwhm_s(), expected,
                    0.02 * expected);
    }
    // A flatter-topped band of the same -6 dB width rings longer.
    EXPECT_GT(probe::PulseEcho(5e6, 0.8, 1.3, 1.0).envelope_fwhm_s(),
              1.1 * probe::PulseEcho(5e6, 0.8, gaussian, 1.0).envelope_fwhm_s());
    // More cycles: a narrower spectrum, a longer echo.
    EXPECT_GT(probe::PulseEcho(5e6, 0.8, 1.5, 4.0).envelope_fwhm_s(),
              1.5 * probe::PulseEcho(5e6, 0.8, 1.5, 1.0).envelope_fwhm_s());
}

struct PointImage {
    std::vector<double> line_x, lateral, axial;  // lateral: peak per line; axial: centre line
    double sample_mm = 0.0;
};

// A point at (x0, z) imaged by `t` (no tracing: a point target through the RF chain).
PointImage image_point(const probe::Transducer& t, double x0, double z) {
    imaging::ImagingSettings settings;
    settings.speckle = false;
    imaging::MapToWorld to_world;  // map frame = probe plane
    const imaging::LineData rf =
        imaging::synthesize_rf(t, {}, {}, {}, to_world, settings, {{glm::dvec2(x0, z), 1.0}});
    const imaging::LineData env = imaging::envelope(rf);
    PointImage out;
    const probe::ScanGeometry g(t);
    const int centre_sample = int(std::lround(z / env.depth_mm(1)));
    int best_line = 0;
    for (int l = 0; l < env.lines; ++l) {
        double peak = 0.0;
        for (int i = std::max(0, centre_sample - 20); i < std::min(env.samples, centre_sample + 20);
             ++i)
            peak = std::max(peak, double(env.at(l, i)));
        out.line_x.push_back(g.point(l, 0.0).x);
        out.lateral.push_back(peak);
        if (peak > out.lateral[std::size_t(best_line)]) best_line = l;
    }
    for (int i = 0; i < env.samples; ++i) out.axial.push_back(env.at(best_line, i));
    out.sample_mm = env.depth_mm(1);
    return out;
}

probe::Transducer linear_for_psf(double rx_f_number) {
    probe::Transducer t = probe::find_transducer("linear", "test");
    t.lines = 768;  // 0.05 mm apart: a FWHM of 0.2-0.5 mm spans 4-10 lines
    t.rx_f_number = rx_f_number;
    return t;
}

// Axial FWHM of the point's echo within 10 % of the pulse-echo waveform's envelope
// (computed above from first principles).
TEST(Psf, PointTargetAxialResolutionIsThePulseEnvelope) {
    const probe::Transducer t = linear_for_psf(2.0);
    for (const double z : {10.0, 20.0, 30.0}) {
        const PointImage image = image_point(t, 0.013, z);
        const double measured = test::peak_width_samples(image.axial) * image.sample_mm;
        const double expected = 0.5 * kC0 * 1e3 *
                                reference_pulse_fwhm_s(t.frequency_mhz * 1e6, t.bandwidth,
                                                       t.band_shape * t.bandwidth, t.cycles);
        std::printf("axial FWHM at %.0f mm: %.3f mm (pulse envelope %.3f)\n", z, measured,
                    expected);
        EXPECT_NEAR(measured, expected, 0.1 * expected) << z;
        EXPECT_NEAR(test::argmax(image.axial) * image.sample_mm, z, image.sample_mm) << z;
    }
}

// The cores' cell lookup (a speed-up) answers as the plain search over every core does:
// random cores of mixed radii and random queries, many near the cores' edges.
TEST(Psf, TargetCoresAnswerAsTheSearchOverEveryCore) {
    std::mt19937 rng(5);
    std::uniform_real_distribution<double> at(-5.0, 5.0), radius(0.01, 0.6);
    std::vector<imaging::PointEcho> points;
    for (int k = 0; k < 300; ++k) points.push_back({{at(rng), at(rng)}, 1.0, radius(rng)});
    const imaging::TargetCores cores(points);
    int inside = 0;
    for (int n = 0; n < 20000; ++n) {
        glm::dvec2 q(at(rng), at(rng));
        if (n % 2 == 0) {  // on a random core's rim, within a hair either side
            const auto& p = points[std::size_t(n / 2) % points.size()];
            const double a = at(rng);
            q = p.position +
                (p.core_radius_mm + 1e-9 * at(rng)) * glm::dvec2(std::cos(a), std::sin(a));
        }
        bool expected = false;
        for (const auto& p : points)
            expected = expected || glm::length(q - p.position) <= p.core_radius_mm;
        ASSERT_EQ(cores.contains(q), expected) << q.x << ", " << q.y;
        inside += expected;
    }
    EXPECT_GT(inside, 2000);
    EXPECT_FALSE(imaging::TargetCores({}).contains({0.0, 0.0}));
}

TEST(Psf, ImpossibleAperturesAreRefusedNamingTheField) {
    auto refused = [](auto change, const char* field) {
        probe::Transducer t = probe::find_transducer("linear", "test");
        change(t);
        try {
            t.validate("probe.json");
            ADD_FAILURE() << field << " accepted";
        } catch (const std::exception& e) {
            EXPECT_NE(std::string(e.what()).find(field), std::string::npos) << e.what();
        }
    };
    refused([](probe::Transducer& t) { t.rx_f_number = 0.0; }, "rx-f-number");
    refused([](probe::Transducer& t) { t.rx_f_number = -1.0; }, "rx-f-number");
    refused([](probe::Transducer& t) { t.rx_f_number = std::nan(""); }, "rx-f-number");
    refused([](probe::Transducer& t) { t.cycles = 0.0; }, "cycles");
    EXPECT_THROW(probe::parse_apodization("gaussian", "probe.json", "rx-apodization"),
                 std::exception);
}

}  // namespace
}  // namespace sonotrace

namespace sonotrace {
namespace {

// receive_weights keeps the weights of the particles it last saw: the same particles
// (relative to the face) give the same weights wherever the probe stands, and a change of
// any value the weights are made from makes them again, with the change in them.
TEST(Psf, ReceiveWeightsAreKeptForTheSameParticlesOnly) {
    const probe::Transducer t = probe::find_transducer("linear", "test");
    const glm::dvec2 face(30.0, 2.0);
    const probe::Sources<2> sources = probe::make_beams(t, {16, 7}, face);
    const auto first = imaging::receive_weights(t, sources, face);
    EXPECT_EQ(imaging::receive_weights(t, sources, face), first) << "kept";
    // Rows follow the particles within their lines; make_beams emits line by line.
    for (std::size_t q = 1; q < sources.size(); ++q)
        ASSERT_LE(sources[q - 1].line, sources[q].line);
    const std::size_t p = sources.size() / 2, row = p;  // a particle of a central line
    using Change = void (*)(probe::SourceParticle<2>&);
    const Change changes[] = {
        [](probe::SourceParticle<2>& s) { s.position.x += 0.3f; },
        [](probe::SourceParticle<2>& s) {
            s.direction = glm::normalize(s.direction + glm::vec2(0.05f, 0.0f));
        },
        [](probe::SourceParticle<2>& s) { s.time_s += 2e-7f; },
        [](probe::SourceParticle<2>& s) { s.energy *= 3.0f; },
    };
    for (std::size_t c = 0; c < std::size(changes); ++c) {
        probe::Sources<2> changed = sources;
        changes[c](changed[p]);
        const auto again = imaging::receive_weights(t, changed, face);
        ASSERT_NE(again, first) << "change " << c;
        // The changed particle's weights (or, for its energy, the line mean and so every
        // particle's) differ somewhere along its row.
        bool differs = false;
        for (int b = 0; b < first->bins; ++b)
            differs |= again->weight[row * std::size_t(first->bins) + std::size_t(b)] !=
                       first->weight[row * std::size_t(first->bins) + std::size_t(b)];
        if (c == 3) {
            for (std::size_t q = 0; q < first->weight.size() && !differs; ++q)
                differs = again->weight[q] != first->weight[q];
        }
        EXPECT_TRUE(differs) << "change " << c;
    }
    // The whole frame moved by 4 mm: the same particles relative to the face up to the
    // floats' rounding of the moved positions (1e-6 mm), so the same weights within it.
    probe::Sources<2> moved = sources;
    for (auto& s : moved) s.position += glm::vec2(4.0f, 0.0f);
    const auto shifted = imaging::receive_weights(t, moved, face + glm::dvec2(4.0, 0.0));
    ASSERT_EQ(shifted->weight.size(), first->weight.size());
    for (std::size_t q = 0; q < first->weight.size(); ++q)
        ASSERT_NEAR(shifted->weight[q], first->weight[q], 1e-3f * (1.0f + first->weight[q])) << q;
}

}  // namespace
}  // namespace sonotrace

namespace sonotrace {
namespace {

// PulseEcho::analytic (both parts from one table position: the reflections' pulses ask
// for every sample) is in_phase + i quadrature, bit for bit, inside and beyond the support.
TEST(Psf, PulseAnalyticIsInPhaseAndQuadratureBitForBit) {
    const probe::PulseEcho pulse(5e6, 0.6, 1.5, 2.0);
    const double reach = 1.2 * pulse.half_length_s();
    long differing = 0, nonzero = 0;
    for (int n = -5000; n <= 5000; ++n) {
        const double t = reach * n / 5000.0;
        const std::complex<double> a = pulse.analytic(t);
        const double p = pulse.in_phase(t), q = pulse.quadrature(t), ap = a.real(), aq = a.imag();
        differing += std::memcmp(&p, &ap, sizeof p) != 0 || std::memcmp(&q, &aq, sizeof q) != 0;
        nonzero += p != 0.0;
    }
    EXPECT_EQ(differing, 0);
    EXPECT_GT(nonzero, 7000);
}

TEST(Speckle, FourSubLinesAtATimeAddAsOneAtATime) {
    std::mt19937 rng(11);
    std::normal_distribution<float> normal;
    const int N = 37, sub_lines = 23;
    std::vector<float> sub(std::size_t(N) * std::size_t(sub_lines));
    std::vector<float> f(static_cast<std::size_t>(N));
    for (float& v : sub) v = normal(rng);
    for (float& v : f) v = std::uniform_real_distribution<float>(0.0f, 1.0f)(rng);
    std::vector<std::complex<float>> w0(static_cast<std::size_t>(sub_lines));
    std::vector<std::complex<float>> w1(w0.size());
    for (std::size_t j = 0; j < w0.size(); ++j)
        w0[j] = {normal(rng), normal(rng)}, w1[j] = {normal(rng), normal(rng)};
    const int centre = 11;  // the line's own sub-line
    for (int j_first = -11; j_first <= -5; ++j_first)
        for (int j_last = j_first; j_last <= 11; ++j_last) {
            std::vector<float> fast_i(std::size_t(N), 0.5f), fast_q(std::size_t(N), -0.25f);
            std::vector<float> plain_i = fast_i, plain_q = fast_q;
            const int begin = 3, end = N - 2;
            imaging::detail::add_weighted_sub_lines(w0.data() + centre, w1.data() + centre, j_first,
                                                    j_last, sub.data() + std::size_t(centre * N), N,
                                                    f.data(), begin, end, fast_i.data(),
                                                    fast_q.data());
            for (int j = j_first; j <= j_last; ++j) {  // the loop it replaced
                const std::complex<float> h0 = w0[std::size_t(centre + j)],
                                          h1 = w1[std::size_t(centre + j)];
                const float* v = sub.data() + std::size_t((centre + j) * N);
                for (int i = begin; i < end; ++i) {
                    plain_i[std::size_t(i)] +=
                        (h0.real() + f[std::size_t(i)] * (h1.real() - h0.real())) * v[i];
                    plain_q[std::size_t(i)] +=
                        (h0.imag() + f[std::size_t(i)] * (h1.imag() - h0.imag())) * v[i];
                }
            }
            ASSERT_EQ(std::memcmp(fast_i.data(), plain_i.data(), fast_i.size() * 4), 0)
                << j_first << ".." << j_last;
            ASSERT_EQ(std::memcmp(fast_q.data(), plain_q.data(), fast_q.size() * 4), 0)
                << j_first << ".." << j_last;
        }
}

}  // namespace
}  // namespace sonotrace
