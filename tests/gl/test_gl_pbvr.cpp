// The GPU path of the GUI's 3D context and of `render --renderer gpu` (ui/gl/gl_pbvr.h)
// against the CPU renderer, in the headless OpenGL 3.3 core context the command line
// opens (ui/gl/headless_gl.h: EGL, Mesa's llvmpipe on a machine without GPU): the same particles
// (PbvrRenderer::splats), drawn with OpenGL's depth test and averaged on the GPU, give
// the CPU's ensemble image. The expectation is the CPU renderer's own image, which the
// PBVR tests validate against the emission-absorption ray caster; the two differ only
// where particles tie in depth or sit on a disc's edge within float rounding. Stated
// tolerance: PSNR of 40 dB or more over all pixels and channels.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "imaging/pbvr/overlay.h"
#include "imaging/pbvr/pbvr.h"
#include "probe/transducer.h"
#include "ui/gl/gl_pbvr.h"
#include "ui/gl/headless_gl.h"

namespace sonotrace {
namespace {

using namespace imaging::pbvr;

// Nested shells with a smooth modulation: surfaces at several depths, ties rare.
tissue::Volume shells() {
    tissue::VolumeGeometry g;
    g.dims = {64, 64, 64};
    g.spacing = glm::dvec3(1.0);
    tissue::Volume v(g);
    for (int k = 0; k < 64; ++k)
        for (int j = 0; j < 64; ++j)
            for (int i = 0; i < 64; ++i) {
                const double r = glm::length(glm::dvec3(i, j, k) - 31.5);
                const double shell = 0.5 + 0.5 * std::cos(r * 0.45);
                v.at(i, j, k) = float(r < 30.0 ? shell * (0.6 + 0.4 * std::sin(0.2 * i)) : 0.0);
            }
    return v;
}

TEST(GlPbvr, TheGpuImageIsTheCpuImageOfTheSameParticles) {
    const gl::HeadlessGl context;  // throws (the test fails) without an OpenGL 3.3 context
    std::printf("OpenGL renderer: %s\n", context.renderer().c_str());
    const tissue::Volume volume = shells();
    ColourTransferFunction tf = load_colour_tf("ramp");
    tf.bind(volume);
    const RenderVolume render_volume(volume, tf);
    const OrbitCamera camera = fit_camera(volume.geometry(), 35.0, 20.0, 30.0, 240, 180);
    RenderSettings settings;
    settings.subpixel_level = 2;
    settings.seed = 3;
    settings.background = glm::vec3(0.05f, 0.1f, 0.15f);
    // A B-mode frame through the centre, as the GUI overlays it.
    FrameOverlay overlay;
    overlay.frame = cv::Mat(80, 100, CV_8U);
    for (int r = 0; r < 80; ++r)
        for (int c = 0; c < 100; ++c) overlay.frame.at<uint8_t>(r, c) = uint8_t((r * 3 + c) % 256);
    overlay.transducer = probe::find_transducer("linear", "test");
    overlay.origin_mm = {-20.0, 0.0};
    overlay.pixel_mm = {0.4, 0.4};
    overlay.position = {31.5, 31.5, 5.0};
    overlay.axial = {0.0, 0.0, 1.0};
    overlay.lateral = {1.0, 0.0, 0.0};
    overlay.elevation = {0.0, 1.0, 0.0};
    const std::vector<uint64_t> layer = overlay_layer(overlay, camera, settings.subpixel_level);

    PbvrRenderer cpu(render_volume, tf, camera, settings);
    cpu.set_overlay(layer);
    gl::GlPbvr gpu(camera.width, camera.height, settings.subpixel_level, settings.background);
    gpu.set_overlay(layer);
    constexpr int kRepetitions = 6;
    std::size_t particles = 0;
    for (int r = 0; r < kRepetitions; ++r) {
        const std::vector<Splat> splats = cpu.splats(uint32_t(r));
        particles += splats.size();
        gpu.add_repetition(splats);
        ASSERT_TRUE(cpu.add_repetition());
    }
    const RgbImage reference = cpu.image(), image = gpu.image();
    ASSERT_EQ(image.width, reference.width);
    // Not a blank image: the shells cover much of the view.
    double mean = 0.0;
    for (const glm::vec3& p : reference.pixels) mean += p.x + p.y + p.z;
    mean /= 3.0 * double(reference.pixels.size());
    EXPECT_GT(mean, 0.15) << "the reference shows nothing";
    EXPECT_EQ(gpu.clipped(), 0u);
    // splats() lists what add_repetition draws (those whose discs reach a sub-pixel).
    EXPECT_EQ(uint64_t(particles), cpu.particles_drawn());
    const double db = psnr(image, reference);
    std::printf("%zu particles in %d repetitions: GPU against CPU %.1f dB\n", particles,
                kRepetitions, db);
    EXPECT_GE(db, 40.0);
    // And one repetition fewer on the GPU is visibly different: the comparison can fail.
    gl::GlPbvr short_of_one(camera.width, camera.height, settings.subpixel_level,
                            settings.background);
    short_of_one.set_overlay(layer);
    for (int r = 1; r < kRepetitions; ++r) short_of_one.add_repetition(cpu.splats(uint32_t(r)));
    EXPECT_LT(psnr(short_of_one.image(), reference), db - 3.0);
}

}  // namespace
}  // namespace sonotrace
