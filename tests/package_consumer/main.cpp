// One frame of a catalogue phantom through the installed library: load the scene, set the
// probe it is meant for, simulate the plane with its labels. Exit 0 when the frame has an
// image and the labels show more than one tissue.
#include <cstdio>
#include <set>

#include "imaging/simulation.h"
#include "phantoms/scene/scene.h"
#include "probe/transducer.h"
#include "tissue/base/error.h"

int main() {
    using namespace sonotrace;
    try {
        scene::SceneOptions options;
        options.phantom = SONOTRACE_PHANTOMS "/cyst_and_stone.json";
        const auto scene = scene::load_scene(options);
        imaging::SimulationSettings settings;
        settings.transducer = probe::find_transducer(scene->probe_preset, "consumer");
        settings.quality = imaging::Quality::interactive;
        scene->apply_to(settings);
        const imaging::SimulatedFrame result =
            imaging::simulate_plane(scene->mapper, scene->start, settings, /*with_labels=*/true);
        const cv::Mat& image = result.frame.image.image;
        std::set<int> labels;
        for (int r = 0; r < result.labels->rows; ++r) {
            for (int c = 0; c < result.labels->cols; ++c)
                labels.insert(result.labels->at<uint8_t>(r, c));
        }
        std::printf("consumer: %dx%d frame, %zu labels\n", image.cols, image.rows, labels.size());
        return image.empty() || labels.size() < 2 ? 1 : 0;
    } catch (const base::InputError& e) {
        std::fprintf(stderr, "consumer: %s\n", e.what());
        return 1;
    }
}
