#pragma once
// Object-space particle-based volume rendering (Sakamoto & Koyamada, sec. 3.1-3.5) on the
// CPU, streaming, deterministic; and the emission-absorption ray caster it is measured
// against.
//
// Model: opaque spheres of radius r, a Poisson process of density rho = sigma / (pi r^2)
// (eq. 12, sigma from the transfer function). A ray meets the first sphere whose centre
// lies within r of it; the probability that none lies within a segment is
// exp(-integral sigma dt), so the expected colour of a sub-pixel is the emission-
// absorption integral (eq. 6). Each particle is drawn as a disc around its projection:
// every sub-pixel whose centre the disc covers sees it (a Z-buffer keeps the nearest).
// The disc has the area of the sphere's image, an ellipse stretched radially by
// 1 / cos(theta) off the axis: radius f r / z / sqrt(cos theta). The plain f r / z
// gives each ray sigma cos(theta) per mm, too little optical depth off the axis.
//
// A cell's r is proportional to its camera depth: the sub-pixel footprint there, times
// radius_scale / sqrt(pi). Particles then project to discs of the same size everywhere,
// and a repetition's particle count follows the image, not the camera's distance. With
// one r for all, set at the orbit target, a camera close to the head projected each
// near particle over thousands of pixels. The model holds cell by cell: r changes only
// at cell faces, by the ratio of neighbouring depths, and where that ratio is large, r is
// far below the cell size.
//
// Each repetition generates, projects and drops its particles, so memory is the volume
// plus a few image-sized buffers; the ensemble average over repetitions converges to
// the integral.
//
// Determinism: random numbers come from counter-based streams keyed by (seed,
// repetition, cell or tetrahedron); the one Z-buffer keeps the minimum of packed (depth,
// colour, id) entries, a total order, whatever order the threads write in, so images are
// byte-identical on any thread count.
#include <array>
#include <atomic>
#include <cstdint>
#include <cstring>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <tbb/enumerable_thread_specific.h>
#include <glm/glm.hpp>
#include <opencv2/core.hpp>

#include "imaging/pbvr/camera.h"
#include "imaging/pbvr/colour_tf.h"
#include "imaging/pbvr/sampling.h"
#include "imaging/pbvr/tetra.h"
#include "tissue/base/fast_math.h"
#include "tissue/base/memory.h"
#include "tissue/volume.h"

namespace sonotrace::imaging::pbvr {

// The scalar (normalized by the transfer function's window) and its gradient (1/mm, in
// the volume's local frame) at a point.
struct VoxelSample {
    float value = 0.0f;
    glm::vec3 gradient{0.0f};
};

// The volume as the renderers sample it: the normalized value per voxel (4 bytes) and
// its central-difference gradient packed in 4 more (computing it where a sample needs it
// was a fifth of a repetition). Local frame: mm along the index axes,
// q = spacing * ijk; world = origin + direction * q.
class RenderVolume {
  public:
    RenderVolume(const tissue::Volume& volume, const ColourTransferFunction& tf);

    const tissue::VolumeGeometry& geometry() const { return geometry_; }
    glm::ivec3 dims() const { return geometry_.dims; }
    glm::vec3 spacing() const { return spacing_; }
    glm::vec3 extent() const { return extent_; }  // (dims - 1) * spacing
    float value(int i, int j, int k) const {
        return values_[(std::size_t(k) * std::size_t(geometry_.dims.y) + std::size_t(j)) *
                           std::size_t(geometry_.dims.x) +
                       std::size_t(i)];
    }
    // Central differences at a voxel (one-sided at the border), 1/mm.
    glm::vec3 gradient(int i, int j, int k) const;
    // The same as stored: three 8-bit mantissas and a shared exponent (4 bytes a voxel;
    // relative error below 1 %, for shading).
    glm::vec3 stored_gradient(int i, int j, int k) const;
    // Trilinear at local position q (clamped to the domain): the value, and the value
    // with the voxels' gradients.
    float sample_value(const glm::vec3& q) const;
    VoxelSample sample(const glm::vec3& q) const;

