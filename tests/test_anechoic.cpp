// Anechoic regions stay dark, and the physics switches of `simulate --disable` do what
// they say.
//
// A CSF cylinder (no scatterers) 8 mm across in brain at the convex probe's transmit focus,
// the default frame's probe and quality: the envelope inside it (1 mm clear of its wall)
// against the brain beside it at the same depths. Linear acoustics bounds it: the only
// energy inside is the two-way PSF's tails from the brain 1 mm and more away, whose
// apodized side lobes lie below -30 dB; the issue asks 20 dB.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "imaging/simulation.h"
#include "phantoms/phantom.h"
#include "tissue/error.h"

namespace sonotrace {
namespace {

struct Contrast {
    double inside_db = 0.0, beside_mean_square = 0.0;
    int inside = 0, beside = 0;
};

Contrast cylinder_contrast(const imaging::PhysicsSwitches& physics) {
    const nlohmann::json j = {
        {"name", "csf cylinder"},
        {"size", {100, 90, 20}},
        {"resolution", 0.25},
        {"smoothing", 0.3},
        {"background", {{"tissue", "brain"}}},
        {"shapes", {{{"type", "wire"}, {"at", {50, 50}}, {"radius", 4}, {"tissue", "csf"}}}},
        {"probe", {{"preset", "convex"}, {"at", {50, 0, 10}}}}};
    const phantoms::Phantom ph = phantoms::parse_phantom(j, "test");
    imaging::SimulationSettings s;
    s.transducer = probe::find_transducer("convex", "test");
    s.trace.interface_reach_mm = 1.0;
    imaging::apply(physics, s);
    imaging::ScenePlacement scene;
    scene.pose = ph.pose;
    const imaging::PlaneMapper mapper = [&ph](const tissue::VolumeGeometry& grid,
                                              tissue::Volume* labels) {
        return phantoms::rasterise(ph, grid, labels);
    };
    const imaging::Frame f = imaging::simulate_plane(mapper, scene, s, false).frame;
    // The cylinder's centre in the probe plane: 50 mm straight down the central line.
    const probe::ScanGeometry g(s.transducer);
    const glm::dvec2 centre(0.0, 50.0);
    double in = 0.0, out = 0.0;
    Contrast c;
    for (int l = 0; l < f.envelope.lines; ++l) {
        for (int i = 0; i < f.envelope.samples; ++i) {
            const glm::dvec2 p = g.point(l, f.envelope.depth_mm(i));
            if (std::abs(p.y - centre.y) > 2.5) continue;  // the same depths
            const double d = glm::length(p - centre), v = f.envelope.at(l, i);
            if (d <= 3.0) in += v * v, ++c.inside;
            if (d >= 6.0 && d <= 12.0) out += v * v, ++c.beside;
        }
    }
    c.inside_db = 10.0 * std::log10((in / c.inside) / (out / c.beside) + 1e-30);
    c.beside_mean_square = out / c.beside;
    return c;
}

TEST(Anechoic, CsfCylinderInBrainStaysDarkWithEveryPhysicsOn) {
    const Contrast c = cylinder_contrast({});
    std::printf("CSF cylinder interior: %.1f dB against brain (%d / %d samples)\n", c.inside_db,
                c.inside, c.beside);
    ASSERT_GT(c.inside, 100);
    ASSERT_GT(c.beside, 100);
    EXPECT_LT(c.inside_db, -20.0);
}

TEST(Anechoic, DisabledPhysicsParsesNamesAndRefusesUnknownOnes) {
    const imaging::PhysicsSwitches p =
        imaging::disabled_physics("refraction,speckle", "--disable", "");
    EXPECT_FALSE(p.refraction);
    EXPECT_FALSE(p.speckle);
    EXPECT_TRUE(p.scattering && p.specular_reflection && p.diffuse_reflection && p.attenuation);
    EXPECT_EQ(imaging::disabled_physics("", "--disable", ""), imaging::PhysicsSwitches{});
    try {
        imaging::disabled_physics("refraction,gravity", "--disable", "");
        FAIL() << "accepted an unknown switch";
    } catch (const tissue::InputError& e) {
        EXPECT_NE(std::string(e.what()).find("gravity"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("--disable"), std::string::npos) << e.what();
    }
    // Applied: the tracer's and the image's settings follow.
    imaging::SimulationSettings s;
    imaging::apply(imaging::disabled_physics("scattering,bounces,face,attenuation", "-", ""), s);
    EXPECT_FALSE(s.trace.scattering);
    EXPECT_FALSE(s.trace.absorption);
    EXPECT_EQ(s.trace.max_bounces, 0);
    EXPECT_EQ(s.transducer.face_reflectivity, 0.0);
    EXPECT_TRUE(s.imaging.speckle);
}

TEST(Anechoic, SpeckleOffSilencesHomogeneousBrain) {
    // Homogeneous brain 2-8 mm beside the cylinder has no reflector: with the speckle
    // switched off it holds only the wall echoes' pulse tails, at least 60 dB below its
    // speckle.
    imaging::PhysicsSwitches off;
    off.speckle = false;
    const double with = cylinder_contrast({}).beside_mean_square;
    const double without = cylinder_contrast(off).beside_mean_square;
    EXPECT_LT(without, 1e-6 * with) << with << " " << without;
}

}  // namespace
}  // namespace sonotrace
