#include "simulator/tracer.h"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/task_group.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <cmath>
#include <memory>
#include <numeric>

#include "simulator/batch.h"
#include "simulator/deposit_tiles.h"
#include "simulator/interactions.h"
#include "simulator/interface_events.h"
#include "simulator/interface_search.h"
#include "simulator/line_output.h"
#include "simulator/probe_face_geometry.h"
#include "simulator/rng.h"
#include "simulator/step.h"
#include "simulator/tracer_constants.h"

namespace sonotrace::simulator {

namespace {

using namespace detail;

// Russian roulette: a particle below the threshold survives with probability
// E / (kRouletteRestart * threshold) and then carries that energy (unbiased).
constexpr float kRouletteRestart = 2.0f;

// Below this fraction of uniform blocks the tracer does not look for them
// (TracerConstants::look_up_blocks).
constexpr double kFewUniformBlocks = 0.05;

template <int Dim>
class LineTracer {
  public:
    using V = Vec<Dim>;
    using Texel = tissue::AcousticTexel<Dim>;
    using ScalarState = StepState<ScalarLane, Dim>;  // one particle's state (step.h)

    LineTracer(const tissue::AcousticMap<Dim>& map, const TraceSettings& settings,
               const TracerConstants<Dim>& constants)
        : map_(map), settings_(settings), c_(constants), search_(map, settings) {
        search_.set_view(c_.view);
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
            out.scattered.assign(c_.profile_scattered ? bins : 0, ProfileBin<Dim>{});
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
            if (c_.vector_steps) {
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
        if (!c_.uniform_runs) {
            std::fill_n(f.eligible.begin(), b.count, -1);
        } else {
            find_uniform_blocks(c_.view, b, f, b.count);
        }
        for (int k = 0; c_.uniform_runs && k < b.count;) {
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
        sample_lanes(c_.view, b, f, lanes);
        vector_step(b, f, c_.step, results_, lanes);
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
            if (c_.deposit_maps) deposits_->prefetch(b.pending_texel[i]);
        }
        if (c_.profile_enabled && c_.scatter_enabled) {
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
        b.rough_bounces[k] = 0;
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
                                                    receive, backscatter, c_.profile_scale),
                          backscatter);
    }

    void add_profile_terms(const V& x, double time, const ProfileTerms<ScalarLane>& terms,
                           float backscatter) {
        out_->add_profile(x, time * c_.inverse_profile_bin, terms.lit,
                          backscatter > 0.0f ? terms.scattered : 0.0f);
    }

    void flush_deposits(Batch<Dim>& b, int k) {
        deposit(b.pending_texel[k], b.pending_fluence[k], b.pending_absorbed[k]);
        b.pending_fluence[k] = b.pending_absorbed[k] = 0.0f;
    }

