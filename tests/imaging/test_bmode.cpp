// Image formation: the pulse's axial resolution, fully developed speckle statistics, TGC
// and log compression against their closed forms, scan conversion of known points.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <numbers>
#include <random>

#include "imaging/anatomy_truth.h"
#include "imaging/bmode.h"
#include "imaging/scan_conversion.h"
#include "probe/aperture.h"
#include "probe/pulse.h"
#include "probe/transducer.h"
#include "simulator/trace_setups.h"
#include "tissue/acoustic_map.h"
#include "tissue/base/half_maximum.h"

namespace sonotrace {
namespace {

using imaging::LineData;

constexpr double kC0 = 1540.0;  // m/s

// `per_line` particles per line (one by default), each leaving the face along the line
// (an echo's range is that of its unfolded path).
probe::Sources<2> one_particle_per_line(const probe::Transducer& t, int per_line = 1) {
    const probe::ScanGeometry g(t);
    probe::Sources<2> sources(std::size_t(t.lines) * std::size_t(per_line));
    for (std::size_t s = 0; s < sources.size(); ++s) {
        const int l = int(s) / per_line;
        sources[s].line = uint32_t(l);
        sources[s].position = glm::vec2(g.line(l).origin);
        sources[s].direction = glm::vec2(g.line(l).direction);
    }
    return sources;
}

// One reflection event on line `line` at one-way time t, through the whole chain.
LineData point_echo_envelope(const probe::Transducer& t, double one_way_time_s, int line) {
    const probe::ScanGeometry g(t);
    const probe::Sources<2> sources = one_particle_per_line(t);
    simulator::EchoEvent<2> e;
    e.line = uint32_t(line);
    e.particle = 0;
    e.time_s = float(one_way_time_s);
    e.energy = 1.0f;
    e.weight = 0.5f;
    e.kind = simulator::EchoKind::specular;
    e.position = glm::vec2(g.point(line, one_way_time_s * kC0 * 1e3));
    imaging::ImagingSettings settings;
    settings.speckle = false;
    const LineData rf = imaging::synthesize_rf(t, sources, {e}, {}, {}, settings);
    return imaging::envelope(rf);
}

// The envelope of the linear preset for one reflection at 20 mm below its face on the
// central line, as `shape` sets the event (kind, normal, direction, incidence); met by
// `particles` particles of the line, each its own path, if more than one.
LineData reflection_envelope(const std::function<void(simulator::EchoEvent<2>&)>& shape,
                             int particles = 1) {
    const probe::Transducer t = probe::find_transducer("linear", "test");
    const probe::ScanGeometry g(t);
    const int line = t.lines / 2;
    const probe::Sources<2> sources = one_particle_per_line(t, particles);
    simulator::EchoEvent<2> e;
    e.line = uint32_t(line);
    e.time_s = float(20e-3 / kC0);
    e.energy = 1.0f;
    e.weight = 0.5f;
    e.position = glm::vec2(g.point(line, 20.0));
    e.normal = -glm::vec2(g.line(line).direction);  // a plane facing the probe
    e.direction = glm::vec2(g.line(line).direction);
    shape(e);
    std::vector<simulator::EchoEvent<2>> events(std::size_t(particles), e);
    for (int k = 0; k < particles; ++k) events[std::size_t(k)].particle = uint32_t(k);
    imaging::ImagingSettings settings;
    settings.speckle = false;
    return imaging::envelope(imaging::synthesize_rf(t, sources, events, {}, {}, settings));
}

// The share of an envelope's energy (envelope^2 summed) off its central line.
double share_off_the_central_line(const LineData& env) {
    double own = 0.0, all = 0.0;
    for (int l = 0; l < env.lines; ++l)
        for (int i = 0; i < env.samples; ++i) {
            const double p = double(env.at(l, i)) * double(env.at(l, i));
            all += p;
            if (l == env.lines / 2) own += p;
        }
    EXPECT_GT(all, 0.0);
    return 1.0 - own / all;
}

// Its peak envelope^2 on the central line.
double reflection_peak(const std::function<void(simulator::EchoEvent<2>&)>& shape) {
    const LineData env = reflection_envelope(shape);
    const int line = env.lines / 2;
    double peak = 0.0;
    for (int i = 0; i < env.samples; ++i) peak = std::max(peak, double(env.at(line, i)));
    return peak * peak;
}

// By reciprocity a reflector sends a particle's piece of the wavefront back to the
// aperture only if it faces that piece: a plane facing the probe but met by a piece that
// refraction turned by 20 degrees reflects it 40 degrees off its way back, beyond the
// linear preset's angular span at 20 mm (largest_sin_tilt: about 7 degrees of tilt), so
// next to nothing; the same plane tilted by the same 20 degrees faces the turned piece and
// echoes exactly as the untilted plane does the untouched beam. (The plane's tilt against
// the line alone got both the other way round.)
TEST(Bmode, AReflectorEchoesTheWavefrontItFaces) {
    const double face_on = reflection_peak([](auto& e) { e.kind = simulator::EchoKind::specular; });
    const glm::vec2 turned(std::sin(0.349f), std::cos(0.349f));  // 20 degrees off the line
    const double turned_piece = reflection_peak([&](auto& e) {
        e.kind = simulator::EchoKind::specular;
        e.direction = turned;
    });
    const double facing_turned = reflection_peak([&](auto& e) {
        e.kind = simulator::EchoKind::specular;
        e.direction = turned;
        e.normal = -turned;
    });
    ASSERT_GT(face_on, 0.0);
    EXPECT_LT(turned_piece, 1e-3 * face_on);
    EXPECT_NEAR(facing_turned, face_on, 1e-4 * face_on);
}

// A rough reflector sends back the share of its lobe cos^c about the mirror direction that
// heads back the way the particle came: at grazing incidence (87 degrees) the mirror lies
// 174 degrees from the way back, 4.7 to 5.8 lobe sigmas (1 / sqrt(3) rad for c = 3) over
// the receive's +-18 degrees at 20 mm: a Gaussian tail of 1.2e-6 against 0.42 at normal
// incidence, a ratio of 2.9e-6, whatever the plane's tilt to the line (here none; judged
// by that tilt, the grazing echo was as strong as the normal one).
TEST(Bmode, ARoughReflectorAtGrazingIncidenceSendsNothingBack) {
    auto rough = [](float cos_incidence) {
        return [cos_incidence](simulator::EchoEvent<2>& e) {
            e.kind = simulator::EchoKind::diffuse;
            e.lobe_exponent = 3.0f;
            e.cos_incidence = cos_incidence;
        };
    };
    const double normal = reflection_peak(rough(1.0f)), grazing = reflection_peak(rough(0.05f));
    ASSERT_GT(normal, 0.0);
    EXPECT_LT(grazing, 1e-5 * normal);
}

// After a reflection too, an echo comes back along the particle's path reversed only as
// far as its last reflector sends it back the way it came (reciprocity): a rough plane
// met at 87 degrees sends back the same Gaussian tail as above (ratio 2.9e-6), and a
// mirror met at 30 degrees sends everything 60 degrees off the way back, far outside the
// receive's +-18 degrees (a share below 1e-100 for its lobe of sigma 1e-3 rad), although
// both planes face the line. (Judged by that facing alone, a bounced particle meeting
// the skin at grazing incidence lit the temporal view's ventricles 37 dB above the brain.)
TEST(Bmode, AfterABounceAReflectorStillSendsBackOnlyWhatHeadsBack) {
    auto bounced = [](simulator::EchoKind kind, float lobe_exponent, float cos_incidence) {
        return [=](simulator::EchoEvent<2>& e) {
            e.kind = kind;
            e.bounces = 1;
            e.lobe_exponent = lobe_exponent;
            e.cos_incidence = cos_incidence;
        };
    };
    const double rough_normal = reflection_peak(bounced(simulator::EchoKind::diffuse, 3.0f, 1.0f));
    const double rough_grazing =
        reflection_peak(bounced(simulator::EchoKind::diffuse, 3.0f, 0.05f));
    ASSERT_GT(rough_normal, 0.0);
    EXPECT_LT(rough_grazing, 1e-5 * rough_normal);
    const double mirror_normal =
        reflection_peak(bounced(simulator::EchoKind::specular, 1e6f, 1.0f));
    const double mirror_oblique =
        reflection_peak(bounced(simulator::EchoKind::specular, 1e6f, 0.866f));
    ASSERT_GT(mirror_normal, 0.0);
    EXPECT_LT(mirror_oblique, 1e-6 * mirror_normal);
}

// Which echoes are drawn as clutter (imaging/incoherent_echoes.h). A rough interface's
// echo (EchoKind::diffuse) is a sum over its patch's random heights, so its phase is
// random; met after a mirror-like bounce by one particle alone, it is spread as incoherent
// intensity over a lone echo's kernel (a Gaussian of sigma 2.5 mm, over lines 0.3 mm apart
// here: 0.3 / (sqrt(2 pi) 2.5) = 5 % of it on the echo's own line in expectation, the rest
// on its neighbours). Met by 20 particles (more than the kernels' 16 neighbours within
// 2 mm: paths dense enough to image themselves, as a rough wire's ghost in a flat mirror),
// it stays a pulse on its own line, as a mirror's echo after the same bounce and a rough
// interface met directly do.
TEST(Bmode, AfterABounceALoneRoughEchoIsClutterAndAMirrorsEchoIsAPulse) {
    auto off_line_share = [](simulator::EchoKind kind, int bounces, int particles = 1) {
        return share_off_the_central_line(reflection_envelope(
            [&](simulator::EchoEvent<2>& e) {
                e.kind = kind;
                e.bounces = uint16_t(bounces);
                e.lobe_exponent = kind == simulator::EchoKind::diffuse ? 3.0f : 1e6f;
            },
            particles));
    };
    EXPECT_GT(off_line_share(simulator::EchoKind::diffuse, 1), 0.8);
    EXPECT_LT(off_line_share(simulator::EchoKind::diffuse, 1, 20), 1e-9);
    EXPECT_LT(off_line_share(simulator::EchoKind::specular, 1), 1e-9);
    EXPECT_LT(off_line_share(simulator::EchoKind::diffuse, 0), 1e-9);
}

// One particle's rough echo met directly, as `shape` sets it up: its share off the
// central line.
double off_line_share(const std::function<void(simulator::EchoEvent<2>&)>& shape) {
    return share_off_the_central_line(reflection_envelope([&](simulator::EchoEvent<2>& e) {
        e.kind = simulator::EchoKind::diffuse;
        e.lobe_exponent = 3.0f;
        shape(e);
    }));
}

// A rough echo met directly by a particle that refraction turned 60 degrees from its
// launch (beyond the beam's full angular width: the linear preset's receive half-angle at
// 20 mm is atan(aperture / 40 mm), under 30 degrees for any F-number above 0.87) and
// shown 30 mm from where it happened (beyond a lone kernel's reach of 3 x 2.5 mm) is a
// lone path's echo: clutter, more than 80 % of it off its line (5 % expected on it, as
// above). Turned as far but shown where it happened, or shown as far but not turned, it
// stays a pulse on its own line.
TEST(Bmode, ARoughEchoTurnedOffTheBeamAndShownFarFromItIsClutter) {
    const probe::Transducer t = probe::find_transducer("linear", "test");
    const probe::ScanGeometry g(t);
    const probe::ScanLine axis = g.line(t.lines / 2);
    const double turn = 60.0 / 180.0 * std::numbers::pi;
    ASSERT_LT(2.0 * std::atan(0.5 * t.receive_aperture_mm(20.0) / 20.0), 0.9 * turn);
    const glm::vec2 turned =
        glm::vec2(std::cos(turn) * glm::dvec2(axis.direction) +
                  std::sin(turn) * glm::dvec2(axis.direction.y, -axis.direction.x));
    const glm::vec2 aside = 30.0f * glm::vec2(axis.direction.y, -axis.direction.x);
    EXPECT_GT(off_line_share([&](auto& e) {
                  e.direction = turned;
                  e.position += aside;
              }),
              0.8);
    EXPECT_LT(off_line_share([&](auto& e) { e.direction = turned; }), 1e-9);
    EXPECT_LT(off_line_share([&](auto& e) { e.position += aside; }), 1e-9);
}

// FWHM of the envelope of line `l` around its peak, in mm of depth (linear interpolation).
double axial_fwhm_mm(const LineData& env, int l, double* peak_depth) {
    int peak = 0;
    for (int i = 0; i < env.samples; ++i)
        if (env.at(l, i) > env.at(l, peak)) peak = i;
    *peak_depth = env.depth_mm(peak);
    return base::half_maximum(env.samples, peak, [&](int i) { return env.at(l, i); }).width() *
           (env.depth_mm(1) - env.depth_mm(0));
}

// The envelope of a Gaussian-modulated cosine A exp(-t^2 / 2 s^2) cos(w t + phi) is its
// Gaussian, whatever the phase, to the spectral leakage of a pulse of ~7 cycles under its
// envelope (its spectrum's Gaussian at DC is exp(-(w s)^2 / 2) < 1e-20): 1e-4 of the peak
// bounds float rounding through two transforms. Lengths with an odd and an even padded
// transform size.
TEST(Bmode, EnvelopeOfAGaussianPulseIsItsGaussian) {
    for (const int samples : {1050, 1237}) {  // transforms of 1125 and 1350
        LineData rf;
        rf.lines = 5, rf.samples = samples, rf.fs_hz = 40e6;
        rf.values.assign(std::size_t(rf.lines) * std::size_t(samples), 0.0f);
        const double f0 = 5e6, sigma = 0.35e-6, w = 2.0 * std::numbers::pi * f0;
        auto gaussian = [&](int l, int i) {
            const double t = (i - samples / 2 - 40 * l) / rf.fs_hz;
            return 2.0 * std::exp(-0.5 * t * t / (sigma * sigma));
        };
        for (int l = 0; l < rf.lines; ++l) {
            const double phase = 1.3 * l;
            for (int i = 0; i < samples; ++i) {
                const double t = (i - samples / 2 - 40 * l) / rf.fs_hz;
                rf.at(l, i) = float(gaussian(l, i) * std::cos(w * t + phase));
            }
        }
        const LineData env = imaging::envelope(rf);
        ASSERT_EQ(env.samples, samples);
        for (int l = 0; l < rf.lines; ++l) {
            double worst = 0.0;
            for (int i = 0; i < samples; ++i)
                worst = std::max(worst, std::abs(double(env.at(l, i)) - gaussian(l, i)));
            EXPECT_LT(worst, 2.0 * 1e-4) << "line " << l << ", " << samples << " samples";
        }
    }
}

// An echo's envelope ends where its pulse ends, plus the Hilbert transformer's reach
// (48 samples): past that, where the RF is zero, the envelope is zero. The FFT's ideal
// transformer spread a strong near echo along the whole line 69 dB down, which the TGC
// raised into stripes at depth. Also the envelope at fs = 4 f0 (the frames' sampling):
// a Gaussian burst of 60 % bandwidth has its Gaussian as envelope within 2e-4 (the
// transformer's gain is 1 within 1e-4 over the burst's band; float rounding).
TEST(Bmode, AnEchosEnvelopeEndsWithItsPulse) {
    LineData rf;
    rf.lines = 3, rf.samples = 2000, rf.fs_hz = 4.0 * 3.5e6;
    rf.values.assign(std::size_t(rf.lines) * std::size_t(rf.samples), 0.0f);
    const double f0 = 3.5e6, w = 2.0 * std::numbers::pi * f0;
    // -6 dB fractional bandwidth 0.6: sigma_f = 0.6 f0 / (2 sqrt(2 ln 2)), sigma_t = 1 / (2 pi
    // sigma_f)
    const double sigma_t =
        1.0 / (2.0 * std::numbers::pi * 0.6 * f0 / (2.0 * std::sqrt(2.0 * std::log(2.0))));
    const int centre = 200, reach = int(std::ceil(6.0 * sigma_t * rf.fs_hz));
    auto gaussian = [&](int i) {
        const double t = (i - centre) / rf.fs_hz;
        return 1e3 * std::exp(-0.5 * t * t / (sigma_t * sigma_t));  // strong: a skull's echo
    };
    for (int l = 0; l < rf.lines; ++l)
        for (int i = std::max(0, centre - reach); i <= centre + reach; ++i)
            rf.at(l, i) = float(gaussian(i) * std::cos(w * (i - centre) / rf.fs_hz + 0.9 * l));
    const LineData env = imaging::envelope(rf);
    for (int l = 0; l < rf.lines; ++l) {
        double worst = 0.0;
        for (int i = 0; i < rf.samples; ++i)
            if (std::abs(i - centre) <= reach - 48)
                worst = std::max(worst, std::abs(double(env.at(l, i)) - gaussian(i)));
        EXPECT_LT(worst, 2e-4 * 1e3) << "line " << l;
        for (int i = centre + reach + 49; i < rf.samples; ++i)
            ASSERT_EQ(env.at(l, i), 0.0f) << "line " << l << ", sample " << i;
    }
}

// Axial FWHM of a point reflector within 20 % (issue) of the pulse's theoretical value
// c0/2 * 2 sqrt(2 ln 2) sigma_t, sigma_t = 2 sqrt(2 ln 2) / (2 pi B f0); and at its depth.
TEST(Bmode, PointEchoHasThePulsesAxialResolution) {
    for (const probe::Transducer& t : probe::transducer_presets()) {
        const double depth_mm = 0.5 * t.depth_mm;
        const LineData env = point_echo_envelope(t, depth_mm * 1e-3 / kC0, t.lines / 2);
        double peak_depth = 0.0;
        const double fwhm = axial_fwhm_mm(env, t.lines / 2, &peak_depth);
        // The pulse-echo waveform's envelope (checked against the excitation convolved with
        // the impulse response from first principles in test_psf), within 7 %: sampling at
        // 4 f0 and the envelope's linear interpolation between samples.
        const double expected = probe::PulseEcho(t).axial_fwhm_mm();
        EXPECT_NEAR(fwhm, expected, 0.07 * expected) << t.name;
        EXPECT_NEAR(peak_depth, depth_mm, env.depth_mm(1)) << t.name;
        // Other lines stay silent: a reflection belongs to the line whose particle made it.
        EXPECT_EQ(env.at(0, env.samples / 2), 0.0f) << t.name;
    }
}

// band_level_difference_db against band_contrast_db on developed speckle (exponential
// intensities, seed 5): an interior 10 dB below its surroundings reads -10 dB both ways,
// since the mean of 10 log10 of an exponential intensity lies 10 gamma / ln 10 = 2.51 dB
// below 10 log10 of its mean on both sides. The level's spread is 5.57 dB (pi 10 /
// (sqrt 6 ln 10)), so with 20,000 samples a side its standard error is 0.056 dB; 0.25 dB
// is 4.5 of them. One outside sample 10^5 times the mean (a lone heavy echo) lifts the
// outside's mean intensity sixfold, and its mean level by 50 dB / 20,000.
TEST(AnatomyTruth, ALoneHeavySampleMovesTheMeanIntensityNotTheMeanLevel) {
    std::mt19937_64 random(5);
    std::exponential_distribution<double> speckle(1.0);
    imaging::ClearSamples samples;
    std::vector<double> intensity;
    for (int n = 0; n < 40000; ++n) {
        imaging::TruthSample t;
        t.sample = n;
        t.depth_mm = 40.0 + 20.0 * double(n % 20000) / 20000.0;  // 10 bands of 2 mm
        const bool inside = n < 20000;
        intensity.push_back((inside ? 0.1 : 1.0) * speckle(random));
        (inside ? samples.inside : samples.outside).push_back(t);
    }
    auto mean_intensity = [&] {
        return imaging::band_contrast_db(samples, [&](const imaging::TruthSample& t) {
            return intensity[std::size_t(t.sample)];
        });
    };
    auto mean_level = [&] {
        return imaging::band_level_difference_db(samples, [&](const imaging::TruthSample& t) {
            return 10.0 * std::log10(intensity[std::size_t(t.sample)]);
        });
    };
    EXPECT_NEAR(mean_intensity(), -10.0, 0.25);
    EXPECT_NEAR(mean_level(), -10.0, 0.25);
    const double level_before = mean_level();
    intensity[30000] = 1e5;              // an outside sample
    EXPECT_LT(mean_intensity(), -17.0);  // 10 log10 (0.1 / 6): -17.8 dB
    EXPECT_NEAR(mean_level(), level_before, 0.01);
}

// The truth's refracted walk (imaging::TruthWalk::refracted) follows the ray equation
// d(n dr/ds)/ds = grad n. In a medium whose index grows across the line, n = 1 + a x, a
// ray launched along the line bends towards the higher index: its offset after a path s
// is a s^2 / 2, to first order in a s (a = 1e-3 /mm, s up to 30 mm: 0.45 mm, the next
// order a thousandth of it). The samples' points within 2 % of that (the walk's 0.02 mm
// Euler steps); the straight walk stays on the line.
TEST(AnatomyTruth, TheRefractedWalkBendsAsTheRayEquationSays) {
    probe::Transducer t = probe::find_transducer("linear", "test");
    t.depth_mm = 30.0;
    const probe::ScanGeometry g(t);
    const int line = t.lines / 2;
    const double h = 0.25, a = 1e-3, x0 = 25.0;
    const int n = 201;  // 50 mm square
    tissue::PropertyMaps maps =
        simulator::homogeneous(n, n, h, simulator::lossless_medium(1540.0, 1000.0));
    for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i)
            maps[tissue::Property::speed_of_sound].at(i, j) =
                float(tissue::kReferenceSpeed / (1.0 + a * (i * h - x0)));
    const auto map = tissue::AcousticMap<2>::build(maps);
    const tissue::Volume labels(maps[tissue::Property::speed_of_sound].geometry(), 1.0f);
    const glm::dvec2 to_map = glm::dvec2(x0, 5.0) - g.point(line, 0.0);
    const imaging::LineData envelope = imaging::rf_layout(t, imaging::ImagingSettings{});
    for (const auto walk : {imaging::TruthWalk::refracted, imaging::TruthWalk::straight}) {
        const imaging::ClearSamples samples =
            imaging::clear_samples(envelope, g, to_map, map, labels, 1, 2, 0.0, 5.0, 30.0, walk);
        int checked = 0;
        for (const imaging::TruthSample& s : samples.inside) {
            if (s.line != line) continue;
            const double expected =
                walk == imaging::TruthWalk::refracted ? 0.5 * a * s.depth_mm * s.depth_mm : 0.0;
            ASSERT_NEAR(s.map.x - x0, expected, 0.02 * expected + 1e-6) << s.depth_mm << " mm";
            ++checked;
        }
        EXPECT_GT(checked, 100);
    }
}

// A constant scattered intensity on every line and sample, from the line's axis.
simulator::EchoProfile<2> constant_profile(const probe::Transducer& t,
                                           const imaging::ImagingSettings& settings) {
    const LineData layout = imaging::rf_layout(t, settings);
    simulator::EchoProfile<2> profile;
    profile.lines = t.lines;
    profile.bins = layout.samples;
    profile.bin_s = 1.0 / layout.fs_hz;
    profile.intensity.assign(std::size_t(t.lines) * std::size_t(profile.bins), 1e-6f);
    profile.position.resize(profile.intensity.size());
    const probe::ScanGeometry g(t);
    for (int l = 0; l < t.lines; ++l)
        for (int i = 0; i < profile.bins; ++i)
            profile.position[std::size_t(l) * std::size_t(profile.bins) + std::size_t(i)] =
                glm::vec2(g.point(l, layout.depth_mm(i)));
    return profile;
}

// Fully developed speckle: with a constant scattered intensity, the envelope is Rayleigh
// distributed, mean/std = sqrt(pi / (4 - pi)) = 1.913. The issue asks 1.91 +- 0.15 at
// three depths; with 128 lines x ~60 samples (3 mm) per depth the estimate's own spread
// (~0.03) is far below that. Depth bands, not the whole line: the mean level follows the
// two-way beam's focusing, and mixing levels would lower the ratio.
// Also with the interactive preset's sub-lines 1.5 beam sigmas apart.
TEST(Bmode, FullyDevelopedSpeckleHasRayleighSnr) {
    for (const double spacing : {1.0, 1.5}) {
        const probe::Transducer t = probe::find_transducer("convex", "x");
        imaging::ImagingSettings settings;
        settings.sub_line_sigmas = spacing;
        const simulator::EchoProfile<2> profile = constant_profile(t, settings);
        probe::Sources<2> sources(1);
        const imaging::MapToWorld to_world;  // the map plane is the world's xy plane
        const LineData env =
            imaging::envelope(imaging::synthesize_rf(t, sources, {}, profile, to_world, settings));
        for (const double depth : {20.0, 40.0, 60.0}) {
            double sum = 0.0, sum2 = 0.0;
            int n = 0;
            const int from = int((depth - 1.5) / env.depth_mm(1)),
                      to = int((depth + 1.5) / env.depth_mm(1));
            for (int l = 0; l < t.lines; ++l) {
                for (int i = from; i < to; ++i) {
                    sum += env.at(l, i);
                    sum2 += double(env.at(l, i)) * env.at(l, i);
                    ++n;
                }
            }
            const double mean = sum / n, sd = std::sqrt(sum2 / n - mean * mean);
            EXPECT_NEAR(mean / sd, std::sqrt(std::numbers::pi / (4.0 - std::numbers::pi)), 0.15)
                << "sub-lines " << spacing << " sigmas apart, at " << depth << " mm";
        }
    }
}

TEST(Bmode, TgcAndLogCompressionFollowTheirFormulas) {
    const std::vector<imaging::TgcPoint> curve = {{10.0, 0.0}, {50.0, 20.0}, {80.0, 26.0}};
    EXPECT_DOUBLE_EQ(imaging::tgc_gain_db(curve, 0.0), 0.0);    // constant before
    EXPECT_DOUBLE_EQ(imaging::tgc_gain_db(curve, 30.0), 10.0);  // linear between
    EXPECT_DOUBLE_EQ(imaging::tgc_gain_db(curve, 65.0), 23.0);
    EXPECT_DOUBLE_EQ(imaging::tgc_gain_db(curve, 200.0), 26.0);  // constant after
    EXPECT_DOUBLE_EQ(imaging::tgc_gain_db({}, 40.0), 0.0);
    // 20 log10(e) + gain mapped from -range..0 dB onto 0..1.
    EXPECT_NEAR(imaging::log_compress(float(std::pow(10.0, -30.0 / 20.0)), 10.0, 60.0),
                (-30.0 + 10.0 + 60.0) / 60.0, 1e-6);
    EXPECT_EQ(imaging::log_compress(1.0f, 10.0, 60.0), 1.0f);  // clipped white
    EXPECT_EQ(imaging::log_compress(1e-9f, 0.0, 60.0), 0.0f);  // below the range: black
    EXPECT_EQ(imaging::log_compress(0.0f, 0.0, 60.0), 0.0f);

    // Compression: TGC applied at each sample's depth c0 t / 2.
    imaging::ImagingSettings s;
    s.tgc = {{0.0, 0.0}, {38.5, 20.0}};  // sample i sits at i * 0.0385 mm at 20 MHz
    s.gain_db = 30.0;
    s.dynamic_range_db = 40.0;
    const double fs = 20e6;
    const imaging::Compression compression(1000, fs, s);
    for (int i : {0, 250, 500, 999}) {
        const double depth = 0.5 * kC0 * (i / fs) * 1e3;
        const double db = -60.0 + 30.0 + std::min(20.0, 20.0 * depth / 38.5);
        EXPECT_NEAR(compression(1e-3f, compression.offset(i)),  // -60 dB
                    std::clamp((db + 40.0) / 40.0, 0.0, 1.0), 1e-5)
            << i;
    }
}

// A bright sample at (line, depth) lands at the pixel the probe geometry predicts,
// computed here from the textbook formulas, for the three probe types.
TEST(Bmode, ScanConversionPutsKnownPointsAtTheirPixels) {
    for (const probe::Transducer& t : probe::transducer_presets()) {
        imaging::ImagingSettings settings;
        LineData data = imaging::rf_layout(t, settings);
        data.values.assign(std::size_t(data.lines) * std::size_t(data.samples), 0.0f);
        const int line = data.lines / 5;
        const int sample = data.samples * 2 / 3;
        const double depth = data.depth_mm(sample);
        for (int i = sample - 8; i <= sample + 8; ++i)
            data.at(line, i) = 1.0f;  // finer than pixels
        const double pixel = 0.1;
        // The same lines as the display takes them: baseband 1 there, 0 elsewhere, shown
        // at level 1 (gain 0 dB) and 0.
        imaging::BasebandLines lines;
        lines.lines = data.lines, lines.samples = data.samples, lines.fs_hz = data.fs_hz;
        lines.sigma_samples = 2.0;
        for (float v : data.values) lines.values.emplace_back(v, 0.0f);
        imaging::ImagingSettings shown;
        shown.pixel_mm = pixel;
        for (const imaging::ScanConverted& sc : {imaging::scan_convert(data, t, pixel),
                                                 imaging::scan_convert_display(lines, t, shown)}) {
            // Centroid of the pixels brighter than half.
            glm::dvec2 sum(0.0);
            double weight = 0.0;
            for (int r = 0; r < sc.image.rows; ++r) {
                for (int c = 0; c < sc.image.cols; ++c) {
                    const float v = sc.image.at<float>(r, c);
                    if (v > 0.5f) sum += double(v) * glm::dvec2(c, r), weight += v;
                }
            }
            ASSERT_GT(weight, 0.0) << t.name;
            const glm::dvec2 found = sc.origin + sum / weight * pixel;
            glm::dvec2 expected;
            if (t.type == probe::TransducerType::linear) {
                const double span = t.elements * t.pitch_mm;
                expected = {-0.5 * span + (line + 0.5) * span / t.lines, depth};
            } else {
                // Fans from the arc's centre (0, -R): convex and radial arrays have an arc.
                const double r = t.type == probe::TransducerType::phased ? 0.0 : t.radius_mm;
                const double fov = t.fov_deg * std::numbers::pi / 180.0;
                const double angle = -0.5 * fov + (line + 0.5) * fov / t.lines;
                expected = {(r + depth) * std::sin(angle), (r + depth) * std::cos(angle) - r};
            }
            EXPECT_NEAR(found.x, expected.x, pixel) << t.name;
            EXPECT_NEAR(found.y, expected.y, pixel) << t.name;
            // Inside mask: the face's centre line is inside, a far corner is not.
            EXPECT_EQ(sc.inside.at<uint8_t>(sc.inside.rows - 1, 0),
                      t.type == probe::TransducerType::linear ? 255 : 0)
                << t.name;
        }
    }
}

// A radial array's frame is a full annulus around the ring: every pixel between the ring
// and the imaging depth is inside, also between the last line and the first (where the
// numbering wraps), and a field constant over the lines reads constant there.
TEST(ScanConversion, ARadialFrameClosesTheCircle) {
    probe::Transducer t = probe::find_transducer("radial", "test");
    t.lines = 64;
    LineData data;
    data.lines = t.lines;
    data.fs_hz = 20e6;
    data.samples = int(std::ceil(2.0 * t.depth_mm * 1e-3 / kC0 * data.fs_hz)) + 1;
    data.values.assign(std::size_t(data.lines) * std::size_t(data.samples), 0.0f);
    for (int l = 0; l < t.lines; ++l)
        for (int i = 0; i < data.samples; ++i) data.at(l, i) = 1.0f + 0.5f * float(l == 0);
    const double pixel = 0.2;
    const imaging::ScanConverted frame = imaging::scan_convert(data, t, pixel, -1.0f);
    const glm::dvec2 centre(0.0, -t.radius_mm);
    int checked = 0, outside = 0;
    double seam_low = 2.0, seam_high = 0.0;
    for (int k = 0; k < 3600; ++k) {
        const double angle = 2.0 * std::numbers::pi * k / 3600.0;
        for (double r :
             {t.radius_mm + 1.0, t.radius_mm + 0.5 * t.depth_mm, t.radius_mm + t.depth_mm - 1.0}) {
            const glm::dvec2 p = centre + r * glm::dvec2(std::sin(angle), std::cos(angle));
            const int c = int(std::lround((p.x - frame.origin.x) / pixel)),
                      row = int(std::lround((p.y - frame.origin.y) / pixel));
            ASSERT_TRUE(c >= 0 && row >= 0 && c < frame.image.cols && row < frame.image.rows);
            ++checked;
            if (!frame.inside.at<uint8_t>(row, c)) {
                ++outside;
                continue;
            }
            const float v = frame.image.at<float>(row, c);
            EXPECT_GE(v, 1.0f - 1e-6f);
            EXPECT_LE(v, 1.5f + 1e-6f);
            // Near the seam (angle pi, where line 0 starts and line L-1 ends), values blend
            // line 0's 1.5 and line L-1's 1.
            if (std::abs(angle - std::numbers::pi) < 2.0 * std::numbers::pi / t.lines)
                seam_low = std::min(seam_low, double(v)),
                seam_high = std::max(seam_high, double(v));
        }
    }
    EXPECT_EQ(outside, 0) << "of " << checked;
    // Halfway between line L-1 and line 0 the two blend equally: 1.25 (a scan conversion
    // that clamped to the end lines would read 1 or 1.5 there). At mid-depth the lines lie
    // 2.5 mm apart, so the pixel grid's 0.1 mm offset moves the blend by under 0.05.
    {
        const glm::dvec2 p = centre + (t.radius_mm + 0.5 * t.depth_mm) * glm::dvec2(0.0, -1.0);
        const int c = int(std::lround((p.x - frame.origin.x) / pixel)),
                  row = int(std::lround((p.y - frame.origin.y) / pixel));
        EXPECT_NEAR(frame.image.at<float>(row, c), 1.25f, 0.05f);
    }
    EXPECT_LT(seam_low, 1.1);   // line L-1's value is reached on one side of the seam
    EXPECT_GT(seam_high, 1.4);  // and line 0's on the other
}

// The display pairs a radial array's last line with its first: lines of one level whose
// phase alternates by a third of a turn read that level everywhere between lines, the
// seam included (the power the phase step takes midway, 1 - 3 f (1 - f), restored from
// the pair's own means; paired with itself, the seam would dip 6 dB midway).
TEST(ScanConversion, TheDisplayAcrossARadialSeamPairsTheLastLineWithTheFirst) {
    probe::Transducer t = probe::find_transducer("radial", "test");
    t.lines = 64;
    imaging::BasebandLines lines;
    lines.lines = t.lines;
    lines.fs_hz = 20e6;
    lines.samples = int(std::ceil(2.0 * t.depth_mm * 1e-3 / kC0 * lines.fs_hz)) + 1;
    lines.sigma_samples = 2.0;
    for (int l = 0; l < t.lines; ++l)
        for (int i = 0; i < lines.samples; ++i)
            lines.values.push_back(std::polar(1.0f, float(l % 2) * 2.0f * 3.14159265f / 3.0f));
    imaging::ImagingSettings settings;
    settings.pixel_mm = 0.2;
    settings.gain_db = -30.0;  // level 1 shown at (60 - 30) / 60 = 0.5
    const imaging::ScanConverted frame = imaging::scan_convert_display(lines, t, settings);
    const glm::dvec2 centre(0.0, -t.radius_mm);
    double lowest = 1.0, highest = 0.0;
    for (int k = 0; k < 3600; ++k) {
        const double angle = 2.0 * std::numbers::pi * k / 3600.0;
        const glm::dvec2 p = centre + (t.radius_mm + 0.5 * t.depth_mm) *
                                          glm::dvec2(std::sin(angle), std::cos(angle));
        const int c = int(std::lround((p.x - frame.origin.x) / settings.pixel_mm)),
                  row = int(std::lround((p.y - frame.origin.y) / settings.pixel_mm));
        ASSERT_TRUE(frame.inside.at<uint8_t>(row, c));
        const double v = frame.image.at<float>(row, c);
        lowest = std::min(lowest, v), highest = std::max(highest, v);
    }
    // 0.01 of the 60 dB range: 0.6 dB.
    EXPECT_NEAR(lowest, 0.5, 0.01);
    EXPECT_NEAR(highest, 0.5, 0.01);
}

}  // namespace
}  // namespace sonotrace
