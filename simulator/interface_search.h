#pragma once
// The interface search of the tracer (simulator/tracer.cpp), private to it: whether a
// particle stands on a sharp transition (a plateau on each side within reach) or a graded
// medium, and for a sharp one its patch normal, middle, plateaus and roughness
// (InterfaceSides), found once per texel and trace (InterfaceCache). What an interface
// event then does with the sides is interface_events.h's (crossing_of, reflection_at).
#include <algorithm>
#include <cmath>
#include <cstdint>

#include "simulator/batch.h"
#include "simulator/interactions.h"
#include "simulator/interface_cache.h"
#include "simulator/trace_settings.h"
#include "tissue/acoustic_map.h"

namespace sonotrace::simulator::detail {
// Internal linkage, as when this lived in tracer.cpp: the one file that includes it
// inlines what it calls once.
namespace {

template <int Dim>
class InterfaceSearch {
  public:
    using V = Vec<Dim>;
    using Texel = tissue::AcousticTexel<Dim>;

    InterfaceSearch(const tissue::AcousticMap<Dim>& map, const TraceSettings& settings)
        : map_(map), settings_(settings) {
        texel_mm_ = map.smallest_spacing();
        threshold2_ = float(settings.interface_threshold * settings.interface_threshold);
        // At least 4 texels: central differences and interpolation spread even a one-texel
        // step over 3 texels of gradient, so from anywhere inside it the plateau can lie 3
        // texels off. A shorter reach on a coarse map (interactive frames: 0.5 mm texels,
        // phantoms' 1 mm reach) took sharp interfaces for graded ones: no reflections.
        plateau_steps_ =
            settings.interface_reach_mm > 0.0
                ? std::max(8, int(std::ceil(settings.interface_reach_mm / (0.5 * texel_mm_))))
                : 16;
        inverse_texel2_ = 1.0f / (texel_mm_ * texel_mm_);
    }
    // The tracer's view of the map (its own copy: searched points are sampled through it).
    void set_view(const MapView<Dim>& view) { map_view_ = view; }
    // The table of one trace the sides are kept in.
    void use(InterfaceCache<Dim>& cache) { cache_ = &cache; }

    float texel_mm() const { return texel_mm_; }  // the map's smallest spacing
    float threshold2() const { return threshold2_; }
    float inverse_texel2() const { return inverse_texel2_; }
    int plateau_steps() const { return plateau_steps_; }  // the reach, in half texels
    bool gas(const Plateau& side) const { return side.refractive_index > gas_index_min_; }

    // |grad Z| h / Z above the interface threshold, squared: no root or division.
    template <class Sample>  // Texel or tissue::ImpedanceSample
    bool steep(const Sample& t) const {
        float g2 = 0.0f;
        for (int a = 0; a < Dim; ++a) g2 += t.grad_impedance[a] * t.grad_impedance[a];
        const float z = std::max(t.impedance, 1e-12f);
        return g2 > threshold2_ * z * z * inverse_texel2_;
    }

    // Walks from x along `dir` in half-texel steps until the impedance gradient falls
    // below the interface threshold (at most the interface reach, TraceSettings): the
    // plateau beyond the interface, at *end. Returns whether a plateau was reached: a
    // sharp interface has one on each side within a few texels, a graded medium (the
    // fibre of figure 4) does not.
    // The walk's points are sampled 8 at a time by the vector stage (the same bits as
    // one by one; the last few may be sampled for nothing).
    bool plateau(V x, const V& dir, V* end) const {
        const float h = 0.5f * texel_mm_;
        ImpedancePoints<Dim>& points = points_;
        tissue::ImpedanceSample<Dim> t;
        for (int first = 0;;) {  // x: the walk's point number `first`
            const int count = std::min(8, plateau_steps_ + 1 - first);
            V p = x;
            for (int i = 0; i < count; ++i) {
                if (i > 0) p += h * dir;
                for (int a = 0; a < Dim; ++a)
                    points.position[std::size_t(a)][std::size_t(i)] = p[a];
            }
            sample_impedance_points(map_view_, points, count);
            for (int i = 0; i < count; ++i) {
                if (i > 0) x += h * dir;
                const auto& v = points.sample[std::size_t(i)];
                t.impedance = v[0];
                for (int a = 0; a < Dim; ++a) t.grad_impedance[a] = v[std::size_t(1 + a)];
                if (!steep(t)) return *end = x, true;
            }
            first += count;
            if (first > plateau_steps_) return *end = x, false;  // no plateau within reach
            x += h * dir;
        }
    }

