#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/partitioner.h>
#include <tbb/task_group.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <limits>
#include <map>
#include <memory>
#include <mutex>
#include <numbers>
#include <numeric>
#include <optional>
#include <tuple>
#include <type_traits>

#include "imaging/psf.h"
#include "imaging/psf_row_store.h"
#include "probe/aperture.h"
#include "probe/aperture_terms.h"
#include "probe/array_geometry.h"

// Building a PSF table (imaging/psf.h): the rows the lattice computes, from the fields'
// shared element terms, their mirror images, and the rows interpolated between them.
namespace sonotrace::imaging {

// What a row depends on, of a transducer: the parameters that shape the PSF's rows
// (TransducerParameterDoc::shapes_psf_rows: everything but the imaging depth, which only
// says how many rows a table takes, and what the lateral rows do not see), and the rows'
// spacing.
using RowStoreKey = std::pair<std::vector<probe::TransducerParameterDoc::Value>, double>;
RowStoreKey row_store_key(const probe::Transducer& t, double dz) {
    RowStoreKey key{{}, dz};
    for (const auto& doc : probe::transducer_parameter_docs())
        if (doc.shapes_psf_rows) key.first.push_back(doc.get(t));
    return key;
}

namespace {
// Rows lambda apart, doubled until at most 400 cover the depth: one spacing for depths
// within a factor of two, so their tables share rows.
double row_spacing_mm(const probe::Transducer& t) {
    double dz = t.wavelength_mm();
    while (t.depth_mm / dz > 400.0) dz *= 2.0;
    return dz;
}

std::shared_ptr<PsfTable::RowStore> shared_row_store(const probe::Transducer& t) {
    static std::mutex mutex;
    static std::vector<std::pair<RowStoreKey, std::shared_ptr<PsfTable::RowStore>>> kept;
    const RowStoreKey key = row_store_key(t, row_spacing_mm(t));
    const std::lock_guard<std::mutex> lock(mutex);
    for (const auto& [k, store] : kept)
        if (k == key) return store;
    kept.emplace_back(key, std::make_shared<PsfTable::RowStore>());
    if (kept.size() > 4) kept.erase(kept.begin());  // tables keep theirs alive
    return kept.back().second;
}
}  // namespace

namespace {
// out += w c, the samples as floats (complex<float> is two of them, [complex.numbers]),
// through restrict pointers: as complex arrays that might overlap the loop stayed scalar.
void blend_into(PsfTable::Row& out, const PsfTable::Row& c, float w) {
    constexpr std::size_t n = 2 * PsfTable::kHalfRow + 1;
    float* __restrict h = reinterpret_cast<float*>(out.h.data());
    const float* __restrict ch = reinterpret_cast<const float*>(c.h.data());
    for (std::size_t j = 0; j < 2 * n; ++j) h[j] += w * ch[j];
    float* __restrict r = out.receive_power.data();
    const float* __restrict cr = c.receive_power.data();
    for (std::size_t j = 0; j < n; ++j) r[j] += w * cr[j];
}
}  // namespace

struct PsfTableBuilder {
    using Key = std::array<long, 7>;
    // Rows computed from the fields (exact) or interpolated from four exact ones.
    struct Job {
        int line, depth, id;
        bool far;                     // the far lattice's fields (lines snapped to whole elements)
        std::pair<int, int> receive;  // the receive aperture's elements [first, last)
        int elements;                 // in the line's array
        int mirror_of = -1;           // the job whose row this one mirrors, if any
        PsfTable::Row* row = nullptr;
    };
    // Computed rows of one depth that take their element terms from one line's array.
    struct Group {
        int rep, depth;
        double depth_mm;
        bool far;
        struct Member {
            int job;
            // The rep's element of the job line's element e: e + index, or for a mirrored
            // member (its line sees the rep's array mirrored, x -> -x) index - e.
            int index;
            bool mirrored;
        };
        std::vector<Member> members;
    };
    struct Blend {
        int id, depth;
        std::array<int, 4> corner;  // rows at (l0, i0), (l1, i0), (l0, i1), (l1, i1)
        double across, along;       // weights of l1 and i1
    };

