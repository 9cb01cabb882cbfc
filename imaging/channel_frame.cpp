#include "imaging/channel_frame.h"

#include <bit>
#include <chrono>
#include <cmath>
#include <numbers>

#include <tbb/parallel_for.h>
#include <opencv2/imgproc.hpp>

#include "imaging/coherent_surfaces.h"
#include "imaging/delay_and_sum.h"
#include "imaging/electronic_noise.h"
#include "probe/array_geometry.h"
#include "tissue/base/hash.h"

namespace sonotrace::imaging {
namespace {

// The transmit's intensity at each texel over its free-field value: the traced fluence,
// smoothed, over the fluence of the same particles in a lossless medium (energy 1 spread
// over the face's length, thinned by a diverging wave's spreading).
class Illumination {
  public:
    Illumination(const tissue::Volume& fluence, double smoothing_mm, double face_mm)
        : geometry_(fluence.geometry()), face_mm_(face_mm) {
        const glm::ivec3 d = geometry_.dims;
        cv::Mat values(d.y, d.x, CV_32F);
        for (int j = 0; j < d.y; ++j)
            for (int i = 0; i < d.x; ++i) values.at<float>(j, i) = fluence.at(i, j);
        const double sx = smoothing_mm / geometry_.spacing.x,
                     sy = smoothing_mm / geometry_.spacing.y;
        cv::GaussianBlur(values, smoothed_, cv::Size(0, 0), sx, sy, cv::BORDER_REPLICATE);
    }
    // Amplitude factor at map-frame point p (mm), for a wave whose free-field spreading
    // there is `spreading` (1: plane).
    double amplitude(const glm::dvec2& p, double spreading) const {
        const double x = p.x / geometry_.spacing.x, y = p.y / geometry_.spacing.y;
        const int i = int(std::floor(x)), j = int(std::floor(y));
        if (i < 0 || j < 0 || i + 1 >= smoothed_.cols || j + 1 >= smoothed_.rows) return 0.0;
        const double fx = x - i, fy = y - j;
        const double v = (1 - fx) * (1 - fy) * smoothed_.at<float>(j, i) +
                         fx * (1 - fy) * smoothed_.at<float>(j, i + 1) +
                         (1 - fx) * fy * smoothed_.at<float>(j + 1, i) +
                         fx * fy * smoothed_.at<float>(j + 1, i + 1);
        return std::sqrt(std::max(v, 0.0) * face_mm_ / std::max(spreading, 1e-6));
    }

