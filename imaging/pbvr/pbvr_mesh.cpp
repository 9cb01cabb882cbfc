// PBVR of tetrahedral meshes (I-PBVR, sec. 3.4): a renderer of meshes alone, mesh layers,
// and the image-space rasterization of each tetrahedron's front and back faces.
#include <tbb/parallel_for.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>

#include "imaging/pbvr/pbvr.h"
#include "imaging/pbvr/renderer_parts.h"
#include "tissue/base/error.h"

namespace sonotrace::imaging::pbvr {

using base::InputError;

namespace {
constexpr std::size_t kTetBlock = 1024;  // tetrahedra per task
// What a renderer of meshes alone renders as its regular volume: nothing.
const ColourTransferFunction& clear_tf() {
    static const ColourTransferFunction clear(
        "clear", "internal", {{0.0, glm::vec3(0.0f), 0.0}, {1.0, glm::vec3(0.0f), 0.0}}, 1.0, 0.0,
        1.0);
    return clear;
}
const RenderVolume& empty_volume() {
    static const RenderVolume volume(tissue::Volume(tissue::VolumeGeometry{{2, 2, 2}}), clear_tf());
    return volume;
}
}  // namespace

std::string to_string(DepthSampling depth) {
    switch (depth) {
        case DepthSampling::cdf:
            return "cdf";
        case DepthSampling::entry:
            return "entry";
        case DepthSampling::middle:
            return "middle";
        case DepthSampling::exit:
            return "exit";
        case DepthSampling::random:
            return "random";
    }
    return "?";
}

PbvrRenderer::PbvrRenderer(const OrbitCamera& camera, const RenderSettings& settings)
    : PbvrRenderer(empty_volume(), clear_tf(), camera, settings) {}

PbvrRenderer::~PbvrRenderer() = default;

void PbvrRenderer::add_mesh(const TetMesh& mesh, const ColourTransferFunction& tf,
                            DepthSampling depth) {
    auto layer = std::make_unique<MeshLayer>(MeshLayer{&mesh, &tf, PreIntegration(tf), depth, {}});
    layer->values.resize(mesh.values.size());
    for (std::size_t p = 0; p < mesh.values.size(); ++p)
        layer->values[p] = tf.normalize(mesh.values[p]);
    meshes_.push_back(std::move(layer));
}

// Image-space PBVR of one mesh (sec. 3.4). Each tetrahedron is projected and its
// footprint split by which face the ray enters and which it leaves through: the regions
// of constant (front, back) face pair are the projected-tetrahedra triangles. Both faces
// are rasterized with perspective-correct interpolation of the scalar and the depth (the
// scalar is linear on each face in 3D, so this is exact), which gives every sub-pixel's
// fragment: s_f, s_b, D_f, D_b and the length l of the ray inside.
// Every fragment that becomes a particle in `repetition` goes to emit(x, y, entry,
// block): its sub-pixel, its Z-buffer entry and its block of kTetBlock tetrahedra (blocks
// in parallel; a block's fragments in one task, in a fixed order).
template <class Emit>
void PbvrRenderer::mesh_fragments(const MeshLayer& layer, std::size_t index, uint32_t repetition,
                                  Emit&& emit) const {
    const TetMesh& mesh = *layer.mesh;
    const Projection p = Projection::of(camera_, settings_.subpixel_level);
    const uint64_t stream_seed = settings_.seed ^ (0x632BE59BD9B4E019ull * (index + 1));
    constexpr int kFaces[4][3] = {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}};
    // Per sub-pixel of a footprint: the nearest and farthest face points met.
    struct FaceHits {
        float near_depth, near_value, far_depth, far_value;
        int count;
    };
    tbb::enumerable_thread_specific<std::vector<FaceHits>> scratch;
    tbb::parallel_for(
        std::size_t(0), (mesh.tets.size() + kTetBlock - 1) / kTetBlock, [&](std::size_t block) {
            if (cancelled()) return;
            std::vector<FaceHits>& hits = scratch.local();
            const std::size_t last = std::min(mesh.tets.size(), (block + 1) * kTetBlock);
            for (std::size_t t = block * kTetBlock; t != last; ++t) {
                const auto& tet = mesh.tets[t];
                // -- project the corners: screen position, 1/depth, value
                glm::dvec2 q[4];
                double inverse_depth[4], value[4];
                glm::dvec2 low(1e300), high(-1e300);
                bool visible = true;
                for (int v = 0; v < 4; ++v) {
                    const glm::dvec3 e = glm::dmat3(p.rotation) *
                                         (mesh.points[tet[std::size_t(v)]] - glm::dvec3(p.eye));
                    if (e.z <= 1e-3) visible = false;
                    inverse_depth[v] = 1.0 / e.z;
                    q[v] = {p.centre_x + p.focal * e.x / e.z, p.centre_y + p.focal * e.y / e.z};
                    value[v] = layer.values[tet[std::size_t(v)]];
                    low = glm::min(low, q[v]), high = glm::max(high, q[v]);
                }
                if (!visible) continue;  // tetrahedra reaching behind the eye are not drawn
                int x0, x1, y0, y1;
                centres_within(low.x, high.x, sub_width_, &x0, &x1);
                centres_within(low.y, high.y, sub_height_, &y0, &y1);
                if (x0 > x1 || y0 > y1) continue;
                const int w = x1 - x0 + 1, h = y1 - y0 + 1;
                hits.assign(std::size_t(w) * std::size_t(h), FaceHits{0, 0, 0, 0, 0});
                // -- the four faces, each over its own bounding box
                for (const auto& face : kFaces) {
                    const glm::dvec2 a = q[face[0]], b = q[face[1]], c = q[face[2]];
                    const double area = (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x);
                    if (std::abs(area) < 1e-12) continue;  // seen edge-on
                    int fx0, fx1, fy0, fy1;
                    centres_within(std::min({a.x, b.x, c.x}), std::max({a.x, b.x, c.x}), sub_width_,
                                   &fx0, &fx1);
                    centres_within(std::min({a.y, b.y, c.y}), std::max({a.y, b.y, c.y}),
                                   sub_height_, &fy0, &fy1);
                    fx0 = std::max(fx0, x0), fx1 = std::min(fx1, x1);
                    fy0 = std::max(fy0, y0), fy1 = std::min(fy1, y1);
                    for (int y = fy0; y <= fy1; ++y) {
                        for (int x = fx0; x <= fx1; ++x) {
                            const glm::dvec2 m(x + 0.5, y + 0.5);
                            // screen barycentrics by edge functions
                            const double ba =
                                ((b.x - m.x) * (c.y - m.y) - (b.y - m.y) * (c.x - m.x)) / area;
                            const double bb =
                                ((c.x - m.x) * (a.y - m.y) - (c.y - m.y) * (a.x - m.x)) / area;
                            const double bc = 1.0 - ba - bb;
                            if (ba < 0.0 || bb < 0.0 || bc < 0.0) continue;
                            // perspective-correct: weights by 1/depth
                            const double ua = ba * inverse_depth[face[0]],
                                         ub = bb * inverse_depth[face[1]],
                                         uc = bc * inverse_depth[face[2]];
                            const double sum = ua + ub + uc;
                            const float depth = float(1.0 / sum);
                            const float v = float(
                                (ua * value[face[0]] + ub * value[face[1]] + uc * value[face[2]]) /
                                sum);
                            FaceHits& hit =
                                hits[std::size_t(y - y0) * std::size_t(w) + std::size_t(x - x0)];
                            if (hit.count == 0) {
                                hit = {depth, v, depth, v, 1};
                            } else {
                                if (depth < hit.near_depth)
                                    hit.near_depth = depth, hit.near_value = v;
                                if (depth > hit.far_depth) hit.far_depth = depth, hit.far_value = v;
                                hit.count++;
                            }
                        }
                    }
                }
                CellRandom random(stream_seed, repetition, uint32_t(t));
                for (int y = y0; y <= y1; ++y) {
                    for (int x = x0; x <= x1; ++x) {
                        const FaceHits& hit =
                            hits[std::size_t(y - y0) * std::size_t(w) + std::size_t(x - x0)];
                        if (hit.count < 2 || !(hit.far_depth > hit.near_depth)) continue;
                        // -- the fragment: length along the ray from the depths
                        const double dx = (x + 0.5 - p.centre_x) / p.focal,
                                     dy = (y + 0.5 - p.centre_y) / p.focal;
                        const double length = double(hit.far_depth - hit.near_depth) *
                                              std::sqrt(1.0 + dx * dx + dy * dy);
                        const double s_front = hit.near_value, s_back = hit.far_value;
                        // -- a particle with the pre-integrated opacity (eq. 18). Its
                        // number is the fragment's own, stratified across repetitions
                        // (CellSequence): one fragment decides a sub-pixel of a single
                        // layer alone, so the repetitions cover [0, 1) evenly and that
                        // image's error falls as 1 / N, not 1 / sqrt(N).
                        const uint64_t fragment =
                            base::finalise64(uint64_t(t)) ^
                            (uint64_t(uint32_t(y)) << 32 | uint64_t(uint32_t(x)));
                        const double r = CellSequence::of_stream(stream_seed, repetition, fragment)
                                             .count_uniform();
                        const double alpha = layer.pre.opacity(s_front, s_back, length);
                        if (!(r < alpha)) continue;
                        double wd = 0.5;
                        switch (layer.depth) {
                            case DepthSampling::cdf:
                                wd = layer.pre.inverse(r, s_front, s_back, length);
                                break;
                            case DepthSampling::entry:
                                wd = 0.0;
                                break;
                            case DepthSampling::middle:
                                wd = 0.5;
                                break;
                            case DepthSampling::exit:
                                wd = 1.0;
                                break;
                            case DepthSampling::random:
                                wd = random.next();
                                break;
                        }
                        // -- its depth (eq. 26) and colour
                        const double depth = (1.0 - wd) * hit.near_depth + wd * hit.far_depth;
                        const glm::vec3 colour =
                            layer.tf->colour(float((1.0 - wd) * s_front + wd * s_back));
                        emit(x, y, zbuffer_entry(float(depth), colour, uint32_t(t)), block);
                    }
                }
            }
        });
}

