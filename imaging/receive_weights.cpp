#include "imaging/receive_weights.h"

#include <tbb/parallel_for.h>

#include <cmath>
#include <limits>
#include <memory>
#include <mutex>
#include <vector>

#include "imaging/psf.h"
#include "probe/array_geometry.h"
#include "probe/elevation.h"
#include "tissue/acoustic_map.h"

namespace sonotrace::imaging {

namespace {

template <int Dim>
std::shared_ptr<const simulator::ReceiveWeights> compute_receive_weights(
    const probe::Transducer& t, const probe::Sources<Dim>& sources,
    const glm::vec<Dim, double>& face_in_map) {
    // Columns 0.25 mm of one-way range apart: |R|^2 of a focused receive changes over
    // millimetres along the line.
    const double bin_s = 0.25e-3 / tissue::kReferenceSpeed;
    const std::shared_ptr<const PsfTable> psf = PsfTable::of(t);
    const std::shared_ptr<const probe::ElevationTable> lens =
        Dim == 3 ? probe::ElevationTable::of(t) : nullptr;
    const probe::ScanGeometry geometry(t);
    const int L = t.lines;
    auto out = std::make_shared<simulator::ReceiveWeights>();
    out->set_bin_s(bin_s);
    // One-way times up to the echo window's close (half the round trip of the depth):
    // later events make no echo.
    out->bins = int(std::ceil(t.depth_mm * 1e-3 / tissue::kReferenceSpeed / bin_s)) + 2;
    std::vector<std::vector<uint32_t>> of_line(static_cast<std::size_t>(L));
    for (std::size_t s = 0; s < sources.size(); ++s)
        if (sources[s].line < uint32_t(L)) of_line[sources[s].line].push_back(uint32_t(s));
    out->first_of_line.assign(std::size_t(L) + 1, 0);
    for (int l = 0; l < L; ++l)
        out->first_of_line[std::size_t(l) + 1] =
            out->first_of_line[std::size_t(l)] + uint32_t(of_line[std::size_t(l)].size());
    out->weight.assign(std::size_t(out->first_of_line.back()) * std::size_t(out->bins), 1.0f);
    const double mm_per_s = tissue::kReferenceSpeed * 1e3;
    tbb::parallel_for(0, L, [&](int l) {
        const probe::ScanLine axis = geometry.line(l);
        const glm::dvec2 across(axis.direction.y, -axis.direction.x);
        const auto& line = of_line[std::size_t(l)];
        struct Launch {
            double x, z, dx, dz, t0, energy;  // line frame: across, along
            double inverse_dz;                // 1 / dz where dz > 1e-3 (the means use)
            double e = 0.0, de = 0.0;         // elevation (3D)
        };
        // The receive's power at a point of a line's frame, in 3D times the lens's.
        const PsfTable::LineReceive receive(*psf, l);
        auto power = [&](double x, double z, double e) {
            const double in_plane = receive.power(x, z);
            if constexpr (Dim == 3) return in_plane * lens->intensity(e, z);
            (void)e;
            return in_plane;
        };
        std::vector<Launch> launches;
        for (const uint32_t index : line) {
            const auto& s = sources[index];
            const glm::dvec2 from = glm::dvec2(s.position.x, s.position.y) -
                                    glm::dvec2(face_in_map.x, face_in_map.y) - axis.origin;
            // In 3D the in-plane components per mm of path: slower across the plane.
            const glm::dvec2 d(s.direction.x, s.direction.y);
            const double along = glm::dot(d, axis.direction);
            Launch launch{glm::dot(from, across),
                          glm::dot(from, axis.direction),
                          glm::dot(d, across),
                          glm::dot(d, axis.direction),
                          double(s.time_s),
                          double(s.energy),
                          along > 1e-3 ? 1.0 / along : 0.0};
            if constexpr (Dim == 3) {
                launch.e = double(s.position.z) - face_in_map.z;
                launch.de = double(s.direction.z);
            }
            launches.push_back(launch);
        }
        // The reciprocal of the mean over the line's particles at a range (0.5 mm apart,
        // as needed; NaN: not yet; 0: no particle within the receive's reach). Ranges are
        // positive: keys from 0.
        std::vector<double> inverse_mean_at;
        auto inverse_mean = [&](double z) {
            const auto key = std::size_t(std::lround(z * 2.0));
            if (key >= inverse_mean_at.size())
                inverse_mean_at.resize(key + 1 + key / 4, std::numeric_limits<double>::quiet_NaN());
            double& value = inverse_mean_at[key];
            if (!std::isnan(value)) return value;
            const double zk = std::max(0.5 * double(key), 0.25);
            double sum = 0.0, energy = 0.0;
            for (const Launch& p : launches) {
                if (!(p.dz > 1e-3)) continue;
                const double to = (zk - p.z) * p.inverse_dz;
                sum += p.energy * power(p.x + to * p.dx, zk, p.e + to * p.de);
                energy += p.energy;
            }
            value = energy > 0.0 && sum > 0.0 ? energy / sum : 0.0;
            return value;
        };
        for (std::size_t p = 0; p < launches.size(); ++p) {
            const Launch& a = launches[p];
            float* row =
                out->weight.data() +
                (std::size_t(out->first_of_line[std::size_t(l)]) + p) * std::size_t(out->bins);
            for (int b = 0; b < out->bins; ++b) {
                const double s = ((b + 0.5) * bin_s - a.t0) * mm_per_s;
                const double z = a.z + s * a.dz;
                if (!(z > 0.0)) continue;
                const double inverse = inverse_mean(z);
                if (!(inverse > 0.0)) continue;  // no particle within the receive's reach: as is
                row[b] = float(power(a.x + s * a.dx, z, a.e + s * a.de) * inverse);
            }
        }
    });
    return out;
}

}  // namespace

namespace {

template <int Dim>
std::shared_ptr<const simulator::ReceiveWeights> kept_receive_weights(
    const probe::Transducer& t, const probe::Sources<Dim>& sources,
    const glm::vec<Dim, double>& face_in_map) {
    // The weights are a pure function of the probe set-up (its PSF table) and of each
    // particle's line, launch point relative to the face, direction, start time and
    // energy, exactly the values the computation reads: frames of one probe set-up and
    // seed (a sweep, the GUI, repeated views) launch the same particles wherever the probe
    // stands, so their weights are kept (the last four) rather than made again (a fifth
    // of a standard frame).
    const std::shared_ptr<const PsfTable> psf = PsfTable::of(t);
    std::vector<double> key;
    key.reserve(sources.size() * (3 + 2 * Dim) + 3);
    key.push_back(double(t.lines));
    key.push_back(double(Dim));
    // The lens (3D): its aperture and focus.
    key.push_back(Dim == 3 ? t.elevation_aperture_mm() * 1e3 + t.elevation_focus_mm : 0.0);
    for (const auto& s : sources) {
        key.push_back(double(s.line));
        for (int a = 0; a < Dim; ++a) key.push_back(double(s.position[a]) - face_in_map[a]);
        for (int a = 0; a < Dim; ++a) key.push_back(double(s.direction[a]));
        key.insert(key.end(), {double(s.time_s), double(s.energy)});
    }
    struct Kept {
        std::shared_ptr<const PsfTable> psf;
        std::vector<double> key;
        std::shared_ptr<const simulator::ReceiveWeights> weights;
    };
    static std::mutex mutex;
    static std::vector<Kept> kept;  // most recent last
    {
        const std::lock_guard<std::mutex> lock(mutex);
        for (const Kept& k : kept)
            if (k.psf == psf && k.key == key) return k.weights;
    }
    auto weights = compute_receive_weights<Dim>(t, sources, face_in_map);
    const std::lock_guard<std::mutex> lock(mutex);
    kept.push_back({psf, std::move(key), weights});
    if (kept.size() > 4) kept.erase(kept.begin());
    return weights;
}

}  // namespace

std::shared_ptr<const simulator::ReceiveWeights> receive_weights(const probe::Transducer& t,
                                                                 const probe::Sources<2>& sources,
                                                                 const glm::dvec2& face_in_map) {
    return kept_receive_weights<2>(t, sources, face_in_map);
}

std::shared_ptr<const simulator::ReceiveWeights> receive_weights(const probe::Transducer& t,
                                                                 const probe::Sources<3>& sources,
                                                                 const glm::dvec3& face_in_map) {
    return kept_receive_weights<3>(t, sources, face_in_map);
}

}  // namespace sonotrace::imaging
