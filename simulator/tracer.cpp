#include "simulator/tracer.h"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/task_group.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <cmath>
#include <limits>
#include <memory>
#include <mutex>
#include <numeric>

#include "simulator/batch.h"
#include "simulator/deposit_tiles.h"
#include "simulator/interactions.h"
#include "simulator/interface_search.h"
#include "simulator/probe_face_geometry.h"
#include "simulator/rng.h"
#include "simulator/step.h"
#include "tissue/base/error.h"
#include "tissue/base/memory.h"

namespace sonotrace::simulator {

namespace {

using namespace detail;

// One bin of a line's echo profile: a sum and its first moment, in double (sums of
// millions of small steps). The illumination's and the scattered intensity's bins lie in
// two arrays: a frame lit by its map touches only the first, half the memory.
template <int Dim>
struct ProfileBin {
    double sum;
    std::array<double, Dim> first;  // sum of value x
};

// Everything one scan line produces; lines are merged in order afterwards.
template <int Dim>
struct LineOutput {
    std::vector<EchoEvent<Dim>> echoes;
    std::vector<Path<Dim>> paths;
    std::vector<double> ring;
    // The echo profile's bins of this line: the illumination and the scattered intensity
    // w (EchoProfile); the second empty without EchoProfileSettings::scattered.
    std::vector<ProfileBin<Dim>> lit, scattered;
    EnergyLedger ledger;
    TraceStats stats;
};

// Russian roulette: a particle below the threshold survives with probability
// E / (kRouletteRestart * threshold) and then carries that energy (unbiased).
constexpr float kRouletteRestart = 2.0f;

// Below this fraction of uniform blocks the tracer does not look for them (LineTracer).
constexpr double kFewUniformBlocks = 0.05;

template <int Dim>
class LineTracer {
  public:
    using V = Vec<Dim>;
    using Texel = tissue::AcousticTexel<Dim>;
    using ScalarState = StepState<ScalarLane, Dim>;  // one particle's state (step.h)

    // `look_up_blocks`: uniform blocks are worth looking up (trace(): kFewUniformBlocks).
    LineTracer(const tissue::AcousticMap<Dim>& map, const TraceSettings& settings,
               bool look_up_blocks)
        : map_(map), settings_(settings), search_(map, settings) {
        texel_mm_ = search_.texel_mm();
        step_mm_ = float(settings.step_texels) * texel_mm_;
        scatter_enabled_ =
            settings.physics.on(Physics::scattering) && settings.mode == PhysicsMode::acoustic;
        profile_enabled_ = settings.echo_profile.has_value();
        deposit_maps_ = settings.deposition_maps;
        if (profile_enabled_) {
            inverse_profile_bin_ = 1.0 / settings.echo_profile->bin_s;
            profile_scattered_ = settings.echo_profile->scattered;
        }
        profile_scale_ = float(settings.scattering_rate_per_mm) * step_mm_ *
                         float(settings.scatter_echo_fraction);
        follow_reflections_above_ = float(settings.follow_reflections_above);
        max_bounces_ = settings.physics.on(Physics::bounces) ? settings.max_bounces : 0;
        if (const ProbeFace<Dim>* face = probe_face())
            face_reflectivity_ = settings.physics.on(Physics::face) ? face->reflectivity : 0.0f;
        // dB/mm of path -> Np (intensity) per second of the particle's time at c0.
        roulette_loss_per_s_ = settings.roulette_loss_db_per_mm * std::log(10.0) / 10.0 *
                               tissue::kReferenceSpeed * 1e3;
        // alpha [dB/(cm MHz)] * f [MHz] / 10 [mm/cm] -> dB/mm; * ln(10)/10 -> Np/mm (intensity).
        attenuation_per_mm_ = float(tissue::attenuation_per_mm(1.0, settings.frequency_mhz));
        seconds_per_mm_ = float(1e-3 / tissue::kReferenceSpeed);  // times n gives 1/c
        // A map with few uniform blocks (the head's are mostly air the particles never
        // reach) is not searched for them: the lookup at every particle and step costs
        // more than the few steps run in blocks save. The general step
        // gives the uniform run's results to float rounding.
        look_up_blocks_ = settings.uniform_runs && look_up_blocks;
        uniform_runs_ = look_up_blocks_ && probe_face() == nullptr && !(Dim == 2 && settings.ring);
        max_time_s_ = settings.max_time_s > 0.0 ? settings.max_time_s
                                                : std::numeric_limits<double>::infinity();
        // The vector stage has no probe face or ring detector test.
        vector_steps_ =
            settings.vector_steps && probe_face() == nullptr && !(Dim == 2 && settings.ring);
        StepConstants<Dim>& c = step_constants_;
        c.step_mm = step_mm_;
        c.attenuation_per_mm = attenuation_per_mm_;
        c.scattering_rate_per_mm = float(settings.scattering_rate_per_mm);
        c.threshold2 = search_.threshold2();
        c.inverse_texel2 = search_.inverse_texel2();
        c.step_time_per_index = double(step_mm_) * seconds_per_mm_;
        c.max_path_mm = settings.max_path_mm;
        c.max_time_s = max_time_s_;
        for (int a = 0; a < Dim; ++a) c.extent[std::size_t(a)] = map.extent_mm()[a];
        c.deposition_maps = deposit_maps_;
        c.attenuation = settings.physics.on(Physics::attenuation);
        c.scattering = scatter_enabled_;
        c.refraction = settings.physics.on(Physics::refraction);
        c.profile = profile_enabled_;
        c.profile_scale = profile_scale_;
        c.receive = settings.receive_weights.get();
        MapView<Dim>& m = map_view_;
        m.texels = reinterpret_cast<const float*>(map.texels());
        for (int a = 0; a < Dim; ++a) {
            const auto axis = std::size_t(a);
            m.dims[axis] = map.dims()[a];
            m.inverse_spacing[axis] = map.inverse_spacing()[a];
            m.deposit_tiles[axis] = DepositTiles<Dim>::tiles_along(map.dims()[a]);
        }
        m.deposit_texels = deposit_maps_;
        m.prefetch_mm = step_mm_;
        if (uniform_runs_) {
            m.block_records = map.block_records();
            for (int a = 0; a < Dim; ++a) m.block_dims[std::size_t(a)] = map.block_dims()[a];
            m.block_shift = tissue::AcousticMap<Dim>::kBlockShift;
        }
        search_.set_view(map_view_);
    }

