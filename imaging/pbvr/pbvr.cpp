#include "imaging/pbvr/pbvr.h"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <numbers>

#include "tissue/error.h"

namespace sonotrace::imaging::pbvr {

using tissue::InputError;

// ---- volume ------------------------------------------------------------------------

RenderVolume::RenderVolume(const tissue::Volume& volume, const ColourTransferFunction& tf)
    : geometry_(volume.geometry()) {
    const glm::ivec3 n = geometry_.dims;
    if (n.x < 2 || n.y < 2 || n.z < 2)
        throw InputError("volume", "dims", "volume rendering needs at least 2 voxels per axis");
    spacing_ = glm::vec3(geometry_.spacing);
    inverse_spacing_ = 1.0f / spacing_;
    extent_ = glm::vec3(n - 1) * spacing_;
    voxels_.resize(volume.size());
    tbb::parallel_for(0, n.z, [&](int k) {
        for (int j = 0; j < n.y; ++j) {
            for (int i = 0; i < n.x; ++i) {
                auto s = [&](int a, int b, int c) {
                    return tf.normalize(volume.at(std::clamp(a, 0, n.x - 1),
                                                  std::clamp(b, 0, n.y - 1),
                                                  std::clamp(c, 0, n.z - 1)));
                };
                VoxelSample& v = voxels_[volume.linear_index(i, j, k)];
                v.value = s(i, j, k);
                // central differences (one-sided at the border), per mm
                auto d = [&](int lo, int hi, float a, float b, float h) {
                    return (b - a) / (float(hi - lo) * h);
                };
                const int i0 = std::max(i - 1, 0), i1 = std::min(i + 1, n.x - 1);
                const int j0 = std::max(j - 1, 0), j1 = std::min(j + 1, n.y - 1);
                const int k0 = std::max(k - 1, 0), k1 = std::min(k + 1, n.z - 1);
                v.gradient = {d(i0, i1, s(i0, j, k), s(i1, j, k), spacing_.x),
                              d(j0, j1, s(i, j0, k), s(i, j1, k), spacing_.y),
                              d(k0, k1, s(i, j, k0), s(i, j, k1), spacing_.z)};
            }
        }
    });
}

// ---- settings, shading, images -----------------------------------------------------

void RenderSettings::validate() const {
    using tissue::require_in_range;
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

glm::vec3 shade(const glm::vec3& colour, const glm::vec3& gradient, const glm::vec3& to_eye,
                const Shading& shading) {
    if (shading.model == Shading::Model::none) return colour;
    const float g2 = glm::dot(gradient, gradient);
    // No surface where the field is flat: ambient + diffuse as if facing the light.
    const float facing = g2 > 1e-12f ? std::abs(glm::dot(gradient, to_eye)) / std::sqrt(g2) : 1.0f;
    glm::vec3 c = colour * (shading.ambient + shading.diffuse * facing);
    if (shading.model == Shading::Model::blinn_phong) {
        // headlight: the half vector is the view direction itself
        c += glm::vec3(shading.specular * std::pow(facing, shading.shininess));
    }
    return c;
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
            auto byte = [](float v) {  // display gamma 2.2 of the linear colour
                return static_cast<unsigned char>(
                    std::lround(std::pow(glm::clamp(v, 0.0f, 1.0f), 1.0f / 2.2f) * 255.0f));
            };
            picture.at<cv::Vec3b>(y, x) = {byte(c.z), byte(c.y), byte(c.x)};
        }
    }
    return picture;
}

// ---- particle renderer -------------------------------------------------------------

namespace {

// The Z-buffer of one thread: per sub-pixel the nearest particle's key (depth bits
// above, particle id below: a total order) and colour.
struct SubpixelBuffer {
    std::vector<uint64_t> key;
    std::vector<glm::vec3> colour;
    void reset(std::size_t n) {
        key.assign(n, std::numeric_limits<uint64_t>::max());
        colour.resize(n);
    }
};

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
    // pi r^2 = the sub-pixel's footprint at the target distance (times radius_scale^2)
    const double footprint = camera.distance_mm / (camera.focal_px() * L);
    radius_ = float(settings.radius_scale * footprint / std::sqrt(std::numbers::pi));

    // Cells that can hold particles, with their majorants.
    const glm::ivec3 n = volume.dims() - 1;
    std::vector<std::vector<Cell>> slabs(std::size_t(n.z));
    tbb::parallel_for(0, n.z, [&](int k) {
        for (int j = 0; j < n.y; ++j) {
            for (int i = 0; i < n.x; ++i) {
                float lo = 1.0f, hi = 0.0f;
                for (int c = 0; c < 8; ++c) {
                    const float s = volume.voxel(i + (c & 1), j + (c >> 1 & 1), k + (c >> 2)).value;
                    lo = std::min(lo, s), hi = std::max(hi, s);
                }
                const float majorant = generation_tf_.max_extinction(lo, hi);
                if (majorant > 0.0f) {
                    const uint32_t index = uint32_t((std::size_t(k) * std::size_t(n.y) + std::size_t(j)) *
                                                        std::size_t(n.x) +
                                                    std::size_t(i));
                    slabs[std::size_t(k)].push_back({index, majorant});
                }
            }
        }
    });
    for (auto& slab : slabs) cells_.insert(cells_.end(), slab.begin(), slab.end());
    accumulated_.assign(std::size_t(camera.width) * std::size_t(camera.height), glm::dvec3(0.0));
}