    // Without maps, the pending sums run over the particle's whole path and reach the
    // ledger when it ends.
    void deposit(uint32_t texel, float fluence, float absorbed) {
        if (c_.deposit_maps) {
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
        // The decision stays here, where the transition begins (deeper in, the fringe has
        // bent the particle); the echo is timed where the path crosses (crossing_of).
        const Crossing<Dim> crossing = crossing_of(search_, sides, x, r, t);
        if (leaving_a_gas_transition(search_, crossing, t.impedance)) {
            p.state = int32_t(kOutside);
            return;
        }
        p.state = int32_t(kCrossing);
        out_->stats.interface_events++;
        p.interface_normal = to_lanes(crossing.normal);
        decide_reflection(
            b, k, p, crossing,
            reflection_at(settings_, crossing, r, t.refractive_index, sides.roughness));
    }

    // The reflection decision at a sharp interface: records the expected echo R^2 and
    // reflects with probability R^2. Without specular reflection only total reflection,
    // which is refraction's (Snell's law between the plateaus has no solution), happens,
    // with no decision and no echo otherwise.
    void decide_reflection(Batch<Dim>& b, int k, ScalarState& p, const Crossing<Dim>& crossing,
                           const Reflection<Dim>& reflection) {
        if (!settings_.physics.on(Physics::specular) && !reflection.total()) return;
        const V x = to_vec(p.x), r = to_vec(p.r);
        float& E = p.E;
        const auto [R2, converted] = reflection.fractions;
        const float c = reflection.lobe_exponent;
        const double to_middle_s =
            double(crossing.to_middle_mm) * c_.seconds_per_mm * crossing.near_side.refractive_index;
        record_echo(b, k, x + r * crossing.to_middle_mm, reflection.incoming, E, R2,
                    reflection.diffuse() ? EchoKind::diffuse : EchoKind::specular, reflection.cos_i,
                    c, to_middle_s, -crossing.forward);
        if (R2 < c_.follow_reflections_above) {  // scored, not followed (TraceSettings)
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
        const V mirror = reflect<Dim>(reflection.incoming, crossing.forward);
        float weight = 1.0f;
        const V leaving = reflection.diffuse()
                              ? sample_lobe(mirror, crossing.forward, c, settings_.lobe_weight,
                                            b.random[k], &weight)
                              : mirror;
        p.r = to_lanes(leaving);
        if (reflection.diffuse() && settings_.diffuse_return_half_angle_rad > 0.0) {
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
        p.path_length += 2.0 * crossing.to_middle_mm;
        b.bounces[k]++;
        if (reflection.diffuse() && b.rough_bounces[k] < 255) b.rough_bounces[k]++;
        out_->stats.reflections++;
        if (reflection.total()) out_->stats.total_reflections++;
    }

    [[gnu::noinline]] void record_echo(const Batch<Dim>& b, int k, const V& x, const V& direction,
                                       float energy, float weight, EchoKind kind,
                                       float cos_incidence = 1.0f, float lobe_exponent = 1e6f,
                                       double extra_time_s = 0.0, const V& normal = V(0.0f)) {
        out_->echoes.push_back({line_, b.particle[k], float(b.time[k] + extra_time_s), energy,
                                weight, x, b.bounces[k], kind, b.rough_bounces[k], cos_incidence,
                                lobe_exponent, b.return_factor[k], normal, direction});
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
        f.texel = c_.deposit_maps ? int32_t(texel_index(x)) : 0;
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
            if (tracer.c_.profile_enabled)
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
            c_.look_up_blocks && !outside_blocks ? map_.uniform_block(from) : nullptr;
        const Texel t = uniform ? *uniform : map_.sample(from);
        stats.steps++;
        stats.uniform_steps += uniform != nullptr;
        ScalarState p = load_state(b, k);
        ScalarEvents events{*this, b, k, t};
        take_step(p, fields_of(t, from), c_.step, events);
        store_state(b, k, p);
        V x = to_vec(p.x), r = to_vec(p.r);
        float E = p.E;

        // -- the probe face captures what comes back through it
        if (const auto* face = probe_face_of<Dim>(settings_)) {
            if (crosses_face(*face, from, x)) {
                stats.captured++;
                const float kept = E * c_.face_reflectivity;
                record_echo(b, k, x, r, E, 1.0f - c_.face_reflectivity,
                            EchoKind::returned_to_probe);
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
                const int bin = settings_.ring->bin_crossed(from, x);
                if (bin >= 0) out_->ring[std::size_t(bin)] += E;
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
        if (!inside_domain<ScalarLane>(to_lanes(x), c_.step)) {
            ledger.escaped += E;
            return false;
        }
        if (b.path_length[k] > settings_.max_path_mm || b.bounces[k] > c_.max_bounces ||
            b.time[k] > c_.max_time_s) {
            ledger.remaining += E;
            return false;
        }
        // The threshold falls with the energy a particle keeps in tissue of the nominal
        // loss: the image's TGC raises late echoes by as much, so a particle deep in the
        // frame is not negligible for being weak. Looked at again only when the energy
        // falls below its last value (the time's exponential, rarely).
        if (E < b.roulette_below[k] && c_.roulette_loss_per_s > 0.0)
            b.roulette_below[k] = float(settings_.roulette_energy * double(b.initial_energy[k]) *
                                        std::exp(-c_.roulette_loss_per_s * b.time[k]));
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

    // How many more steps from x along r surely stay in x's block: the exit distance
    // minus 1 % of a texel (positions accumulate rounding), in steps.
    int steps_to_block_exit(const V& x, const V& r) const {
        const float steps = (map_.distance_to_block_exit(x, r) - 0.01f * c_.texel_mm) / c_.step_mm;
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
        if (!c_.uniform_runs) return RunEnd::step;
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
        const StepConstants<Dim>& c = c_.step;
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
            if (c_.profile_enabled && c.scattering)
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

  private:
    const tissue::AcousticMap<Dim>& map_;
    const TraceSettings& settings_;
    const TracerConstants<Dim> c_;  // a copy: the hot loop reads it through `this`
    DepositTiles<Dim>* deposits_ = nullptr;
    LineOutput<Dim>* out_ = nullptr;
    uint32_t line_ = 0;
    InterfaceSearch<Dim> search_;
    LaneFields<Dim> fields_;
    LaneResults<Dim> results_;
};

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
    const TracerConstants<Dim> constants(map, settings, InterfaceSearch<Dim>(map, settings),
                                         map.uniform_block_fraction() >= kFewUniformBlocks);
    // The result maps are zeroed beside the tracing, by whichever thread is free first:
    // clearing them afterwards on one thread left the others idle meanwhile.
    TraceResult<Dim> result;
    tbb::task_group clearing;
    if (settings.deposition_maps) {
        clearing.run([&] { result.fluence = tissue::Volume(map.geometry()); });
        clearing.run([&] { result.absorbed = tissue::Volume(map.geometry()); });
    }
    tbb::parallel_for(std::size_t(0), lines, [&](std::size_t l) {
        LineTracer<Dim> tracer(map, settings, constants);
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
    if (settings.deposition_maps) merge_deposits(maps, per_texel, result.fluence, result.absorbed);
    if (settings.ring) result.ring_profile.assign(std::size_t(settings.ring->bins), 0.0);
    if (settings.echo_profile) {
        std::vector<uint32_t> line_ids(lines);
        for (std::size_t l = 0; l < lines; ++l) line_ids[l] = sources[order[starts[l]]].line;
        result.echo_profile =
            merge_echo_profiles(outputs, line_ids, *settings.echo_profile,
                                double(float(settings.step_texels) * map.smallest_spacing()));
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