    void run(const Sources<Dim>& sources, const std::vector<uint32_t>& order, std::size_t begin,
             std::size_t end, DepositTiles<Dim>& deposits, InterfaceCache<Dim>& interfaces,
             LineOutput<Dim>& out) {
        deposits_ = &deposits;
        search_.use(interfaces);
        out_ = &out;
        if (settings_.ring) out.ring.assign(std::size_t(settings_.ring->bins), 0.0);
        if (settings_.echo_profile) {
            const auto bins = std::size_t(settings_.echo_profile->bins);
            out.lit.assign(bins, ProfileBin<Dim>{});
            out.scattered.assign(profile_scattered_ ? bins : 0, ProfileBin<Dim>{});
        }
        auto batch = std::make_unique<Batch<Dim>>();
        std::size_t next = begin;
        while (next < end || batch->count > 0) {
            // Refill the batch from the line's particles.
            while (batch->count < Batch<Dim>::kSize && next < end) {
                emit(sources[order[next]], uint32_t(next - begin), *batch);
                ++next;
            }
            // Lockstep over the batch. (Running each particle to its end instead measured
            // the same within noise.)
            if (vector_steps_) {
                lockstep_vector(*batch);
                continue;
            }
            for (int k = 0; k < batch->count;) {
                const RunEnd run_end = uniform_run(*batch, k);
                if (run_end != RunEnd::ended &&
                    step(*batch, k, run_end == RunEnd::step_outside_blocks)) {
                    ++k;
                } else {
                    flush_deposits(*batch, k);
                    batch->remove(k);
                }
            }
        }
    }

  private:
    static V to_vec(const LaneVec<float, Dim>& v) {
        V out;
        for (int a = 0; a < Dim; ++a) out[a] = v[std::size_t(a)];
        return out;
    }
    static LaneVec<float, Dim> to_lanes(const V& v) {
        LaneVec<float, Dim> out;
        for (int a = 0; a < Dim; ++a) out[std::size_t(a)] = v[a];
        return out;
    }

    // One lockstep round with the general step in the vector stage (batch.h): uniform
    // runs, then the fields at every lane's position, the vector stage, and what it left
    // (events, deposits, profile, paths, endings) lane by lane in order.
    void lockstep_vector(Batch<Dim>& b) {
        // -- uniform blocks: tight runs per particle. Outside every block (nearly every
        // step in the head) the general step applies.
        LaneFields<Dim>& f = fields_;
        if (!uniform_runs_) {
            std::fill_n(f.eligible.begin(), b.count, -1);
        } else {
            find_uniform_blocks(map_view_, b, f, b.count);
        }
        for (int k = 0; uniform_runs_ && k < b.count;) {
            const auto i = std::size_t(k);
            if (f.block[i] < 0) {
                ++k;
                continue;
            }
            const RunEnd run_end = uniform_run(b, k, map_.uniform_record(f.block[i]));
            if (run_end == RunEnd::ended) {
                flush_deposits(b, k);
                b.remove(k);  // the last lane moves here, with its block
                const auto last = std::size_t(b.count);
                f.block[i] = f.block[last], f.eligible[i] = f.eligible[last];
                continue;
            }
            f.eligible[i] = run_end == RunEnd::step_outside_blocks ? -1 : 0;
            ++k;
        }
        // -- the fields at each lane's position, then the general step, eight lanes at a time
        const int lanes = (b.count + 7) & ~7;
        for (int k = b.count; k < lanes; ++k) f.eligible[std::size_t(k)] = 0;
        sample_lanes(map_view_, b, f, lanes);
        vector_step(b, f, step_constants_, results_, lanes);
        // -- the rest, through the vector stage's lane masks (a branch per lane on its
        // flags was taken at random: deposits about every other step), each kind in lane
        // order, so the ledger's sums keep one order
        static_assert(Batch<Dim>::kSize <= 64);
        const uint64_t live = b.count == 64 ? ~uint64_t(0) : (uint64_t(1) << b.count) - 1;
        const uint64_t to_step = results_.to_step & live, may_end = results_.may_end & live;
        uint64_t flushed = results_.flush & live;
        const uint64_t vector_stepped = live & ~to_step;
        for (; flushed != 0; flushed &= flushed - 1) {
            const auto i = std::size_t(std::countr_zero(flushed));
            deposit(results_.flush_texel[i], results_.flush_fluence[i], results_.flush_absorbed[i]);
            // The new texel's cell is written when the particle leaves it, 2-3 steps on:
            // fetched now, its cache miss is over by then.
            if (deposit_maps_) deposits_->prefetch(b.pending_texel[i]);
        }
        if (profile_enabled_ && scatter_enabled_) {
            for (uint64_t m = vector_stepped; m != 0; m &= m - 1) {
                const int k = std::countr_zero(m);
                const auto i = std::size_t(k);
                V start;
                for (std::size_t a = 0; a < Dim; ++a) start[int(a)] = results_.start_position[a][i];
                add_profile_terms(start, results_.start_time[i],
                                  {results_.profile_lit[i], results_.profile_scattered[i]},
                                  f.backscatter[i]);
            }
        }
        if (settings_.record_paths > 0) {
            for (uint64_t m = vector_stepped; m != 0; m &= m - 1) {
                const int k = std::countr_zero(m);
                if (b.path[std::size_t(k)] >= 0)
                    out_->paths[std::size_t(b.path[std::size_t(k)])].vertices.push_back(
                        {b.position[k], b.energy[std::size_t(k)]});
            }
        }
        uint64_t ended = 0;  // bit k: lane k ended
        for (uint64_t m = to_step; m != 0; m &= m - 1) {
            const int k = std::countr_zero(m);
            if (!step(b, k, f.eligible[std::size_t(k)] != 0)) ended |= uint64_t(1) << k;
        }
        for (uint64_t m = may_end; m != 0; m &= m - 1) {  // vector-stepped lanes only
            const int k = std::countr_zero(m);
            if (!continues(b, k, b.position[k])) ended |= uint64_t(1) << k;
        }
        const auto taken = uint64_t(std::popcount(vector_stepped));  // steps the vector stage took
        out_->stats.steps += taken;
        out_->stats.vector_steps += taken;
        while (ended != 0) {  // from the highest lane down: remove() moves the last lane
            const int k = 63 - std::countl_zero(ended);
            ended &= ~(uint64_t(1) << k);
            flush_deposits(b, k);
            b.remove(k);
        }
    }

    void emit(const SourceParticle<Dim>& s, uint32_t index, Batch<Dim>& b) {
        out_->stats.particles++;
        out_->ledger.injected += s.energy;
        line_ = s.line;
        if (!map_.inside(s.position)) {  // born outside the domain: escapes at once
            out_->ledger.escaped += s.energy;
            return;
        }
        const int k = b.count++;
        b.position.set(k, s.position);
        b.direction.set(k, glm::normalize(s.direction));
        b.energy[k] = b.initial_energy[k] = s.energy;
        b.roulette_below[k] = float(settings_.roulette_energy) * s.energy;
        b.optical_depth[k] = 0.0f;
        b.previous_index[k] = map_.sample_refractive_index(s.position);
        b.pending_texel[k] = uint32_t(texel_index(s.position));
        b.pending_fluence[k] = b.pending_absorbed[k] = 0.0f;
        b.return_factor[k] = 1.0f;
        b.time[k] = double(s.time_s);
        b.path_length[k] = 0.0;
        b.bounces[k] = 0;
        b.in_interface[k] = kOutside;
        b.graded_steps[k] = 0;
        b.particle[k] = index;
        b.receive_row[std::size_t(k)] =
            settings_.receive_weights ? settings_.receive_weights->row(s.line, index) : nullptr;
        b.random[k] = RandomStream{ParticleRng(settings_.seed, s.line, index)};
        b.scatter_target[k] = -std::log(std::max(b.random[k].next(), 1e-12f));
        b.path[k] = -1;
        if (int(index) < settings_.record_paths &&
            s.line % uint32_t(settings_.record_paths_line_stride) == 0) {
            b.path[k] = int(out_->paths.size());
            out_->paths.push_back({s.line, index, {{s.position, s.energy}}});
        }
    }

