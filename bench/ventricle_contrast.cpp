// The default head frame's ventricles against the parenchyma, measured on the envelope,
// with physics switched off one at a time to take the leak apart (issue 29).
//
//   build/bench/ventricle_contrast [OPTIONS]
//
// What is measured:
//   --seeds N, --first-seed S  sum the frames of seeds S..S+N-1 (default 1, 1: one frame
//                              is dominated by a few rays)
//   --from MM, --to MM         the depths counted (default 40 mm and deeper)
//   --clear MM                 how far from other labels the interior and parenchyma lie (1)
//   --ventricles               the interior only within 22 mm of the midline (MNI |x|, the
//                              lateral ventricles' bodies, as add_colin27_anatomy), not the
//                              insular cisterns' CSF at the fan's edge
//   --temporal, --depth MM     the temporal view (phased probe through the skull), its depth
//   --frequency MHZ, --focus MM, --rx-f-number F
//                              the probe's centre frequency, transmit focus, receive F-number
//                              (the PSF's reach from the walls)
//   --smoothing MM             SimulationSettings::refraction_smoothing_mm (the probe's)
//   --step T                   the tracer's step in map texels (0: the quality's)
//   --max-bounces N            reflections before a particle is retired (TraceSettings)
//   --roulette F               Russian roulette below F of a particle's initial energy
//   --stats                    each frame's trace counts (steps, interfaces, reflections)
//   --trace3d                  traced in the slab the elevation beam spans (--trace 3d)
//   --nominal                  the truth at c0 t / 2 instead of through the speed map
//   --refracted                the truth along each line's ray bent by the map's refractive
//                              index (imaging::TruthWalk::refracted)
//   --variant K                only the K-th variant of the list in main()
// What is shown besides:
//   --ideal                    the interior as linear acoustics alone images it (the map's
//                              backscatter^2 through each line's two-way |H|^2)
//   --brightest N              the N brightest interior samples (seed, line, depth)
//   --picture FILE             the first variant's envelope by line and depth (PNG, 60 dB
//                              below the 99.5th percentile), interior samples marked
//   --line L FROM TO           labels, map fields and envelope (dB) along line L, and its
//                              |H|^2 across
//   --at X Y                   the map's fields at a point of the map frame (repeatable)
//   --paths L FILE             line L's particle paths over the impedance (PNG, first seed)
//   --paths-particle K         with --paths: where particle K of the line turns (> 1 degree;
//                              --paths-all: every vertex)
//   --events L FROM TO         line L's strongest reflection echoes placed FROM-TO mm deep
//                              (L = 9999: every line), and their sum by bounce count
//
// Truth: each envelope sample's position is found by walking its scan line through the
// map's speed of sound (echo time = 2/c0 x the integral of n = c0/c), not at c0 t / 2:
// brain at 1560 m/s shows the ventricles 0.8 mm shallower than they are at 60 mm, which
// at c0 would put the floor echoes inside the interior. Interior: CSF samples whose
// labels within 1 mm are all CSF (the 1 mm erosion), deeper than --from
// (default 40 mm: the lateral ventricles, not the sulci under the craniotomy).
// Parenchyma: brain samples 1 mm clear of other tissue. Per 2 mm depth band the interior's
// mean intensity is divided by the parenchyma's of the same band; the total weighs the
// bands by their interior samples.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <optional>
#include <string>
#include <vector>

#include "imaging/anatomy_truth.h"
#include "imaging/colin27.h"
#include "imaging/picture.h"
#include "imaging/psf.h"
#include "imaging/receive_weights.h"
#include "imaging/simulation.h"
#include "imaging/trace_pictures.h"
#include "phantoms/scene/scene.h"
#include "probe/aperture.h"
#include "tissue/image_io.h"
#include "tissue/tissue_table.h"

using namespace sonotrace;