void PbvrRenderer::add_repetition() {
    const std::size_t subpixels = std::size_t(sub_width_) * std::size_t(sub_height_);
    tbb::enumerable_thread_specific<SubpixelBuffer> buffers([&] {
        SubpixelBuffer b;
        b.reset(subpixels);
        return b;
    });
    tbb::enumerable_thread_specific<uint64_t> counts(0);
    const glm::ivec3 n = volume_.dims() - 1;
    const glm::vec3 h = volume_.spacing();
    const float inverse_area = float(1.0 / (std::numbers::pi * double(radius_) * radius_));
    const uint32_t repetition = uint32_t(repetitions_);
    const auto& cut = settings_.cut_away;

    tbb::parallel_for(
        tbb::blocked_range<std::size_t>(0, cells_.size(), 2048),
        [&](const tbb::blocked_range<std::size_t>& range) {
            SubpixelBuffer& buffer = buffers.local();
            uint64_t& drawn = counts.local();
            for (std::size_t c = range.begin(); c != range.end(); ++c) {
                const Cell cell = cells_[c];
                const uint32_t i = cell.index % uint32_t(n.x);
                const uint32_t j = cell.index / uint32_t(n.x) % uint32_t(n.y);
                const uint32_t k = cell.index / (uint32_t(n.x) * uint32_t(n.y));
                const glm::vec3 origin = glm::vec3(float(i), float(j), float(k)) * h;
                CellRandom random(settings_.seed, repetition, cell.index);
                uint32_t emitted = 0;
                // -- density: rho = sigma / (pi r^2) of the generation transfer function
                auto density = [&](const glm::vec3& q) {
                    const VoxelSample v = volume_.sample(q);
                    return std::pair{generation_tf_.extinction(v.value) * inverse_area, v};
                };
                auto emit = [&](const glm::vec3& q, const VoxelSample& v) {
                    const uint32_t id = particle_id(cell.index, emitted++);
                    if (cut && cut->contains(q)) return;
                    float radius = radius_;
                    if (adapt_radius_) {
                        // Eq. 13 keeps the density and changes the radius. As printed the
                        // ratio is inverted: from eq. 12 with rho fixed,
                        // r' = r sqrt(ln(1 - alpha') / ln(1 - alpha)) = r sqrt(sigma'/sigma).
                        const float before = generation_tf_.extinction(v.value);
                        const float after = tf_.extinction(v.value);
                        if (!(after > 0.0f) || !(before > 0.0f)) return;
                        radius *= std::sqrt(after / before);
                    }
                    // -- project
                    const glm::vec3 e = to_camera_ * q + camera_offset_;
                    if (e.z <= radius) return;  // behind or at the eye
                    const float inverse_z = 1.0f / e.z;
                    const float px = centre_x_ + focal_ * e.x * inverse_z;
                    const float py = centre_y_ + focal_ * e.y * inverse_z;
                    const float rp = focal_ * radius * inverse_z;
                    const int x0 = std::max(0, int(std::ceil(px - rp - 0.5f)));
                    const int x1 = std::min(sub_width_ - 1, int(std::floor(px + rp - 0.5f)));
                    const int y0 = std::max(0, int(std::ceil(py - rp - 0.5f)));
                    const int y1 = std::min(sub_height_ - 1, int(std::floor(py + rp - 0.5f)));
                    if (x0 > x1 || y0 > y1) return;
                    const uint64_t key = uint64_t(std::bit_cast<uint32_t>(e.z)) << 32 | id;
                    bool shaded = false;
                    glm::vec3 colour;
                    // -- the disc: every sub-pixel centre within rp, nearest wins
                    for (int y = y0; y <= y1; ++y) {
                        const float dy = float(y) + 0.5f - py;
                        for (int x = x0; x <= x1; ++x) {
                            const float dx = float(x) + 0.5f - px;
                            if (dx * dx + dy * dy > rp * rp) continue;
                            const std::size_t s = std::size_t(y) * std::size_t(sub_width_) +
                                                  std::size_t(x);
                            if (key >= buffer.key[s]) continue;
                            if (!shaded) {
                                colour = shade(tf_.colour(v.value), v.gradient, to_eye_,
                                               settings_.shading);
                                shaded = true;
                            }
                            buffer.key[s] = key;
                            buffer.colour[s] = colour;
                        }
                    }
                    ++drawn;
                };
                const glm::vec3 size = h;
                if (settings_.sampling == Sampling::uniform)
                    sample_cell_uniform(origin, size, cell.majorant * inverse_area, density,
                                        random, emit);
                else
                    sample_cell_metropolis(origin, size, density, random, emit);
            }
        });

    // -- merge the thread buffers by the same total order, then average sub-pixels
    std::vector<const SubpixelBuffer*> all;
    for (const SubpixelBuffer& b : buffers) all.push_back(&b);
    for (const uint64_t c : counts) particles_ += c;
    const int L = settings_.subpixel_level;
    const double weight = 1.0 / double(L * L);
    tbb::parallel_for(0, camera_.height, [&](int y) {
        for (int x = 0; x < camera_.width; ++x) {
            glm::dvec3 sum(0.0);
            for (int sy = 0; sy < L; ++sy) {
                for (int sx = 0; sx < L; ++sx) {
                    const std::size_t s = std::size_t(y * L + sy) * std::size_t(sub_width_) +
                                          std::size_t(x * L + sx);
                    uint64_t best = std::numeric_limits<uint64_t>::max();
                    glm::vec3 colour = settings_.background;
                    for (const SubpixelBuffer* b : all) {
                        if (b->key[s] < best) best = b->key[s], colour = b->colour[s];
                    }
                    sum += glm::dvec3(colour);
                }
            }
            accumulated_[std::size_t(y) * std::size_t(camera_.width) + std::size_t(x)] +=
                sum * weight;
        }
    });
    ++repetitions_;
}