    // Track-length estimate of the scattered echo of this step and of its illumination
    // (EchoProfileSettings); every step adds to the illumination, those that scatter to
    // the echo.
    void add_to_profile(const Batch<Dim>& b, int k, const V& x, float E, float backscatter,
                        double time) {
        // The particle's next weights fetched ahead: 64 particles walk their own rows,
        // too many streams for the hardware's prefetcher.
        const float* receive_row = b.receive_row[std::size_t(k)];
        float receive = 1.0f;
        if (receive_row != nullptr) {
            const int column = settings_.receive_weights->column(time);
            receive = receive_row[column];
            if (column + 16 < settings_.receive_weights->bins)
                __builtin_prefetch(receive_row + column + 16);
        }
        add_profile_terms(x, time,
                          profile_terms<ScalarLane>(E, b.initial_energy[k], b.return_factor[k],
                                                    receive, backscatter, profile_scale_),
                          backscatter);
    }

    // The terms into the bin of the echo's time (twice the step's), with the position.
    void add_profile_terms(const V& x, double time, const ProfileTerms<ScalarLane>& terms,
                           float backscatter) {
        const double echo_time = 2.0 * time;
        if (!(echo_time >= 0.0)) return;
        const double bin = echo_time * inverse_profile_bin_;
        if (bin >= double(out_->lit.size())) return;
        // The line's next bins fetched ahead, as the weights above.
        const auto at = std::size_t(bin);
        if (at + 8 < out_->lit.size()) __builtin_prefetch(out_->lit.data() + at + 8);
        ProfileBin<Dim>& l = out_->lit[at];
        const double lit = double(terms.lit);
        l.sum += lit;
        for (int a = 0; a < Dim; ++a) l.first[std::size_t(a)] += lit * double(x[a]);
        if (!profile_scattered_ || !(backscatter > 0.0f)) return;
        ProfileBin<Dim>& w = out_->scattered[at];
        const double intensity = double(terms.scattered);
        w.sum += intensity;
        for (int a = 0; a < Dim; ++a) w.first[std::size_t(a)] += intensity * double(x[a]);
    }

    void flush_deposits(Batch<Dim>& b, int k) {
        deposit(b.pending_texel[k], b.pending_fluence[k], b.pending_absorbed[k]);
        b.pending_fluence[k] = b.pending_absorbed[k] = 0.0f;
    }

    // Without maps, the pending sums run over the particle's whole path and reach the
    // ledger when it ends.
    void deposit(uint32_t texel, float fluence, float absorbed) {
        if (deposit_maps_) {
            DepositCell& cell = (*deposits_)[texel];
            cell.fluence += to_fixed(double(fluence));
            cell.absorbed += to_fixed(double(absorbed));
        }
        out_->ledger.absorbed += double(absorbed);
    }

    // The deposit cell of the texel nearest to x.
    uint32_t texel_index(const V& x) const {
        glm::vec<Dim, int> i;
        for (int a = 0; a < Dim; ++a)
            i[a] = std::clamp(int(x[a] * map_.inverse_spacing()[a] + 0.5f), 0, map_.dims()[a] - 1);
        return deposits_->index(i);
    }

    // A particle meets a steep impedance gradient: if the transition is sharp, it is
    // crossed as a whole (patch normal, one reflection decision); otherwise the medium is
    // graded. Rare: kept out of line. `t`: the fields at the particle's position, p.x.
    [[gnu::noinline]] void enter_interface(Batch<Dim>& b, int k, const Texel& t, ScalarState& p) {
        const V x = to_vec(p.x), r = to_vec(p.r);
        const InterfaceSides<Dim>& sides = search_.sides_at(x, t);
        if (sides.kind != InterfaceSides<Dim>::Kind::sharp) {
            p.state = int32_t(kGraded);  // no plateau within reach: refract step by step only
            p.graded_steps = 0;
            return;
        }
        p.state = int32_t(kCrossing);
        out_->stats.interface_events++;
        // Where the reflection happens: where the particle's own path crosses the
        // transition (ln Z halfway between the plateaus), within twice the reach. The
        // patch's middle lies along grad Z, which beside a wall (the side of the choroid
        // plexus, a corner) points across the path: with the zone's normal facing the
        // particle, echoes were timed there, up to 2 mm before the face the path meets,
        // inside the CSF. The decision stays here, where the transition begins (deeper in,
        // the fringe has bent the particle). Which way the path crosses: by grad Z where
        // the particle stands, along it or against it; beside a wall (the path all but
        // across grad Z) by the zone's normal, which stands for the face further on. A path
        // that meets no crossing runs along the wall it is beside: it meets that wall, at
        // grazing incidence, with the patch's own normal, at the middle.
        const float reach_mm = float(search_.plateau_steps()) * texel_mm_;
        const V end = x + r * reach_mm;
        V towards(0.0f);
        for (int a = 0; a < Dim; ++a) towards[a] = t.grad_impedance[a];
        const float along_gradient = glm::dot(r, towards);
        auto crosses_upwards = [&](const V& normal) {
            return glm::dot(along_gradient >= 0.0f ? towards : -towards, normal) >= 0.0f;
        };
        const bool beside = std::abs(along_gradient) < 0.1f * glm::length(towards);
        const bool upwards =
            beside ? glm::dot(r, sides.normal) >= 0.0f : crosses_upwards(sides.normal);
        Plateau near_side = upwards ? sides.low : sides.high;
        Plateau far_side = upwards ? sides.high : sides.low;
        V normal = sides.normal;
        V forward = upwards ? normal : -normal;
        const V crossing = search_.halfway_point(x, end, near_side.impedance, far_side.impedance);
        float to_middle_mm = glm::dot(crossing - x, r);
        if (crossing == end) {
            normal = sides.patch_normal;
            const bool into_wall = crosses_upwards(normal);
            forward = into_wall ? normal : -normal;
            near_side = into_wall ? sides.low : sides.high;
            far_side = into_wall ? sides.high : sides.low;
            const float ahead = glm::dot(sides.middle - x, forward);
            to_middle_mm = std::max(ahead, 0.0f) / std::max(glm::dot(r, forward), 0.1f);
        }
        p.interface_normal = to_lanes(normal);
        // Without specular reflection only total reflection, which is refraction's
        // (Snell's law between the plateaus has no solution), reflects.
        decide_reflection(b, k, p, t, near_side, far_side, sides.roughness, forward, to_middle_mm,
                          settings_.physics.on(Physics::specular));
    }

