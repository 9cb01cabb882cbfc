#pragma once
// PBVR's projection and ensemble average on the GPU (OpenGL 3.3 core): the particles of
// imaging::pbvr::PbvrRenderer::splats(), generated on the CPU as for the CPU renderer,
// drawn as discs with a depth test into a sub-pixel framebuffer, each repetition's
// sub-pixels averaged into a float accumulation. The CPU renderer stays the reference
// (and the CLI's): for the same particles both images agree within the PSNR the test
// states (tests/gui/test_gl_pbvr.cpp).
//
// Coverage and depth follow the CPU's Z-buffer: a disc covers the sub-pixels whose centres
// lie within its radius; the nearest particle wins (the depth buffer holds camera depth
// over a power of two, so distinct float depths stay distinct). Ties in depth, which the
// CPU breaks by colour, go to the first drawn. Points are clipped by their centres, so
// the framebuffer has a margin of kMargin sub-pixels round the image: a disc whose
// centre lies within it still draws its part inside; larger discs are counted in
// clipped().
#include <cstdint>
#include <vector>

#include <glm/glm.hpp>

#include "imaging/pbvr/pbvr.h"

namespace sonotrace::gl {

// A 2D texture (`reuse`'s name, or a new one) of `internal` format filled from `data`
// (null: left undefined), clamped at the edges, nearest or linear filtering, tightly
// packed rows; left bound to GL_TEXTURE_2D. A current OpenGL context is needed.
unsigned texture_2d(int internal, int width, int height, unsigned format, unsigned type,
                    const void* data, bool linear = false, unsigned reuse = 0);

class GlPbvr {
  public:
    static constexpr int kMargin = 32;  // sub-pixels round the image

    // An OpenGL 3.3 core context must be current, here and in every call. Throws
    // std::runtime_error if a shader or framebuffer cannot be made.
    GlPbvr(int width, int height, int subpixel_level, const glm::vec3& background);
    ~GlPbvr();
    GlPbvr(const GlPbvr&) = delete;
    GlPbvr& operator=(const GlPbvr&) = delete;

    int width() const { return width_; }
    int height() const { return height_; }
    int subpixel_level() const { return level_; }

    // Opaque surfaces under the particles: Z-buffer entries per sub-pixel as
    // PbvrRenderer::set_overlay takes them (empty: none).
    void set_overlay(const std::vector<uint64_t>& layer);
    // One repetition: clears to the background and the overlay, draws the splats with
    // the depth test, adds the sub-pixels' mean to the ensemble.
    void add_repetition(const std::vector<imaging::pbvr::Splat>& splats);
    int repetitions() const { return repetitions_; }
    // Splats whose discs reached beyond the margin (partly lost), over all repetitions.
    uint64_t clipped() const { return clipped_; }

    // The ensemble average read back (background before the first repetition).
    imaging::pbvr::RgbImage image() const;
    // The ensemble average as an RGBA8 texture, rows top to bottom (ImGui::Image's
    // order); updated by add_repetition.
    unsigned texture() const { return display_texture_; }

  private:
    int width_, height_, level_;
    int sub_width_, sub_height_;  // with the margin
    glm::vec3 background_;
    int repetitions_ = 0;
    uint64_t clipped_ = 0;
    float point_size_max_ = 1.0f;
    unsigned splat_program_ = 0, overlay_program_ = 0, accumulate_program_ = 0,
             display_program_ = 0;
    unsigned empty_vao_ = 0, splat_vao_ = 0, splat_buffer_ = 0;
    unsigned sub_fbo_ = 0, sub_colour_ = 0, sub_depth_ = 0;
    unsigned accumulation_fbo_ = 0, accumulation_ = 0;
    unsigned display_fbo_ = 0, display_texture_ = 0;
    unsigned overlay_depth_ = 0, overlay_colour_ = 0;
    bool has_overlay_ = false;
};

}  // namespace sonotrace::gl