  private:
    // The cell corner (clamped so that i0 + 1 stays inside) and the fractions.
    void locate(const glm::vec3& q, glm::ivec3* i0, glm::vec3* f) const {
        for (int a = 0; a < 3; ++a) {
            const float x =
                glm::clamp(q[a] * inverse_spacing_[a], 0.0f, float(geometry_.dims[a] - 1));
            (*i0)[a] = std::min(int(x), geometry_.dims[a] - 2);
            (*f)[a] = x - float((*i0)[a]);
        }
    }
    tissue::VolumeGeometry geometry_;
    glm::vec3 spacing_{1.0f}, inverse_spacing_{1.0f}, extent_{0.0f};
    std::vector<float> values_;
    std::vector<uint32_t> gradients_;  // packed: x, y, z mantissas (int8), exponent (int8)
};

inline float RenderVolume::sample_value(const glm::vec3& q) const {
    glm::ivec3 i;
    glm::vec3 f;
    locate(q, &i, &f);
    auto row = [&](int j, int k) {
        const float a = value(i.x, j, k), b = value(i.x + 1, j, k);
        return a + f.x * (b - a);
    };
    const float lower = row(i.y, i.z) + f.y * (row(i.y + 1, i.z) - row(i.y, i.z));
    const float upper = row(i.y, i.z + 1) + f.y * (row(i.y + 1, i.z + 1) - row(i.y, i.z + 1));
    return lower + f.z * (upper - lower);
}

inline glm::vec3 RenderVolume::gradient(int i, int j, int k) const {
    const glm::ivec3 n = geometry_.dims;
    const int i0 = std::max(i - 1, 0), i1 = std::min(i + 1, n.x - 1);
    const int j0 = std::max(j - 1, 0), j1 = std::min(j + 1, n.y - 1);
    const int k0 = std::max(k - 1, 0), k1 = std::min(k + 1, n.z - 1);
    return {(value(i1, j, k) - value(i0, j, k)) / (float(i1 - i0) * spacing_.x),
            (value(i, j1, k) - value(i, j0, k)) / (float(j1 - j0) * spacing_.y),
            (value(i, j, k1) - value(i, j, k0)) / (float(k1 - k0) * spacing_.z)};
}

inline glm::vec3 RenderVolume::stored_gradient(int i, int j, int k) const {
    const uint32_t packed =
        gradients_[(std::size_t(k) * std::size_t(geometry_.dims.y) + std::size_t(j)) *
                       std::size_t(geometry_.dims.x) +
                   std::size_t(i)];
    // std::ldexp was a library call per corner, a fifth of a repetition's time.
    const float scale = base::power_of_two(int8_t(packed >> 24));
    return glm::vec3(float(int8_t(packed)), float(int8_t(packed >> 8)),
                     float(int8_t(packed >> 16))) *
           scale;
}

inline VoxelSample RenderVolume::sample(const glm::vec3& q) const {
    glm::ivec3 i;
    glm::vec3 f;
    locate(q, &i, &f);
    VoxelSample out;
    for (int c = 0; c < 8; ++c) {
        const int dx = c & 1, dy = c >> 1 & 1, dz = c >> 2;
        const float w = (dx ? f.x : 1.0f - f.x) * (dy ? f.y : 1.0f - f.y) * (dz ? f.z : 1.0f - f.z);
        out.value += w * value(i.x + dx, i.y + dy, i.z + dz);
        out.gradient += w * stored_gradient(i.x + dx, i.y + dy, i.z + dz);
    }
    return out;
}

struct Shading {
    enum class Model { none, lambert, blinn_phong };
    Model model = Model::blinn_phong;
    float ambient = 0.35f, diffuse = 0.65f, specular = 0.25f, shininess = 24.0f;
};

// An axis-aligned box in the volume's local frame (mm) whose content is not drawn: a
// cut-away that opens the head.
struct CutAway {
    glm::vec3 low{0.0f}, high{0.0f};
    bool contains(const glm::vec3& q) const {
        return q.x >= low.x && q.y >= low.y && q.z >= low.z && q.x <= high.x && q.y <= high.y &&
               q.z <= high.z;
    }
};

// The view the head preset is rendered from (the README picture, the benchmark).
inline constexpr double kHeadAzimuthDeg = 235.0, kHeadElevationDeg = 18.0;

// A camera looking at the volume's centre from `azimuth`/`elevation`, at the distance
// where 0.8 x its box's half diagonal fills the field of view (heads do not fill their
// box's corners).
OrbitCamera fit_camera(const tissue::VolumeGeometry& geometry, double azimuth_deg,
                       double elevation_deg, double fov_deg, int width, int height);
// The octant of the volume's box that faces the camera: a cut-away that opens it.
CutAway facing_octant(const tissue::VolumeGeometry& geometry, const OrbitCamera& camera);

struct RenderSettings {
    // Defaults: 35 dB against the ray-cast reference on the Colin27 head preset after 17
    // of the 32 repetitions of 2 x 2 sub-pixels, particles twice the sub-pixel
    // footprint: fewer, larger particles reach a given PSNR faster, bench/README.md.
    int repetitions = 32;    // ensemble size
    int subpixel_level = 2;  // sub-pixels per pixel side (L x L rays per pixel)
    uint64_t seed = 1;
    Sampling sampling = Sampling::uniform;
    double radius_scale = 2.0;  // particle radius relative to the sub-pixel footprint
    Shading shading;
    glm::vec3 background{0.0f};
    std::optional<CutAway> cut_away;
    // A half-space not drawn, in the local frame: points q with dot(xyz, q) + w > 0 (the
    // side of a scan plane that faces the camera, so the plane's surroundings show).
    std::optional<glm::vec4> clip_plane;
    bool removed(const glm::vec3& q) const {
        return (cut_away && cut_away->contains(q)) ||
               (clip_plane && glm::dot(glm::vec3(*clip_plane), q) + clip_plane->w > 0.0f);
    }
    // True if every point within `margin` mm of the box [low, high] is removed (by the
    // cut-away, or by the clip plane): nothing generated in the box can be drawn.
    bool removes_box(const glm::vec3& low, const glm::vec3& high, float margin) const;
    // Skip cells hidden behind an optical depth of 5 (transmittance < 0.7 %) along every
    // ray of a grid 4 pixels apart around their projection (cells off the image or behind
    // the eye are always skipped).
    bool occlusion_culling = true;
    // Before cells are classified one by one, bricks of 4^3 cells that are transparent or
    // hidden as a whole are skipped, and bricks and cells that the cut-away or the clip
    // plane removes whole (their particles were generated and dropped: a third of the
    // head view's candidates) are not kept. The same particles are drawn, at a fraction of
    // the work; off: every cell is classified and kept, for the test that checks this.
    bool early_culling = true;