    // The reflection decision at a sharp interface (eq. 10 with the plateau values on
    // both sides). Records the expected echo R^2 and reflects with probability R^2.
    // `to_middle_mm`: path from p.x to the middle of the transition, where it reflects.
    // `partial_reflection` false: only total reflection happens (no decision, no echo
    // otherwise).
    void decide_reflection(Batch<Dim>& b, int k, ScalarState& p, const Texel& t,
                           const Plateau& near_side, const Plateau& far_side, float roughness,
                           const V& forward, float to_middle_mm, bool partial_reflection) {
        const V x = to_vec(p.x), r = to_vec(p.r);
        float& E = p.E;
        // The direction the particle had on the near plateau: undo the slight
        // refraction it met in the fringe, using the conserved n sin(theta).
        const float cos_now = glm::dot(r, forward);
        V tangential = (r - cos_now * forward) * (t.refractive_index / near_side.refractive_index);
        // Beyond 1 the fringe's index is not the near side's (the particle came through
        // another transition): it met the interface at grazing incidence. Kept a unit
        // vector, or the reflected particle would fly faster than its clock.
        const float tangential_length = glm::length(tangential);
        if (tangential_length > 1.0f) tangential /= tangential_length;
        const float sin_i = std::min(tangential_length, 1.0f);
        const float cos_i = std::sqrt(1.0f - sin_i * sin_i);
        const V incoming = tangential + cos_i * forward;
        const float sin_t = sin_i * near_side.refractive_index / far_side.refractive_index;
        const float cos_t = sin_t >= 1.0f ? 0.0f : std::sqrt(1.0f - sin_t * sin_t);
        if (!partial_reflection && cos_t > 0.0f) return;
        const auto [R2, converted] =
            reflected_and_converted(near_side, far_side, sin_i, sin_t, cos_i, cos_t);
        const float c = settings_.physics.on(Physics::diffuse)
                            ? lobe_exponent(near_side, far_side, roughness)
                            : 1e6f;
        const double to_middle_s =
            double(to_middle_mm) * seconds_per_mm_ * near_side.refractive_index;
        record_echo(b, k, x + r * to_middle_mm, incoming, E, R2,
                    c < 1e4f ? EchoKind::diffuse : EchoKind::specular, cos_i, c, to_middle_s,
                    -forward);
        if (R2 < follow_reflections_above_) {  // scored, not followed (TraceSettings)
            out_->ledger.recorded += double(E) * R2;
            E -= E * R2;
            return;
        }
        if (!(b.random[k].next() < R2)) {
            b.return_factor[k] *= 1.0f - R2;
            if (converted > 0.0f) {  // the solid's shear wave: absorbed where it converts
                const float lost = E * std::min(converted / (1.0f - R2), 1.0f);
                E -= lost;
                deposit(uint32_t(texel_index(x)), 0.0f, lost);
            }
            return;
        }
        b.return_factor[k] *= R2;
        const V mirror = reflect<Dim>(incoming, forward);
        float weight = 1.0f;
        const V leaving = c < 1e4f ? diffuse(mirror, forward, c, b, k, &weight) : mirror;
        p.r = to_lanes(leaving);
        if (c < 1e4f && settings_.diffuse_return_half_angle_rad > 0.0) {
            // The echo's way back through this lobe (TraceSettings): by reciprocity the
            // reversed lobe lies as far from the way back as this one from `leaving`.
            const double off_mirror =
                std::acos(std::clamp(double(glm::dot(leaving, mirror)), -1.0, 1.0));
            b.return_factor[k] *=
                float(lobe_share(off_mirror, c, settings_.diffuse_return_half_angle_rad));
        }
        if (weight < 1.0f) {  // lossy lobe: the rest becomes heat
            const float lost = E * (1.0f - weight);
            E -= lost;
            deposit(uint32_t(texel_index(x)), 0.0f, lost);
        }
        p.state = int32_t(kLeavingAfterReflection);  // leave on the near side, unrefracted
        // To the middle and back: the time and path of the reflection where it happens.
        p.time += 2.0 * to_middle_s;
        p.path_length += 2.0 * to_middle_mm;
        b.bounces[k]++;
        out_->stats.reflections++;
        if (cos_t == 0.0f) out_->stats.total_reflections++;
    }

    // The fractions of the energy an interface reflects and converts into a solid's shear
    // wave (0 between fluids). From the fluid side, fluid_solid_fractions at the incidence;
    // from inside the solid, by reciprocity the fluid side's at the transmitted angle:
    // the same longitudinal share crosses, the same shear share converts (the solid-side
    // split of the rest between reflected longitudinal and shear waves is taken as the
    // fluid side's).
    struct Fractions {
        float reflected, converted;
    };
    Fractions reflected_and_converted(const Plateau& near_side, const Plateau& far_side,
                                      float sin_i, float sin_t, float cos_i, float cos_t) const {
        const float fluid_r2 =
            reflected_fraction(near_side.impedance, far_side.impedance, cos_i, cos_t);
        if (!settings_.physics.on(Physics::shear) || settings_.mode != PhysicsMode::acoustic)
            return {fluid_r2, 0.0f};
        auto speed = [](const Plateau& p) {
            return tissue::kReferenceSpeed / std::max(double(p.refractive_index), 1e-9);
        };
        const double c_near = speed(near_side), c_far = speed(far_side);
        const bool near_solid = c_near > kSolidSpeedMin, far_solid = c_far > kSolidSpeedMin;
        if (near_solid == far_solid) return {fluid_r2, 0.0f};
        const Plateau& fluid = far_solid ? near_side : far_side;
        const Plateau& solid = far_solid ? far_side : near_side;
        const double c_fluid = far_solid ? c_near : c_far, c_solid = far_solid ? c_far : c_near;
        const double sin_fluid = far_solid ? double(sin_i) : double(sin_t);
        const SolidFractions f = fluid_solid_fractions(
            double(fluid.impedance) / c_fluid, c_fluid, double(solid.impedance) / c_solid, c_solid,
            kShearToLongitudinalSpeed * c_solid, sin_fluid);
        return {float(f.reflected), float(f.shear)};
    }

    [[gnu::noinline]] void record_echo(const Batch<Dim>& b, int k, const V& x, const V& direction,
                                       float energy, float weight, EchoKind kind,
                                       float cos_incidence = 1.0f, float lobe_exponent = 1e6f,
                                       double extra_time_s = 0.0, const V& normal = V(0.0f)) {
        out_->echoes.push_back({line_, b.particle[k], float(b.time[k] + extra_time_s), energy,
                                weight, x, b.bounces[k], kind, cos_incidence, lobe_exponent,
                                b.return_factor[k], normal, direction});
    }

