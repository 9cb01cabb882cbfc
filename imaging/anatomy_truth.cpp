#include "imaging/anatomy_truth.h"

#include <cmath>

namespace sonotrace::imaging {

ClearSamples clear_samples(const LineData& envelope, const probe::ScanGeometry& geometry,
                           const glm::dvec2& to_map, const tissue::AcousticMap<2>& map,
                           const tissue::Volume& labels, int inside_label, int outside_label,
                           const Clearance& clear_mm, double from_mm, double to_mm,
                           TruthWalk walk) {
    ClearSamples out;
    const glm::dvec3 h = labels.geometry().spacing;
    const glm::ivec3 dims = labels.geometry().dims;
    auto label_at = [&](int i, int j) {
        return i < 0 || j < 0 || i >= dims.x || j >= dims.y ? -1 : int(labels.at(i, j, 0));
    };
    const bool nominal = walk == TruthWalk::nominal, bent = walk == TruthWalk::refracted;
    for (int l = 0; l < envelope.lines; ++l) {
        double travelled = 0.0, optical = 0.0;
        glm::dvec2 at = geometry.point(l, 0.0) + to_map, along = geometry.line(l).direction;
        constexpr double ds = 0.02;  // mm of the walk
        for (int i = 0; i < envelope.samples; ++i) {
            const double displayed = envelope.depth_mm(i);
            while (!nominal && optical < displayed) {
                if (bent) {  // midpoint rule: the index and its gradient half a step on
                    const glm::dvec2 mid = at + 0.5 * ds * along;
                    if (!map.inside(glm::vec2(mid))) break;
                    const auto texel = map.sample(glm::vec2(mid));
                    const double n = texel.refractive_index;
                    const glm::dvec2 grad(texel.grad_refractive_index[0],
                                          texel.grad_refractive_index[1]);
                    optical += ds * n;
                    at += ds * along;
                    along = glm::normalize(along + ds * (grad - glm::dot(grad, along) * along) / n);
                } else {
                    const glm::dvec2 q = geometry.point(l, travelled + 0.5 * ds) + to_map;
                    optical += ds * map.sample_refractive_index(glm::vec2(q));
                }
                travelled += ds;
            }
            if (bent && optical < displayed) break;  // the ray left the map
            const double d = nominal ? displayed : travelled;
            if (d < from_mm || d > to_mm) continue;
            const glm::dvec2 m = bent ? at : geometry.point(l, d) + to_map;
            const int ti = int(std::floor(m.x / h.x + 0.5)), tj = int(std::floor(m.y / h.y + 0.5));
            const int label = label_at(ti, tj);
            if (label != inside_label && label != outside_label) continue;
            const int r = int(std::ceil(clear_mm.at_depth(d) / h.x));
            bool clear = true;
            for (int dj = -r; dj <= r && clear; ++dj)
                for (int di = -r; di <= r && clear; ++di)
                    clear = di * di + dj * dj > r * r || label_at(ti + di, tj + dj) == label;
            if (!clear) continue;
            (label == inside_label ? out.inside : out.outside).push_back({l, i, d, m});
        }
    }
    return out;
}

}  // namespace sonotrace::imaging
