#include "imaging/simulation.h"

#include "imaging/channel_frame.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <iterator>
#include <numbers>
#include <numeric>
#include <unordered_map>
#include <vector>

#include "imaging/electronic_noise.h"
#include "imaging/mirror_ghosts.h"
#include "imaging/psf.h"
#include "imaging/receive_weights.h"
#include "probe/array_geometry.h"
#include "probe/elevation.h"
#include "probe/placement.h"
#include "tissue/base/error.h"
#include "tissue/tissue_table.h"
#include "tissue/transfer_function.h"

namespace sonotrace::imaging {

PlaneGrid plane_grid(const probe::Transducer& t, const probe::Pose& pose, double pixel_mm) {
    const auto [lo, hi] = probe::ScanGeometry(t).bounds();
    const double margin = 2.0;  // mm around the scanned region: gradients need neighbours
    PlaneGrid grid;
    grid.top_margin_mm = std::max(0.0, -lo.y) + margin;
    tissue::ProbeFrame frame = pose.frame();
    frame.origin -= frame.axial * grid.top_margin_mm;  // the grid starts above the face
    tissue::GridExtent extent;
    extent.width_mm = 2.0 * std::max(std::abs(lo.x), std::abs(hi.x)) + 2.0 * margin;
    extent.depth_mm = hi.y + grid.top_margin_mm + margin;
    extent.elevation_mm = 0.0;
    extent.pixel_mm = pixel_mm;
    grid.geometry = tissue::probe_grid(frame, extent, "probe grid");
    // Pixel centres: lateral (i - (nx-1)/2) h, depth from the shifted origin (j + 1/2) h.
    grid.to_map = {0.5 * (grid.geometry.dims.x - 1) * pixel_mm,
                   grid.top_margin_mm - 0.5 * pixel_mm};
    return grid;
}

PlaneGrid slab_grid(const probe::Transducer& t, const probe::Pose& pose, double pixel_mm,
                    double elevation_pixel_mm) {
    PlaneGrid grid = plane_grid(t, pose, pixel_mm);
    const double half = probe::ElevationTable::of(t)->slab_half_mm();
    const int side = std::max(1, int(std::ceil(half / elevation_pixel_mm)));
    tissue::VolumeGeometry& g = grid.geometry;
    g.dims.z = 2 * side + 1;
    g.spacing.z = elevation_pixel_mm;
    g.origin -= g.direction[2] * (side * elevation_pixel_mm);
    grid.plane_slice = side;
    grid.plane_elevation_in_map = side * elevation_pixel_mm;
    return grid;
}

void light_from_slab(tissue::PropertyMaps& plane, const PlaneGrid& plane_grid,
                     const tissue::PropertyMaps& slab, const PlaneGrid& slab_grid,
                     const probe::Transducer& t) {
    const tissue::VolumeGeometry& g = plane.geometry();
    const tissue::VolumeGeometry& s = slab.geometry();
    const std::shared_ptr<const probe::ElevationTable> lens = probe::ElevationTable::of(t);
    tissue::Volume& backscatter = plane[tissue::Property::backscatter];
    const tissue::Volume& slab_backscatter = slab[tissue::Property::backscatter];
    const int k0 = slab_grid.plane_slice;
    tbb::parallel_for(0, g.dims.y, [&](int j) {
        // The row's depth below the face, and each slice's two-way intensity there.
        const double depth = j * g.spacing.y - plane_grid.to_map.y;
        std::vector<double> w(std::size_t(s.dims.z));
        double total = 0.0;
        for (int k = 0; k < s.dims.z; ++k) {
            const double one_way = lens->intensity((k - k0) * s.spacing.z, std::max(depth, 0.0));
            w[std::size_t(k)] = one_way * one_way;
            total += w[std::size_t(k)];
        }
        if (!(total > 0.0)) return;  // above the face: the plane's own
        // The row in the slab's texels (bilinear, clamped to the edge).
        const double v = std::clamp((depth + slab_grid.to_map.y) / s.spacing.y, 0.0,
                                    double(s.dims.y - 1) - 1e-9);
        const int j0 = int(v);
        const double fv = v - j0;
        for (int i = 0; i < g.dims.x; ++i) {
            const double x = i * g.spacing.x - plane_grid.to_map.x;
            const double u = std::clamp((x + slab_grid.to_map.x) / s.spacing.x, 0.0,
                                        double(s.dims.x - 1) - 1e-9);
            const int i0 = int(u);
            const double fu = u - i0;
            const double own = backscatter.at(i, j);
            double sum = w[std::size_t(k0)] * own * own;
            for (int k = 0; k < s.dims.z; ++k) {
                if (k == k0) continue;
                auto at = [&](int a, int b) { return double(slab_backscatter.at(a, b, k)); };
                const double b = (1.0 - fv) * ((1.0 - fu) * at(i0, j0) + fu * at(i0 + 1, j0)) +
                                 fv * ((1.0 - fu) * at(i0, j0 + 1) + fu * at(i0 + 1, j0 + 1));
                sum += w[std::size_t(k)] * b * b;
            }
            backscatter.at(i, j) = float(std::sqrt(sum / total));
        }
    });
}

MapToWorld map_to_world(const probe::Pose& pose, const PlaneGrid& grid) {
    // world = position + lateral (m.x - to_map.x) + axial (m.y - to_map.y)
    const glm::dvec3 lateral = pose.lateral(), axial = pose.axial();
    return {pose.position - lateral * grid.to_map.x - axial * grid.to_map.y, lateral, axial,
            grid.to_map};
}

TargetCores::TargetCores(const std::vector<PointEcho>& points) : points_(points) {
    for (const PointEcho& p : points_) cell_ = std::max(cell_, p.core_radius_mm);
    for (std::size_t k = 0; k < points_.size(); ++k)
        cells_[key(cell_of(points_[k].position))].push_back(uint32_t(k));
}

glm::ivec2 TargetCores::cell_of(const glm::dvec2& at) const {
    return {int(std::floor(at.x / cell_)), int(std::floor(at.y / cell_))};
}

uint64_t TargetCores::key(const glm::ivec2& c) {
    return (uint64_t(uint32_t(c.x)) << 32) | uint64_t(uint32_t(c.y));
}

bool TargetCores::contains(const glm::dvec2& at) const {
    if (points_.empty()) return false;
    // A core within its radius of `at` lies in `at`'s cell or a neighbour: cells are as
    // wide as the largest radius.
    const glm::ivec2 c = cell_of(at);
    for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
            const auto found = cells_.find(key(c + glm::ivec2(dx, dy)));
            if (found == cells_.end()) continue;
            for (const uint32_t k : found->second)
                if (glm::length(at - points_[k].position) <= points_[k].core_radius_mm) return true;
        }
    return false;
}