    // The diffuse lobe (eq. 11) about the specular direction `mirror`; `forward` points
    // into the far medium, so a valid reflected direction has dot(dir, forward) < 0.
    V diffuse(const V& mirror, const V& forward, float c, Batch<Dim>& b, int k, float* weight) {
        RandomStream& rs = b.random[k];
        auto uniform = [&rs] { return rs.next(); };
        for (int attempt = 0; attempt < 8; ++attempt) {
            V dir;
            if (settings_.lobe_weight == LobeWeight::probability) {
                if constexpr (Dim == 2)
                    dir = rotate(mirror, sample_cos_power_angle_2d(c, uniform));
                else
                    dir = sample_cos_power_direction_3d(mirror, c, rs.next(), rs.next());
                *weight = 1.0f;
            } else {  // uniform over the opening angle, energy weighted by cos^c
                float cos_phi;
                if constexpr (Dim == 2) {
                    const float phi = (2.0f * rs.next() - 1.0f) * std::numbers::pi_v<float> / 2.0f;
                    dir = rotate(mirror, phi), cos_phi = std::cos(phi);
                } else {
                    dir = sample_cos_power_direction_3d(mirror, 0.0f, rs.next(), rs.next());
                    cos_phi = glm::dot(dir, mirror);
                }
                *weight = std::pow(std::max(cos_phi, 0.0f), c);
            }
            if (glm::dot(dir, forward) < 0.0f) return dir;
        }
        *weight = 1.0f;
        return mirror;
    }

    float lobe_exponent(const Plateau& near_side, const Plateau& far_side, float roughness) const {
        switch (settings_.lobe_exponent) {
            case LobeExponent::roughness:
                return roughness <= 1e-3f ? 1e6f : 1.0f / (roughness * roughness) - 1.0f;
            case LobeExponent::reflecting_density:
                return float(settings_.lobe_scale) * far_side.impedance;
            case LobeExponent::density_ratio:
                return float(settings_.lobe_scale) * far_side.impedance /
                       std::max(near_side.impedance, 1e-12f);
        }
        return 1e6f;
    }

    static ScalarState load_state(const Batch<Dim>& b, int k) {
        const auto i = std::size_t(k);
        ScalarState p;
        for (std::size_t a = 0; a < Dim; ++a) {
            p.x[a] = b.position.axis[a][i];
            p.r[a] = b.direction.axis[a][i];
            p.interface_normal[a] = b.interface_normal.axis[a][i];
        }
        p.E = b.energy[i];
        p.fluence = b.pending_fluence[i], p.absorbed = b.pending_absorbed[i];
        p.optical_depth = b.optical_depth[i], p.scatter_target = b.scatter_target[i];
        p.previous_index = b.previous_index[i];
        p.pending_texel = int32_t(b.pending_texel[i]);
        p.state = int32_t(b.in_interface[i]);
        p.graded_steps = b.graded_steps[i];
        p.time = b.time[i], p.path_length = b.path_length[i];
        return p;
    }
    static void store_state(Batch<Dim>& b, int k, const ScalarState& p) {
        const auto i = std::size_t(k);
        for (std::size_t a = 0; a < Dim; ++a) {
            b.position.axis[a][i] = p.x[a];
            b.direction.axis[a][i] = p.r[a];
            b.interface_normal.axis[a][i] = p.interface_normal[a];
        }
        b.energy[i] = p.E;
        b.pending_fluence[i] = p.fluence, b.pending_absorbed[i] = p.absorbed;
        b.optical_depth[i] = p.optical_depth, b.scatter_target[i] = p.scatter_target;
        b.previous_index[i] = p.previous_index;
        b.pending_texel[i] = uint32_t(p.pending_texel);
        b.in_interface[i] = InterfaceState(p.state);
        b.graded_steps[i] = p.graded_steps;
        b.time[i] = p.time, b.path_length[i] = p.path_length;
    }

    // The fields take_step() reads, from a texel at x.
    StepFields<ScalarLane, Dim> fields_of(const Texel& t, const V& x) const {
        StepFields<ScalarLane, Dim> f;
        f.refractive_index = t.refractive_index;
        f.impedance = t.impedance;
        f.attenuation = t.attenuation;
        f.backscatter = t.backscatter;
        for (int a = 0; a < Dim; ++a) {
            f.grad_refractive_index[std::size_t(a)] = t.grad_refractive_index[a];
            f.grad_impedance[std::size_t(a)] = t.grad_impedance[a];
        }
        f.texel = deposit_maps_ ? int32_t(texel_index(x)) : 0;
        return f;
    }

    // step.h's events for one particle, handled where they happen.
    struct ScalarEvents {
        LineTracer& tracer;
        Batch<Dim>& b;
        int k;
        const Texel& t;  // the fields at the step's start
        SONOTRACE_LANE_INLINE void flush_deposits(bool changed, const ScalarState& p) {
            if (changed) tracer.deposit(uint32_t(p.pending_texel), p.fluence, p.absorbed);
        }
        SONOTRACE_LANE_INLINE void beyond_series(bool beyond, float optical, float& transmitted) {
            if (beyond) transmitted = std::exp(-optical);
        }
        SONOTRACE_LANE_INLINE void scatter_profile(const ScalarState& p, float backscatter) {
            if (tracer.profile_enabled_)
                tracer.add_to_profile(b, k, to_vec(p.x), p.E, backscatter, p.time);
        }
        SONOTRACE_LANE_INLINE void scattering_event(bool happens, ScalarState& p,
                                                    float backscatter) {
            if (happens) tracer.scattering_event(b, k, p, backscatter);
        }
        SONOTRACE_LANE_INLINE void interface_event(bool happens, ScalarState& p) {
            if (happens) tracer.enter_interface(b, k, t, p);
        }
    };

    // The optical depth reached the particle's draw: a share of its energy is scattered
    // back as an echo, and the next depth is drawn.
    [[gnu::noinline]] void scattering_event(Batch<Dim>& b, int k, ScalarState& p,
                                            float backscatter) {
        const float fraction = float(settings_.scatter_echo_fraction) * backscatter;
        if (settings_.record_scatter_echoes)
            record_echo(b, k, to_vec(p.x), to_vec(p.r), p.E, fraction, EchoKind::scatter);
        out_->ledger.recorded += double(p.E) * fraction;
        p.E -= p.E * fraction;
        out_->stats.scatter_events++;
        p.optical_depth = 0.0f;
        p.scatter_target = -std::log(std::max(b.random[k].next(), 1e-12f));
    }