    // Throws base::InputError("render settings", field).
    void validate() const;
};

// Document each parameter once; the CLI and GUI reuse these.
namespace doc {
inline constexpr const char* kRepetitions =
    "ensemble size: repetitions of particle generation and projection averaged per image";
inline constexpr const char* kSubpixel = "sub-pixel level L: L x L particle rays per pixel";
inline constexpr const char* kRadiusScale =
    "particle radius as a multiple of the sub-pixel footprint at the particle's depth";
inline constexpr const char* kSampling =
    "particle generation per cell: 'uniform' (thinning, exact counts) or 'metropolis'";
}  // namespace doc

struct RgbImage {
    int width = 0, height = 0;
    std::vector<glm::vec3> pixels;  // RGB 0..1, rows top to bottom
    glm::vec3& at(int x, int y) {
        return pixels[std::size_t(y) * std::size_t(width) + std::size_t(x)];
    }
    const glm::vec3& at(int x, int y) const {
        return pixels[std::size_t(y) * std::size_t(width) + std::size_t(x)];
    }
};

// A Z-buffer entry: depth (the float's bits, which order like the floats for positive
// values) above the colour (RGB8) and 8 bits of particle id. The minimum over all
// particles is a total order, so the buffer's content does not depend on the order in
// which threads write it (ties in depth are broken by colour, then id).
inline constexpr uint64_t kEmptyEntry = ~uint64_t(0);
uint64_t zbuffer_entry(float depth, const glm::vec3& colour, uint32_t id);
glm::vec3 entry_colour(uint64_t entry);

// PSNR in dB of `image` against `reference` (colours clamped to 0..1, all channels).
double psnr(const RgbImage& image, const RgbImage& reference);
// 8-bit BGR picture (for imaging::write_png and overlays).
cv::Mat to_picture(const RgbImage& image);

// The colour a sample shows: the transfer function's colour, shaded with the gradient
// as normal under a headlight (light and view along `to_eye`, a unit vector in the local
// frame). Shared by both renderers.
glm::vec3 shade(const glm::vec3& colour, const glm::vec3& gradient, const glm::vec3& to_eye,
                const Shading& shading);
// facing^shininess for facing in (0, 1]: by squaring for whole exponents up to 64 (the
// default 24 takes six products instead of the exp2 and log2 calls that were ~4 % of a
// repetition; relative error below (n - 1) 2^-24), else exp2(shininess log2 facing).
float specular_power(float facing, float shininess);

// Where a particle of a tetrahedron's fragment sits between the fragment's entry and
// exit (Sakamoto & Koyamada, sec. 4): drawn from the opacity CDF (eqs. 24-26, the
// default), or at the entry, middle or exit point, or uniformly (the paper's comparison).
enum class DepthSampling { cdf, entry, middle, exit, random };
std::string to_string(DepthSampling depth);

// A particle as the projection drew it, for a renderer elsewhere (the GUI's OpenGL
// path): its disc of radius `radius` sub-pixels centred at (x, y) (sub-pixel units from
// the image's top left; it covers the sub-pixels whose centres lie within), its camera
// depth (mm) and its shaded colour as the Z-buffer stores it (RGB8: R in bits 16-23).
struct Splat {
    float x, y, radius, depth;
    uint32_t rgb;
};

class PbvrRenderer {
  public:
    // `tf` gives colours and opacity. With `generation_tf`, particles are generated from
    // its density and drawn with the radius adapted to `tf`'s opacity (eq. 13), as after
    // an opacity edit without regeneration. Throws InputError on bad settings/camera.
    PbvrRenderer(const RenderVolume& volume, const ColourTransferFunction& tf,
                 const OrbitCamera& camera, const RenderSettings& settings,
                 const ColourTransferFunction* generation_tf = nullptr);