namespace {

struct Options {
    double from_mm = 40.0;
    bool nominal = false;                // truth at c0 t / 2 instead of through the speed map
    bool refracted = false;              // truth along each line's refracted ray
    std::optional<double> smoothing_mm;  // the refraction smoothing; unset: the probe's
    double step_texels = 0.0;            // the tracer's step; 0: the quality's
    int max_bounces = -1;                // --max-bounces; -1: the tracer's
    double roulette = -1.0;              // --roulette; < 0: the tracer's
    bool stats = false;                  // --stats: the trace's counts per frame
    bool trace_3d = false;               // --trace3d: traced in the elevation beam's slab
    int seeds = 1;                       // frames of seeds first_seed.., their intensities summed
    int first_seed = 1;                  // --first-seed
    int variant = -1;                    // only this variant (index into the list in main), -1: all
    std::string picture;
    int brightest = 0;               // print the brightest interior samples
    std::vector<glm::dvec2> points;  // print the map's fields there (map frame, mm)
    double to_mm = 1e9;              // the deepest sample counted
    bool temporal = false;
    bool ideal = false;     // also the interior as linear acoustics alone would image it  // the
                            // temporal view (phased probe through the skull)
    double depth_mm = 0.0;  // imaging depth; 0: the preset's
    double frequency_mhz = 0.0, focus_mm = 0.0, rx_f_number = 0.0;  // 0: the preset's
    double clear_mm = 1.0;    // the interior's and the parenchyma's distance from other labels
    bool ventricles = false;  // --ventricles: the interior within 22 mm of the midline only
    int probe_line = -1;      // print labels and map fields along this line
    int path_line = -1;       // --paths: draw this line's particle paths
    int path_particle = -1;   // --paths-particle: print this particle's turns
    bool path_all = false;    // --paths-all: every vertex of it
    std::string path_picture;
    int event_line = -1;  // --events
    double event_from = 0.0, event_to = 0.0;
    double probe_from = 0.0,
           probe_to = 0.0;  // a PNG of the first variant's envelope (dB), interior samples marked
};

// The largest launch energy of a set of paths (the colour scale's full blue).
float path_energy(const std::vector<simulator::Path<2>>& paths) {
    float e = 0.0f;
    for (const auto& p : paths)
        if (!p.vertices.empty()) e = std::max(e, p.vertices.front().energy);
    return e;
}

double measure(const scene::Scene& head, const char* what, const imaging::PhysicsSwitches& physics,
               const Options& o) {
    const imaging::ScenePlacement& scene = head.start;
    imaging::SimulationSettings s;
    s.transducer = probe::find_transducer(o.temporal ? "phased" : "convex", "ventricle_contrast");
    if (o.depth_mm > 0.0) s.transducer.depth_mm = o.depth_mm;
    if (o.frequency_mhz > 0.0) s.transducer.frequency_mhz = o.frequency_mhz;
    if (o.focus_mm > 0.0) s.transducer.focus_mm = o.focus_mm;
    if (o.rx_f_number > 0.0) s.transducer.rx_f_number = o.rx_f_number;
    head.apply_to(s);
    imaging::apply(physics, s);
    s.refraction_smoothing_mm = o.smoothing_mm;
    s.step_texels = o.step_texels;
    if (o.max_bounces >= 0) s.trace.max_bounces = o.max_bounces;
    if (o.roulette >= 0.0) s.trace.roulette_energy = o.roulette;
    constexpr int kBands = 60;
    constexpr double kBandMm = 2.0;
    std::vector<double> in(kBands), out(kBands);
    std::vector<int> n_in(kBands), n_out(kBands);
    std::vector<double> in_ideal(kBands), out_ideal(kBands);  // --ideal
    std::vector<std::size_t> interior;  // line * samples + sample, of the last seed
    struct Sample {
        double intensity;
        int seed, line;
        double depth_mm;
    };
    std::vector<Sample> brightest;  // interior samples, for --brightest
    imaging::LineData picture;
    for (int seed = o.first_seed; seed < o.first_seed + o.seeds; ++seed) {
        s.seed = uint64_t(seed);
        const imaging::QualityLevel level = imaging::quality_level(s.quality);
        const imaging::PlaneGrid grid =
            imaging::plane_grid(s.transducer, scene.pose, level.map_pixel_mm);
        tissue::Volume labels;
        tissue::PropertyMaps maps = head.mapper(grid.geometry, &labels);
        imaging::prepare_plane(maps, grid, scene, 5.0, &labels);
        const auto map = imaging::frame_map(maps, s);
        const auto psf = imaging::PsfTable::of(s.transducer);
        if (o.path_line >= 0) {
            s.trace.record_paths = imaging::quality_level(s.quality).particles_per_line;
            s.trace.record_paths_line_stride = 1;
        }
        s.keep_echoes = o.event_line >= 0;
        // --trace3d: the slab's trace (scan_plane), imaged on this plane's map as above.
        const imaging::Frame f =
            o.trace_3d ? [&] {
                imaging::SimulationSettings s3 = s;
                s3.trace_dimensions = 3;
                return imaging::scan_plane(head.mapper, scene, s3, false).frame;
            }()
                       : imaging::simulate_frame(map, grid, scene.pose, s);
        if (o.event_line >= 0 && seed == o.first_seed) {  // E R^2 (return) of the echoes there
            std::vector<simulator::EchoEvent<2>> there;
            for (const auto& e : f.echoes) {
                const double depth = tissue::kReferenceSpeed * 1e3 * e.time_s;
                if ((o.event_line == 9999 || int(e.line) == o.event_line) &&
                    depth >= o.event_from && depth <= o.event_to)
                    there.push_back(e);
            }
            double by_bounces[3] = {0.0, 0.0, 0.0};  // 0, 1, more
            for (const auto& e : there)
                by_bounces[std::min<int>(e.bounces, 2)] +=
                    double(e.energy) * e.weight * e.return_weight;
            int strong = 0;  // reflectors as strong as bone's (R^2 > 0.1)
            for (const auto& e : there) strong += e.weight > 0.1f;
            std::printf(
                "  E R^2 return by bounces: 0: %.3g  1: %.3g  more: %.3g; %d of %zu with R^2 > "
                "0.1\n",
                by_bounces[0], by_bounces[1], by_bounces[2], strong, there.size());
            int non_unit = 0;
            for (const auto& e : f.echoes) non_unit += glm::length(e.direction) > 1.01f;
            std::printf("  %d of %zu echoes arrive with a direction longer than 1\n", non_unit,
                        f.echoes.size());
            auto strength = [](const simulator::EchoEvent<2>& e) {
                return double(e.energy) * e.weight * e.return_weight;
            };
            std::sort(there.begin(), there.end(),
                      [&](const auto& a, const auto& b) { return strength(a) > strength(b); });
            // The receive weight each echo is imaged with (the frame's own particles).
            const probe::Sources<2> sources =
                probe::make_beams(s.transducer, {level.particles_per_line, s.seed}, grid.to_map);
            const auto receive = imaging::receive_weights(s.transducer, sources, grid.to_map);
            for (std::size_t n = 0; n < std::min<std::size_t>(there.size(), 15); ++n) {
                const auto& e = there[n];
                std::printf("  receive weight %.3g; ", receive->at(e.line, e.particle, e.time_s));
                std::printf(
                    "  echo: particle %2u at %6.2f mm, kind %d, bounces %u, E R^2 return %.3g "
                    "(E %.3g, R^2 %.3g, return %.3g), at map (%.1f %.1f), cos %.2f, lobe %.3g, "
                    "arriving (%.2f %.2f)\n",
                    e.particle, tissue::kReferenceSpeed * 1e3 * e.time_s, int(e.kind),
                    unsigned(e.bounces), strength(e), e.energy, e.weight, e.return_weight,
                    e.position.x, e.position.y, e.cos_incidence, e.lobe_exponent, e.direction.x,
                    e.direction.y);
            }
        }
        if (o.path_line >= 0 && seed == o.first_seed) {
            std::vector<simulator::Path<2>> paths;
            for (const auto& path : f.paths)
                if (int(path.line) == o.path_line) paths.push_back(path);
            // The path of one particle (--paths-particle K), its turns (> 1 degree).
            for (const auto& path : paths) {
                if (int(path.particle) != o.path_particle) continue;
                glm::vec2 last_dir(0.0f);
                for (std::size_t v = 0; v + 1 < path.vertices.size(); ++v) {
                    const glm::vec2 a = path.vertices[v].position,
                                    b = path.vertices[v + 1].position;
                    if (glm::length(b - a) <= 0.0f) continue;
                    const glm::vec2 dir = glm::normalize(b - a);
                    if (v == 0 || glm::dot(dir, last_dir) < std::cos(0.0175f) || o.path_all ||
                        v + 2 == path.vertices.size())
                        std::printf("  particle %d at (%.2f %.2f) heading (%.3f %.3f)\n",
                                    o.path_particle, a.x, a.y, dir.x, dir.y);
                    last_dir = dir;
                }
            }
            imaging::PathStyle style;
            style.reference_energy =
                paths.empty() || path_energy(paths) <= 0.0f ? 1.0f : path_energy(paths);
            imaging::write_png(imaging::draw_paths(maps.impedance(), paths, style), o.path_picture);
            std::printf("  %zu paths of line %d drawn to %s\n", paths.size(), o.path_line,
                        o.path_picture.c_str());
        }
        const imaging::LineData& env = f.envelope;
        if (o.stats)
            std::printf(
                "  stats: particles %llu steps %llu interface %llu reflections %llu total %llu "
                "scatter %llu\n",
                (unsigned long long)f.stats.particles, (unsigned long long)f.stats.steps,
                (unsigned long long)f.stats.interface_events,
                (unsigned long long)f.stats.reflections,
                (unsigned long long)f.stats.total_reflections,
                (unsigned long long)f.stats.scatter_events);
        if (o.stats) {
            const simulator::EnergyLedger& e = f.ledger;
            const double injected = std::max(e.injected, 1e-30);
            std::printf(
                "  ledger (of the injected): absorbed %.3f escaped %.3f recorded %.3f "
                "remaining %.3f roulette killed %.3f added %.3f\n",
                e.absorbed / injected, e.escaped / injected, e.recorded / injected,
                e.remaining / injected, e.roulette_killed / injected, e.roulette_added / injected);
        }
        picture = env;
        interior.clear();
        const probe::ScanGeometry g(s.transducer);
        const int csf = tissue::tissue_label_of("csf"), brain = tissue::tissue_label_of("brain");
        const glm::ivec3 dims = labels.geometry().dims;
        auto label_at = [&](int i, int j) {
            return i < 0 || j < 0 || i >= dims.x || j >= dims.y ? -1 : int(labels.at(i, j, 0));
        };
        for (const glm::dvec2& m : o.points) {  // the map at given points
            const auto tx = map.sample(glm::vec2(m));
            std::printf(
                "  map (%.2f %.2f): Z %.4f  n %.4f  b %.3f  att %.2f  grad Z (%.4f %.4f) /mm\n",
                m.x, m.y, tx.impedance, tx.refractive_index, tx.backscatter, tx.attenuation,
                tx.grad_impedance[0], tx.grad_impedance[1]);
        }
        if (o.probe_line >= 0 && seed == o.first_seed) {  // labels and the map along one line
            for (double d = o.probe_from; d <= o.probe_to; d += 0.25) {
                const glm::dvec2 m = g.point(o.probe_line, d) + grid.to_map;
                const auto tx = map.sample(glm::vec2(m));
                // The envelope at the sample timed at this depth (c0 t / 2, not walked).
                const int sample =
                    std::clamp(int(std::lround(d / env.depth_mm(1))), 0, env.samples - 1);
                std::printf(
                    "  line %d at %.2f mm (map %.2f %.2f): label %d  Z %.4f  n %.4f  "
                    "b %.3f  att %.2f  envelope %.1f dB\n",
                    o.probe_line, d, m.x, m.y,
                    label_at(int(std::floor(m.x / labels.geometry().spacing.x + 0.5)),
                             int(std::floor(m.y / labels.geometry().spacing.y + 0.5))),
                    tx.impedance, tx.refractive_index, tx.backscatter, tx.attenuation,
                    20.0 * std::log10(double(env.at(o.probe_line, sample)) + 1e-30));
            }
        }
        if (o.probe_line >= 0 && o.trace_3d && seed == o.first_seed) {  // the slab's map too
            const imaging::PlaneGrid slab = imaging::slab_grid(
                s.transducer, scene.pose, 2.0 * level.map_pixel_mm, 4.0 * level.map_pixel_mm);
            tissue::PropertyMaps slab_maps = head.mapper(slab.geometry, nullptr);
            imaging::prepare_plane(slab_maps, slab, scene, 5.0, nullptr);
            const auto slab_map =
                tissue::AcousticMap<3>::build(slab_maps, imaging::refraction_smoothing_mm(s));
            for (double d = o.probe_from; d <= o.probe_to; d += 0.25) {
                const glm::dvec2 m = g.point(o.probe_line, d) + slab.to_map;
                const auto tx = slab_map.sample(
                    glm::vec3(float(m.x), float(m.y), float(slab.plane_elevation_in_map)));
                std::printf("  slab: line %d at %.2f mm: Z %.4f  n %.4f\n", o.probe_line, d,
                            tx.impedance, tx.refractive_index);
            }
        }
        if (o.probe_line >= 0 &&
            seed == o.first_seed) {  // the line's two-way PSF across, mid-range
            const probe::LineFields fields(s.transducer,
                                           probe::line_array(s.transducer, o.probe_line));
            const double z = 0.5 * (o.probe_from + o.probe_to);
            const double h0 = std::norm(fields.two_way({0.0, z}));
            for (double x = 0.25; x <= 2.01; x += 0.25)
                std::printf("  |H|^2 at %.2f mm across, %.1f mm deep: %6.1f / %6.1f dB\n", x, z,
                            10.0 * std::log10(std::norm(fields.two_way({x, z})) / h0),
                            10.0 * std::log10(std::norm(fields.two_way({-x, z})) / h0));
        }
        imaging::ClearSamples samples =
            imaging::clear_samples(env, g, grid.to_map, map, labels, csf, brain, o.clear_mm,
                                   o.from_mm, std::min(o.to_mm, kBands * kBandMm - 1e-6),
                                   o.nominal     ? imaging::TruthWalk::nominal
                                   : o.refracted ? imaging::TruthWalk::refracted
                                                 : imaging::TruthWalk::straight);
        if (o.probe_line >= 0 && o.refracted && seed == o.first_seed) {  // where the ray goes
            const imaging::ClearSamples along =
                imaging::clear_samples(env, g, grid.to_map, map, labels, csf, brain, 0.0,
                                       o.probe_from, o.probe_to, imaging::TruthWalk::refracted);
            for (const auto* list : {&along.inside, &along.outside})
                for (const imaging::TruthSample& t : *list)
                    if (t.line == o.probe_line && t.sample % 8 == 0)
                        std::printf(
                            "  line %d's ray at %.2f mm: map (%.2f %.2f), straight (%.2f %.2f)\n",
                            t.line, t.depth_mm, t.map.x, t.map.y,
                            (g.point(t.line, t.depth_mm) + grid.to_map).x,
                            (g.point(t.line, t.depth_mm) + grid.to_map).y);
        }
        if (o.ventricles) {
            const imaging::MapToWorld to_world = imaging::map_to_world(scene.pose, grid);
            std::erase_if(samples.inside, [&](const imaging::TruthSample& t) {
                return std::abs(to_world(t.map).x) > 22.0;
            });
        }
        for (const auto* list : {&samples.inside, &samples.outside}) {
            const bool inside = list == &samples.inside;
            for (const imaging::TruthSample& t : *list) {
                const int l = t.line, i = t.sample;
                const std::size_t b = std::size_t(t.depth_mm / kBandMm);
                const double v = double(env.at(l, i)) * env.at(l, i);
                if (o.ideal) {  // linear acoustics alone: the map's b^2 seen through |H|^2
                    const glm::dvec2 dir = g.line(l).direction, across(dir.y, -dir.x);
                    double ideal = 0.0;
                    for (double x = -10.0; x <= 10.0; x += 0.05) {
                        const float bs = map.sample_backscatter(glm::vec2(t.map + x * across));
                        ideal += std::norm(psf->at(l, x, env.depth_mm(i))) * double(bs * bs);
                    }
                    (inside ? in_ideal : out_ideal)[b] += ideal;
                }
                if (inside) {
                    interior.push_back(std::size_t(l) * env.samples + i);
                    in[b] += v, ++n_in[b];
                    if (o.brightest > 0) brightest.push_back({v, seed, l, t.depth_mm});
                } else {
                    out[b] += v, ++n_out[b];
                }
            }
        }
    }
    if (!o.picture.empty()) {  // lines across, depth down; 60 dB; interior samples odd-marked
        std::vector<float> sorted = picture.values;  // 0 dB at the 99.5th percentile
        std::nth_element(sorted.begin(),
                         sorted.begin() + std::ptrdiff_t(sorted.size() * 995 / 1000), sorted.end());
        const float peak = sorted[sorted.size() * 995 / 1000];
        std::vector<float> pixels(picture.values.size());
        for (int l = 0; l < picture.lines; ++l)
            for (int i = 0; i < picture.samples; ++i)
                pixels[std::size_t(i) * picture.lines + l] = std::clamp(
                    255.0f * (1.0f + 20.0f * std::log10(picture.at(l, i) / peak + 1e-9f) / 60.0f),
                    0.0f, 255.0f);
        for (std::size_t at : interior) {
            const std::size_t l = at / picture.samples, i = at % picture.samples;
            if (i % 4 == 0) pixels[i * picture.lines + l] = 255.0f;
        }
        tissue::write_gray_image(o.picture, picture.lines, picture.samples, pixels, 8);
        const_cast<Options&>(o).picture.clear();
    }
    double sum_in = 0.0, expected = 0.0;
    std::printf("%s\n", what);
    std::sort(brightest.begin(), brightest.end(),
              [](const Sample& a, const Sample& b) { return a.intensity > b.intensity; });
    for (int k = 0; k < std::min<int>(o.brightest, int(brightest.size())); ++k) {
        const Sample& x = brightest[std::size_t(k)];
        const std::size_t u = std::size_t(x.depth_mm / kBandMm);
        std::printf("  bright: seed %d line %3d at %5.1f mm: %5.1f dB over the band's parenchyma\n",
                    x.seed, x.line, x.depth_mm,
                    10.0 * std::log10(x.intensity / (out[u] / n_out[u])));
    }
    for (int b = 0; b < kBands; ++b) {
        const std::size_t u = std::size_t(b);
        if (n_in[u] < 20 || n_out[u] < 20) continue;
        sum_in += in[u], expected += n_in[u] * out[u] / n_out[u];
        std::printf("  %3.0f-%3.0f mm: %5d interior, %6d parenchyma samples (%6.1f dB): %6.1f dB",
                    b * kBandMm, (b + 1) * kBandMm, n_in[u], n_out[u],
                    10.0 * std::log10(out[u] / n_out[u] + 1e-30),
                    10.0 * std::log10(in[u] / n_in[u] / (out[u] / n_out[u]) + 1e-30));
        if (o.ideal)
            std::printf(
                " (linear acoustics alone %6.1f dB)",
                10.0 * std::log10(in_ideal[u] / n_in[u] / (out_ideal[u] / n_out[u]) + 1e-30));
        std::printf("\n");
    }
    const double total = 10.0 * std::log10(sum_in / expected + 1e-30);
    std::printf("  interior against parenchyma: %.1f dB\n", total);
    if (o.ideal) {
        double ideal_in = 0.0, ideal_expected = 0.0;
        for (int b = 0; b < kBands; ++b) {
            const std::size_t u = std::size_t(b);
            if (n_in[u] < 20 || n_out[u] < 20) continue;
            ideal_in += in_ideal[u], ideal_expected += n_in[u] * out_ideal[u] / n_out[u];
        }
        std::printf("  linear acoustics alone (the map's backscatter^2 through |H|^2): %.1f dB\n",
                    10.0 * std::log10(ideal_in / ideal_expected + 1e-30));
    }
    return total;
}

}  // namespace