void PbvrRenderer::rasterize_mesh(const MeshLayer& layer, std::size_t index,
                                  tbb::enumerable_thread_specific<uint64_t>& counts) {
    mesh_fragments(
        layer, index, uint32_t(repetitions_), [&](int x, int y, uint64_t entry, std::size_t) {
            ++counts.local();
            std::atomic<uint64_t>& cell =
                zbuffer_[std::size_t(y) * std::size_t(sub_width_) + std::size_t(x)];
            uint64_t current = cell.load(std::memory_order_relaxed);
            while (entry < current &&
                   !cell.compare_exchange_weak(current, entry, std::memory_order_relaxed)) {
            }
        });
}

void PbvrRenderer::append_mesh_splats(uint32_t repetition, std::vector<Splat>& out) const {
    // A fragment covers its own sub-pixel: a disc of radius 1/2 on the sub-pixel's centre
    // reaches no other centre. Per block of tetrahedra, in order: the same list on any
    // thread count.
    for (std::size_t m = 0; m < meshes_.size(); ++m) {
        const MeshLayer& layer = *meshes_[m];
        std::vector<std::vector<Splat>> per_block((layer.mesh->tets.size() + kTetBlock - 1) /
                                                  kTetBlock);
        mesh_fragments(layer, m, repetition, [&](int x, int y, uint64_t entry, std::size_t block) {
            per_block[block].push_back({float(x) + 0.5f, float(y) + 0.5f, 0.5f,
                                        std::bit_cast<float>(uint32_t(entry >> 32)),
                                        uint32_t(entry >> 8 & 0xFFFFFFu)});
        });
        for (const auto& b : per_block) out.insert(out.end(), b.begin(), b.end());
    }
}

}  // namespace sonotrace::imaging::pbvr