    // The rows of a group from shared element terms. A member whose elements are not
    // where the rep's are (a ring's numbering wraps) takes the terms of its own array.
    static void compute_group(const Group& group, const std::vector<Job>& jobs,
                              const std::vector<std::optional<probe::LineFields>>& fields,
                              const std::vector<std::optional<probe::LineFields>>& far_fields,
                              double dx) {
        auto fields_of = [&](int l) -> const probe::LineFields& {
            return group.far ? *far_fields[std::size_t(l)] : *fields[std::size_t(l)];
        };
        const double z = group.depth_mm;
        const probe::LineFields& rep = fields_of(group.rep);
        struct Member {
            int job;
            const probe::LineFields* terms;  // whose array's terms
            std::vector<double> tx, rx;      // weights in that array's numbering
            double tx_norm, rx_norm;
            int side;  // -1: the row at x is the terms' sums at -x (a mirrored member)
        };
        std::vector<Member> members;
        for (const Group::Member& g : group.members) {
            const probe::LineFields& f = fields_of(jobs[std::size_t(g.job)].line);
            const auto receive = f.receive_weights(z);
            Member m{g.job,
                     &rep,
                     in_numbering_of(f, rep, f.transmit_weights(), g.index, g.mirrored),
                     in_numbering_of(f, rep, receive.weights, g.index, g.mirrored),
                     f.transmit_norm(),
                     receive.norm,
                     g.mirrored ? -1 : 1};
            if (m.tx.empty() || m.rx.empty())
                m = {g.job,        &f, f.transmit_weights(), receive.weights, f.transmit_norm(),
                     receive.norm, 1};
            members.push_back(std::move(m));
        }
        for (std::size_t a = 0; a < members.size(); ++a) {
            const probe::LineFields* terms_of = members[a].terms;
            if (std::any_of(members.begin(), members.begin() + std::ptrdiff_t(a),
                            [&](const Member& m) { return m.terms == terms_of; }))
                continue;  // done with an earlier member's
            int first = int(members[a].tx.size()), last = 0;
            for (const Member& m : members)
                if (m.terms == terms_of)
                    for (const auto* w : {&m.tx, &m.rx})
                        for (int e = 0; e < int(w->size()); ++e)
                            if ((*w)[std::size_t(e)] != 0.0)
                                first = std::min(first, e), last = std::max(last, e + 1);
            // An array symmetric about its line over the elements summed (element e's
            // mirror image is element S - e): the terms at -x are those at x of the
            // mirrored elements, so a row at -x is its mirrored apertures' sums at x.
            const int S = mirror_index_sum(terms_of->array(), first, last);
            if (S >= 0) {
                const int lo = std::min(first, S + 1 - last), hi = std::max(last, S + 1 - first);
                first = lo, last = hi;
            }
            probe::ApertureTerms terms(*terms_of, first, last, z);
            struct Apertures {
                int tx, rx, mirrored_tx, mirrored_rx;
                PsfTable::Row* row;
                int side;
            };
            std::vector<Apertures> apertures;
            for (const Member& m : members)
                if (m.terms == terms_of) {
                    PsfTable::Row& row =
                        PsfTable::RowStore::Rows::start(jobs[std::size_t(m.job)].row);
                    row.dx = dx;
                    Apertures entry{terms.add_transmit(m.tx, m.tx_norm),
                                    terms.add_receive(m.rx, m.rx_norm),
                                    -1,
                                    -1,
                                    &row,
                                    m.side};
                    if (S >= 0) {
                        entry.mirrored_tx = terms.add_transmit(mirrored(m.tx, S), m.tx_norm);
                        entry.mirrored_rx = terms.add_receive(mirrored(m.rx, S), m.rx_norm);
                    }
                    apertures.push_back(entry);
                }
            auto sample = [&](int j, const Apertures& each, int tx, int rx) {
                const probe::LineFields::Speckle s = terms.speckle(tx, rx);
                const auto at = std::size_t(each.side * j + PsfTable::kHalfRow);
                each.row->h[at] = std::complex<float>(s.weight);
                each.row->receive_power[at] = float(s.receive_power);
                each.row->power += s.power * dx;
            };
            for (int j = S >= 0 ? 0 : -PsfTable::kHalfRow; j <= PsfTable::kHalfRow; ++j) {
                terms.at({j * dx, z});
                for (const Apertures& each : apertures) {
                    sample(j, each, each.tx, each.rx);
                    if (S >= 0 && j > 0) sample(-j, each, each.mirrored_tx, each.mirrored_rx);
                }
            }
        }
    }
    // The index sum S of an array whose element e is the mirror image (x -> -x) of element
    // S - e for every e in [first, last) and its mirror images, to 1e-9 mm; -1 if none.
    static int mirror_index_sum(const probe::LineArray& a, int first, int last) {
        const int n = int(a.position.size());
        int centre = 0;
        for (int e = 1; e < n; ++e)
            if (std::abs(a.position[std::size_t(e)].x) <
                std::abs(a.position[std::size_t(centre)].x))
                centre = e;
        auto mirrors = [&](int e, int k) {
            if (e < 0 || k < 0 || e >= n || k >= n) return false;
            const glm::dvec2 p = a.position[std::size_t(e)], q = a.position[std::size_t(k)];
            const glm::dvec2 u = a.normal[std::size_t(e)], v = a.normal[std::size_t(k)];
            return std::abs(p.x + q.x) <= 1e-9 && std::abs(p.y - q.y) <= 1e-9 &&
                   std::abs(u.x + v.x) <= 1e-12 && std::abs(u.y - v.y) <= 1e-12;
        };
        for (const int S : {2 * centre, 2 * centre - 1, 2 * centre + 1}) {
            if (!mirrors(centre, S - centre)) continue;
            const int lo = std::min(first, S + 1 - last), hi = std::max(last, S + 1 - first);
            bool all = true;
            for (int e = lo; e < hi && all; ++e) all = mirrors(e, S - e);
            if (all) return S;
        }
        return -1;
    }
    // w mirrored: element e takes the weight of element S - e.
    static std::vector<double> mirrored(const std::vector<double>& w, int S) {
        std::vector<double> out(w.size(), 0.0);
        for (int e = 0; e < int(w.size()); ++e)
            if (S - e >= 0 && S - e < int(w.size())) out[std::size_t(e)] = w[std::size_t(S - e)];
        return out;
    }
    // Whether line b sees the array as line a does, mirrored (x -> -x, element e ->
    // N - 1 - e), with the transmit aperture mirrored: then b's rows are a's reversed
    // wherever their receive apertures' spans mirror too (the sums depend on distances
    // and |sin theta| alone; the apodizations are symmetric). To 1e-6 mm and 1e-9.
    static bool mirror_images(const probe::LineFields& a, const probe::LineFields& b) {
        const probe::LineArray &p = a.array(), &q = b.array();
        const std::size_t n = p.position.size();
        if (q.position.size() != n || q.along.size() != n || p.along.size() != n) return false;
        const std::vector<double>&u = a.transmit_weights(), &v = b.transmit_weights();
        if (u.size() != n || v.size() != n ||
            std::abs(a.transmit_norm() / b.transmit_norm() - 1.0) > 1e-9)
            return false;
        for (std::size_t e = 0; e < n; ++e) {
            const std::size_t k = n - 1 - e;
            const glm::dvec2 moved = p.position[e] - glm::dvec2(-q.position[k].x, q.position[k].y),
                             turned = p.normal[e] - glm::dvec2(-q.normal[k].x, q.normal[k].y);
            if (glm::dot(moved, moved) > 1e-12 || glm::dot(turned, turned) > 1e-12 ||
                std::abs(p.along[e] + q.along[k]) > 1e-6 || std::abs(u[e] - v[k]) > 1e-9)
                return false;
        }
        return true;
    }
    // Weights w of line array `from` in the numbering of `to` (element e at e + index, or
    // mirrored at index - e: `from`'s element e where `to`'s is, x -> -x); empty if an
    // element with a weight is not at that place and facing that way.
    static std::vector<double> in_numbering_of(const probe::LineFields& from,
                                               const probe::LineFields& to,
                                               const std::vector<double>& w, int index,
                                               bool mirrored) {
        const probe::LineArray &a = from.array(), &b = to.array();
        const glm::dvec2 flip(mirrored ? -1.0 : 1.0, 1.0);
        std::vector<double> out(b.position.size(), 0.0);
        for (int e = 0; e < int(w.size()); ++e) {
            if (w[std::size_t(e)] == 0.0) continue;
            const int k = mirrored ? index - e : e + index;
            if (k < 0 || k >= int(out.size())) return {};
            const auto i = std::size_t(e), j = std::size_t(k);
            const glm::dvec2 moved = a.position[i] - flip * b.position[j],
                             turned = a.normal[i] - flip * b.normal[j];
            if (glm::dot(moved, moved) > 1e-12 || glm::dot(turned, turned) > 1e-12) return {};
            out[j] = w[i];
        }
        return out;
    }