    // Advances particle k by one step (step.h's take_step, then the probe face and the
    // ring detector); false when it has ended.
    // `outside_blocks`: uniform_run() found the particle outside every uniform block.
    bool step(Batch<Dim>& b, int k, bool outside_blocks) {
        EnergyLedger& ledger = out_->ledger;
        TraceStats& stats = out_->stats;
        const V from = b.position[k];
        // -- fields: a uniform block's record as it is, elsewhere interpolated
        const Texel* uniform =
            look_up_blocks_ && !outside_blocks ? map_.uniform_block(from) : nullptr;
        const Texel t = uniform ? *uniform : map_.sample(from);
        stats.steps++;
        stats.uniform_steps += uniform != nullptr;
        ScalarState p = load_state(b, k);
        ScalarEvents events{*this, b, k, t};
        take_step(p, fields_of(t, from), step_constants_, events);
        store_state(b, k, p);
        V x = to_vec(p.x), r = to_vec(p.r);
        float E = p.E;

        // -- the probe face captures what comes back through it
        if (const auto* face = probe_face()) {
            if (crosses_face(*face, from, x)) {
                stats.captured++;
                const float kept = E * face_reflectivity_;
                record_echo(b, k, x, r, E, 1.0f - face_reflectivity_, EchoKind::returned_to_probe);
                ledger.recorded += double(E) - kept;
                E = kept;
                r = reflect<Dim>(r, face_normal_at(*face, x));
                x = from;  // stay in the tissue
                b.bounces[k]++;
            }
        }

        // -- ring detector: energy leaving the circle, by polar angle
        if constexpr (Dim == 2) {
            if (settings_.ring) {
                const RingDetector& ring = *settings_.ring;
                const float d0 = glm::length(from - ring.centre), d1 = glm::length(x - ring.centre);
                if (d0 < ring.radius_mm && d1 >= ring.radius_mm) {
                    const V rel_pos = x - ring.centre;
                    const float deg = glm::degrees(std::atan2(
                        glm::dot(rel_pos, ring.up), glm::dot(rel_pos, ring.zero_direction)));
                    if (deg >= 0.0f && deg <= 180.0f) {
                        const int bin = std::min(ring.bins - 1, int(deg / 180.0f * ring.bins));
                        out_->ring[std::size_t(bin)] += E;
                    }
                }
            }
        }

        b.position.set(k, x);
        b.direction.set(k, r);
        b.energy[k] = E;
        if (b.path[k] >= 0) out_->paths[std::size_t(b.path[k])].vertices.push_back({x, E});
        return continues(b, k, x);
    }

    // The endings after a step to x: the domain boundary, the limits, roulette. False if
    // the particle ended; roulette may raise b.energy[k].
    [[gnu::always_inline]] bool continues(Batch<Dim>& b, int k, const V& x) {
        EnergyLedger& ledger = out_->ledger;
        const float E = b.energy[k];
        if (!inside_domain<ScalarLane>(to_lanes(x), step_constants_)) {
            ledger.escaped += E;
            return false;
        }
        if (b.path_length[k] > settings_.max_path_mm || b.bounces[k] > max_bounces_ ||
            b.time[k] > max_time_s_) {
            ledger.remaining += E;
            return false;
        }
        // The threshold falls with the energy a particle keeps in tissue of the nominal
        // loss: the image's TGC raises late echoes by as much, so a particle deep in the
        // frame is not negligible for being weak. Looked at again only when the energy
        // falls below its last value (the time's exponential, rarely).
        if (E < b.roulette_below[k] && roulette_loss_per_s_ > 0.0)
            b.roulette_below[k] = float(settings_.roulette_energy * double(b.initial_energy[k]) *
                                        std::exp(-roulette_loss_per_s_ * b.time[k]));
        const float threshold = b.roulette_below[k];
        if (E < threshold) {
            // A survivor restarts at twice the threshold, so the next roulette comes once
            // its energy has halved. (Restarting at the threshold itself drew a random
            // number at nearly every later step.)
            const float restart = kRouletteRestart * threshold;
            const float survive = E / restart;
            if (b.random[k].next() < survive) {
                ledger.roulette_added += double(restart) - E;
                b.energy[k] = restart;
                // The echo's way back loses what the way out lost, E / E0 before the
                // restart: unbiased energy times deterministic loss, not the restart squared
                // (echoes and the profile go as E^2 / E0: through the skull every survivor's
                // 1 / survive made a bright dot).
                b.return_factor[k] *= survive;
            } else {
                ledger.roulette_killed += E;
                return false;
            }
        }
        return true;
    }

    // How many more steps of length s from x along r surely stay in x's block: the exit
    // distance minus 1 % of a texel (positions accumulate rounding), over s.
    int steps_to_block_exit(const V& x, const V& r) const {
        constexpr float kBlock = float(tissue::AcousticMap<Dim>::kBlock);
        float distance = std::numeric_limits<float>::max();
        for (int a = 0; a < Dim; ++a) {
            // The block as uniform_block() finds it.
            const float h = map_.spacing()[a];
            const int block =
                int(x[a] * map_.inverse_spacing()[a]) >> tissue::AcousticMap<Dim>::kBlockShift;
            const float lo = float(block) * kBlock * h;
            if (r[a] > 0.0f) distance = std::min(distance, (lo + kBlock * h - x[a]) / r[a]);
            if (r[a] < 0.0f) distance = std::min(distance, (x[a] - lo) / -r[a]);
        }
        const float steps = (distance - 0.01f * texel_mm_) / step_mm_;
        return steps >= 1.0f ? int(std::min(steps, 1e6f)) : 0;
    }

