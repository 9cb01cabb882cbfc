#include "phantoms/validation/head_frames.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "tissue/acoustic_map.h"

namespace sonotrace::validation {

imaging::ClearSamples TruthFrame::samples(int inside, int outside,
                                          const imaging::Clearance& clear_mm, double from_mm,
                                          double to_mm) const {
    return imaging::clear_samples(frame.envelope, probe::ScanGeometry(transducer), grid.to_map, map,
                                  labels, inside, outside, clear_mm, from_mm, to_mm);
}

std::shared_ptr<const scene::Scene> head_view(const std::string& view,
                                              imaging::SimulationSettings* s, double depth_mm) {
    scene::SceneOptions options;
    options.view = view;
    auto head = scene::load_scene(options);
    s->transducer = probe::find_transducer(head->probe_preset, "head_view");
    if (depth_mm > 0.0) s->transducer.depth_mm = depth_mm;
    head->apply_to(*s);
    // The display as `simulate` makes it: the scene's gain, the automatic TGC.
    s->imaging.gain_db = head->gain_db;
    const probe::Transducer& t = s->transducer;
    s->imaging.tgc = {{0.0, 0.0},
                      {t.depth_mm, imaging::automatic_tgc_db(t.frequency_mhz, t.depth_mm)}};
    return head;
}

TruthFrame truth_frame(const scene::Scene& head, imaging::SimulationSettings s, uint64_t seed) {
    s.seed = seed;
    TruthFrame t;
    if (s.trace_dimensions == 3) {  // traced in the elevation beam's slab, as `--trace 3d`
        imaging::PlaneScan scan = imaging::scan_plane(head.mapper, head.start, s, true);
        t.grid = scan.grid;
        t.labels = std::move(*scan.labels);
        t.map = imaging::frame_map(scan.maps, s);
        t.frame = std::move(scan.frame);
        t.transducer = s.transducer;
        return t;
    }
    t.grid = imaging::plane_grid(s.transducer, head.start.pose,
                                 imaging::quality_level(s.quality).map_pixel_mm);
    tissue::PropertyMaps maps = head.mapper(t.grid.geometry, &t.labels);
    imaging::prepare_plane(maps, t.grid, head.start, 5.0, &t.labels);
    t.map = imaging::frame_map(maps, s);
    t.frame = imaging::simulate_frame(t.map, t.grid, head.start.pose, s);
    t.transducer = s.transducer;
    return t;
}

NearSkull near_skull(const TruthFrame& truth, int line) {
    const probe::ScanGeometry g(truth.transducer);
    auto at = [&](double d) {
        const glm::dvec2 m = g.point(line, d) + truth.grid.to_map;
        return truth.map.sample(glm::vec2(m));
    };
    auto speed = [&](double d) { return tissue::kReferenceSpeed / double(at(d).refractive_index); };
    NearSkull s;
    for (double d = 1.0; d <= 40.0; d += 0.05) {
        if (speed(d) <= 2000.0) continue;
        glm::dvec2 normal(0.0);
        for (double e = d - 1.0; e <= d + 1.0; e += 0.05) {
            const auto texel = at(e);
            normal += glm::dvec2(texel.grad_impedance[0], texel.grad_impedance[1]);
        }
        const glm::dvec2 along = glm::normalize(g.point(line, d + 1.0) - g.point(line, d));
        const double cosine = std::abs(glm::dot(along, glm::normalize(normal)));
        double fastest = 0.0;
        for (double e = d; e <= d + 3.0; e += 0.05) fastest = std::max(fastest, speed(e));
        s.found = true;
        s.incidence_deg = std::acos(std::min(cosine, 1.0)) * 180.0 / std::numbers::pi;
        s.critical_deg =
            std::asin(std::min(speed(d - 1.0) / fastest, 1.0)) * 180.0 / std::numbers::pi;
        return s;
    }
    return s;
}

}  // namespace sonotrace::validation