std::vector<PointEcho> point_echoes(const std::vector<tissue::PointTarget>& targets,
                                    const tissue::AcousticMap<2>& map, const PlaneGrid& grid,
                                    const probe::Pose& pose, const probe::Transducer& t,
                                    double margin_mm) {
    const probe::ScanGeometry geometry(t);
    const probe::ElevationBeam elevation(t);
    const glm::dvec3 lateral = pose.lateral(), axial = pose.axial(), normal = pose.elevation();
    const double lambda = t.wavelength_mm();
    const double step = 0.5 * std::min(map.spacing().x, map.spacing().y);
    // What the plane sees of each target (tissue/point_target.h): a point is a piece of
    // wire as long as its diameter, weighted by the lens's two-way elevation profile
    // p(e, z) (probe/elevation.h); a wire is its pieces, lambda/4 apart, wherever p
    // reaches. A wire across the plane that stays on one spot of it within the slice sums
    // to one echo of the wire's own strength (p has unit integral).
    struct Piece {
        glm::dvec3 at;
        double strength;
        double diameter_mm;
    };
    std::vector<Piece> pieces;
    auto depth_of = [&](const glm::dvec3& p) { return glm::dot(p - pose.position, axial); };
    auto elevation_of = [&](const glm::dvec3& p) { return glm::dot(p - pose.position, normal); };
    // No wire piece farther than this from its crossing can lie in the image.
    const auto [scan_low, scan_high] = geometry.bounds();
    const double plane_extent = glm::length(scan_high - scan_low) + 10.0;
    for (const tissue::PointTarget& target : targets) {
        const double strength =
            std::sqrt(target.backscatter_width_mm() * lambda / (2.0 * std::numbers::pi));
        const double d = target.diameter_mm;
        if (target.type == tissue::PointTarget::Type::point) {
            pieces.push_back(
                {target.at,
                 strength * d * elevation.profile(elevation_of(target.at), depth_of(target.at)),
                 d});
            continue;
        }
        const double across = glm::dot(target.axis, normal);
        const bool crosses = std::abs(across) > 1e-6;
        // Where the wire crosses the plane; a wire parallel to it, its point at `at`.
        const glm::dvec3 centre =
            crosses ? target.at - target.axis * (elevation_of(target.at) / across) : target.at;
        const double reach = elevation.reach_mm(depth_of(centre));
        if (!crosses && std::abs(elevation_of(target.at)) > reach) continue;
        const double half_length =
            crosses ? std::min(reach / std::abs(across), plane_extent) : plane_extent;
        const double drift = glm::length(target.axis - normal * across) * half_length;
        if (drift < 0.125 * lambda) {  // one spot of the plane: the wire's whole echo
            pieces.push_back({centre, strength, d});
            continue;
        }
        const double ds = 0.25 * lambda;
        const int n = int(std::ceil(half_length / ds));
        for (int k = -n; k <= n; ++k) {
            const glm::dvec3 at = centre + target.axis * (k * ds);
            const double z = depth_of(at);
            if (!(z > 0.0 && z < geometry.depth_mm() + 1.0)) continue;
            const double weight = elevation.profile(elevation_of(at), z);
            if (weight > 1e-6 * elevation.profile(0.0, z))
                pieces.push_back({at, strength * weight * ds, d});
        }
    }
    std::vector<PointEcho> echoes;
    if (pieces.empty()) return echoes;
    const MirrorSearch mirrors(map, grid.to_map, t);
    for (const Piece& piece : pieces) {
        const glm::dvec3 d = piece.at - pose.position;
        const double strength = piece.strength;
        const glm::dvec2 plane(glm::dot(d, lateral), glm::dot(d, axial));
        const glm::dvec2 line = geometry.line_and_depth(plane);
        if (!(line.x > -1.0 && line.x < geometry.lines() && line.y > 0.0 &&
              line.y < geometry.depth_mm()))
            continue;
        const glm::dvec2 from =
            geometry.point(std::clamp(line.x, 0.0, geometry.lines() - 1.0), 0.0) + grid.to_map;
        const glm::dvec2 to = plane + grid.to_map;
        // March the straight path up to the core, in double: attenuation and impedance runs.
        const double length = glm::length(to - from) - 0.5 * piece.diameter_mm - margin_mm;
        const glm::dvec2 direction = glm::normalize(to - from);
        double optical = 0.0, transmission = 1.0, delay = 0.0;
        double run_start = 0.0, previous = 0.0, previous_s = 0.0;
        int run_sign = 0;
        auto close_run = [&](double z_end) {
            const double r = (z_end - run_start) / (z_end + run_start);
            transmission *= 1.0 - r * r;
        };
        const int steps = std::max(0, int(std::ceil(length / step)));
        for (int k = 0; k <= steps; ++k) {
            const double s = std::min(k * step, std::max(length, 0.0));
            const glm::vec2 p(from + direction * s);
            if (!map.inside(p)) continue;
            const tissue::AcousticTexel<2> texel = map.sample(p);
            const double z = texel.impedance;
            if (k == 0) {
                run_start = previous = z;
                continue;
            }
            optical += tissue::attenuation_per_mm(texel.attenuation, t.frequency_mhz) * step;
            delay += (double(texel.refractive_index) - 1.0) * (s - previous_s);
            previous_s = s;
            const double change = z - previous;
            const int sign = std::abs(change) < 1e-6 * z ? 0 : (change > 0.0 ? 1 : -1);
            if (sign != 0 && run_sign != 0 && sign != run_sign) {  // the run turned: close it
                close_run(previous);
                run_start = previous;
            }
            if (sign != 0) run_sign = sign;
            previous = z;
        }
        if (steps > 0) close_run(previous);
        echoes.push_back({to, strength * transmission * std::exp(-optical),
                          0.5 * piece.diameter_mm + margin_mm, delay});
        for (const MirrorGhost& g : mirrors.ghosts(plane, 0.5 * piece.diameter_mm + margin_mm)) {
            echoes.push_back({g.at + grid.to_map,
                              strength * g.reflection * g.reflection * std::exp(-g.optical), 0.0,
                              g.delay_mm});
        }
    }
    return echoes;
}