    // The first point from `from` towards `to` where the impedance crosses the geometric
    // mean of two plateaus' (linear between samples a quarter texel apart); `to` if none.
    V halfway_point(const V& from, const V& to, float near_impedance, float far_impedance) const {
        const float half = std::sqrt(near_impedance * far_impedance);
        const float sign = far_impedance >= near_impedance ? 1.0f : -1.0f;
        const int steps = std::max(1, int(std::ceil(4.0f * glm::length(to - from) / texel_mm_)));
        float previous = sign * (map_.sample_impedance(from).impedance - half);
        if (previous >= 0.0f) return from;
        ImpedancePoints<Dim>& points = points_;  // sampled 8 at a time, as in plateau()
        for (int first = 1; first <= steps; first += 8) {
            const int count = std::min(8, steps + 1 - first);
            for (int c = 0; c < count; ++c) {
                const V p = from + (to - from) * (float(first + c) / float(steps));
                for (int a = 0; a < Dim; ++a)
                    points.position[std::size_t(a)][std::size_t(c)] = p[a];
            }
            sample_impedance_points(map_view_, points, count);
            for (int c = 0; c < count; ++c) {
                const float now = sign * (points.sample[std::size_t(c)][0] - half);
                if (now >= 0.0f) {
                    const float f = previous / (previous - now);  // previous < 0 <= now
                    return from + (to - from) * ((float(first + c - 1) + f) / float(steps));
                }
                previous = now;
            }
        }
        return to;
    }

    // The interface normal: the sum of grad Z over a patch of the transition, lines from
    // the near to the far plateau at lateral offsets of up to 2 texels, samples a texel
    // apart (a cross of lines in 3D). On a transition a few texels wide, finite differences alias
    // into direction errors of up to ~25 degrees at its fringe and ~1 degree along any single line;
    // over the patch they cancel. Only evaluated at interface events.
    static constexpr int kPatchLines = 2;
    V interface_normal(const V& near_end, const V& far_end, const V& guess) const {
        V tangents[2];
        int tangent_count = 1;
        if constexpr (Dim == 2) {
            tangents[0] = V(-guess.y, guess.x);
        } else {
            orthonormal_basis(guess, &tangents[0], &tangents[1]);
            tangent_count = 2;
        }
        // Lines run a texel past each plateau point so the gradient's tails are whole.
        const V unit = glm::normalize(far_end - near_end + guess * 1e-6f);
        const V first = near_end - unit * texel_mm_;
        const V across = far_end + unit * texel_mm_ - first;
        const int steps = std::max(2, int(glm::length(across) / texel_mm_) + 1);
        // The points in order, sampled 64 at a time by the vector stage (the same bits as
        // sample_impedance one by one, in less time: the interface searches are a large
        // share of a 3D trace), summed in order.
        V sum = guess * 0.0f;
        ImpedancePoints<Dim>& points = points_;
        int count = 0;
        auto add_points = [&] {
            sample_impedance_points(map_view_, points, count);
            for (int p = 0; p < count; ++p)
                for (int a = 0; a < Dim; ++a) sum[a] += points.sample[std::size_t(p)][1 + a];
            count = 0;
        };
        for (int tn = 0; tn < tangent_count; ++tn) {
            for (int o = -kPatchLines; o <= kPatchLines; ++o) {
                if (tn == 1 && o == 0) continue;  // the centre line is already summed
                const V start = first + tangents[tn] * (texel_mm_ * float(o));
                for (int i = 0; i <= steps; ++i) {
                    const V x = start + across * (float(i) / float(steps));
                    for (int a = 0; a < Dim; ++a) points.position[std::size_t(a)][count] = x[a];
                    if (++count == ImpedancePoints<Dim>::kSize) add_points();
                }
            }
        }
        add_points();
        return glm::length(sum) > 0.0f ? glm::normalize(sum) : guess;
    }