    // A renderer of tetrahedral meshes alone (add_mesh), without a regular volume.
    PbvrRenderer(const OrbitCamera& camera, const RenderSettings& settings);
    ~PbvrRenderer();

    // Adds a tetrahedral mesh (world coordinates) to every repetition: image-space PBVR,
    // one fragment per sub-pixel and tetrahedron, an opaque particle with probability
    // the pre-integrated opacity (eq. 18), at the depth `depth` picks, coloured by `tf`
    // (bound to the mesh's values) at its scalar; the same Z-buffer as the particles, so
    // overlapping volumes fuse. The mesh and tf must outlive the renderer.
    void add_mesh(const TetMesh& mesh, const ColourTransferFunction& tf, DepthSampling depth);

    // Opaque surfaces drawn with the particles (overlay.h): one Z-buffer entry per
    // sub-pixel (zbuffer_entry), depth-tested against them in every repetition.
    void set_overlay(std::vector<uint64_t> layer);
    // Adds one repetition to the ensemble; false if `cancel` (set_cancel) was raised during
    // it, which leaves the ensemble as it was before the repetition.
    bool add_repetition();
    // A flag add_repetition() polls while it works (a Ctrl-C handler's), or null.
    void set_cancel(const std::atomic<bool>* cancel) { cancel_ = cancel; }
    int repetitions_done() const { return repetitions_; }
    // The ensemble average so far (background where nothing was ever drawn).
    RgbImage image() const;
    // The particles repetition `repetition` draws (add_repetition draws repetition
    // repetitions_done()), in an order that does not depend on the threads, without
    // drawing them: the volume's particles, then each mesh's fragments (discs of radius
    // 1/2 on their sub-pixel's centre). Each is what add_repetition depth-tests: the same
    // disc, depth and colour.
    std::vector<Splat> splats(uint32_t repetition) const;
    int subpixel_width() const { return sub_width_; }
    int subpixel_height() const { return sub_height_; }