int main(int argc, char** argv) {
    Options o;
    for (int a = 1; a < argc; ++a) {
        if (!std::strcmp(argv[a], "--from") && a + 1 < argc) {
            o.from_mm = std::atof(argv[++a]);
        } else if (!std::strcmp(argv[a], "--smoothing") && a + 1 < argc) {
            o.smoothing_mm = std::atof(argv[++a]);
        } else if (!std::strcmp(argv[a], "--trace3d")) {
            o.trace_3d = true;
        } else if (!std::strcmp(argv[a], "--stats")) {
            o.stats = true;
        } else if (!std::strcmp(argv[a], "--roulette") && a + 1 < argc) {
            o.roulette = std::atof(argv[++a]);
        } else if (!std::strcmp(argv[a], "--max-bounces") && a + 1 < argc) {
            o.max_bounces = std::atoi(argv[++a]);
        } else if (!std::strcmp(argv[a], "--step") && a + 1 < argc) {
            o.step_texels = std::atof(argv[++a]);
        } else if (!std::strcmp(argv[a], "--first-seed") && a + 1 < argc) {
            o.first_seed = std::max(1, std::atoi(argv[++a]));
        } else if (!std::strcmp(argv[a], "--seeds") && a + 1 < argc) {
            o.seeds = std::max(1, std::atoi(argv[++a]));
        } else if (!std::strcmp(argv[a], "--variant") && a + 1 < argc) {
            o.variant = std::atoi(argv[++a]);
        } else if (!std::strcmp(argv[a], "--line") && a + 3 < argc) {
            o.probe_line = std::atoi(argv[++a]);
            o.probe_from = std::atof(argv[++a]);
            o.probe_to = std::atof(argv[++a]);
        } else if (!std::strcmp(argv[a], "--paths-all")) {
            o.path_all = true;
        } else if (!std::strcmp(argv[a], "--paths-particle") && a + 1 < argc) {
            o.path_particle = std::atoi(argv[++a]);
        } else if (!std::strcmp(argv[a], "--paths") && a + 2 < argc) {
            o.path_line = std::atoi(argv[++a]);
            o.path_picture = argv[++a];
        } else if (!std::strcmp(argv[a], "--events") && a + 3 < argc) {
            o.event_line = std::atoi(argv[++a]);
            o.event_from = std::atof(argv[++a]);
            o.event_to = std::atof(argv[++a]);
        } else if (!std::strcmp(argv[a], "--clear") && a + 1 < argc) {
            o.clear_mm = std::atof(argv[++a]);
        } else if (!std::strcmp(argv[a], "--at") && a + 2 < argc) {
            const double x = std::atof(argv[++a]);
            o.points.emplace_back(x, std::atof(argv[++a]));
        } else if (!std::strcmp(argv[a], "--to") && a + 1 < argc) {
            o.to_mm = std::atof(argv[++a]);
        } else if (!std::strcmp(argv[a], "--ventricles")) {
            o.ventricles = true;
        } else if (!std::strcmp(argv[a], "--ideal")) {
            o.ideal = true;
        } else if (!std::strcmp(argv[a], "--temporal")) {
            o.temporal = true;
        } else if (!std::strcmp(argv[a], "--frequency") && a + 1 < argc) {
            o.frequency_mhz = std::atof(argv[++a]);
        } else if (!std::strcmp(argv[a], "--focus") && a + 1 < argc) {
            o.focus_mm = std::atof(argv[++a]);
        } else if (!std::strcmp(argv[a], "--rx-f-number") && a + 1 < argc) {
            o.rx_f_number = std::atof(argv[++a]);
        } else if (!std::strcmp(argv[a], "--depth") && a + 1 < argc) {
            o.depth_mm = std::atof(argv[++a]);
        } else if (!std::strcmp(argv[a], "--brightest") && a + 1 < argc) {
            o.brightest = std::atoi(argv[++a]);
        } else if (!std::strcmp(argv[a], "--picture") && a + 1 < argc) {
            o.picture = argv[++a];
        } else if (!std::strcmp(argv[a], "--refracted")) {
            o.refracted = true;
        } else if (!std::strcmp(argv[a], "--nominal")) {
            o.nominal = true;
        } else {
            std::fprintf(stderr, "usage: %s [OPTIONS] (the options are listed in %s)\n", argv[0],
                         __FILE__);
            return 1;
        }
    }
    scene::SceneOptions options;
    options.view = o.temporal ? "temporal" : "craniotomy";
    const auto head = scene::load_scene(options);
    // Each variant is its --disable list, read as simulate reads it.
    const char* variants[] = {
        "",
        "refraction",
        "specular",
        "diffuse",
        "specular,diffuse",
        "refraction,specular,diffuse",
        "refraction,specular,diffuse,bounces",
        "bounces",
    };
    std::vector<std::pair<std::string, double>> totals;
    for (const char*& v : variants) {
        if (o.variant >= 0 && &v != &variants[o.variant]) continue;
        const imaging::PhysicsSwitches p = imaging::disabled_physics(v, "variant", "");
        const std::string name = v[0] ? std::string("--disable ") + v : "every physics on";
        totals.emplace_back(name, measure(*head, name.c_str(), p, o));
    }
    std::printf("\nsummary (interior against parenchyma, %.0f mm deep and more)\n", o.from_mm);
    for (const auto& [name, db] : totals) std::printf("  %6.1f dB  %s\n", db, name.c_str());
    return 0;
}