    // The transition around `from` (whose sample is `at`): walks along grad Z to the
    // plateau on the higher side, then the lower; both found: a sharp interface with its
    // patch normal and middle; otherwise a graded medium.
    template <class Sample>  // Texel or tissue::ImpedanceSample
    void find_sides(const V& from, const Sample& at, InterfaceSides<Dim>& sides) const {
        V g(0.0f);
        for (int a = 0; a < Dim; ++a) g[a] = at.grad_impedance[a];
        g = glm::normalize(g);
        sides.kind = InterfaceSides<Dim>::Kind::graded;
        V high_end, low_end;
        if (!plateau(from, g, &high_end)) return;  // graded: the other side need not be searched
        if (!plateau(from, -g, &low_end)) return;
        const Texel high = map_.sample(high_end), low = map_.sample(low_end);
        sides.kind = InterfaceSides<Dim>::Kind::sharp;
        sides.low = {low.refractive_index, low.impedance};
        sides.high = {high.refractive_index, high.impedance};
        sides.normal = interface_normal(low_end, high_end, g);
        if (glm::dot(sides.normal, g) < 0.0f) sides.normal = -sides.normal;
        // The particle meets the transition at its fringe; the interface itself is about
        // half the smoothing width further on, where ln Z is halfway between the plateaus
        // (a transition thinner than the pulse reflects like a step at the centre of
        // d(ln Z)/dx). Echoes and reflections are timed there, or every echo would come
        // early by that much.
        sides.middle = halfway_point(low_end, high_end, low.impedance, high.impedance);
        sides.patch_normal = sides.normal;
        sides.normal = map_.zone_normal(sides.middle, sides.normal);
        // The lobe's roughness: the rougher of the plateaus (a map of its own, sampled
        // here only); none against a gas (kGasSpeedMax).
        const bool against_gas =
            std::max(low.refractive_index, high.refractive_index) > gas_index_min_;
        sides.roughness =
            settings_.physics.on(Physics::diffuse) &&
                    settings_.lobe_exponent == LobeExponent::roughness && !against_gas
                ? std::max(map_.sample_roughness(low_end), map_.sample_roughness(high_end))
                : 0.0f;
    }

    // The transition around x, found from the centre of x's nearest texel (once per texel
    // and trace: InterfaceCache), or from x itself where that centre is not steep.
    const InterfaceSides<Dim>& sides_at(const V& x, const Texel& t) {
        glm::vec<Dim, int> i;
        uint32_t texel = 0;
        for (int a = Dim - 1; a >= 0; --a) {
            i[a] = std::clamp(int(x[a] * map_.inverse_spacing()[a] + 0.5f), 0, map_.dims()[a] - 1);
            texel = texel * uint32_t(map_.dims()[a]) + uint32_t(i[a]);
        }
        const InterfaceSides<Dim>& cached =
            cache_->get(texel, scratch_sides_, [&](InterfaceSides<Dim>& sides) {
                // From the centre, or where it is not steep (a texel on the transition's
                // fringe), from the first steep point of four along grad Z beside it.
                const V centre = V(i) * map_.spacing();
                auto c = map_.sample_impedance(centre);
                if (steep(c)) return find_sides(centre, c, sides);
                V g(0.0f);
                for (int a = 0; a < Dim; ++a) g[a] = c.grad_impedance[a];
                sides.kind = InterfaceSides<Dim>::Kind::from_position;
                if (!(glm::dot(g, g) > 0.0f)) return;
                g = glm::normalize(g) * texel_mm_;
                for (const float offset : {0.5f, -0.5f, 1.0f, -1.0f}) {
                    const V start = centre + offset * g;
                    c = map_.sample_impedance(start);
                    if (steep(c)) return find_sides(start, c, sides);
                }
            });
        if (cached.kind != InterfaceSides<Dim>::Kind::from_position) return cached;
        find_sides(x, t, scratch_sides_);
        return scratch_sides_;
    }

  private:
    const tissue::AcousticMap<Dim>& map_;
    const TraceSettings& settings_;
    MapView<Dim> map_view_;
    float texel_mm_ = 1.0f, threshold2_ = 0.0f, inverse_texel2_ = 1.0f;
    int plateau_steps_ = 16;
    // The refractive index above which a medium is a gas (kGasSpeedMax).
    float gas_index_min_ = float(tissue::kReferenceSpeed / kGasSpeedMax);
    InterfaceCache<Dim>* cache_ = nullptr;
    InterfaceSides<Dim> scratch_sides_;
    mutable ImpedancePoints<Dim> points_;  // the searches' sample points, eight at a time
};

}  // namespace
}  // namespace sonotrace::simulator::detail