    // Steps through uniform blocks (AcousticMap::uniform_block) in a tight loop: there a
    // step is take_step() minus sampling, the interface test and refraction (zero
    // gradient, n0 == n1): its stages (step.h), with the absorbed fraction computed once
    // per record, so the results are the same bit for bit. Stops before a step that scatters, where
    // the medium varies, or where the particle has not left an interface state; step() takes those.
    // Says whether the particle ended, or how step() goes on.
    enum class RunEnd { ended, step, step_outside_blocks };
    RunEnd uniform_run(Batch<Dim>& b, int k) {
        if (!uniform_runs_) return RunEnd::step;
        // Most steps in a textured medium (the head) are not in a uniform block: leave
        // before loading and storing back the particle's state.
        const Texel* first = map_.uniform_block(b.position[k]);
        if (first == nullptr) return RunEnd::step_outside_blocks;  // step() need not look again
        return uniform_run(b, k, first);
    }
    // The same for a particle in the block whose record is `first`.
    RunEnd uniform_run(Batch<Dim>& b, int k, const Texel* first) {
        if (b.in_interface[k] != kOutside || first->refractive_index != b.previous_index[k])
            return RunEnd::step;
        // The particle's state in locals (registers) for the run, written back at its end.
        const StepConstants<Dim>& c = step_constants_;
        const float s = c.step_mm;
        ScalarState p = load_state(b, k);
        const float roulette_below = b.roulette_below[k];
        const bool record_path = b.path[k] >= 0;
        ScalarEvents events{*this, b, k, *first};

        const Texel* record = nullptr;
        float absorbed = 0.0f, scatter_depth = 0.0f;  // per step, of the record's medium
        double time = 0.0;
        uint64_t steps = 0;
        int steps_in_block = 0;  // steps known to stay inside the current block
        bool limit_reached = false;
        while (true) {
            const Texel* u = record;
            if (steps_in_block-- <= 0) {  // look the block up again
                u = map_.uniform_block(to_vec(p.x));
                if (u == nullptr || u->refractive_index != p.previous_index) break;
                steps_in_block = steps_to_block_exit(to_vec(p.x), to_vec(p.r));
            }
            if (u != record) {  // per-record constants, from take_step()'s stages
                record = u;
                absorbed =
                    c.attenuation ? absorbed_fraction<ScalarLane>(u->attenuation, c, events) : 0.0f;
                scatter_depth =
                    c.scattering ? scatter_increment<ScalarLane>(u->backscatter, c) : 0.0f;
                time = step_time<ScalarLane>(u->refractive_index, c);
            }
            if (scatter_depth > 0.0f && p.optical_depth + scatter_depth >= p.scatter_target)
                break;  // a scattering event: step() records it
            ++steps;
            if (c.deposition_maps)
                enter_deposit_texel(p, int32_t(texel_index(to_vec(p.x))), events);
            absorb(p, absorbed);
            add_fluence(p, s);
            // -- the scattered echo's track-length estimate and the illumination
            if (profile_enabled_ && c.scattering)
                add_to_profile(b, k, to_vec(p.x), p.E, u->backscatter, p.time);
            if (scatter_depth > 0.0f) p.optical_depth = p.optical_depth + scatter_depth;
            move(p, s, time);
            if (record_path)
                out_->paths[std::size_t(b.path[k])].vertices.push_back({to_vec(p.x), p.E});
            // -- endings are decided by continues() below
            if (!inside_domain<ScalarLane>(p.x, c) || p.path_length > c.max_path_mm ||
                p.time > c.max_time_s || p.E < roulette_below) {
                limit_reached = true;
                break;
            }
        }
        store_state(b, k, p);
        out_->stats.steps += steps;
        out_->stats.uniform_steps += steps;
        return !limit_reached || continues(b, k, to_vec(p.x)) ? RunEnd::step : RunEnd::ended;
    }

    const ProbeFace<Dim>* probe_face() const {
        if constexpr (Dim == 2)
            return settings_.probe_face_2d ? &*settings_.probe_face_2d : nullptr;
        else
            return settings_.probe_face_3d ? &*settings_.probe_face_3d : nullptr;
    }

  public:
    bool scatter_enabled_ = false, profile_enabled_ = false;
    // Off with the probe face or the ring detector: the tight loop does not test them.
    bool uniform_runs_ = false;
    bool look_up_blocks_ = false;  // uniform blocks are looked up (kFewUniformBlocks)