  private:
    tissue::VolumeGeometry geometry_;
    double face_mm_;
    cv::Mat smoothed_;
};

}  // namespace

int particles_per_transmit(const SimulationSettings& settings) {
    const probe::Transducer& t = settings.transducer;
    const double per_wavelength =
        std::max(2.0, quality_level(settings.quality).particles_per_line / 8.0);
    return int(std::ceil(per_wavelength * t.array_length_mm() / t.wavelength_mm()));
}

Frame simulate_channel_frame(const tissue::AcousticMap<2>& map, const PlaneGrid& grid,
                             const probe::Pose& pose, const SimulationSettings& settings,
                             const FrameProgress& progress) {
    Frame frame;
    auto stage = [&](const char* name, auto&& work) { timed_stage(frame, name, work); };
    const probe::Transducer& t = settings.transducer;
    const probe::TransmitScheme& scheme = *settings.transmit;
    ChannelSettings channel_settings;
    channel_settings.sampling_mhz = settings.imaging.sampling_mhz;
    const ChannelData layout = channel_layout(t, scheme, channel_settings);
    const int count = particles_per_transmit(settings);
    const glm::dvec2 to_map = grid.to_map;
    probe::Sources<2> sources;
    stage("beams", [&] { sources = probe::transmit_sources(t, scheme, count, to_map); });

    simulator::TraceSettings trace = frame_trace_settings(settings);
    // Scattering after a reflection is echoed from its events (the mirrored speckle);
    // the rest of the speckle is the scatterers below.
    trace.record_scatter_echoes = settings.imaging.speckle;
    trace.deposition_maps = true;
    trace.max_time_s = layout.time_s(layout.samples);
    trace.diffuse_return_half_angle_rad = 0.0;  // the secondary sources radiate to every element

    // The tissue's scatterers, once: they do not move between transmits.
    const std::pair<glm::dvec2, glm::dvec2> bounds = probe::ScanGeometry(t).bounds();
    std::vector<ChannelEcho> scatterers;
    stage("scatterers", [&] {
        // Without scattering the tissue is dark, as in the focused mode; without speckle
        // there is nothing of it a channel could hold.
        if (!settings.imaging.speckle || !trace.physics.on(simulator::Physics::scattering)) return;
        const double rate =
            trace.scattering_rate_per_mm * trace.scatter_echo_fraction * t.rx_f_number;
        ScattererSettings s;
        s.per_resolution_cell = quality_level(settings.quality).scatterers_per_cell;
        s.seed = settings.seed;
        scatterers = channel_scatterers(
            t, bounds.first - glm::dvec2(2.0, 0.0), bounds.second + glm::dvec2(2.0, 2.0), s,
            [&](const glm::dvec2& r) {
                return double(map.sample_backscatter(glm::vec2(r + to_map))) * std::sqrt(rate);
            });
    });
    const std::vector<PointEcho> points =
        point_echoes(settings.targets, map, grid, pose, t, settings.target_margin_mm);
    const TargetCores cores(points);
    const double lambda = t.wavelength_mm();
    const double piece = t.array_length_mm() / count;  // mm of the wavefront per particle
    // The staircase's steps are the map's texels: a fit over 16 of them, links of 4.
    const double texel = map.geometry().spacing.x;
    SurfaceSmoothing smoothing;
    smoothing.link_mm = 4.0 * texel;
    smoothing.window_mm = 16.0 * texel;

    auto echoes_of = [&](int w) {
        const probe::TransmitWave& wave = scheme.waves[std::size_t(w)];
        const probe::TransmitField field(t, wave);
        const probe::Sources<2> own(sources.begin() + std::ptrdiff_t(w) * count,
                                    sources.begin() + std::ptrdiff_t(w + 1) * count);
        simulator::TraceSettings traced = trace;
        traced.seed = base::mix64(settings.seed ^ (uint64_t(w) << 20));
        simulator::TraceResult<2> result;
        stage("trace", [&] { result = simulator::trace(map, own, traced, {}); });
        frame.ledger += result.ledger;
        frame.stats += result.stats;
        // The energy map and the paths drawn: the whole acquisition's.
        if (frame.absorbed.size() == 0)
            frame.absorbed = result.absorbed;
        else
            for (std::size_t k = 0; k < result.absorbed.size(); ++k)
                frame.absorbed.voxels()[k] += result.absorbed.voxels()[k];
        frame.paths.insert(frame.paths.end(), std::make_move_iterator(result.paths.begin()),
                           std::make_move_iterator(result.paths.end()));
        std::vector<ChannelEcho> echoes;
        echoes.reserve(result.echoes.size() + points.size() + scatterers.size());
        std::vector<SurfaceEcho> surface;  // the coherent echoes, for surface_patches
        std::vector<std::size_t> surface_index;
        stage("echoes", [&] {
            // The image point of an event's path: the launch point plus its time of
            // flight at c0 along its launch direction (a mirrored path images where the
            // mirror puts it).
            auto image_of = [&](const simulator::EchoEvent<2>& e) {
                const probe::SourceParticle<2>& source = own[e.particle];
                return glm::dvec2(source.position) - to_map +
                       double(e.time_s - source.time_s) * kC0MmPerS * glm::dvec2(source.direction);
            };
            // How the event's particle left the face: its ray (where the transmit's
            // directivity is taken) and its apodization.
            auto launch_of = [&](const simulator::EchoEvent<2>& e) {
                return probe::launch_arc_mm(t, count, int(e.particle));
            };
            auto lit_by = [&](const simulator::EchoEvent<2>& e) {
                ChannelEcho::Lit lit;
                lit.arrival_s = double(e.time_s);
                lit.transmit_sin_angle = field.ray_from(launch_of(e)).sin_angle;
                lit.incident = glm::dvec2(own[e.particle].direction);
                return lit;
            };
            // Scattering a particle met after a reflection: its echo returns the way the
            // particle came and shows at the path's image point (the speckle and the
            // scatterers behind a mirror). By random phases, an estimator of intensity:
            // (E / E_0)^2 (both ways) times the event's weight w (scatter fraction x b) and
            // return weight, over the particle's piece of wavefront and the receive's 1 / F,
            // so that the
            // events' mean intensity per area is the scatterers' n |sigma|^2 = rate x
            // fraction x b^2 x F (header) where they light the same tissue; sqrt(lambda) /
            // pitch is a lit source's scale (a perpendicular reflector's sum). Each transmit
            // draws its own events, so they add incoherently over the transmits where fixed
            // scatterers add coherently: sqrt(transmits) keeps the compounded mean (imaged
            // from its events, the phantom's bone wire lit directly reads -39.9 dB, from its
            // scatterers -39.8), its speckle grain is a single transmit's.
            auto mirrored_scattering = [&](const simulator::EchoEvent<2>& e) {
                if (e.particle >= own.size() || cores.contains(glm::dvec2(e.position))) return;
                const probe::SourceParticle<2>& source = own[e.particle];
                const glm::dvec2 image = image_of(e);
                if (!field.geometry().in_front(image)) return;
                const double loss = double(e.energy) / std::max(double(source.energy), 1e-30);
                const double intensity = loss * loss * double(e.weight) * double(e.return_weight) *
                                         t.rx_f_number * piece * lambda;
                const uint64_t bits =
                    base::mix64(settings.seed ^
                                base::mix64((uint64_t(w) << 40) ^ (uint64_t(e.particle) << 16) ^
                                            (uint64_t(e.bounces) << 8) ^ 0x5ca7u) ^
                                uint64_t(std::bit_cast<uint32_t>(e.time_s)));
                const std::complex<double> strength =
                    std::polar(std::sqrt(intensity * double(scheme.waves.size())) / t.pitch_mm,
                               2.0 * std::numbers::pi * double(bits >> 11) * 0x1.0p-53);
                if (!(std::abs(strength) > 0.0)) return;
                echoes.push_back({image, strength, 0.0, lit_by(e)});
            };
            // Reflections: secondary sources at their paths' image points.
            // Events come by particle, then time: whether a particle has met a rough
            // interface before this event (after which its echoes add incoherently).
            uint32_t particle = UINT32_MAX;
            bool roughened = false;
            for (const simulator::EchoEvent<2>& e : result.echoes) {
                if (e.particle != particle) particle = e.particle, roughened = false;
                if (e.kind == simulator::EchoKind::scatter) {
                    if (e.bounces > 0) mirrored_scattering(e);
                    continue;
                }
                if (e.kind != simulator::EchoKind::specular &&
                    e.kind != simulator::EchoKind::diffuse)
                    continue;
                const bool coherent = e.kind == simulator::EchoKind::specular && !roughened;
                if (e.kind == simulator::EchoKind::diffuse) roughened = true;
                if (e.particle >= own.size() || cores.contains(glm::dvec2(e.position))) continue;
                const probe::SourceParticle<2>& source = own[e.particle];
                const glm::dvec2 image = image_of(e);
                if (!field.geometry().in_front(image)) continue;
                const double loss = double(e.energy) / std::max(double(source.energy), 1e-30);
                // Coherent echoes (specular, the particle's phase still the transmit's):
                // an estimator of amplitude, without the return weight (header). Echoes
                // through a rough interface add with random phases, so their intensities
                // add: an estimator of intensity, with it, as the focused mode's.
                double amplitude =
                    field.aperture_weight(launch_of(e)) * loss *
                    std::sqrt(double(e.weight) * (coherent ? 1.0 : double(e.return_weight))) *
                    piece / t.pitch_mm;
                // A diverging wave's particles part as it spreads: each then stands for
                // piece / G of the wavefront, where the wave's amplitude is sqrt(G) of a
                // plane wave's (G: TransmitField's spreading), so a coherent source carries 1 /
                // sqrt(G).
                if (coherent) amplitude /= std::sqrt(std::max(field.spreading(image), 1e-6));
                // The share of the reflector's lobe that heads back the way the particle
                // came, within the receive's half-angle: a rough interface's echo, and any
                // echo after a reflection (as the focused mode takes them). A direct
                // specular echo needs none: its secondary sources' sum makes the mirrored
                // wave, and that picks its own direction.
                const double range = glm::length(image);
                const double half_angle =
                    std::atan(0.5 * t.receive_aperture_mm(range) / std::max(range, 1e-3));
                if (!coherent || e.bounces > 0)
                    amplitude *= std::sqrt(reflection_back_fraction(
                        double(e.cos_incidence), double(e.lobe_exponent), half_angle));
                std::complex<double> strength = amplitude;
                if (!coherent) {
                    const uint64_t bits = base::mix64(
                        settings.seed ^ base::mix64((uint64_t(w) << 40) ^
                                                    (uint64_t(e.particle) << 16) ^ e.bounces));
                    strength = std::polar(amplitude,
                                          2.0 * std::numbers::pi * double(bits >> 11) * 0x1.0p-53);
                }
                if (!(std::abs(strength) > 0.0)) continue;
                if (coherent) {
                    surface.push_back(
                        {e.particle, int(e.bounces), image, glm::dvec2(source.direction)});
                    surface_index.push_back(echoes.size());
                }
                echoes.push_back({image, strength, 0.0, lit_by(e)});
            }
            // The coherent sources onto their surfaces, below the map's staircase.
            const std::vector<SurfacePatch> patches = surface_patches(surface, smoothing);
            for (std::size_t k = 0; k < patches.size(); ++k) {
                ChannelEcho& echo = echoes[surface_index[k]];
                echo.position += patches[k].move_mm * surface[k].direction;
                echo.lit->arrival_s += patches[k].move_mm / kC0MmPerS;
                // A first reflection radiates as its facet; after a bounce the unfolded
                // surface is not the one the echo leaves, and the lobe share stands.
                if (surface[k].bounces == 0) {
                    echo.lit->facet_mm = patches[k].width_mm;
                    echo.lit->tangent = patches[k].tangent;
                }
            }
            // The particles a chain skipped, between its neighbours on the fitted surface.
            for (std::size_t k = 0; k < patches.size(); ++k) {
                if (patches[k].next < 0) continue;
                const std::size_t j = std::size_t(patches[k].next);
                const uint32_t gap = surface[j].particle - surface[k].particle;
                const ChannelEcho a = echoes[surface_index[k]], b = echoes[surface_index[j]];
                for (uint32_t m = 1; m < gap; ++m) {
                    const double f = double(m) / double(gap);
                    ChannelEcho filled = a;
                    filled.position = glm::mix(a.position, b.position, f);
                    filled.strength = (1.0 - f) * a.strength + f * b.strength;
                    filled.lit->arrival_s = (1.0 - f) * a.lit->arrival_s + f * b.lit->arrival_s;
                    filled.lit->incident =
                        glm::normalize(glm::mix(a.lit->incident, b.lit->incident, f));
                    filled.lit->tangent =
                        glm::normalize(glm::mix(a.lit->tangent, b.lit->tangent, f));
                    echoes.push_back(filled);
                }
            }
            // Point targets through the transmit's wave.
            for (const PointEcho& p : points)
                echoes.push_back({p.position - to_map, p.amplitude / std::sqrt(lambda),
                                  2.0 * p.delay_mm / kC0MmPerS, std::nullopt});
            // Scatterers, lit by the traced intensity.
            if (!scatterers.empty()) {
                const Illumination light(result.fluence, 1.0, t.array_length_mm());
                for (const ChannelEcho& s : scatterers) {
                    // The transmit's loss on the way in, and again on the way out (the
                    // way back repeats the way in, as in the focused mode).
                    const double a =
                        light.amplitude(s.position + to_map, field.spreading(s.position));
                    if (a > 0.0)
                        echoes.push_back({s.position, s.strength * a * a, 0.0, std::nullopt});
                }
            }
        });
        if (progress) progress(std::size_t(w + 1), scheme.waves.size());
        return echoes;
    };
    ChannelData channels;
    {
        const auto start = std::chrono::steady_clock::now();
        channels = channel_data(t, scheme, echoes_of, channel_settings);
        const double total =
            std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        frame.timings["channels"] =
            total - frame.timings.value("trace", 0.0) - frame.timings.value("echoes", 0.0);
    }
    if (settings.imaging.noise_snr_db) {
        // Receiver noise on every channel, as on the focused mode's lines.
        stage("noise", [&] {
            LineData rf;
            rf.lines = channels.transmits * channels.elements;
            rf.samples = channels.samples;
            rf.fs_hz = channels.fs_hz;
            rf.values = std::move(channels.values);
            add_electronic_noise(rf, t, *settings.imaging.noise_snr_db, settings.seed);
            channels.values = std::move(rf.values);
        });
    }

    // The display: delay-and-sum at the focused mode's pixels.
    const double pixel = settings.imaging.pixel_mm;
    const glm::dvec2 lo = bounds.first, hi = bounds.second;
    PixelGrid pixels;
    pixels.x0_mm = lo.x, pixels.z0_mm = lo.y, pixels.dx_mm = pixels.dz_mm = pixel;
    pixels.nx = int(std::floor((hi.x - lo.x) / pixel)) + 1;
    pixels.nz = int(std::floor((hi.y - lo.y) / pixel)) + 1;
    DasSettings das;
    das.f_number = t.rx_f_number;
    das.apodization = t.rx_apodization;
    BeamformedImage beamformed;
    stage("beamforming", [&] { beamformed = delay_and_sum(channels, t, pixels, das); });
    stage("display", [&] {
        const probe::ScanGeometry geometry(t);
        // TGC by depth along the pixel's scan line, as the focused mode's: one step per
        // pixel of depth ("sample" of 2 pixel / c0).
        const double fs = kC0MmPerS / (2.0 * pixel);
        const int depth_steps = int(std::ceil(t.depth_mm / pixel)) + 1;
        const Compression compression(depth_steps, fs, settings.imaging);
        // A perpendicular reflector of R = 1: sqrt(lambda) / pitch at each element.
        const double unit = std::sqrt(lambda) / t.pitch_mm;
        ScanConverted& out = frame.image;
        out.pixel_mm = pixel;
        out.origin = lo;
        out.image = cv::Mat(pixels.nz, pixels.nx, CV_32F, cv::Scalar(0.0f));
        out.inside = cv::Mat(pixels.nz, pixels.nx, CV_8U, cv::Scalar(0));
        frame.beamformed = cv::Mat(pixels.nz, pixels.nx, CV_32F, cv::Scalar(0.0f));
        tbb::parallel_for(0, pixels.nz, [&](int j) {
            const double z = pixels.z(j);
            for (int i = 0; i < pixels.nx; ++i) {
                const glm::dvec2 ld = geometry.line_and_depth({pixels.x(i), z});
                if (!(ld.x >= -0.5 && ld.x <= t.lines - 0.5 && ld.y >= 0.0 && ld.y <= t.depth_mm))
                    continue;
                const double weight = beamformed.weight_sum(i, j);
                const float envelope =
                    weight > 0.0 ? float(std::abs(beamformed.at(i, j)) / (weight * unit)) : 0.0f;
                const int step = std::min(int(std::lround(ld.y / pixel)), depth_steps - 1);
                out.image.at<float>(j, i) = compression(envelope, compression.offset(step));
                frame.beamformed.at<float>(j, i) = envelope;
                out.inside.at<uint8_t>(j, i) = 255;
            }
        });
    });
    frame.channels = std::move(channels);
    return frame;
}

}  // namespace sonotrace::imaging