RgbImage PbvrRenderer::image() const {
    RgbImage out{camera_.width, camera_.height, {}};
    out.pixels.resize(accumulated_.size(), settings_.background);
    if (repetitions_ == 0) return out;
    for (std::size_t p = 0; p < accumulated_.size(); ++p)
        out.pixels[p] = glm::vec3(accumulated_[p] / double(repetitions_));
    return out;
}

// ---- reference ray caster ----------------------------------------------------------

RgbImage raycast(const RenderVolume& volume, const ColourTransferFunction& tf,
                 const OrbitCamera& camera, const RenderSettings& settings, double step_mm) {
    camera.validate();
    settings.validate();
    tissue::require_in_range("raycast", "step", step_mm, 1e-4, 100.0, "mm");
    const int L = settings.subpixel_level;
    const tissue::VolumeGeometry& g = volume.geometry();
    // Rays in the local frame: q = D^-1 (world - origin).
    const glm::dmat3 to_local = glm::inverse(g.direction);
    const glm::dvec3 eye = to_local * (camera.eye() - g.origin);
    const glm::dvec3 right = to_local * camera.right(), down = to_local * -camera.up(),
                     forward = to_local * camera.forward();
    const glm::vec3 to_eye = glm::normalize(glm::vec3(-forward));
    const double focal = camera.focal_px() * L;
    const glm::dvec3 extent(volume.extent());
    const float step = float(step_mm);
    RgbImage out{camera.width, camera.height, {}};
    out.pixels.assign(std::size_t(camera.width) * std::size_t(camera.height), glm::vec3(0.0f));
    tbb::parallel_for(0, camera.height, [&](int y) {
        for (int x = 0; x < camera.width; ++x) {
            glm::dvec3 pixel(0.0);
            for (int sy = 0; sy < L; ++sy) {
                for (int sx = 0; sx < L; ++sx) {
                    const double u = (x * L + sx + 0.5 - 0.5 * camera.width * L) / focal;
                    const double v = (y * L + sy + 0.5 - 0.5 * camera.height * L) / focal;
                    const glm::dvec3 dir = glm::normalize(forward + u * right + v * down);
                    // -- clip the ray to the volume box
                    double t0 = 0.0, t1 = std::numeric_limits<double>::max();
                    for (int a = 0; a < 3; ++a) {
                        if (std::abs(dir[a]) < 1e-12) {
                            if (eye[a] < 0.0 || eye[a] > extent[a]) t1 = -1.0;
                            continue;
                        }
                        double ta = (0.0 - eye[a]) / dir[a], tb = (extent[a] - eye[a]) / dir[a];
                        if (ta > tb) std::swap(ta, tb);
                        t0 = std::max(t0, ta), t1 = std::min(t1, tb);
                    }
                    glm::vec3 colour(0.0f);
                    float transmittance = 1.0f;
                    // -- front to back, midpoint samples
                    for (double t = t0; t < t1 && transmittance > 1e-5f; t += step) {
                        const double length = std::min(double(step), t1 - t);
                        const glm::vec3 q(eye + (t + 0.5 * length) * dir);
                        if (settings.cut_away && settings.cut_away->contains(q)) continue;
                        const VoxelSample s = volume.sample(q);
                        const float sigma = tf.extinction(s.value);
                        if (sigma <= 0.0f) continue;
                        const float alpha = 1.0f - std::exp(-sigma * float(length));
                        colour += transmittance * alpha *
                                  shade(tf.colour(s.value), s.gradient, to_eye, settings.shading);
                        transmittance *= 1.0f - alpha;
                    }
                    pixel += glm::dvec3(colour + transmittance * settings.background);
                }
            }
            out.at(x, y) = glm::vec3(pixel / double(L * L));
        }
    });
    return out;
}

}  // namespace sonotrace::imaging::pbvr