  private:
    const tissue::AcousticMap<Dim>& map_;
    const TraceSettings& settings_;
    float texel_mm_ = 1.0f, step_mm_ = 0.5f, attenuation_per_mm_ = 0.0f, seconds_per_mm_ = 0.0f;
    double max_time_s_ = 0.0;
    float follow_reflections_above_ = 0.0f;
    int max_bounces_ = 64;              // TraceSettings::max_bounces, 0 with bounces off
    float face_reflectivity_ = 0.0f;    // the probe face's, 0 with face reflection off
    double roulette_loss_per_s_ = 0.0;  // TraceSettings::roulette_loss_db_per_mm, per second
    double inverse_profile_bin_ = 0.0;
    bool profile_scattered_ = true;  // EchoProfileSettings::scattered
    float profile_scale_ = 0.0f;
    DepositTiles<Dim>* deposits_ = nullptr;
    bool deposit_maps_ = true;
    LineOutput<Dim>* out_ = nullptr;
    uint32_t line_ = 0;
    bool vector_steps_ = true;
    StepConstants<Dim> step_constants_;
    MapView<Dim> map_view_;
    InterfaceSearch<Dim> search_;
    LaneFields<Dim> fields_;
    LaneResults<Dim> results_;
};

// A line's echoes ordered by particle (its index within the line, < `particles`), each
// particle's in the order recorded (time order): a counting sort, what std::stable_sort
// gives, in two passes instead of a merge sort's log2(n).
template <int Dim>
void sort_by_particle(std::vector<EchoEvent<Dim>>& echoes, std::size_t particles) {
    std::vector<uint32_t> first(particles + 1, 0);
    for (const EchoEvent<Dim>& e : echoes) ++first[e.particle + 1];
    std::partial_sum(first.begin(), first.end(), first.begin());
    std::vector<EchoEvent<Dim>> sorted(echoes.size());
    for (const EchoEvent<Dim>& e : echoes) sorted[first[e.particle]++] = e;
    echoes = std::move(sorted);
}

template <int Dim>
void validate_sources(const Sources<Dim>& sources) {
    for (std::size_t n = 0; n < sources.size(); ++n) {
        const auto& s = sources[n];
        bool finite = std::isfinite(s.energy);
        for (int a = 0; a < Dim; ++a)
            finite = finite && std::isfinite(s.position[a]) && std::isfinite(s.direction[a]);
        const std::string field = "sources[" + std::to_string(n) + "]";
        if (!finite)
            throw base::InputError("sources", field,
                                   "position, direction and energy must be finite");
        if (s.energy < 0.0f) throw base::InputError("sources", field + ".energy", "must be >= 0");
        if (!(glm::length(s.direction) > 0.0f))
            throw base::InputError("sources", field + ".direction", "is zero");
    }
}

}  // namespace

template <int Dim>
TraceResult<Dim> trace(const tissue::AcousticMap<Dim>& map, const Sources<Dim>& sources,
                       const TraceSettings& settings, const TraceProgress& progress) {
    settings.validate("trace settings");
    validate_sources(sources);

    // Particles grouped by line (stable: the particle index within a line is its order).
    std::vector<uint32_t> order(sources.size());
    std::iota(order.begin(), order.end(), 0u);
    std::stable_sort(order.begin(), order.end(),
                     [&](uint32_t a, uint32_t b) { return sources[a].line < sources[b].line; });
    std::vector<std::size_t> starts;
    for (std::size_t n = 0; n < order.size(); ++n) {
        if (n == 0 || sources[order[n]].line != sources[order[n - 1]].line) starts.push_back(n);
    }
    starts.push_back(order.size());
    const std::size_t lines = starts.size() - 1;

    const glm::ivec3 dims = map.geometry().dims;
    tbb::enumerable_thread_specific<DepositTiles<Dim>> deposits(
        [dims] { return DepositTiles<Dim>(dims); });
    std::vector<LineOutput<Dim>> outputs(lines);
    InterfaceCache<Dim> interfaces(sources.size(), settings.interface_cache);
    std::atomic<std::size_t> done{0};
    const bool look_up_blocks = map.uniform_block_fraction() >= kFewUniformBlocks;  // once
    // The result maps are zeroed beside the tracing, by whichever thread is free first:
    // clearing them afterwards on one thread left the others idle meanwhile.
    TraceResult<Dim> result;
    tbb::task_group clearing;
    if (settings.deposition_maps) {
        clearing.run([&] { result.fluence = tissue::Volume(map.geometry()); });
        clearing.run([&] { result.absorbed = tissue::Volume(map.geometry()); });
    }
    tbb::parallel_for(std::size_t(0), lines, [&](std::size_t l) {
        LineTracer<Dim> tracer(map, settings, look_up_blocks);
        tracer.run(sources, order, starts[l], starts[l + 1], deposits.local(), interfaces,
                   outputs[l]);
        // Batches interleave particles; order the line's echoes by particle, then time.
        sort_by_particle(outputs[l].echoes, starts[l + 1] - starts[l]);
        if (progress) progress(++done, lines);
    });
    clearing.wait();

    // Merge in line order (deterministic), maps by integer sums.
    double area = 1.0;
    for (int a = 0; a < Dim; ++a) area *= map.spacing()[a];
    const double per_texel = 1.0 / (kFixedScale * area);  // energy*mm per texel -> per mm^Dim
    std::vector<const DepositTiles<Dim>*> maps;           // one per thread that traced
    for (const DepositTiles<Dim>& d : deposits) maps.push_back(&d);
    const std::size_t tiles = settings.deposition_maps && !maps.empty() ? maps[0]->tile_count() : 0;
    tbb::parallel_for(std::size_t(0), tiles, [&](std::size_t t) {
        if (std::none_of(maps.begin(), maps.end(), [t](auto* m) { return m->tile(t) != nullptr; }))
            return;  // nothing deposited: the result is zero there already
        // Row by row of the tile (cells x fastest), within the map's edge.
        constexpr int side = DepositTiles<Dim>::kSide;
        // The next tile's first half, prefetched: tiles lie anywhere in their chunks, and
        // the hardware's stream prefetch restarts at each.
        for (const DepositTiles<Dim>* m : maps) {
            const auto* next = t + 1 < tiles ? m->tile(t + 1) : nullptr;
            if (next == nullptr) continue;
            for (std::size_t line = 0; line < sizeof(*next) / 128; ++line)
                __builtin_prefetch(reinterpret_cast<const char*>(next->data()) + 64 * line);
        }
        const glm::ivec3 origin = maps[0]->tile_origin(t);
        const int width = std::min(side, dims.x - origin.x);
        const int height = std::min(side, dims.y - origin.y);
        const int depth = Dim == 3 ? std::min(side, dims.z - origin.z) : 1;
        for (int z = 0; z < depth; ++z) {
            for (int y = 0; y < height; ++y) {
                const auto first = uint32_t((z * side + y) * side);
                const std::size_t to =
                    result.fluence.linear_index(origin.x, origin.y + y, origin.z + z);
                for (int x = 0; x < width; ++x) {
                    const uint32_t c = first + uint32_t(x);
                    int64_t fluence = 0, absorbed = 0;
                    for (const DepositTiles<Dim>* m : maps) {
                        if (const auto* tile = m->tile(t))
                            fluence += (*tile)[c].fluence, absorbed += (*tile)[c].absorbed;
                    }
                    result.fluence.voxels()[to + std::size_t(x)] =
                        float(double(fluence) * per_texel);
                    result.absorbed.voxels()[to + std::size_t(x)] =
                        float(double(absorbed) / kFixedScale);
                }
            }
        }
    });
    if (settings.ring) result.ring_profile.assign(std::size_t(settings.ring->bins), 0.0);
    if (settings.echo_profile) {
        // Lines are numbered by id; ids without particles keep empty rows.
        uint32_t max_line = 0;
        for (const auto& s : sources) max_line = std::max(max_line, s.line);
        EchoProfile<Dim>& p = result.echo_profile;
        p.lines = sources.empty() ? 0 : int(max_line) + 1;
        p.bins = settings.echo_profile->bins;
        p.bin_s = settings.echo_profile->bin_s;
        // As LineTracer steps: step_texels of the smallest spacing.
        double texel_mm = map.spacing()[0];
        for (int a = 1; a < Dim; ++a) texel_mm = std::min(texel_mm, double(map.spacing()[a]));
        p.step_mm = double(float(settings.step_texels) * float(texel_mm));
        p.intensity.assign(std::size_t(p.lines) * std::size_t(p.bins), 0.0f);
        p.illumination.assign(p.intensity.size(), 0.0f);
        p.illuminated_position.assign(p.intensity.size(), Vec<Dim>(0.0f));
        p.position.assign(p.intensity.size(), Vec<Dim>(0.0f));
        tbb::parallel_for(std::size_t(0), lines, [&](std::size_t l) {
            const std::size_t row =
                std::size_t(sources[order[starts[l]]].line) * std::size_t(p.bins);
            const LineOutput<Dim>& o = outputs[l];
            for (int i = 0; i < p.bins; ++i) {
                const std::size_t at = row + std::size_t(i);
                const ProfileBin<Dim>& lit = o.lit[std::size_t(i)];
                p.illumination[at] = float(lit.sum);
                if (lit.sum > 0.0)
                    for (int a = 0; a < Dim; ++a)
                        p.illuminated_position[at][a] = float(lit.first[std::size_t(a)] / lit.sum);
                if (o.scattered.empty()) continue;
                const ProfileBin<Dim>& w = o.scattered[std::size_t(i)];
                p.intensity[at] = float(w.sum);
                if (!(w.sum > 0.0)) continue;
                const double inverse_w = 1.0 / w.sum;
                for (int a = 0; a < Dim; ++a)
                    p.position[at][a] = float(w.first[std::size_t(a)] * inverse_w);
            }
        });
    }
    std::size_t echo_count = 0;
    for (const LineOutput<Dim>& o : outputs) echo_count += o.echoes.size();
    result.echoes.reserve(echo_count);
    for (LineOutput<Dim>& o : outputs) {
        result.echoes.insert(result.echoes.end(), o.echoes.begin(), o.echoes.end());
        for (auto& p : o.paths) result.paths.push_back(std::move(p));
        for (std::size_t i = 0; i < o.ring.size(); ++i) result.ring_profile[i] += o.ring[i];
        result.ledger += o.ledger;
        result.stats += o.stats;
    }
    return result;
}

template TraceResult<2> trace<2>(const tissue::AcousticMap<2>&, const Sources<2>&,
                                 const TraceSettings&, const TraceProgress&);
template TraceResult<3> trace<3>(const tissue::AcousticMap<3>&, const Sources<3>&,
                                 const TraceSettings&, const TraceProgress&);

}  // namespace sonotrace::simulator