namespace {

// An echo of the slab seen from the scan plane: its in-plane position, direction and
// normal (as the 2D image formation reads them); a mirror tilted in elevation returns to
// the lens by its plane response sinc^2(2 H sin(beta) / lambda) (rectangular lens of
// height H; beta: the normal's angle out of the plane).
simulator::EchoEvent<2> on_the_plane(const simulator::EchoEvent<3>& e, const glm::vec2& shift,
                                     double lens_mm, double lambda_mm) {
    simulator::EchoEvent<2> out;
    out.line = e.line;
    out.particle = e.particle;
    out.time_s = e.time_s;
    out.energy = e.energy;
    out.weight = e.weight;
    out.position = glm::vec2(e.position.x, e.position.y) + shift;
    out.bounces = e.bounces;
    out.kind = e.kind;
    out.rough_bounces = e.rough_bounces;
    out.cos_incidence = e.cos_incidence;
    out.lobe_exponent = e.lobe_exponent;
    out.return_weight = e.return_weight;
    auto in_plane = [](const glm::vec3& v) {
        const glm::vec2 p(v.x, v.y);
        const float n = glm::length(p);
        return n > 0.0f ? p / n : glm::vec2(0.0f);
    };
    out.normal = in_plane(e.normal);
    out.direction = in_plane(e.direction);
    if (e.kind == simulator::EchoKind::specular && glm::dot(e.normal, e.normal) > 0.0f) {
        const double u = 2.0 * lens_mm * double(e.normal.z) / lambda_mm;
        const double sinc =
            std::abs(u) < 1e-9 ? 1.0 : std::sin(std::numbers::pi * u) / (std::numbers::pi * u);
        out.weight = float(double(out.weight) * sinc * sinc);
    }
    return out;
}

}  // namespace

