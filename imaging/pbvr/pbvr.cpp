#include "imaging/pbvr/pbvr.h"

#include "imaging/pbvr/preintegration.h"
#include "imaging/pbvr/renderer_parts.h"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <numbers>

#include "tissue/base/error.h"
#include "tissue/base/fast_math.h"

namespace sonotrace::imaging::pbvr {

using base::InputError;

// ---- volume ------------------------------------------------------------------------

RenderVolume::RenderVolume(const tissue::Volume& volume, const ColourTransferFunction& tf)
    : geometry_(volume.geometry()) {
    const glm::ivec3 n = geometry_.dims;
    if (n.x < 2 || n.y < 2 || n.z < 2)
        throw InputError("volume", "dims", "volume rendering needs at least 2 voxels per axis");
    spacing_ = glm::vec3(geometry_.spacing);
    inverse_spacing_ = 1.0f / spacing_;
    extent_ = glm::vec3(n - 1) * spacing_;
    values_.resize(volume.size());
    tbb::parallel_for(std::size_t(0), volume.size(),
                      [&](std::size_t v) { values_[v] = tf.normalize(volume.voxels()[v]); });
    gradients_.resize(volume.size());
    tbb::parallel_for(0, n.z, [&](int k) {
        for (int j = 0; j < n.y; ++j)
            for (int i = 0; i < n.x; ++i) {
                const glm::vec3 g = gradient(i, j, k);
                const float largest = std::max({std::abs(g.x), std::abs(g.y), std::abs(g.z)});
                int exponent = 0;
                if (largest > 0.0f) std::frexp(largest / 127.0f, &exponent);  // |g| / 2^e <= 127
                exponent = std::clamp(exponent, -126, 127);                   // 2^e a normal float
                const glm::vec3 m = glm::round(g * std::ldexp(1.0f, -exponent));
                auto byte = [](float v) {
                    return uint32_t(uint8_t(int8_t(std::clamp(v, -127.0f, 127.0f))));
                };
                gradients_[volume.linear_index(i, j, k)] =
                    byte(m.x) | byte(m.y) << 8 | byte(m.z) << 16 |
                    uint32_t(uint8_t(int8_t(exponent))) << 24;
            }
    });
}

// ---- views -------------------------------------------------------------------------

OrbitCamera fit_camera(const tissue::VolumeGeometry& geometry, double azimuth_deg,
                       double elevation_deg, double fov_deg, int width, int height) {
    OrbitCamera camera;
    const glm::dvec3 extent = glm::dvec3(geometry.dims - 1) * geometry.spacing;
    camera.target = geometry.index_to_world(glm::dvec3(geometry.dims - 1) * 0.5);
    camera.azimuth_deg = azimuth_deg;
    camera.elevation_deg = elevation_deg;
    camera.fov_deg = fov_deg;
    camera.width = width;
    camera.height = height;
    camera.distance_mm =
        0.8 * 0.5 * glm::length(extent) / std::sin(0.5 * glm::radians(std::max(fov_deg, 0.1)));
    return camera;
}

CutAway facing_octant(const tissue::VolumeGeometry& geometry, const OrbitCamera& camera) {
    const glm::dvec3 extent = glm::dvec3(geometry.dims - 1) * geometry.spacing;
    const glm::dvec3 to_eye = glm::inverse(geometry.linear()) * (camera.eye() - camera.target);
    CutAway cut;
    for (int a = 0; a < 3; ++a) {
        const float mid = float(0.5 * extent[a]);
        cut.low[a] = to_eye[a] > 0.0 ? mid : -1.0f;
        cut.high[a] = to_eye[a] > 0.0 ? float(extent[a]) + 1.0f : mid;
    }
    return cut;
}

// ---- settings, shading, images -----------------------------------------------------

bool RenderSettings::removes_box(const glm::vec3& low, const glm::vec3& high, float margin) const {
    if (cut_away && cut_away->contains(low - margin) && cut_away->contains(high + margin))
        return true;
    if (!clip_plane) return false;
    // A half-space holds the box if it holds every corner, each `margin` inside.
    const glm::vec3 normal(*clip_plane);
    const float inside = margin * glm::length(normal);
    for (int v = 0; v < 8; ++v) {
        const glm::vec3 corner(v & 1 ? high.x : low.x, v & 2 ? high.y : low.y,
                               v & 4 ? high.z : low.z);
        if (!(glm::dot(normal, corner) + clip_plane->w > inside)) return false;
    }
    return true;
}

void RenderSettings::validate() const {
    using base::require_in_range;
    const std::string source = "render settings";
    require_in_range(source, "repetitions", repetitions, 1, 1e7);
    require_in_range(source, "subpixel_level", subpixel_level, 1, 16);
    require_in_range(source, "radius_scale", radius_scale, 0.05, 20.0);
    for (int c = 0; c < 3; ++c) require_in_range(source, "background", background[c], 0.0, 1.0);
    require_in_range(source, "shading.ambient", shading.ambient, 0.0, 10.0);
    require_in_range(source, "shading.diffuse", shading.diffuse, 0.0, 10.0);
    require_in_range(source, "shading.specular", shading.specular, 0.0, 10.0);
    require_in_range(source, "shading.shininess", shading.shininess, 1.0, 1000.0);
}

float specular_power(float facing, float shininess) {
    const int whole = int(shininess);
    if (float(whole) == shininess && whole >= 0 && whole <= 64) {
        float power = 1.0f, square = facing;
        for (int e = whole; e > 0; e >>= 1) {
            if (e & 1) power *= square;
            square *= square;
        }
        return power;
    }
    return std::exp2(shininess * std::log2(facing));
}

glm::vec3 shade(const glm::vec3& colour, const glm::vec3& gradient, const glm::vec3& to_eye,
                const Shading& shading) {
    if (shading.model == Shading::Model::none) return colour;
    const float g2 = glm::dot(gradient, gradient);
    // No surface where the field is flat: ambient + diffuse as if facing the light.
    const float facing = g2 > 1e-12f ? std::abs(glm::dot(gradient, to_eye)) / std::sqrt(g2) : 1.0f;
    glm::vec3 c = colour * (shading.ambient + shading.diffuse * facing);
    if (shading.model == Shading::Model::blinn_phong && facing > 0.0f) {
        // headlight: the half vector is the view direction itself
        c += glm::vec3(shading.specular * specular_power(facing, shading.shininess));
    }
    return c;
}

uint64_t zbuffer_entry(float depth, const glm::vec3& colour, uint32_t id) {
    // Rounded half up, as std::lround for these non-negative values, without its call.
    auto byte = [](float v) {
        const float x = glm::clamp(v, 0.0f, 1.0f) * 255.0f;
        const int whole = int(x);
        return uint64_t(whole + int(x - float(whole) >= 0.5f));
    };
    return uint64_t(std::bit_cast<uint32_t>(depth)) << 32 | byte(colour.x) << 24 |
           byte(colour.y) << 16 | byte(colour.z) << 8 | (id & 0xFFu);
}

glm::vec3 entry_colour(uint64_t entry) {
    return glm::vec3(float(entry >> 24 & 0xFF), float(entry >> 16 & 0xFF),
                     float(entry >> 8 & 0xFF)) *
           (1.0f / 255.0f);
}

double psnr(const RgbImage& image, const RgbImage& reference) {
    if (image.width != reference.width || image.height != reference.height)
        throw std::invalid_argument("psnr: image sizes differ");
    double sum = 0.0;
    for (std::size_t p = 0; p < image.pixels.size(); ++p) {
        for (int c = 0; c < 3; ++c) {
            const double d = double(glm::clamp(image.pixels[p][c], 0.0f, 1.0f)) -
                             double(glm::clamp(reference.pixels[p][c], 0.0f, 1.0f));
            sum += d * d;
        }
    }
    const double mse = sum / (3.0 * double(image.pixels.size()));
    return mse > 0.0 ? 10.0 * std::log10(1.0 / mse) : std::numeric_limits<double>::infinity();
}

cv::Mat to_picture(const RgbImage& image) {
    cv::Mat picture(image.height, image.width, CV_8UC3);
    for (int y = 0; y < image.height; ++y) {
        for (int x = 0; x < image.width; ++x) {
            const glm::vec3& c = image.at(x, y);
            auto byte = [](float v) {  // colours are display colours (as the TF gives them)
                return static_cast<unsigned char>(std::lround(glm::clamp(v, 0.0f, 1.0f) * 255.0f));
            };
            picture.at<cv::Vec3b>(y, x) = {byte(c.z), byte(c.y), byte(c.x)};
        }
    }
    return picture;
}

// ---- particle renderer -------------------------------------------------------------

namespace {

uint32_t particle_id(uint32_t cell, uint32_t k) {
    uint32_t h = cell * 0x9E3779B1u ^ (k + 0x7F4A7C15u) * 0x85EBCA77u;
    h ^= h >> 15;
    return h * 0xC2B2AE3Du;
}

}  // namespace

PbvrRenderer::PbvrRenderer(const RenderVolume& volume, const ColourTransferFunction& tf,
                           const OrbitCamera& camera, const RenderSettings& settings,
                           const ColourTransferFunction* generation_tf)
    : volume_(volume),
      tf_(tf),
      generation_tf_(generation_tf ? *generation_tf : tf),
      adapt_radius_(generation_tf != nullptr),
      camera_(camera),
      settings_(settings) {
    camera.validate();
    settings.validate();
    const int L = settings.subpixel_level;
    sub_width_ = camera.width * L;
    sub_height_ = camera.height * L;
    // Camera transform of local positions: world = origin + D q, camera = R (world - eye).
    const Projection p = Projection::of(camera, L);
    const tissue::VolumeGeometry& g = volume.geometry();
    const glm::mat3 direction(g.direction);
    to_camera_ = p.rotation * direction;
    camera_offset_ = p.rotation * (glm::vec3(g.origin) - p.eye);
    to_eye_ = glm::normalize(glm::transpose(direction) * -glm::vec3(camera.forward()));
    focal_ = p.focal;
    centre_x_ = p.centre_x;
    centre_y_ = p.centre_y;
    // pi r^2 = the sub-pixel's footprint at the cell's depth (times radius_scale^2)
    radius_per_depth_ =
        float(settings.radius_scale / (camera.focal_px() * L) / std::sqrt(std::numbers::pi));
    depth_row_ = glm::vec3(to_camera_[0].z, to_camera_[1].z, to_camera_[2].z);
    {
        // sub-pixel x = centre_x + focal e.x / e.z in [0, width]: inside where
        // e.x - low e.z >= 0 and high e.z - e.x >= 0, low, high the edges' slopes
        const float x_low = -centre_x_ / focal_, x_high = (float(sub_width_) - centre_x_) / focal_;
        const float y_low = -centre_y_ / focal_, y_high = (float(sub_height_) - centre_y_) / focal_;
        frustum_planes_ = {glm::normalize(glm::vec3(1.0f, 0.0f, -x_low)),
                           glm::normalize(glm::vec3(-1.0f, 0.0f, x_high)),
                           glm::normalize(glm::vec3(0.0f, 1.0f, -y_low)),
                           glm::normalize(glm::vec3(0.0f, -1.0f, y_high))};
        // A disc's stretch (add_repetition) at the image's corner, doubled for particles
        // just outside it: the plane tests' radius factor.
        const float x_far = std::max(-x_low, x_high), y_far = std::max(-y_low, y_high);
        edge_stretch_ = 2.0f * std::sqrt(std::sqrt(1.0f + x_far * x_far + y_far * y_far));
    }

    // Cells that can hold particles, with their majorants.
    const glm::ivec3 n = volume.dims() - 1;
    if (glm::any(glm::greaterThan(n, glm::ivec3(65535))))
        throw InputError("volume", "dims", "at most 65536 voxels per axis");
    const float cell_volume = volume.spacing().x * volume.spacing().y * volume.spacing().z;
    // Cells off the view (behind the eye, outside the image) are always culled; hidden
    // ones with occlusion culling. Eq. 13's radii are unbounded, so its particles never are.
    const bool cull = !adapt_radius_;
    const bool occlusion = settings.occlusion_culling && cull;
    if (occlusion) build_occlusion_map();
    // Bricks of cells first: one whose voxels are all transparent holds no particle, and
    // one hidden over its whole footprint hides each of its cells (brick_hidden), so
    // their cells are not visited. Most of the head's cells lie in such bricks.
    const glm::ivec3 bricks = (n + kBrick - 1) / kBrick;
    std::vector<uint8_t> brick_skipped(std::size_t(bricks.x) * std::size_t(bricks.y) *
                                       std::size_t(bricks.z));
    std::vector<std::size_t> culled(std::size_t(n.z), 0), removed(std::size_t(n.z), 0);
    // A box removed whole, with a margin far above the rounding of the particles'
    // positions, which are computed from the cell's corner.
    const glm::vec3 spacing = volume.spacing();
    const float margin = 1e-3f * std::max({spacing.x, spacing.y, spacing.z});
    auto removed_whole = [&](const glm::ivec3& first, const glm::ivec3& last) {
        return settings.early_culling &&
               settings.removes_box(glm::vec3(first) * spacing, glm::vec3(last + 1) * spacing,
                                    margin);
    };
    if (settings.early_culling)
        tbb::parallel_for(0, bricks.z, [&](int bz) {
            for (int by = 0; by < bricks.y; ++by) {
                for (int bx = 0; bx < bricks.x; ++bx) {
                    const glm::ivec3 first = glm::ivec3(bx, by, bz) * kBrick;
                    const glm::ivec3 last = glm::min(first + kBrick, n) - 1;  // cells, inclusive
                    float lo = 1.0f, hi = 0.0f;  // over the voxels of its cells
                    for (int k = first.z; k <= last.z + 1; ++k)
                        for (int j = first.y; j <= last.y + 1; ++j)
                            for (int i = first.x; i <= last.x + 1; ++i) {
                                const float s = volume.value(i, j, k);
                                lo = std::min(lo, s), hi = std::max(hi, s);
                            }
                    bool skipped = !(generation_tf_.max_extinction(lo, hi) > 0.0f);
                    const glm::ivec3 size = last - first + 1;
                    const std::size_t cells = std::size_t(size.x * size.y * size.z);
                    if (!skipped && removed_whole(first, last)) {
                        skipped = true;
                        removed[std::size_t(first.z)] += cells;
                    } else if (!skipped && cull && brick_hidden(first, last, occlusion)) {
                        skipped = true;
                        culled[std::size_t(first.z)] += cells;
                    }
                    brick_skipped[(std::size_t(bz) * std::size_t(bricks.y) + std::size_t(by)) *
                                      std::size_t(bricks.x) +
                                  std::size_t(bx)] = skipped;
                }
            }
        });
    skipped_bricks_ = std::size_t(std::count(brick_skipped.begin(), brick_skipped.end(), 1));
    std::vector<std::vector<Cell>> slabs(std::size_t(n.z));
    tbb::parallel_for(0, n.z, [&](int k) {
        for (int j = 0; j < n.y; ++j) {
            const uint8_t* skipped_row =
                &brick_skipped[(std::size_t(k / kBrick) * std::size_t(bricks.y) +
                                std::size_t(j / kBrick)) *
                               std::size_t(bricks.x)];
            for (int i = 0; i < n.x; ++i) {
                if (skipped_row[i / kBrick]) {
                    i = i / kBrick * kBrick + kBrick - 1;  // to the brick's last cell
                    continue;
                }
                float lo = 1.0f, hi = 0.0f;
                for (int c = 0; c < 8; ++c) {
                    const float s = volume.value(i + (c & 1), j + (c >> 1 & 1), k + (c >> 2));
                    lo = std::min(lo, s), hi = std::max(hi, s);
                }
                const float majorant = generation_tf_.max_extinction(lo, hi);
                if (majorant > 0.0f && removed_whole({i, j, k}, {i, j, k})) {
                    removed[std::size_t(k)]++;
                } else if (majorant > 0.0f && cull && cell_hidden(i, j, k, occlusion)) {
                    culled[std::size_t(k)]++;
                } else if (majorant > 0.0f) {
                    const uint32_t index = uint32_t(
                        (std::size_t(k) * std::size_t(n.y) + std::size_t(j)) * std::size_t(n.x) +
                        std::size_t(i));
                    const float radius = cell_radius(
                        (glm::vec3(float(i), float(j), float(k)) + 0.5f) * volume.spacing());
                    const float candidates =
                        majorant / (std::numbers::pi_v<float> * radius * radius) * cell_volume;
                    slabs[std::size_t(k)].push_back(
                        {uint16_t(i), uint16_t(j), uint16_t(k), index, majorant, candidates,
                         candidates <= 100.0f ? std::exp(-candidates) : 0.0f});
                }
            }
        }
    });
    // Front to back along each axis (slabs, rows, cells in a row each taken from the
    // side nearer the eye): most particles behind what is already drawn then fail the
    // Z-buffer's first test, before their shading and its compare-and-swap (13 % less per
    // repetition on the head view; a sort by each cell's depth lost more in locality).
    // The Z-buffer's content does not depend on the order.
    const bool i_down = depth_row_.x < 0.0f, j_down = depth_row_.y < 0.0f,
               k_down = depth_row_.z < 0.0f;
    tbb::parallel_for(std::size_t(0), slabs.size(), [&](std::size_t k) {
        std::vector<Cell>& slab = slabs[k];  // rows of ascending j, each of ascending i
        if (j_down) std::reverse(slab.begin(), slab.end());
        if (i_down != j_down)
            for (auto row = slab.begin(); row != slab.end();) {
                const auto end =
                    std::find_if(row, slab.end(), [&](const Cell& c) { return c.j != row->j; });
                std::reverse(row, end);
                row = end;
            }
    });
    if (k_down) std::reverse(slabs.begin(), slabs.end());
    // One list, copied on both threads into calloc's memory (fresh pages are not touched
    // until then), so that its pages fault in on both (page faults are slow in a virtual
    // machine, and a quarter of the set-up when one thread took them).
    std::vector<std::size_t> first(slabs.size() + 1, 0);
    for (std::size_t k = 0; k < slabs.size(); ++k) first[k + 1] = first[k] + slabs[k].size();
    cells_.resize(first.back());
    tbb::parallel_for(std::size_t(0), slabs.size(), [&](std::size_t k) {
        std::copy(slabs[k].begin(), slabs[k].end(), cells_.begin() + std::ptrdiff_t(first[k]));
        slabs[k] = {};
    });
    for (const std::size_t c : culled) culled_cells_ += c;
    for (const std::size_t c : removed) removed_cells_ += c;
    occluded_beyond_ = {};
    accumulated_.assign(std::size_t(camera.width) * std::size_t(camera.height), glm::dvec3(0.0));
}

// The occlusion map: how deep each ray of a grid over the image (tile corners, kTile
// pixels apart) goes before its optical depth reaches kOpticalDepth (camera depth, mm;
// infinity if never).
void PbvrRenderer::set_overlay(std::vector<uint64_t> layer) {
    if (!layer.empty() && layer.size() != std::size_t(sub_width_) * std::size_t(sub_height_))
        throw std::invalid_argument("overlay layer size differs from the sub-pixel grid");
    overlay_ = std::move(layer);
}

template <typename Draw>
void PbvrRenderer::generate(uint32_t repetition, Draw& draw,
                            tbb::enumerable_thread_specific<uint64_t>& counts) const {
    const glm::vec3 h = volume_.spacing();
    const glm::vec3 inverse_h = 1.0f / h;

    // Blocks of 2048 cells: a block's particles come in one fixed order whatever the
    // threads (splats() keeps them per block).
    const std::size_t blocks = (cells_.size() + kCellBlock - 1) / kCellBlock;
    tbb::parallel_for(std::size_t(0), blocks, [&](std::size_t block) {
        if (cancelled()) return;  // polled per 2048 cells: a Ctrl-C stops within ms
        uint64_t& drawn = counts.local();
        const std::size_t last = std::min(cells_.size(), (block + 1) * kCellBlock);
        for (std::size_t c = block * kCellBlock; c != last; ++c) {
            const Cell& cell = cells_[c];
            const glm::vec3 origin = glm::vec3(float(cell.i), float(cell.j), float(cell.k)) * h;
            // the cell's particle radius and 1 / (pi r^2) of eq. 12
            const float cell_radius_mm =
                cell_radius((glm::vec3(float(cell.i), float(cell.j), float(cell.k)) + 0.5f) * h);
            const float inverse_area =
                1.0f / (std::numbers::pi_v<float> * cell_radius_mm * cell_radius_mm);
            CellRandom random(settings_.seed, repetition, cell.index);
            uint32_t emitted = 0;
            // -- density: rho = sigma / (pi r^2) of the generation transfer function,
            // the value interpolated from the cell's corners (loaded once per cell)
            float corner[8];
            for (int v = 0; v < 8; ++v)
                corner[v] =
                    volume_.value(cell.i + (v & 1), cell.j + (v >> 1 & 1), cell.k + (v >> 2));
            auto density = [&](const glm::vec3& q) {
                const glm::vec3 f = (q - origin) * inverse_h;
                const float x0 = corner[0] + f.x * (corner[1] - corner[0]);
                const float x1 = corner[2] + f.x * (corner[3] - corner[2]);
                const float x2 = corner[4] + f.x * (corner[5] - corner[4]);
                const float x3 = corner[6] + f.x * (corner[7] - corner[6]);
                const float y0 = x0 + f.y * (x1 - x0), y1 = x2 + f.y * (x3 - x2);
                const float value = y0 + f.z * (y1 - y0);
                return std::pair{generation_tf_.extinction(value) * inverse_area, value};
            };
            auto emit = [&](const glm::vec3& q, float value) {
                const uint32_t id = particle_id(cell.index, emitted++);
                if (settings_.removed(q)) return;
                float radius = cell_radius_mm;
                if (adapt_radius_) {
                    // Eq. 13 keeps the density and changes the radius. As printed the
                    // ratio is inverted: from eq. 12 with rho fixed,
                    // r' = r sqrt(ln(1 - alpha') / ln(1 - alpha)) = r sqrt(sigma'/sigma).
                    const float before = generation_tf_.extinction(value);
                    const float after = tf_.extinction(value);
                    if (!(after > 0.0f) || !(before > 0.0f)) return;
                    radius *= std::sqrt(after / before);
                }
                // -- project
                const glm::vec3 e = to_camera_ * q + camera_offset_;
                if (e.z <= radius) return;  // behind or at the eye
                const float inverse_z = 1.0f / e.z;
                const float px = centre_x_ + focal_ * e.x * inverse_z;
                const float py = centre_y_ + focal_ * e.y * inverse_z;
                // Off the axis a sphere's image is an ellipse, stretched radially by
                // 1 / cos(theta) = |e| / e.z; a disc of its area keeps each ray's chance
                // of a hit sigma per mm of the ray, not of depth (the image-plane disc
                // alone gave exp(-sigma l cos theta): 3 % too little optical depth in a
                // 30-degree view, and the fog test failed by 5-8 standard errors).
                const float stretch = std::sqrt(std::sqrt(glm::dot(e, e)) * inverse_z);
                const float rp = focal_ * radius * inverse_z * stretch;
                draw(Projected{q, value, id, uint32_t(c), e.z, px, py, rp}, drawn);
            };
            const glm::vec3 size = h;
            if (settings_.sampling == Sampling::uniform && cell.candidates <= 100.0f) {
                CellSequence sequence(settings_.seed, repetition, cell.index);
                thin_stratified(origin, size, cell.majorant * inverse_area, cell.candidates,
                                cell.no_candidate, density, sequence, emit);
            } else if (settings_.sampling == Sampling::uniform) {
                const int candidates =
                    cell.candidates <= 100.0f
                        ? poisson_count_inversion(cell.candidates, cell.no_candidate, random)
                        : poisson_count(cell.candidates, random);
                thin_candidates(origin, size, cell.majorant * inverse_area, candidates, density,
                                random, emit);
            } else
                sample_cell_metropolis(origin, size, density, random, emit);
        }
    });
}

std::vector<Splat> PbvrRenderer::splats(uint32_t repetition) const {
    // Per block of cells, in the generator's order; then the blocks in order.
    std::vector<std::vector<Splat>> per_block((cells_.size() + kCellBlock - 1) / kCellBlock);
    tbb::enumerable_thread_specific<uint64_t> counts(0);
    auto keep = [&](const Projected& p, uint64_t& drawn) {
        // The sub-pixels the disc can reach: none, and it is not drawn (as the Z-buffer).
        int x0, x1, y0, y1;
        centres_within(p.px - p.rp, p.px + p.rp, sub_width_, &x0, &x1);
        centres_within(p.py - p.rp, p.py + p.rp, sub_height_, &y0, &y1);
        if (x0 > x1 || y0 > y1) return;
        const uint64_t entry = zbuffer_entry(
            p.depth,
            shade(tf_.colour(p.value), volume_.sample(p.q).gradient, to_eye_, settings_.shading),
            p.id);
        const std::size_t block = std::size_t(p.cell) / kCellBlock;
        per_block[block].push_back({p.px, p.py, p.rp, p.depth, uint32_t(entry >> 8 & 0xFFFFFFu)});
        ++drawn;
    };
    generate(repetition, keep, counts);
    std::size_t total = 0;
    for (const auto& b : per_block) total += b.size();
    std::vector<Splat> out;
    out.reserve(total);
    for (const auto& b : per_block) out.insert(out.end(), b.begin(), b.end());
    append_mesh_splats(repetition, out);
    return out;
}

bool PbvrRenderer::add_repetition() {
    const std::size_t subpixels = std::size_t(sub_width_) * std::size_t(sub_height_);
    if (zbuffer_.size() != subpixels) zbuffer_ = decltype(zbuffer_)(subpixels);
    tbb::parallel_for(std::size_t(0), subpixels, [&](std::size_t s) {
        zbuffer_[s].store(overlay_.empty() ? kEmptyEntry : overlay_[s], std::memory_order_relaxed);
    });
    tbb::enumerable_thread_specific<uint64_t> counts(0);
    // The particle's disc into the Z-buffer: sub-pixel centres within rp, nearest wins.
    auto splat = [&](const Projected& p, uint64_t& drawn) {
        const glm::vec3& q = p.q;
        const float value = p.value, px = p.px, py = p.py, rp = p.rp;
        const uint32_t id = p.id;
        int x0, x1, y0, y1;
        centres_within(px - rp, px + rp, sub_width_, &x0, &x1);
        centres_within(py - rp, py + rp, sub_height_, &y0, &y1);
        if (x0 > x1 || y0 > y1) return;
        const uint32_t depth_bits = std::bit_cast<uint32_t>(p.depth);
        uint64_t entry = 0;  // packed once the particle wins a sub-pixel
        // -- the disc, row by row: sub-pixel centres within rp, nearest wins
        for (int y = y0; y <= y1; ++y) {
            const float dy = float(y) + 0.5f - py;
            const float half = std::sqrt(std::max(rp * rp - dy * dy, 0.0f));
            int xa, xb;
            centres_within(px - half, px + half, sub_width_, &xa, &xb);
            xa = std::max(xa, x0), xb = std::min(xb, x1);
            std::atomic<uint64_t>* row = &zbuffer_[std::size_t(y) * std::size_t(sub_width_)];
            for (int x = xa; x <= xb; ++x) {
                uint64_t current = row[x].load(std::memory_order_relaxed);
                if (uint32_t(current >> 32) < depth_bits) continue;
                if (entry == 0) {  // the gradient and shading only for visible particles
                    entry = zbuffer_entry(p.depth,
                                          shade(tf_.colour(value), volume_.sample(q).gradient,
                                                to_eye_, settings_.shading),
                                          id);
                }
                while (entry < current &&
                       !row[x].compare_exchange_weak(current, entry, std::memory_order_relaxed)) {
                }
            }
        }
        ++drawn;
    };
    generate(uint32_t(repetitions_), splat, counts);

    for (std::size_t m = 0; m < meshes_.size() && !cancelled(); ++m)
        rasterize_mesh(*meshes_[m], m, counts);
    if (cancelled()) return false;  // the ensemble is left as it was

    // -- average the sub-pixels into the ensemble
    for (const uint64_t c : counts) particles_ += c;
    const int L = settings_.subpixel_level;
    const double weight = 1.0 / double(L * L);
    tbb::parallel_for(0, camera_.height, [&](int y) {
        for (int x = 0; x < camera_.width; ++x) {
            glm::dvec3 sum(0.0);
            for (int sy = 0; sy < L; ++sy) {
                for (int sx = 0; sx < L; ++sx) {
                    const uint64_t entry =
                        zbuffer_[std::size_t(y * L + sy) * std::size_t(sub_width_) +
                                 std::size_t(x * L + sx)]
                            .load(std::memory_order_relaxed);
                    sum += glm::dvec3(entry == kEmptyEntry ? settings_.background
                                                           : entry_colour(entry));
                }
            }
            accumulated_[std::size_t(y) * std::size_t(camera_.width) + std::size_t(x)] +=
                sum * weight;
        }
    });
    ++repetitions_;
    return true;
}

RgbImage PbvrRenderer::image() const {
    RgbImage out{camera_.width, camera_.height, {}};
    out.pixels.resize(accumulated_.size(), settings_.background);
    if (repetitions_ == 0) return out;
    for (std::size_t p = 0; p < accumulated_.size(); ++p)
        out.pixels[p] = glm::vec3(accumulated_[p] / double(repetitions_));
    return out;
}

}  // namespace sonotrace::imaging::pbvr
