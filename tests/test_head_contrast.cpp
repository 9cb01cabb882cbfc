// The default head's lateral ventricles seen through the skull (the transtemporal view),
// against the parenchyma at the same depths, on the envelope (issue 29: anechoic regions
// dark, at least 12 dB below the parenchyma here). Why dark: CSF holds no scatterers
// (backscatter 0 in the tissue table), so linear acoustics images its interior only
// through the PSF's reach from the walls; what else lights it is the model's doing.
// Measured as bench/ventricle_contrast measures it: frames of seeds 1-4 summed (a single
// frame is dominated by a few rays), the interior CSF 1 mm clear of other labels, 40 to
// 100 mm deep (the ventricles, not the sulci under the temple), each sample placed by
// walking its line through the map's speed of sound.
#include <gtest/gtest.h>

#include <cstdio>

#include "imaging/anatomy_truth.h"
#include "imaging/scene/scene.h"
#include "imaging/simulation.h"
#include "tissue/tissue_table.h"
#include "tissue/transfer_function.h"

namespace sonotrace::imaging {
namespace {

TEST(HeadContrast, TheTemporalViewsVentriclesAreDarkerThanTheParenchymaBy12dB) {
    SceneOptions options;
    options.view = "temporal";
    const auto head = load_scene(options);
    SimulationSettings s;
    s.transducer = probe::find_transducer("phased", "test");
    head->apply_to(s);
    const int csf = tissue::tissue_label_of("csf"), brain = tissue::tissue_label_of("brain");
    ClearSamples all;  // every seed's samples, `sample` indexing `intensities`
    std::vector<double> intensities;
    for (uint64_t seed = 1; seed <= 4; ++seed) {
        s.seed = seed;
        const PlaneGrid grid =
            plane_grid(s.transducer, head->start.pose, quality_level(s.quality).map_pixel_mm);
        tissue::Volume labels;
        tissue::PropertyMaps maps = head->mapper(grid.geometry, &labels);
        prepare_plane(maps, grid, head->start, 5.0, &labels);
        const auto map = frame_map(maps, s);
        const Frame frame = simulate_frame(map, grid, head->start.pose, s);
        const ClearSamples samples =
            clear_samples(frame.envelope, probe::ScanGeometry(s.transducer), grid.to_map, map,
                          labels, csf, brain, 1.0, 40.0, 100.0);
        for (const auto* list : {&samples.inside, &samples.outside})
            for (TruthSample t : *list) {
                const double e = frame.envelope.at(t.line, t.sample);
                t.sample = int(intensities.size());
                intensities.push_back(e * e);
                (list == &samples.inside ? all.inside : all.outside).push_back(t);
            }
    }
    ASSERT_GT(all.inside.size(), 500u) << "too few interior samples to measure";
    const double db = band_contrast_db(
        all, [&](const TruthSample& t) { return intensities[std::size_t(t.sample)]; });
    std::printf("temporal ventricles against parenchyma: %.1f dB (%zu interior samples)\n", db,
                all.inside.size());
    EXPECT_LT(db, -12.0);
}

}  // namespace
}  // namespace sonotrace::imaging