std::size_t frame_particles(const SimulationSettings& settings) {
    if (settings.transmit)
        return settings.transmit->waves.size() * std::size_t(particles_per_transmit(settings));
    return std::size_t(settings.transducer.lines) *
           std::size_t(quality_level(settings.quality).particles_per_line);
}

simulator::TraceSettings frame_trace_settings(const SimulationSettings& settings) {
    const probe::Transducer& t = settings.transducer;
    simulator::TraceSettings trace = settings.trace;
    trace.step_texels = settings.step_texels > 0.0 ? settings.step_texels
                                                   : quality_level(settings.quality).step_texels;
    trace.frequency_mhz = t.frequency_mhz;
    // The roulette's threshold follows the loss the automatic TGC makes up for: a particle
    // 30 dB weaker than brain would leave it at its depth is let go, not one that is weak
    // because it is deep (through the skull, most particles ended before the far side).
    trace.roulette_loss_db_per_mm = 0.5 * automatic_tgc_db(t.frequency_mhz, 1.0);
    trace.seed = settings.seed;
    return trace;
}

namespace {

// One frame: beams, trace, the image. `Dim` 2 traces the plane `map`; 3 the slab `map`
// over `traced`, whose echoes are then projected on the plane and moved to the map frame
// of `grid`, where the image is made over `plane`.
template <int Dim>
Frame trace_and_image(const tissue::AcousticMap<Dim>& map, const PlaneGrid& traced_grid,
                      const tissue::AcousticMap<2>& plane, const PlaneGrid& grid,
                      const probe::Pose& pose, const SimulationSettings& settings,
                      const FrameProgress& progress) {
    Frame frame;
    auto stage = [&](const char* name, auto&& work) { timed_stage(frame, name, work); };
    const probe::Transducer& t = settings.transducer;
    const LineData layout = rf_layout(t, settings.imaging);
    const probe::BeamSettings beam{quality_level(settings.quality).particles_per_line,
                                   settings.seed};
    // Where the probe plane's origin lies in the map frame.
    glm::vec<Dim, double> to_map;
    to_map.x = traced_grid.to_map.x;
    to_map.y = traced_grid.to_map.y;
    if constexpr (Dim == 3) to_map.z = traced_grid.plane_elevation_in_map;

    probe::Sources<Dim> sources;
    stage("beams", [&] {
        if constexpr (Dim == 2)
            sources = probe::make_beams(t, beam, to_map);
        else
            sources = probe::make_beams_3d(t, beam, to_map);
    });

    simulator::TraceSettings trace = frame_trace_settings(settings);
    trace.record_scatter_echoes = false;
    // The speckle is lit by the plane's map (synthesize_rf): the illumination alone.
    trace.echo_profile = simulator::EchoProfileSettings{1.0 / layout.fs_hz, layout.samples};
    trace.echo_profile->scattered = false;
    // The image's receive, applied once to the scattered and reflected echoes.
    stage("receive weights", [&] { trace.receive_weights = receive_weights(t, sources, to_map); });
    // The echo window closes at the last sample: monostatic echoes come at twice the
    // one-way time, captured ones at the particle's own time.
    const double window_s = layout.samples / layout.fs_hz;
    trace.max_time_s = settings.receive == ReceiveModel::capture ? window_s : 0.5 * window_s;
    // Echoes through rough reflections come back within the receive's half-angle (at the
    // transmit focus: the dynamic receive keeps it at every depth until the array ends).
    if (settings.receive == ReceiveModel::monostatic)
        trace.diffuse_return_half_angle_rad =
            std::atan(0.5 * t.receive_aperture_mm(t.focus_mm) / std::max(t.focus_mm, 1.0));
    if (settings.receive == ReceiveModel::capture) {
        if constexpr (Dim == 2)
            trace.probe_face_2d = simulator::probe_face(t, to_map);
        else
            trace.probe_face_3d = simulator::probe_face(t, to_map);
    }
    simulator::TraceResult<Dim> traced;
    stage("trace", [&] { traced = simulator::trace(map, sources, trace, progress); });
    frame.ledger = traced.ledger;
    frame.stats = traced.stats;

    // What the plane's image needs of the trace: 2D as it is, 3D projected.
    probe::Sources<2> plane_sources;
    std::vector<simulator::EchoEvent<2>> plane_echoes;
    simulator::EchoProfile<2> plane_profile;
    if constexpr (Dim == 2) {
        frame.absorbed = std::move(traced.absorbed);
        frame.paths = std::move(traced.paths);
        plane_sources = std::move(sources);
        plane_echoes = std::move(traced.echoes);
        plane_profile = std::move(traced.echo_profile);
    } else {
        stage("projection", [&] {
            // From the slab's map frame to the plane's: both put the probe plane's origin
            // at their own to_map.
            const glm::vec2 shift(grid.to_map - traced_grid.to_map);
            auto on_plane = [&](const glm::vec3& p) { return glm::vec2(p.x, p.y) + shift; };
            if (traced.absorbed.size() > 0) {  // the slab's slice on the plane
                tissue::VolumeGeometry g = traced.absorbed.geometry();
                g.dims.z = 1;
                g.origin = traced.absorbed.geometry().index_to_world(
                    glm::dvec3(0.0, 0.0, traced_grid.plane_slice));
                tissue::Volume slice(g);
                for (int j = 0; j < g.dims.y; ++j)
                    for (int i = 0; i < g.dims.x; ++i)
                        slice.at(i, j) = traced.absorbed.at(i, j, traced_grid.plane_slice);
                frame.absorbed = std::move(slice);
            }
            for (const auto& path : traced.paths) {
                simulator::Path<2>& p = frame.paths.emplace_back();
                p.line = path.line;
                p.particle = path.particle;
                for (const auto& v : path.vertices)
                    p.vertices.push_back({on_plane(v.position), v.energy});
            }
            // In-plane components per mm of path: the image's range and receive read the
            // particle's progress along the plane as the trace made it.
            plane_sources.reserve(sources.size());
            for (const auto& s : sources)
                plane_sources.push_back({on_plane(s.position),
                                         glm::vec2(s.direction.x, s.direction.y), s.energy, s.line,
                                         s.time_s});
            const double lens = t.elevation_aperture_mm(), lambda = t.wavelength_mm();
            plane_echoes.reserve(traced.echoes.size());
            for (const auto& e : traced.echoes)
                plane_echoes.push_back(on_the_plane(e, shift, lens, lambda));
            const auto& p3 = traced.echo_profile;
            plane_profile.lines = p3.lines;
            plane_profile.bins = p3.bins;
            plane_profile.bin_s = p3.bin_s;
            plane_profile.step_mm = p3.step_mm;  // its time, not its projection, sets the comb
            plane_profile.intensity = p3.intensity;
            plane_profile.illumination = p3.illumination;
            for (const auto& v : p3.illuminated_position)
                plane_profile.illuminated_position.push_back(on_plane(v));
            for (const auto& v : p3.position) plane_profile.position.push_back(on_plane(v));
        });
    }

    // Which reflections form the image depends on the receive model; a target's own
    // core echoes through point_echoes, not through the tracer.
    const std::vector<PointEcho> points =
        point_echoes(settings.targets, plane, grid, pose, t, settings.target_margin_mm);
    const TargetCores cores(points);
    auto in_a_core = [&](const glm::vec2& at) { return cores.contains(glm::dvec2(at)); };
    std::vector<simulator::EchoEvent<2>> echoes;
    for (const auto& e : plane_echoes) {
        const bool returned = e.kind == simulator::EchoKind::returned_to_probe;
        if (returned == (settings.receive == ReceiveModel::capture) && !in_a_core(e.position))
            echoes.push_back(e);
    }
    ImagingSettings imaging = settings.imaging;
    imaging.seed = settings.seed;
    imaging.sub_line_sigmas = quality_level(settings.quality).sub_line_sigmas;
    stage("rf", [&] {
        frame.rf = synthesize_rf(t, plane_sources, echoes, plane_profile, map_to_world(pose, grid),
                                 imaging, points, trace.receive_weights, &plane);
    });
    if (imaging.noise_snr_db)
        stage("noise",
              [&] { add_electronic_noise(frame.rf, t, *imaging.noise_snr_db, imaging.seed); });
    if (settings.keep_echoes) frame.echoes = std::move(echoes);
    // The display takes what its pixels can show (PixelBand); the envelope stays the
    // pulse's, at the RF's resolution. Both from one analytic signal.
    BasebandLines shown;
    stage("envelope", [&] {
        shown = baseband(frame.rf, pixel_band(t, frame.rf, imaging.pixel_mm), &frame.envelope);
    });
    stage("scan conversion", [&] { frame.image = scan_convert_display(shown, t, imaging); });
    return frame;
}

}  // namespace

