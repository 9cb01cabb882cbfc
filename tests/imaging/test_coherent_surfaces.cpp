// imaging::surface_patches against surfaces known in closed form: echoes placed on a
// staircase of 0.25 mm texels (each at the texel boundary nearest its true depth, as a
// binary map would have them; worse than the tracer's +-0.09 mm) come back onto the true
// line or circle; echoes already on flat walls do not move, and two walls 1 mm apart are
// not mixed.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <vector>

#include "imaging/coherent_surfaces.h"

namespace sonotrace::imaging {
namespace {

constexpr double kTexel = 0.25;

SurfaceSmoothing smoothing() {
    SurfaceSmoothing s;
    s.link_mm = 4.0 * kTexel;  // as imaging/channel_frame.cpp
    s.window_mm = 16.0 * kTexel;
    return s;
}

// Vertical rays (a plane wave at 0 degrees) at 0.07 mm spacing meeting y = surface(x), the
// echo at the staircase's depth; returns the rms and the largest distance (mm, along the
// ray) from the true surface after the moves, and the rms before.
struct Residual {
    double before_rms, after_rms, after_max;
};
template <class Surface>
Residual staircase(double x0, double x1, Surface surface) {
    std::vector<SurfaceEcho> echoes;
    std::vector<double> truth;
    uint32_t particle = 0;
    for (double x = x0; x <= x1; x += 0.07, ++particle) {
        const double y = surface(x);
        truth.push_back(y);
        echoes.push_back({particle, 0, {x, kTexel * std::round(y / kTexel)}, {0.0, 1.0}});
    }
    const std::vector<SurfacePatch> patches = surface_patches(echoes, smoothing());
    Residual r{0.0, 0.0, 0.0};
    for (std::size_t k = 0; k < echoes.size(); ++k) {
        const double before = echoes[k].position.y - truth[k];
        const double after = before + patches[k].move_mm;
        r.before_rms += before * before;
        r.after_rms += after * after;
        r.after_max = std::max(r.after_max, std::abs(after));
    }
    r.before_rms = std::sqrt(r.before_rms / double(echoes.size()));
    r.after_rms = std::sqrt(r.after_rms / double(echoes.size()));
    return r;
}

TEST(CoherentSurfaces, ATiltedPlaneComesOffItsStaircase) {
    // A tenth of a wavelength at 5 MHz is 0.03 mm: the staircase (rms 0.07) is far off it.
    for (const double tilt : {10.0, 20.0, 35.0}) {
        const double slope = std::tan(tilt * std::numbers::pi / 180.0);
        const Residual r = staircase(-15.0, 15.0, [&](double x) { return 20.0 + slope * x; });
        std::printf("tilt %.0f: rms %.4f -> %.4f mm, largest %.4f\n", tilt, r.before_rms,
                    r.after_rms, r.after_max);
        EXPECT_GT(r.before_rms, 0.05);
        EXPECT_LT(r.after_rms, 0.015) << tilt;
        EXPECT_LT(r.after_max, 0.06) << tilt;
    }
}

TEST(CoherentSurfaces, ACurvedWallKeepsItsCurvature) {
    // The top of a 6 mm cyst (centre 26 mm deep) up to 40 degrees of incidence: a line fit
    // over the 4 mm window would leave its sagitta (0.33 mm); the quadratic follows it.
    const Residual r =
        staircase(-3.8, 3.8, [](double x) { return 26.0 - std::sqrt(36.0 - x * x); });
    std::printf("6 mm wall: rms %.4f -> %.4f mm, largest %.4f\n", r.before_rms, r.after_rms,
                r.after_max);
    EXPECT_LT(r.after_rms, 0.02);
    EXPECT_LT(r.after_max, 0.06);
}

TEST(CoherentSurfaces, FlatWallsStayAndDoNotMix) {
    // A plate's two walls 1 mm apart, each particle meeting both: nothing moves (a line
    // through exact points), and no chain joins the walls (that would pull both).
    std::vector<SurfaceEcho> echoes;
    for (uint32_t p = 0; p < 400; ++p) {
        const double x = -14.0 + 0.07 * p;
        echoes.push_back({p, 0, {x, 20.0}, {0.0, 1.0}});
        echoes.push_back({p, 0, {x, 21.0}, {0.0, 1.0}});
    }
    for (const SurfacePatch& p : surface_patches(echoes, smoothing())) {
        EXPECT_LT(std::abs(p.move_mm), 1e-9);
        // Each stands for the 0.07 mm between its neighbours, along the wall.
        EXPECT_NEAR(p.width_mm, 0.07, 1e-9);
        EXPECT_NEAR(std::abs(p.tangent.x), 1.0, 1e-9);
    }
}

TEST(CoherentSurfaces, ShortChainsStayAsTraced) {
    std::vector<SurfaceEcho> echoes;
    for (uint32_t p = 0; p < 4; ++p)
        echoes.push_back({p, 0, {0.07 * p, 20.1 * (p % 2)}, {0.0, 1.0}});
    for (const SurfacePatch& p : surface_patches(echoes, smoothing())) {
        EXPECT_EQ(p.move_mm, 0.0);
        EXPECT_EQ(p.width_mm, 0.0);
    }
}

}  // namespace
}  // namespace sonotrace::imaging