    // The particle radius at the orbit target's depth (a cell's scales with its depth).
    float particle_radius_mm() const { return radius_per_depth_ * float(camera_.distance_mm); }
    // Over all repetitions: the volume's particles and the meshes' (fragments that became
    // particles).
    uint64_t particles_drawn() const { return particles_; }
    std::size_t occupied_cells() const { return cells_.size(); }  // after culling
    // Cells skipped as hidden: those of hidden bricks (transparent or not), and the
    // non-transparent cells hidden one by one.
    std::size_t culled_cells() const { return culled_cells_; }
    std::size_t skipped_bricks() const { return skipped_bricks_; }  // transparent or hidden
    // Cells not kept because the cut-away or the clip plane removes them whole.
    std::size_t removed_cells() const { return removed_cells_; }

  private:
    // A generated particle, projected: what a renderer needs to draw it.
    struct Projected {
        glm::vec3 q;  // local frame, mm
        float value;  // normalized scalar there
        uint32_t id;
        uint32_t cell;     // index into cells_
        float depth;       // camera depth, mm
        float px, py, rp;  // disc centre and radius, sub-pixels
    };
    static constexpr std::size_t kCellBlock = 2048;
    // Generates repetition `repetition`'s particles cell block by cell block in parallel,
    // calling draw(Projected, drawn counter) for each in front of the eye.
    template <typename Draw>
    void generate(uint32_t repetition, Draw& draw,
                  tbb::enumerable_thread_specific<uint64_t>& counts) const;
    static constexpr int kOcclusionTile = 4;        // pixels between occlusion rays
    static constexpr float kOcclusionDepth = 5.0f;  // transmittance e^-5 < 0.7 % beyond
    // mm a cell must lie behind the occlusion depth to be hidden: guards cells seen
    // between two occlusion rays at silhouettes
    static constexpr float kHiddenMargin = 2.0f;
    static constexpr int kBrick = 4;  // cells per brick side (set-up culling)
    void build_occlusion_map();
    bool cell_hidden(int i, int j, int k, bool occlusion) const;
    bool brick_hidden(const glm::ivec3& first, const glm::ivec3& last, bool occlusion) const;
    float deepest_occlusion(float x0, float x1, float y0, float y1) const;
    bool footprint_hidden(float x0, float x1, float y0, float y1, float nearest,
                          bool occlusion) const;
    struct Cell {
        uint16_t i, j, k;    // the cell's corner voxel
        uint32_t index;      // linear cell index ((dims - 1) grid): its random stream
        float majorant;      // max sigma over the cell (generation TF), 1/mm
        float candidates;    // expected candidates: majorant rho * cell volume
        float no_candidate;  // exp(-candidates) (0 if candidates > 100)
    };
    const RenderVolume& volume_;
    const ColourTransferFunction& tf_;
    const ColourTransferFunction& generation_tf_;
    bool adapt_radius_ = false;
    OrbitCamera camera_;
    RenderSettings settings_;
    glm::mat3 to_camera_{1.0f};  // local frame -> camera
    glm::vec3 camera_offset_{0.0f};
    glm::vec3 to_eye_{0.0f, 0.0f, 1.0f};  // headlight, local frame
    float focal_ = 1.0f, centre_x_ = 0.0f, centre_y_ = 0.0f;
    int sub_width_ = 0, sub_height_ = 0;
    // A cell's particle radius per mm of its centre's camera depth, and that depth's floor
    // (cells at or behind the eye plane): cell_radius.
    float radius_per_depth_ = 0.0f;
    static constexpr float kNearestRadiusDepth = 1.0f;  // mm
    float cell_radius(const glm::vec3& centre) const {
        const float depth = glm::dot(depth_row_, centre) + camera_offset_.z;
        return radius_per_depth_ * std::max(depth, kNearestRadiusDepth);
    }
    glm::vec3 depth_row_{0.0f};  // camera depth = dot(depth_row_, q) + camera_offset_.z
    // The image's four side planes through the eye, unit inward normals in the camera
    // frame: a sphere of radius b at e is off the image if dot(plane, e) < -b for one.
    // Near the eye plane the projected disc cannot tell (cells there straddle z = 0).
    std::array<glm::vec3, 4> frustum_planes_{};
    // Particles' discs are stretched off the axis (add_repetition), so the plane tests
    // take a cell's radius times this bound on the stretch near the image's edges.
    float edge_stretch_ = 2.0f;
    std::vector<Cell, base::UninitializedHugePageAllocator<Cell>> cells_;  // filled in parallel
    std::size_t culled_cells_ = 0;
    std::size_t skipped_bricks_ = 0;
    std::size_t removed_cells_ = 0;
    std::vector<float> occluded_beyond_;  // the occlusion map while cells are listed
    int occlusion_tiles_x_ = 0, occlusion_tiles_y_ = 0;
    std::vector<glm::dvec3, base::HugePageAllocator<glm::dvec3>>
        accumulated_;  // per pixel, sum over repetitions of sub-pixel means
    const std::atomic<bool>* cancel_ = nullptr;
    bool cancelled() const { return cancel_ && cancel_->load(std::memory_order_relaxed); }
    std::vector<std::atomic<uint64_t>> zbuffer_;  // per sub-pixel: depth | RGB8 | id
    std::vector<uint64_t> overlay_;               // its initial content (empty: none)
    struct MeshLayer;
    std::vector<std::unique_ptr<MeshLayer>> meshes_;
    void rasterize_mesh(const MeshLayer& layer, std::size_t index,
                        tbb::enumerable_thread_specific<uint64_t>& counts);
    template <class Emit>
    void mesh_fragments(const MeshLayer& layer, std::size_t index, uint32_t repetition,
                        Emit&& emit) const;
    // The meshes' fragments of `repetition` as splats (splats()), appended to `out`.
    void append_mesh_splats(uint32_t repetition, std::vector<Splat>& out) const;
    int repetitions_ = 0;
    uint64_t particles_ = 0;
};

// The reference for fused volumes: along each sub-pixel ray the extinctions of the
// regular volume (with the renderer's shading, cut-away and clip plane) and of every mesh
// add, and their colours mix by extinction (emission-absorption of the union); midpoint
// samples every `step_mm`, stopped when the transmittance falls below 1e-5. Tetrahedra
// are found through 16 x 16 sub-pixel tiles of their projections.
RgbImage raycast_fused(
    const RenderVolume* volume, const ColourTransferFunction* volume_tf,
    const std::vector<std::pair<const TetMesh*, const ColourTransferFunction*>>& meshes,
    const OrbitCamera& camera, const RenderSettings& settings, double step_mm);
// Meshes alone.
RgbImage raycast_meshes(
    const std::vector<std::pair<const TetMesh*, const ColourTransferFunction*>>& meshes,
    const OrbitCamera& camera, const RenderSettings& settings, double step_mm);

// Emission-absorption ray casting through the same transfer function and shading, one
// ray per sub-pixel centre, midpoint samples every `step_mm`, stopped when the
// transmittance falls below 1e-5.
RgbImage raycast(const RenderVolume& volume, const ColourTransferFunction& tf,
                 const OrbitCamera& camera, const RenderSettings& settings, double step_mm);

}  // namespace sonotrace::imaging::pbvr
