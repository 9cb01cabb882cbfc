// The Colin27 head preset at the default settings against the ray-cast reference
// (label slow: the 512 x 512 reference with 2 x 2 rays per pixel takes ~10 s).
#include <gtest/gtest.h>

#include "imaging/pbvr/pbvr.h"
#include "tissue/volume_io.h"

namespace sonotrace::imaging::pbvr {
namespace {

TEST(PbvrHead, PsnrRisesAndReaches35DbAtTheDefaultRepetitionCount) {
    const tissue::Volume head =
        tissue::load_volume({tissue::kDefaultVolumeName, std::nullopt}).volume;
    ColourTransferFunction tf = load_colour_tf("head");
    tf.bind(head);
    const RenderVolume volume(head, tf);
    const OrbitCamera camera =
        fit_camera(head.geometry(), kHeadAzimuthDeg, kHeadElevationDeg, 30.0, 512, 512);
    RenderSettings settings;  // the defaults
    settings.cut_away = facing_octant(head.geometry(), camera);
    const RgbImage reference = raycast(volume, tf, camera, settings, 0.25);
    PbvrRenderer renderer(volume, tf, camera, settings);
    std::vector<double> db;
    for (int r = 1; r <= settings.repetitions; ++r) {
        renderer.add_repetition();
        if (r == 3 || r == 8 || r == settings.repetitions)
            db.push_back(psnr(renderer.image(), reference));
    }
    ::testing::Test::RecordProperty(
        "psnr_3_8_default",
        std::to_string(db[0]) + " " + std::to_string(db[1]) + " " + std::to_string(db[2]));
    // Noise power falls as 1/N: +4.3 dB from 3 to 8 and +6 dB from 8 to 32 repetitions
    // if noise dominated; at least 3 dB each (the bias floor is ~40 dB, bench/README.md).
    EXPECT_GT(db[1], db[0] + 3.0);
    EXPECT_GT(db[2], db[1] + 3.0);
    EXPECT_GE(db[2], 35.0);
}

}  // namespace
}  // namespace sonotrace::imaging::pbvr
