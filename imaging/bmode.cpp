#include "imaging/bmode.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <map>
#include <memory>
#include <mutex>
#include <numbers>
#include <opencv2/core.hpp>
#include <optional>
#include <unordered_map>

#include "imaging/incoherent_echoes.h"
#include "imaging/psf.h"
#include "imaging/receive_weights.h"
#include "probe/aperture.h"
#include "probe/pulse.h"
#include "simulator/interactions.h"
#include "tissue/acoustic_map.h"
#include "tissue/base/fast_math.h"
#include "tissue/base/hash.h"
#include "tissue/volume.h"

namespace sonotrace::imaging {

using base::kFwhmPerSigma;

namespace {

constexpr double kC0 = tissue::kReferenceSpeed;  // m/s

using base::mix64;
using probe::ScanLine;

// out = in (*) kernel (centred), zero outside. The interior as a weighted sum of shifted
// rows (each sum adds its terms in tap order), the edges as they come.
void convolve(const float* in, int n, const std::vector<float>& kernel, float* out) {
    using T = float;
    const int half = int(kernel.size() / 2), taps = int(kernel.size());
    auto edge = [&](int i) {
        const int lo = std::max(0, i - half), hi = std::min(n - 1, i + half);
        T sum = 0;
        for (int j = lo; j <= hi; ++j) sum += in[j] * kernel[std::size_t(j - i + half)];
        out[i] = sum;
    };
    const int first = std::min(half, n),
              last = std::max(first, n - half);  // interior [first, last)
    for (int i = 0; i < first; ++i) edge(i);
    // The interior: tap k's row is the input shifted by k - half, summed in tap order.
    std::vector<const float*> rows(static_cast<std::size_t>(taps));
    for (int k = 0; k < taps; ++k) rows[std::size_t(k)] = in + first + (k - half);
    tissue::weighted_sum_of_rows(rows.data(), kernel.data(), taps, std::size_t(last - first),
                                 out + first);
    for (int i = last; i < n; ++i) edge(i);
}

// out[n] += Re{amplitude (p + i q)((n - at) / fs)} for n in [lo, hi]: the pulse-echo
// waveform with the echo's phase.
void add_pulse(const probe::PulseEcho& pulse, double at, double fs, std::complex<double> amplitude,
               float* out, int n) {
    const double reach = pulse.half_length_s() * fs;
    const int lo = std::max(0, int(std::ceil(at - reach))),
              hi = std::min(n - 1, int(std::floor(at + reach)));
    for (int i = lo; i <= hi; ++i) {
        const std::complex<double> p = pulse.analytic((i - at) / fs);
        out[i] += float(amplitude.real() * p.real() - amplitude.imag() * p.imag());
    }
}

}  // namespace

double tgc_gain_db(const std::vector<TgcPoint>& curve, double depth_mm) {
    if (curve.empty()) return 0.0;
    if (depth_mm <= curve.front().depth_mm) return curve.front().gain_db;
    for (std::size_t i = 1; i < curve.size(); ++i) {
        if (depth_mm <= curve[i].depth_mm) {
            const TgcPoint &a = curve[i - 1], &b = curve[i];
            const double t = (depth_mm - a.depth_mm) / std::max(b.depth_mm - a.depth_mm, 1e-12);
            return a.gain_db + t * (b.gain_db - a.gain_db);
        }
    }
    return curve.back().gain_db;
}

namespace {
// 20 log10 x = (20 / ln 10) ln x, over the range; the gain shifts the range's top.
float compression_scale(double dynamic_range_db) {
    return float(20.0 / std::numbers::ln10 / dynamic_range_db);
}
float compression_offset(double gain_db, double dynamic_range_db) {
    return float((gain_db + dynamic_range_db) / dynamic_range_db);
}
}  // namespace

Compression::Compression(int samples, double fs_hz, const ImagingSettings& settings)
    : scale_(compression_scale(settings.dynamic_range_db)), offset_(std::size_t(samples)) {
    for (int i = 0; i < samples; ++i) {
        offset_[std::size_t(i)] = compression_offset(
            settings.gain_db + tgc_gain_db(settings.tgc, sample_depth_mm(i, fs_hz)),
            settings.dynamic_range_db);
    }
}

float log_compress(float envelope, double gain_db, double dynamic_range_db) {
    ImagingSettings settings;
    settings.gain_db = gain_db, settings.dynamic_range_db = dynamic_range_db;
    const Compression compression(1, 1.0, settings);  // no TGC: the one offset at every depth
    return compression(envelope, compression.offset(0));
}

double sample_depth_mm(int i, double fs_hz) {
    return 0.5 * kC0 * (double(i) / fs_hz) * 1e3;
}

double LineData::depth_mm(int i) const {
    return sample_depth_mm(i, fs_hz);
}

LineData rf_layout(const probe::Transducer& t, const ImagingSettings& settings) {
    LineData d;
    d.lines = t.lines;
    // 4 f0, as research scanners sample RF: the pulse spectrum at 2 f0 is 37 dB down at
    // B = 0.8; the envelope and scan conversion interpolate between samples.
    d.fs_hz = (settings.sampling_mhz > 0.0 ? settings.sampling_mhz : 4.0 * t.frequency_mhz) * 1e6;
    d.samples = int(std::ceil(2.0 * t.depth_mm * 1e-3 / kC0 * d.fs_hz)) + 1;
    return d;
}

ScattererField::ScattererField(uint64_t seed, double cell_mm)
    : seed_(uint32_t(mix64(seed ^ 0x73636174ull))), inverse_cell_(1.0 / cell_mm) {}

double reflection_back_fraction(double cos_incidence, double lobe_exponent,
                                double half_acceptance_rad) {
    // The way back lies twice the incidence from the mirror direction.
    return simulator::lobe_share(2.0 * std::acos(std::clamp(cos_incidence, -1.0, 1.0)),
                                 lobe_exponent, half_acceptance_rad);
}

double receive_beam_sigma_lines(const probe::Transducer& t, const probe::ScanGeometry& geometry,
                                double range_mm) {
    const double range = std::max(range_mm, 1e-3);
    const double fwhm_mm = t.wavelength_mm() * range / t.receive_aperture_mm(range);
    return fwhm_mm / base::kFwhmPerSigma / std::max(geometry.line_spacing_mm(range), 1e-6);
}

LineData synthesize_rf(const probe::Transducer& t, const probe::Sources<2>& sources,
                       const std::vector<simulator::EchoEvent<2>>& events,
                       const simulator::EchoProfile<2>& profile, const MapToWorld& to_world,
                       const ImagingSettings& settings, const std::vector<PointEcho>& points,
                       std::shared_ptr<const simulator::ReceiveWeights> receive,
                       const tissue::AcousticMap<2>* map) {
    LineData rf = rf_layout(t, settings);
    const int L = rf.lines, N = rf.samples;
    const double fs = rf.fs_hz;
    const probe::PulseEcho pulse(t);
    const probe::ScanGeometry geometry(t);

    // Particle (line, index within line) -> source, for launch points and energies.
    std::vector<std::vector<uint32_t>> of_line(static_cast<std::size_t>(L));
    for (std::size_t s = 0; s < sources.size(); ++s) {
        if (sources[s].line < uint32_t(L)) of_line[sources[s].line].push_back(uint32_t(s));
    }
    // The reflection events of each line, in their order (a counting sort): lines are
    // then independent, and run in parallel.
    auto is_reflection = [L](const simulator::EchoEvent<2>& e) {
        return e.kind != simulator::EchoKind::scatter && e.line < uint32_t(L);
    };
    std::vector<uint32_t> event_start(std::size_t(L) + 1, 0), event_order;
    for (const auto& e : events) {
        if (is_reflection(e)) event_start[e.line + 1]++;
    }
    for (int l = 0; l < L; ++l) event_start[std::size_t(l) + 1] += event_start[std::size_t(l)];
    event_order.resize(event_start.back());
    {
        std::vector<uint32_t> next(event_start.begin(), event_start.end() - 1);
        for (std::size_t n = 0; n < events.size(); ++n) {
            if (is_reflection(events[n])) event_order[next[events[n].line]++] = uint32_t(n);
        }
    }

    // -- speckle (header)
    const bool with_speckle = settings.speckle && profile.lines > 0 && profile.bins == N &&
                              profile.position.size() == profile.intensity.size();
    // The lines' PSF table, where speckle or reflections need it (computed once per probe
    // set-up).
    const std::shared_ptr<const PsfTable> psf =
        with_speckle || !event_order.empty() ? PsfTable::of(t) : nullptr;
    if (!receive && !event_order.empty())
        receive = receive_weights(t, sources, to_world.face_in_map);
    const std::size_t size = std::size_t(L) * std::size_t(N);

    // -- RF per line: speckle (*) pulse, plus a pulse at each reflection bin's echo time
    // and at each point target's. Convolution taps: kernel[m + half] = p(-m / fs).
    const int half = int(std::ceil(pulse.half_length_s() * fs));
    std::vector<float> taps_i(std::size_t(2 * half + 1)), taps_q(std::size_t(2 * half + 1));
    for (int m = -half; m <= half; ++m) {
        taps_i[std::size_t(m + half)] = float(pulse.in_phase(-m / fs));
        taps_q[std::size_t(m + half)] = float(-pulse.quadrature(-m / fs));  // Re{(a+ib)(p+iq)}
    }
    const double depth_to_samples = 2.0 * 1e-3 / kC0 * fs;
    const int echo_half_width = std::max(1, int(std::lround(0.5 * pulse.envelope_fwhm_s() * fs)));
    rf.values.resize(size);
    // One reflection event as line l receives it: where its pulse goes (samples), its
    // intensity and the plane response (its phase); nothing if it makes no echo.
    // `untilted`: the line's echo of an untilted plane by depth row, as diffuse echoes ask
    // it (NaN: not yet): most of a line's echoes, and few rows.
    struct LineEcho {
        double position, intensity;
        std::complex<double> response;
    };
    // The receive aperture's half-angle at a range (mm): the cone whose echoes it focuses.
    auto receive_half_angle = [&t](double range_mm) {
        return std::atan(0.5 * t.receive_aperture_mm(range_mm) / range_mm);
    };
    auto line_echo = [&](int l, const ScanLine& axis, const simulator::EchoEvent<2>& e,
                         std::vector<std::complex<double>>& untilted) -> std::optional<LineEcho> {
        const auto& line = of_line[std::size_t(l)];
        if (e.particle >= line.size()) return std::nullopt;
        const auto& source = sources[line[e.particle]];
        double intensity = double(e.energy) * e.weight;
        double echo_time = e.time_s;  // the particle came back itself: the full round trip
        std::complex<double> response = 1.0;
        if (e.kind != simulator::EchoKind::returned_to_probe) {
            intensity *=
                double(e.energy) / std::max(double(source.energy), 1e-30) * double(e.return_weight);
            // The apparent reflector: where the particle's path, unfolded at every
            // mirror and timed at c0, puts the event, measured along the line (the
            // depth of its image point: a mirrored path images at the mirror position;
            // a direct one at the event's own depth, whatever the particle's slant),
            // tilted from the line by the interface's normal (the image's receive sees
            // the echo come back the way the particle left, by reciprocity). The
            // aperture's plane echo there is the echo of every particle of the beam
            // that meets the plane: one pulse at 2 range / c0, not one per slant path
            // (which would smear the focusing delays over the echo). A rough
            // interface scatters its lobe, of which the receive aperture takes its
            // share.
            const glm::dvec2 launch =
                glm::dvec2(source.position) - to_world.face_in_map - axis.origin;
            const double flight_mm = double(e.time_s - source.time_s) * kC0 * 1e3;
            const double range_mm =
                std::max(glm::dot(launch, axis.direction) +
                             flight_mm * glm::dot(glm::dvec2(source.direction), axis.direction),
                         1e-3);
            echo_time = 2.0 * range_mm * 1e-3 / kC0;
            // The plane's tilt as the aperture sees it. A direct echo (no reflection
            // before it): the plane's normal against the way the particle arrives,
            // carried to the line's frame by the angle it was launched at; the plane
            // sends the particle's piece of the wavefront back the way it came, and by
            // reciprocity to the aperture, only if it faces it. For an unturned beam
            // this is the plane's tilt from the line; a piece turned by refraction
            // (the skull) echoes from the planes that face it, not from those that
            // face the probe. Echoes after reflections keep the plane's tilt from the
            // line: judged in the particle's frame, paths between a mirror and a wire
            // outshone the mirror image (mirror_image, seed 3: 6.7 mm off).
            const bool direct = e.bounces == 0 && glm::dot(e.direction, e.direction) > 0.0f;
            const glm::dvec2 arriving = direct ? glm::dvec2(e.direction) : axis.direction;
            glm::dvec2 away = -glm::dvec2(e.normal);
            if (glm::dot(away, arriving) < 0.0) away = -away;
            auto angle_from = [](const glm::dvec2& v, const glm::dvec2& from) {
                return std::atan2(glm::dot(v, glm::dvec2(from.y, -from.x)), glm::dot(v, from));
            };
            // Only where it is used (not by a direct diffuse echo, most of them).
            auto tilt = [&] {
                return glm::dot(away, away) > 0.0
                           ? angle_from(away, arriving) +
                                 (direct ? angle_from(glm::dvec2(source.direction), axis.direction)
                                         : 0.0)
                           : 0.0;
            };
            // The amplitude share of the reflector's lobe that heads back the way the
            // particle came, within the receive's half-angle at this range.
            auto heads_back = [&] {
                return std::sqrt(reflection_back_fraction(double(e.cos_incidence), e.lobe_exponent,
                                                          receive_half_angle(range_mm)));
            };
            if (e.kind == simulator::EchoKind::diffuse) {
                // The share of the lobe that heads back the way the particle came (by
                // reciprocity, to the aperture), by the particle's own incidence, so a
                // piece of the beam meeting a rough surface at grazing incidence sends
                // next to nothing back, whatever the plane's tilt to the line; after
                // reflections too (bone met at grazing incidence after a bounce lit the
                // temporal view's ventricles 37 dB above the brain).
                std::complex<double>& plane = untilted[std::size_t(psf->depth_index(range_mm))];
                if (std::isnan(plane.real())) plane = psf->plane_echo(l, range_mm, 0.0);
                response = plane * heads_back();
            } else {
                response = psf->plane_echo(l, range_mm, std::sin(tilt()));
                // After reflections the plane is judged from the line (above), but the
                // echo still returns along the particle's path reversed only if the
                // mirror sends it back the way it came: a mirror met obliquely sends
                // it on (gel or bone met at 30 degrees after a bounce lit a far line
                // 47 dB above the brain at 100 mm).
                if (!direct) response *= heads_back();
            }
            // Receive, once (receive_weights): a reflector across the whole beam
            // averages it to 1, so its plane echo above stays exact; a target smaller
            // than the beam echoes on the lines whose receive sees it.
            if (receive) intensity *= receive->at(uint32_t(l), e.particle, e.time_s);
        }
        const double position = echo_time * fs;
        if (!(position >= 0.0) || position >= double(N - 1)) return std::nullopt;
        return LineEcho{position, intensity, response};
    };
    auto no_plane_echoes = [&] {
        return std::vector<std::complex<double>>(
            psf ? std::size_t(psf->depths()) : 0,
            std::complex<double>(std::numeric_limits<double>::quiet_NaN(), 0.0));
    };
    // Echoes after a rough reflection, and rough echoes off the beam (after mirrors, or
    // turned by refraction and shown far from where they happened) where sparse, are
    // incoherent: gathered over the image and drawn as speckle of their mean
    // (incoherent_echoes.h), not as a pulse each.
    // Per line; the rough echoes off the beam with their events' indices. No receive
    // half-angle is narrower than the deepest range's: a turn within it leaves the beam at
    // no range.
    std::vector<std::vector<IncoherentEcho>> incoherent_of(static_cast<std::size_t>(L));
    std::vector<std::vector<std::pair<IncoherentEcho, uint32_t>>> off_beam_of(
        static_cast<std::size_t>(L));
    const double narrowest_half_angle = receive_half_angle(t.depth_mm);
    tbb::parallel_for(0, L, [&](int l) {
        const ScanLine axis = geometry.line(l);
        std::vector<std::complex<double>> untilted = no_plane_echoes();
        for (uint32_t n = event_start[std::size_t(l)]; n < event_start[std::size_t(l) + 1]; ++n) {
            const auto& e = events[event_order[n]];
            const bool rough_path = after_a_rough_reflection(e);
            const glm::vec2 launch = e.particle < of_line[std::size_t(l)].size()
                                         ? sources[of_line[std::size_t(l)][e.particle]].direction
                                         : glm::vec2(0.0f);
            const bool after_mirrors = rough_echo_after_mirrors(e);
            if (!rough_path && !after_mirrors &&
                !rough_echo_turned_off_the_beam(e, launch, narrowest_half_angle))
                continue;
            const auto echo = line_echo(l, axis, e, untilted);
            if (!echo) continue;
            const double weighted = echo->intensity * std::norm(echo->response);
            if (!(weighted > 0.0)) continue;
            const double range_mm = echo->position / depth_to_samples;
            const IncoherentEcho incoherent{l, range_mm, weighted, e.particle};
            auto shown_far = [&] {
                const glm::dvec2 shown = axis.origin + axis.direction * range_mm;
                return shown_far_from_its_event(
                    glm::length(glm::dvec2(e.position) - to_world.face_in_map - shown));
            };
            if (rough_path) {
                incoherent_of[std::size_t(l)].push_back(incoherent);
            } else if (after_mirrors ||
                       (rough_echo_turned_off_the_beam(e, launch, receive_half_angle(range_mm)) &&
                        shown_far())) {
                off_beam_of[std::size_t(l)].push_back({incoherent, event_order[n]});
            }
        }
    });
    std::vector<IncoherentEcho> incoherent_echoes, off_beam;
    std::vector<uint32_t> off_beam_events;
    for (int l = 0; l < L; ++l) {
        const auto line = std::size_t(l);
        incoherent_echoes.insert(incoherent_echoes.end(), incoherent_of[line].begin(),
                                 incoherent_of[line].end());
        for (const auto& [echo, event] : off_beam_of[line])
            off_beam.push_back(echo), off_beam_events.push_back(event);
    }
    std::vector<uint8_t> drawn_as_clutter(events.size(), 0);
    const std::vector<uint8_t> sparse = sparse_echoes(geometry, off_beam);
    for (std::size_t k = 0; k < off_beam.size(); ++k)
        if (sparse[k]) {
            incoherent_echoes.push_back(off_beam[k]);
            drawn_as_clutter[off_beam_events[k]] = 1;
        }
    auto incoherent = [&](const simulator::EchoEvent<2>& e, uint32_t event) {
        return after_a_rough_reflection(e) || drawn_as_clutter[event];
    };
    const bool with_sums = with_speckle || !incoherent_echoes.empty();
    const auto speckle_i = std::make_unique_for_overwrite<float[]>(with_sums ? size : 0);
    const auto speckle_q = std::make_unique_for_overwrite<float[]>(with_sums ? size : 0);
    if (with_speckle)
        detail::speckle_lines(t, *psf, profile, to_world, settings, rf, map, speckle_i.get(),
                              speckle_q.get());
    else if (with_sums)
        std::fill_n(speckle_i.get(), size, 0.0f), std::fill_n(speckle_q.get(), size, 0.0f);
    if (!incoherent_echoes.empty())
        add_incoherent_speckle(incoherent_intensity(geometry, rf, incoherent_echoes), rf, t,
                               geometry, settings.seed, speckle_i.get(), speckle_q.get());

    tbb::parallel_for(0, L, [&](int l) {
        // Reflections: per sample bin, the intensity that reached an interface and came
        // back (energy x R^2 x two-way loss) times the squared plane response of the line
        // at the reflector's depth and tilt, with the intensity-weighted echo time (the
        // pulse goes there exactly: a split between samples 1/(4 f0) apart would add two
        // pulses a quarter period out of phase) and the phase of the plane response.
        std::vector<double> reflected(std::size_t(N), 0.0), reflected_time(std::size_t(N), 0.0);
        std::vector<std::complex<double>> phase(std::size_t(N), 0.0);
        const ScanLine axis = geometry.line(l);
        std::vector<std::complex<double>> untilted = no_plane_echoes();
        const uint32_t events_end = event_start[std::size_t(l) + 1];
        for (uint32_t n = event_start[std::size_t(l)]; n < events_end; ++n) {
            // The receive weight of an event a few ahead, fetched now: the weights are
            // megabytes, read at random, and the wait for each was half of this loop.
            if (receive && n + 6 < events_end) {
                const auto& ahead = events[event_order[n + 6]];
                if (const float* w = receive->row(uint32_t(l), ahead.particle))
                    __builtin_prefetch(w + receive->column(ahead.time_s));
            }
            const auto& e = events[event_order[n]];
            if (incoherent(e, event_order[n])) continue;
            const auto echo = line_echo(l, axis, e, untilted);
            if (!echo) continue;
            const double position = echo->position, intensity = echo->intensity;
            const std::complex<double> response = echo->response;
            const double weighted = intensity * std::norm(response);
            if (!(weighted > 0.0)) continue;
            reflected[std::size_t(position)] += weighted;
            reflected_time[std::size_t(position)] += weighted * position;
            phase[std::size_t(position)] += intensity * response;
        }

        const std::size_t row = std::size_t(l) * std::size_t(N);
        float* out = rf.values.data() + row;
        if (with_sums) {
            std::vector<float> quadrature(static_cast<std::size_t>(N));
            convolve(speckle_i.get() + row, N, taps_i, out);
            convolve(speckle_q.get() + row, N, taps_q, quadrature.data());
            for (int i = 0; i < N; ++i) out[i] += quadrature[std::size_t(i)];
        } else {
            std::fill_n(out, N, 0.0f);
        }
        // One wavefront meeting one interface is one echo of amplitude sqrt(sum of its
        // intensities), however its particles fall into bins: bin i's pulse gets I_i /
        // sqrt(sum of I within the pulse's half width of i), which sums to sqrt(I) over an
        // isolated echo split across neighbouring bins (sqrt per bin would add up to
        // sqrt(bins) times too much).
        for (int i = 0; i < N; ++i) {
            const double intensity = reflected[std::size_t(i)];
            if (!(intensity > 0.0)) continue;
            const double at = reflected_time[std::size_t(i)] / intensity;  // samples
            double local = 0.0;  // summed directly: prefix sums would cancel catastrophically
            for (int j = std::max(0, i - echo_half_width);
                 j <= std::min(N - 1, i + echo_half_width); ++j)
                local += reflected[std::size_t(j)];
            const std::complex<double> p = phase[std::size_t(i)];
            const double magnitude = std::abs(p);
            const std::complex<double> unit = magnitude > 0.0 ? p / magnitude : 1.0;
            add_pulse(pulse, at, fs, intensity / std::sqrt(local) * unit, out, N);
        }
        if (!points.empty()) {  // through the line's exact fields (few targets: no table)
            const probe::LineFields f(t, probe::line_array(t, l));
            // The receive aperture by depth: targets often share depths (a grid's rows).
            std::map<double, probe::LineFields::Receive> apertures;
            auto receive_at = [&](double z) -> const probe::LineFields::Receive& {
                auto it = apertures.find(z);
                if (it == apertures.end()) it = apertures.emplace(z, f.receive_aperture(z)).first;
                return it->second;
            };
            const glm::dvec2 across(axis.direction.y, -axis.direction.x);
            for (const PointEcho& p : points) {
                const glm::dvec2 d = p.position - to_world.face_in_map - axis.origin;
                const glm::dvec2 q(glm::dot(d, across), glm::dot(d, axis.direction));
                if (!(q.y > 0.0) || q.y > t.depth_mm) continue;
                // Beyond its reach nothing: its echo there is 45 dB and more below its
                // peak (test: BroadbandFields.PointEchoesFadeBeforeTheirReach).
                if (std::abs(q.x) > PsfTable::point_reach_mm(t, q.y)) continue;
                const std::complex<double> h = f.broadband(q, receive_at(q.y)).two_way.echo;
                add_pulse(pulse, (q.y + p.delay_mm) * depth_to_samples, fs, p.amplitude * h, out,
                          N);
            }
        }
    });
    return rf;
}

}  // namespace sonotrace::imaging