Frame simulate_frame(const tissue::AcousticMap<2>& map, const PlaneGrid& grid,
                     const probe::Pose& pose, const SimulationSettings& settings,
                     const FrameProgress& progress) {
    if (settings.transmit) return simulate_channel_frame(map, grid, pose, settings, progress);
    return trace_and_image<2>(map, grid, map, grid, pose, settings, progress);
}

Frame simulate_frame(const tissue::AcousticMap<3>& map, const PlaneGrid& slab,
                     const tissue::AcousticMap<2>& plane, const PlaneGrid& grid,
                     const probe::Pose& pose, const SimulationSettings& settings,
                     const FrameProgress& progress) {
    return trace_and_image<3>(map, slab, plane, grid, pose, settings, progress);
}

tissue::AcousticProperties saline() {
    return tissue::find_tissue("water", "", "").properties;
}

std::size_t prepare_plane(tissue::PropertyMaps& maps, const PlaneGrid& grid,
                          const ScenePlacement& scene, double gel_mm, tissue::Volume* labels) {
    const tissue::AcousticProperties gel = saline();
    const tissue::VolumeGeometry& g = maps.geometry();
    std::size_t changed = 0;
    const int rows =
        std::min(g.dims.y, int(std::ceil((grid.top_margin_mm + gel_mm) / g.spacing.y)));
    for (int k = 0; k < g.dims.z; ++k) {
        for (int j = 0; j < rows; ++j) {
            for (int i = 0; i < g.dims.x; ++i) {
                if (maps[tissue::Property::density].at(i, j, k) >= 100.0f) continue;  // not air
                for (std::size_t f = 0; f < tissue::kPropertyCount; ++f)
                    maps.fields[f].at(i, j, k) = gel.values[f];
                ++changed;
            }
        }
    }
    // Skin, not bone: in T1 the air/skin edge passes through the skull's dark intensities,
    // so the edge under the probe reads as a film of bone (R^2 = 0.37 against tissue, a
    // reverberating cavity with the real skull below). Bone-fast samples within 1.5 mm of
    // the gel, in the gel's rows, are the skin's partial volume: soft tissue.
    const tissue::AcousticProperties skin = tissue::find_tissue("soft_tissue", "", "").properties;
    const int reach = std::max(1, int(std::ceil(1.5 / g.spacing.x)));
    std::vector<std::array<int, 3>> to_skin;
    for (int k = 0; k < g.dims.z; ++k) {
        for (int j = 0; j < rows; ++j) {
            for (int i = 0; i < g.dims.x; ++i) {
                if (maps[tissue::Property::speed_of_sound].at(i, j, k) <= 1800.0f) continue;
                bool near_gel = false;
                for (int dj = -reach; dj <= reach && !near_gel; ++dj)
                    for (int di = -reach; di <= reach && !near_gel; ++di) {
                        const int a = i + di, b = j + dj;
                        if (a < 0 || b < 0 || a >= g.dims.x || b >= g.dims.y) continue;
                        near_gel = maps[tissue::Property::density].at(a, b, k) ==
                                       gel[tissue::Property::density] &&
                                   maps[tissue::Property::speed_of_sound].at(a, b, k) ==
                                       gel[tissue::Property::speed_of_sound];
                    }
                if (near_gel) to_skin.push_back({i, j, k});
            }
        }
    }
    for (const auto& [i, j, k] : to_skin)
        for (std::size_t f = 0; f < tissue::kPropertyCount; ++f)
            maps.fields[f].at(i, j, k) = skin.values[f];
    changed += to_skin.size();
    if (scene.craniotomy_radius_mm > 0.0) {
        changed += probe::open_craniotomy(maps, grid.to_map.x, scene.craniotomy_radius_mm,
                                          grid.top_margin_mm + scene.craniotomy_depth_mm, gel);
    }
    if (labels) {
        const float water = float(tissue::tissue_label_of("water"));
        const auto& c = maps[tissue::Property::speed_of_sound].voxels();
        const auto& rho = maps[tissue::Property::density].voxels();
        for (std::size_t n = 0; n < labels->size(); ++n) {
            if (c[n] == gel[tissue::Property::speed_of_sound] &&
                rho[n] == gel[tissue::Property::density])
                labels->voxels()[n] = water;
        }
    }
    return changed;
}