    static std::shared_ptr<PsfTable> build(const probe::Transducer& t,
                                           std::shared_ptr<PsfTable::RowStore> store,
                                           RowLattice lattice) {
        auto table = std::make_shared<PsfTable>();
        table->t_ = t;
        table->store_ = store;
        const double lambda = t.wavelength_mm();
        table->k_ = 2.0 * std::numbers::pi / lambda;
        table->lines_ = t.lines;
        table->dz_ = row_spacing_mm(t);
        table->depths_ = int(std::ceil(t.depth_mm / table->dz_)) + 2;
        const int depths = table->depths_;
        const int L = t.lines;
        auto depth_of = [&](int i) { return std::max(i * table->dz_, 0.5 * table->dz_); };
        // The lattice (RowLattice): the rows computed are every row of the near zone and,
        // from depth index `near` on, every `D`-th depth's rows of the anchor lines (at
        // most `S` apart). A table computes rows up to the lattice depth at or past its
        // last: every row has its anchors, and a row is the same whichever table (of
        // whatever depth) made it.
        const int near = std::min(lattice.near_depths(t, table->dz_), depths);
        const int D = std::max(lattice.depth_step, 1), S = std::max(lattice.line_step, 1);
        auto anchor_depth = [&](int i) { return i < near || (i - near) % D == 0; };
        auto previous_anchor_depth = [&](int i) {
            return i < near ? i : near + (i - near) / D * D;
        };
        auto next_anchor_depth = [&](int i) {
            return i < near ? i : near + (i - near + D - 1) / D * D;
        };
        const int computed = next_anchor_depth(depths - 1) + 1;
        const std::lock_guard<std::mutex> building(store->build);
        const int known = int(store->row_of_depth.size());
        // The lines' fields (snapped to sub-element offsets) and, beyond the near zone,
        // the anchor lines' fields (snapped to whole elements).
        std::vector<std::optional<probe::LineFields>> fields,
            far_fields(static_cast<std::size_t>(L));
        std::vector<Job> jobs;
        std::vector<Group> groups;
        std::vector<Blend> blends;
        // The computed rows, as tasks; the interpolated ones (far rows only) follow as soon
        // as the far groups and their set-up are done, beside the near groups: they are
        // memory-bound where the groups are not.
        tbb::task_group computing;
        auto mirror_rows = [&](bool far) {  // from the rows they mirror, of their depth
            tbb::parallel_for(std::size_t(0), jobs.size(), [&](std::size_t n) {
                if (jobs[n].mirror_of < 0 || jobs[n].far != far) return;
                const PsfTable::Row& from = *jobs[std::size_t(jobs[n].mirror_of)].row;
                PsfTable::Row& row = PsfTable::RowStore::Rows::start(jobs[n].row);
                row.dx = from.dx, row.power = from.power;
                std::reverse_copy(from.h.begin(), from.h.end(), row.h.begin());
                std::reverse_copy(from.receive_power.begin(), from.receive_power.end(),
                                  row.receive_power.begin());
            });
        };
        auto blend_rows = [&] {
            mirror_rows(true);
            tbb::parallel_for(0, int(blends.size()), [&](int n) {
                const Blend& b = blends[std::size_t(n)];
                const std::array<double, 4> w{(1.0 - b.across) * (1.0 - b.along),
                                              b.across * (1.0 - b.along),
                                              (1.0 - b.across) * b.along, b.across * b.along};
                PsfTable::Row& row =
                    PsfTable::RowStore::Rows::start(&store->rows[std::size_t(b.id)]);
                row.dx = PsfTable::reach_mm(t, depth_of(b.depth)) / PsfTable::kHalfRow;
                for (int k = 0; k < 4; ++k) {
                    if (w[std::size_t(k)] == 0.0) continue;  // adds nothing
                    const PsfTable::Row& c = store->rows[std::size_t(b.corner[std::size_t(k)])];
                    blend_into(row, c, float(w[std::size_t(k)]));
                    row.power += w[std::size_t(k)] * c.power;
                }
            });
        };
        std::atomic<int> before_blends{1};  // the far groups left, and the set-up
        auto towards_blends = [&] {
            if (before_blends.fetch_sub(1) == 1) computing.run(blend_rows);
        };
        if (known < computed) {
            const probe::ScanGeometry geometry(t);
            // Anchor lines d from either end of the scan, d + 1 apart at the ends and d / 3
            // further in, at most S: at the array's ends the apertures are clipped and the
            // beam turns fastest from line to line.
            std::vector<char> is_anchor(static_cast<std::size_t>(L), 0);
            for (double d = 0.0; d < L; d += std::clamp(std::floor(d / 3.0), 1.0, double(S))) {
                is_anchor[std::size_t(d)] = 1;
                is_anchor[std::size_t(L - 1 - int(d))] = 1;
            }
            auto anchor_line = [&](int l) { return is_anchor[std::size_t(l)] != 0; };
            std::vector<int> previous_anchor(static_cast<std::size_t>(L)),
                next_anchor(static_cast<std::size_t>(L));
            for (int l = 0, last = 0; l < L; ++l)
                previous_anchor[std::size_t(l)] = last = anchor_line(l) ? l : last;
            for (int l = L - 1, last = L - 1; l >= 0; --l)
                next_anchor[std::size_t(l)] = last = anchor_line(l) ? l : last;
            fields.resize(std::size_t(L));
            // What determines a row: the line's sub-element offset and its active element
            // ranges relative to its centre element (phased lines: the line itself). What
            // does not change with depth is found once per line (and lattice).
            struct LineKey {
                int centre = 0;
                long offset = 0;
                std::pair<long, long> tx;
            };
            std::vector<LineKey> line_keys[2];
            auto range = [](const std::vector<double>& w, int centre) {
                int first = -1, last = -1;
                for (int e = 0; e < int(w.size()); ++e)
                    if (w[std::size_t(e)] != 0.0) last = e, first = first < 0 ? e : first;
                return std::pair<long, long>(first - centre, last - centre);
            };
            auto make_line_key = [&](const probe::LineFields& f, int l) {
                const probe::LineArray& a = f.array();
                LineKey k;
                for (int e = 1; e < int(a.along.size()); ++e)
                    if (std::abs(a.along[std::size_t(e)]) <
                        std::abs(a.along[std::size_t(k.centre)]))
                        k.centre = e;
                k.tx = range(f.transmit_weights(), k.centre);
                const bool steered = !geometry.array().aperture_centre(geometry.line(l));
                k.offset =
                    steered ? 1000000L + l : std::lround(a.along[std::size_t(k.centre)] * 1e4);
                return k;
            };
            for (auto& keys : line_keys) keys.resize(std::size_t(L));
            tbb::parallel_for(0, L, [&](int l) {
                const auto n = std::size_t(l);
                fields[n].emplace(t, probe::line_array(t, l, lattice.snap_fraction * t.pitch_mm));
                line_keys[0][n] = make_line_key(*fields[n], l);
                if (computed > near && anchor_line(l)) {
                    far_fields[n].emplace(t, probe::line_array(t, l, t.pitch_mm));
                    line_keys[1][n] = make_line_key(*far_fields[n], l);
                }
            });
            auto key_of = [&](int l, int i, bool far, const std::pair<int, int>& receive) {
                const LineKey& k = line_keys[far][std::size_t(l)];
                return Key{k.offset,
                           k.tx.first,
                           k.tx.second,
                           receive.first - k.centre,
                           receive.second - 1 - k.centre,
                           i,
                           long(far)};
            };
            // (Flags: the depth test divides, and the loops below visit every row.)
            std::vector<char> is_anchor_depth(static_cast<std::size_t>(computed));
            for (int i = 0; i < computed; ++i) is_anchor_depth[std::size_t(i)] = anchor_depth(i);
            auto anchor = [&](int l, int i) {
                return is_anchor_depth[std::size_t(i)] && (i < near || anchor_line(l));
            };
            // From the middle out: a row that lines share is made by the most central.
            std::vector<int> middle_out(static_cast<std::size_t>(L));
            std::iota(middle_out.begin(), middle_out.end(), 0);
            std::stable_sort(middle_out.begin(), middle_out.end(), [&](int a, int b) {
                return std::abs(2 * a - (L - 1)) < std::abs(2 * b - (L - 1));
            });
            // The anchors first, computed from the fields. A key holds its depth, so the
            // rows of each depth are found apart (in parallel), then numbered in order.
            auto fields_at = [&](int l, int i) -> const probe::LineFields& {
                return i >= near ? *far_fields[std::size_t(l)] : *fields[std::size_t(l)];
            };
            struct DepthRows {
                std::vector<Key> keys;   // distinct, as their lines come from the middle out
                std::vector<int> maker;  // the line that makes each
                std::vector<std::pair<int, int>> receive;  // its receive aperture's span
                std::vector<int> slot;                     // per line: its key's, -1 if none
            };
            std::vector<DepthRows> depth_rows(static_cast<std::size_t>(computed - known));
            tbb::parallel_for(known, computed, [&](int i) {
                if (!is_anchor_depth[std::size_t(i)]) return;
                DepthRows& d = depth_rows[std::size_t(i - known)];
                d.slot.assign(std::size_t(L), -1);
                const bool far = i >= near;
                for (const int l : middle_out) {
                    if (!anchor(l, i)) continue;
                    const auto receive =
                        probe::aperture_span(fields_at(l, i).array(),
                                             t.receive_aperture_mm(depth_of(i)), t.rx_apodization);
                    const Key key = key_of(l, i, far, receive);
                    const auto it = std::find(d.keys.begin(), d.keys.end(), key);
                    d.slot[std::size_t(l)] = int(it - d.keys.begin());
                    if (it == d.keys.end())
                        d.keys.push_back(key), d.maker.push_back(l), d.receive.push_back(receive);
                }
            });
            store->row_of_depth.resize(std::size_t(computed), std::vector<int>(std::size_t(L)));
            for (int i = known; i < computed; ++i) {
                const DepthRows& d = depth_rows[std::size_t(i - known)];
                if (d.slot.empty()) continue;  // no anchors at this depth
                const int first = int(store->rows.size());
                for (std::size_t k = 0; k < d.keys.size(); ++k) {
                    const int l = d.maker[k];
                    store->rows.emplace_back();
                    store->line.push_back(l);
                    jobs.push_back({l, i, first + int(k), i >= near, d.receive[k],
                                    int(fields_at(l, i).array().along.size())});
                }
                for (int l = 0; l < L; ++l)
                    if (d.slot[std::size_t(l)] >= 0)
                        store->row_of_depth[std::size_t(i)][std::size_t(l)] =
                            first + d.slot[std::size_t(l)];
            }
            // A row whose line is the mirror image of a line with a row computed here
            // (line L - 1 - l on a symmetric scan, at the same depth: both new) is that
            // row reversed.
            std::vector<signed char> mirrored_lines[2];
            auto mirrored_line = [&](int l, bool far) {
                std::vector<signed char>& known_pairs = mirrored_lines[far];
                if (known_pairs.empty()) known_pairs.assign(std::size_t(L), -1);
                signed char& m = known_pairs[std::size_t(l)];
                const auto& f = far ? far_fields : fields;
                if (m < 0)
                    m = f[std::size_t(l)] && f[std::size_t(L - 1 - l)] &&
                        mirror_images(*f[std::size_t(L - 1 - l)], *f[std::size_t(l)]);
                return m == 1;
            };
            const int first_job_id = jobs.empty() ? 0 : jobs.front().id;
            for (Job& job : jobs) {
                const int source =
                    store->row_of_depth[std::size_t(job.depth)][std::size_t(L - 1 - job.line)];
                if (source >= job.id || source < first_job_id) continue;  // or it mirrors this one
                const Job& from = jobs[std::size_t(source - first_job_id)];
                if (from.mirror_of >= 0 || !mirrored_line(job.line, job.far)) continue;
                if (job.receive.first == job.elements - from.receive.second &&
                    job.receive.second == job.elements - from.receive.first)
                    job.mirror_of = source - first_job_id;
            }
            // The computed rows of a depth whose lines sit at one sub-element offset share
            // their element terms (probe/aperture_terms.h), taken from the array of the
            // most central line at that offset; their apertures differ.
            std::map<std::pair<long, bool>, int> rep_of_offset;
            for (const int l : middle_out)
                for (const bool far : {false, true}) {
                    if (far && !far_fields[std::size_t(l)]) continue;
                    rep_of_offset.try_emplace({line_keys[far][std::size_t(l)].offset, far}, l);
                }
            // Lines at the opposite offset (x -> -x) take the terms of that offset's rep at
            // -x, through their apertures mirrored: one set of terms for both offsets
            // (compute_group checks the elements, and falls back on the line's own).
            std::map<std::tuple<bool, int, int>, int> group_of;
            for (std::size_t n = 0; n < jobs.size(); ++n) {
                const Job& job = jobs[n];
                if (job.mirror_of >= 0) continue;
                const LineKey& key = line_keys[job.far][std::size_t(job.line)];
                const auto opposite = rep_of_offset.find({-key.offset, job.far});
                const bool mirrored =
                    key.offset > 0 && key.offset < 1000000L && opposite != rep_of_offset.end();
                const int rep =
                    mirrored ? opposite->second : rep_of_offset.at({key.offset, job.far});
                const auto [it, fresh] =
                    group_of.try_emplace({job.far, rep, job.depth}, int(groups.size()));
                if (fresh) groups.push_back({rep, job.depth, depth_of(job.depth), job.far, {}});
                const int rep_centre = line_keys[job.far][std::size_t(rep)].centre;
                groups[std::size_t(it->second)].members.push_back(
                    {int(n), mirrored ? rep_centre + key.centre : rep_centre - key.centre,
                     mirrored});
            }
            // A task per group, the far ones (a whole depth's anchor lines, four times a
            // near group's work) first: halving the range put them all on one thread. The
            // interpolated rows are laid out meanwhile (the rows' chunks do not move).
            std::stable_sort(groups.begin(), groups.end(),
                             [](const Group& a, const Group& b) { return a.far > b.far; });
            for (Job& job : jobs) job.row = &store->rows[std::size_t(job.id)];
            before_blends += int(
                std::count_if(groups.begin(), groups.end(), [](const Group& g) { return g.far; }));
            computing.run([&] {
                tbb::parallel_for(
                    tbb::blocked_range<int>(0, int(groups.size()), 1),
                    [&](const tbb::blocked_range<int>& some) {
                        for (int g = some.begin(); g < some.end(); ++g) {
                            const Group& group = groups[std::size_t(g)];
                            compute_group(
                                group, jobs, fields, far_fields,
                                PsfTable::reach_mm(t, group.depth_mm) / PsfTable::kHalfRow);
                            if (group.far) towards_blends();
                        }
                    },
                    tbb::simple_partitioner());
            });
            // Then the rows between them, bilinear in line and depth; rows whose corners
            // are one row (lines inside the array, away from its ends) are that row.
            for (int i = known; i < computed; ++i) {
                const int i0 = previous_anchor_depth(i), i1 = next_anchor_depth(i);
                for (int l = 0; l < L; ++l) {
                    if (anchor(l, i)) continue;
                    const int l0 = i < near ? l : previous_anchor[std::size_t(l)];
                    const int l1 = i < near ? l : next_anchor[std::size_t(l)];
                    auto row_at = [&](int line, int depth) {
                        return store->row_of_depth[std::size_t(depth)][std::size_t(line)];
                    };
                    const std::array<int, 4> corner{row_at(l0, i0), row_at(l1, i0), row_at(l0, i1),
                                                    row_at(l1, i1)};
                    double across = l1 > l0 ? double(l - l0) / double(l1 - l0) : 0.0;
                    double along = i1 > i0 ? double(i - i0) / double(i1 - i0) : 0.0;
                    // A weight between two equal rows is 0, so that the lines (or depths)
                    // between them share one row.
                    if (corner[0] == corner[1] && corner[2] == corner[3]) across = 0.0;
                    if (corner[0] == corner[2] && corner[1] == corner[3]) along = 0.0;
                    if (corner[0] == corner[1] && corner[0] == corner[2] &&
                        corner[0] == corner[3]) {
                        store->row_of_depth[std::size_t(i)][std::size_t(l)] = corner[0];
                        continue;
                    }
                    // A row of its own, but for lines between two equal rows, which share
                    // the first one's (the lines of a depth come in order).
                    if (across == 0.0 && l > 0 && !blends.empty() && blends.back().depth == i &&
                        blends.back().corner == corner && blends.back().along == along &&
                        blends.back().across == 0.0) {
                        store->row_of_depth[std::size_t(i)][std::size_t(l)] = blends.back().id;
                        continue;
                    }
                    const int id = int(store->rows.size());
                    store->rows.emplace_back();
                    store->line.push_back(l);
                    store->row_of_depth[std::size_t(i)][std::size_t(l)] = id;
                    blends.push_back({id, i, corner, across, along});
                }
            }
        }
        // The table numbers rows as the store does, and sees those made so far.
        table->row_of_.resize(std::size_t(L) * std::size_t(depths));
        for (int l = 0; l < L; ++l)
            for (int i = 0; i < depths; ++i)
                table->row_of_[std::size_t(l) * std::size_t(depths) + std::size_t(i)] =
                    store->row_of_depth[std::size_t(i)][std::size_t(l)];
        for (std::size_t r = 0; r < store->rows.size(); ++r)
            table->rows_.push_back(&store->rows[r]);
        table->row_line_ = store->line;
        towards_blends();
        computing.wait();
        mirror_rows(false);
        // The lines' fields, where they are the ones plane echoes take (fields_of_line),
        // are kept for them: made once, and not freed here one by one.
        if (lattice.snap_fraction == PsfTable::RowStore::kSnapFraction && !fields.empty()) {
            const std::lock_guard<std::mutex> lock(store->fields_mutex);
            for (int l = 0; l < L; ++l) {
                auto& slot = store->fields[l];
                if (!slot)
                    slot = std::make_shared<const probe::LineFields>(
                        std::move(*fields[std::size_t(l)]));
            }
        }
        table->computed_rows_ = int(jobs.size());
        table->focal_power_ = table->power(t.lines / 2, t.focus_mm);
        return table;
    }
};

std::shared_ptr<const PsfTable> PsfTable::of(const probe::Transducer& t) {
    const std::pair<RowStoreKey, double> key{row_store_key(t, row_spacing_mm(t)), t.depth_mm};
    static std::mutex mutex;
    static std::vector<std::pair<std::pair<RowStoreKey, double>, std::shared_ptr<const PsfTable>>>
        cache;
    {
        const std::lock_guard<std::mutex> lock(mutex);
        for (const auto& [k, table] : cache)
            if (k == key) return table;
    }
    std::shared_ptr<const PsfTable> table =
        PsfTableBuilder::build(t, shared_row_store(t), RowLattice{});
    const std::lock_guard<std::mutex> lock(mutex);
    cache.emplace_back(key, table);
    if (cache.size() > 4) cache.erase(cache.begin());
    return table;
}

std::shared_ptr<const PsfTable> PsfTable::build(const probe::Transducer& t, RowLattice lattice) {
    return PsfTableBuilder::build(t, std::make_shared<RowStore>(), lattice);
}

}  // namespace sonotrace::imaging
