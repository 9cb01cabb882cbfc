// Frames traced in 3D (SimulationSettings::trace_dimensions = 3): the slab of the elevation
// beam, echoes projected on the plane. Expectations from the lens's elevation response
// computed here (the Rayleigh-Sommerfeld sum of tests/elevation_reference.h), not from the
// image pipeline; levels measured on the envelope.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <vector>

#include "imaging/simulation.h"
#include "phantoms/phantom.h"
#include "phantoms/scene/scene.h"
#include "probe/transducer.h"
#include "tests/elevation_reference.h"
#include "tissue/tissue_table.h"

namespace sonotrace {
namespace {

struct Envelope {
    imaging::LineData data;
    probe::Transducer t;
    // Mean intensity (envelope^2) over the lines within [x0, x1] mm of the probe's centre
    // and the samples within [z0, z1] mm of depth.
    double mean_intensity(double x0, double x1, double z0, double z1) const {
        const probe::ScanGeometry g(t);
        double sum = 0.0;
        int n = 0;
        for (int l = 0; l < data.lines; ++l) {
            const double x = g.point(l, 0.0).x;
            if (x < x0 || x > x1) continue;
            for (int i = 0; i < data.samples; ++i) {
                const double z = data.depth_mm(i);
                if (z < z0 || z > z1) continue;
                sum += double(data.at(l, i)) * data.at(l, i);
                ++n;
            }
        }
        return n > 0 ? sum / n : 0.0;
    }
};

Envelope frame_of(const nlohmann::json& phantom, const probe::Transducer& t, int dimensions,
                  uint64_t seed) {
    const auto scene = scene::phantom_scene(phantoms::parse_phantom(phantom, "test"));
    imaging::SimulationSettings settings;
    settings.transducer = t;
    settings.quality = imaging::Quality::standard;
    settings.seed = seed;
    settings.trace_dimensions = dimensions;
    scene->apply_to(settings);
    return {imaging::simulate_plane(scene->mapper, scene->start, settings, false).frame.envelope,
            t};
}

double db(double ratio) {
    return 10.0 * std::log10(ratio);
}

// A linear probe with a weak lens: a 4 mm slice at 20 mm (element height lambda F / 4 mm).
probe::Transducer thick_slice_probe() {
    probe::Transducer t = probe::find_transducer("linear", "test");
    t.elevation_focus_mm = 20.0;
    t.slice_thickness_mm = 4.0;
    t.depth_mm = 30.0;
    return t;
}

// A phantom that does not vary in elevation (liver with a fat layer across it): traced in
// 3D, every depth band's mean level equals the 2D frame's within 1.5 dB. The bands hold
// thousands of speckle cells (30 mm x 3-5 mm against cells of about 0.3 x 0.2 mm), whose
// mean has a relative spread of about 2 % (0.1 dB); the margin is for the particles'
// own sampling of the beam, which differs between the two traces.
TEST(Frames3d, AgreeWithTwoDimensionsWhereNothingVariesInElevation) {
    const nlohmann::json phantom = {{"name", "layers"},
                                    {"size", {40, 40, 40}},
                                    {"smoothing", 0.3},
                                    {"background", {{"tissue", "liver"}}},
                                    {"shapes",
                                     {{{"type", "layer"},
                                       {"point", {20, 14, 20}},
                                       {"normal", {0, 1, 0}},
                                       {"thickness", 4},
                                       {"tissue", "fat"}}}},
                                    {"probe", {{"preset", "linear"}}}};
    const probe::Transducer t = thick_slice_probe();
    const Envelope two = frame_of(phantom, t, 2, 5), three = frame_of(phantom, t, 3, 5);
    for (const auto& [z0, z1] : {std::pair{4.0, 9.0}, std::pair{14.5, 17.5}, std::pair{20.0, 25.0},
                                 std::pair{25.0, 29.0}}) {
        const double ratio =
            db(three.mean_intensity(-15, 15, z0, z1) / two.mean_intensity(-15, 15, z0, z1));
        std::printf("depth %.1f-%.1f mm: 3D / 2D %+.2f dB\n", z0, z1, ratio);
        EXPECT_NEAR(ratio, 0.0, 1.5) << z0 << "-" << z1 << " mm";
    }
}

// The slice-thickness artifact: anechoic spheres 3 mm across at the elevation focus, inside
// a 4 mm slice, fill in to the fraction of the slice's two-way intensity that lies beside
// them (|U|^4 of the lens over the elevation, integrated outside the sphere's chord and
// averaged over the measured disk of 0.6 mm, clear of the walls' echoes), within 3 dB; a
// sphere 12 mm across stays dark (more than 15 dB down). The 2D trace, which sees only the
// plane, leaves the small spheres dark. Depths are measured where the image puts them:
// liver is slower than the image's 1540 m/s.
TEST(Frames3d, CystsThinnerThanTheSliceFillInAsTheSliceThicknessPredicts) {
    const probe::Transducer t = thick_slice_probe();
    const double depth = t.elevation_focus_mm, radius = 1.5, disk = 0.6;
    const double apparent =
        depth * 1540.0 /
        double(tissue::find_tissue("liver", "", "").properties[tissue::Property::speed_of_sound]);
    nlohmann::json shapes = nlohmann::json::array();
    const std::vector<double> centres = {-12.0, -6.0, 0.0, 6.0, 12.0};
    for (double x : centres)
        shapes.push_back({{"type", "sphere"},
                          {"centre", {20 + x, depth, 20}},
                          {"radius", radius},
                          {"tissue", "water"}});
    const nlohmann::json small = {{"name", "small cysts"}, {"size", {40, 40, 40}},
                                  {"smoothing", 0.1},      {"background", {{"tissue", "liver"}}},
                                  {"shapes", shapes},      {"probe", {{"preset", "linear"}}}};
    // The expected fill-in: two-way intensity w(e) = (|U|^2)^2, outside the chord.
    auto w = [&](double e) {
        const double a = test::rayleigh_elevation_two_way(t, e, depth);
        return a * a;
    };
    const double de = 0.01, reach = 8.0;
    double total = 0.0;
    for (double e = -reach; e <= reach; e += de) total += w(e);
    // Averaged over the disk by area (rings of radius rho weighted by rho).
    double expected = 0.0, norm = 0.0;
    for (double rho = 0.025; rho < disk; rho += 0.05) {
        const double half_chord = std::sqrt(radius * radius - rho * rho);
        double inside = 0.0;
        for (double e = -half_chord; e <= half_chord; e += de) inside += w(e);
        expected += rho * (1.0 - inside / total);
        norm += rho;
    }
    expected /= norm;

    auto fill = [&](const Envelope& f) {
        double in = 0.0, beside = 0.0;
        for (double x : centres) {
            in += f.mean_intensity(x - disk, x + disk, apparent - disk, apparent + disk);
            beside += f.mean_intensity(x + 2.5, x + 3.5, apparent - disk, apparent + disk);
        }
        return db(in / beside);
    };
    const double three = fill(frame_of(small, t, 3, 7)), two = fill(frame_of(small, t, 2, 7));
    std::printf("3 mm cysts in a 4 mm slice: 3D %+.1f dB, predicted %+.1f dB; 2D %+.1f dB\n", three,
                db(expected), two);
    EXPECT_NEAR(three, db(expected), 3.0);
    EXPECT_LT(two, db(expected) - 6.0) << "the plane alone sees no tissue inside";

    nlohmann::json large = small;
    large["shapes"] = {
        {{"type", "sphere"}, {"centre", {20, depth, 20}}, {"radius", 6.0}, {"tissue", "water"}}};
    const Envelope big = frame_of(large, t, 3, 7);
    const double dark = db(big.mean_intensity(-2, 2, apparent - 1, apparent + 1) /
                           big.mean_intensity(-16, -10, apparent - 1, apparent + 1));
    std::printf("12 mm sphere in the same slice: %+.1f dB\n", dark);
    EXPECT_LT(dark, -15.0);
}

// Reverberation with the probe face in 3D (capture receive model: only particles that
// reach the face count, and the face reflects the fraction f of their energy back): over a
// flat reflector of intensity reflection R^2 in lossless water, the echo at twice its
// depth carries f R^2 of the first echo's energy, within 2 dB. The 3D beam's particles
// converge in elevation and return onto the element rectangle (the reflector lies before
// the lens's focus). (The 2D trace reads -8.1 dB here against -11.2 dB: its first echo
// is low; not this test's subject.)
TEST(Frames3d, TheProbeFaceReverberatesInThreeDimensions) {
    const double z_water = 1.48e6, z_plate = 3.0 * 1.48e6;  // R = (3 - 1) / (3 + 1) = 0.5
    const double r2 = std::pow((z_plate - z_water) / (z_plate + z_water), 2.0);
    const nlohmann::json phantom = {{"name", "plate"},
                                    {"size", {40, 40, 40}},
                                    {"smoothing", 0.0},
                                    {"background",
                                     {{"speed_of_sound", 1480},
                                      {"density", 1000},
                                      {"attenuation", 0.0},
                                      {"backscatter", 0},
                                      {"scatterer_density", 0},
                                      {"roughness", 0}}},
                                    {"shapes",
                                     {{{"type", "half_space"},
                                       {"point", {20, 8, 20}},
                                       {"normal", {0, 1, 0}},
                                       {"speed_of_sound", 1480},
                                       {"density", 3000},
                                       {"attenuation", 0.0},
                                       {"backscatter", 0},
                                       {"scatterer_density", 0},
                                       {"roughness", 0}}}},
                                    {"probe", {{"preset", "linear"}}}};
    probe::Transducer t = probe::find_transducer("linear", "test");
    t.depth_mm = 25.0;
    const double f = t.face_reflectivity;
    const auto scene = scene::phantom_scene(phantoms::parse_phantom(phantom, "test"));
    imaging::SimulationSettings settings;
    settings.transducer = t;
    settings.receive = imaging::ReceiveModel::capture;
    settings.trace_dimensions = 3;
    scene->apply_to(settings);
    const Envelope e{
        imaging::simulate_plane(scene->mapper, scene->start, settings, false).frame.envelope, t};
    // Echo times at 1540 m/s: the plate at 8 mm of 1480 m/s water images at 8.32 mm.
    const double first = 8.0 * 1540.0 / 1480.0;
    const double ratio = db(e.mean_intensity(-10, 10, 2 * first - 1, 2 * first + 1) /
                            e.mean_intensity(-10, 10, first - 1, first + 1));
    std::printf("3D: second echo / first %+.1f dB (f R^2: %+.1f dB)\n", ratio, db(f * r2));
    EXPECT_NEAR(ratio, db(f * r2), 2.0);
}

}  // namespace
}  // namespace sonotrace