double fresnel_smoothing_mm(const probe::Transducer& t) {
    return 0.5 * std::sqrt(t.wavelength_mm() * t.depth_mm);
}

double refraction_smoothing_mm(const SimulationSettings& s) {
    return s.refraction_smoothing_mm.value_or(fresnel_smoothing_mm(s.transducer));
}

tissue::AcousticMap<2> frame_map(const tissue::PropertyMaps& maps, const SimulationSettings& s) {
    return tissue::AcousticMap<2>::build(maps, refraction_smoothing_mm(s));
}

PlaneScan scan_plane(const PlaneMapper& mapper, const ScenePlacement& scene,
                     const SimulationSettings& settings, bool with_labels,
                     const FrameProgress& progress) {
    const QualityLevel level = quality_level(settings.quality);
    PlaneScan out;
    out.grid = plane_grid(settings.transducer, scene.pose, level.map_pixel_mm);
    if (with_labels) out.labels.emplace();
    tissue::Volume* labels = out.labels ? &*out.labels : nullptr;
    out.maps = mapper(out.grid.geometry, labels);
    prepare_plane(out.maps, out.grid, scene, 5.0, labels);
    if (settings.trace_dimensions != 3) {
        const auto map = frame_map(out.maps, settings);
        out.frame = simulate_frame(map, out.grid, scene.pose, settings, progress);
        return out;
    }
    // The slab at twice the map pixel in the plane and four times across it: the beam's
    // elevation varies over millimetres, refraction follows the tissue smoothed over the
    // Fresnel scale (millimetres), and an MRI's voxels are 1 mm; the interfaces the image
    // shows come from the plane's own map.
    out.slab = slab_grid(settings.transducer, scene.pose, 2.0 * level.map_pixel_mm,
                         4.0 * level.map_pixel_mm);
    tissue::PropertyMaps slab = mapper(out.slab->geometry, nullptr);
    prepare_plane(slab, *out.slab, scene, 5.0, nullptr);
    const auto map = tissue::AcousticMap<3>::build(slab, refraction_smoothing_mm(settings));
    light_from_slab(out.maps, out.grid, slab, *out.slab, settings.transducer);
    slab = {};  // the map holds what the trace needs
    const auto plane = frame_map(out.maps, settings);
    out.frame = simulate_frame(map, *out.slab, plane, out.grid, scene.pose, settings, progress);
    return out;
}

SimulatedFrame simulate_plane(const PlaneMapper& mapper, const ScenePlacement& scene,
                              const SimulationSettings& settings, bool with_labels,
                              const FrameProgress& progress) {
    PlaneScan scan = scan_plane(mapper, scene, settings, with_labels, progress);
    SimulatedFrame out;
    out.frame = std::move(scan.frame);
    out.grid = scan.grid;
    if (scan.labels) {
        out.labels = scan_convert_labels(*scan.labels, scan.grid, out.frame.image);
        TruthAtEcho truth =
            truth_at_echo(*scan.labels, scan.maps, scan.grid, settings.transducer, out.frame.image);
        out.echo_labels = std::move(truth.labels);
        out.true_depth = std::move(truth.depth_mm);
        out.echogenicity = std::move(truth.echogenicity);
    }
    return out;
}

}  // namespace sonotrace::imaging
