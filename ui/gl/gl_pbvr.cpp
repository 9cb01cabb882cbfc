#include "ui/gl/gl_pbvr.h"

#define GL_GLEXT_PROTOTYPES
#include <GL/gl.h>
#include <GL/glext.h>

#include <bit>
#include <cmath>
#include <stdexcept>
#include <string>

namespace sonotrace::gl {

namespace {

// Depths are written as depth / kFar into a float depth buffer: a power of two, so the
// division is exact and distinct depths stay distinct.
constexpr float kFar = 131072.0f;  // mm

// The sub-pixel framebuffer's window row of CPU row r (rows top to bottom in the CPU's
// buffer, bottom to top in GL's; the margin on every side), written once for the shaders.
constexpr const char* kRowMapping = R"(
int window_row(int r, int total_height, int margin) { return total_height - margin - 1 - r; }
)";

constexpr const char* kSplatVertex = R"(#version 330 core
layout(location = 0) in vec4 splat;   // x, y (sub-pixels from the image's top left), radius, depth
layout(location = 1) in vec3 colour;  // RGB8, normalized
uniform vec2 total;                   // framebuffer size, sub-pixels
uniform float margin;
uniform float max_point;
flat out vec2 centre;
flat out float radius2;
flat out float depth;
flat out vec3 rgb;
void main() {
    // Window coordinates of the disc's centre: x right, y up from the bottom.
    centre = vec2(margin + splat.x, total.y - margin - splat.y);
    gl_Position = vec4(2.0 * centre / total - 1.0, 0.0, 1.0);
    gl_PointSize = min(2.0 * ceil(splat.z) + 2.0, max_point);
    radius2 = splat.z * splat.z;
    depth = splat.w;
    rgb = colour;
}
)";

// Covered: the sub-pixel's centre within the radius (the CPU's rule, boundary included).
constexpr const char* kSplatFragment = R"(#version 330 core
flat in vec2 centre;
flat in float radius2;
flat in float depth;
flat in vec3 rgb;
uniform float inverse_far;
out vec4 colour;
void main() {
    vec2 d = gl_FragCoord.xy - centre;
    if (dot(d, d) > radius2) discard;
    gl_FragDepth = depth * inverse_far;
    colour = vec4(rgb, 1.0);
}
)";

// A triangle covering the viewport.
constexpr const char* kFullScreenVertex = R"(#version 330 core
void main() {
    vec2 p = vec2(float((gl_VertexID & 1) << 2) - 1.0, float((gl_VertexID & 2) << 1) - 1.0);
    gl_Position = vec4(p, 0.0, 1.0);
}
)";

constexpr const char* kOverlayFragment = R"(
uniform sampler2D overlay_depth;   // camera depth (mm), CPU rows
uniform sampler2D overlay_colour;  // RGB, alpha 0 where the layer is empty
uniform ivec2 image;               // sub-pixels without the margin
uniform int total_height, margin;
uniform float inverse_far;
out vec4 colour;
void main() {
    int c = int(gl_FragCoord.x) - margin;
    int r = total_height - margin - 1 - int(gl_FragCoord.y);
    if (c < 0 || r < 0 || c >= image.x || r >= image.y) discard;
    vec4 rgba = texelFetch(overlay_colour, ivec2(c, r), 0);
    if (rgba.a == 0.0) discard;
    gl_FragDepth = texelFetch(overlay_depth, ivec2(c, r), 0).r * inverse_far;
    colour = vec4(rgba.rgb, 1.0);
}
)";

// One pixel (rows top to bottom) = the mean of its L x L sub-pixels, added by blending.
constexpr const char* kAccumulateFragment = R"(
uniform sampler2D subpixels;
uniform int level, total_height, margin, height;
out vec4 colour;
void main() {
    int x = int(gl_FragCoord.x), y = int(gl_FragCoord.y);
    vec3 sum = vec3(0.0);
    for (int sy = 0; sy < level; ++sy)
        for (int sx = 0; sx < level; ++sx)
            sum += texelFetch(subpixels,
                              ivec2(margin + x * level + sx,
                                    window_row(y * level + sy, total_height, margin)), 0).rgb;
    colour = vec4(sum / float(level * level), 1.0);
}
)";

constexpr const char* kDisplayFragment = R"(#version 330 core
uniform sampler2D accumulation;
uniform float scale;  // 1 / repetitions
out vec4 colour;
void main() {
    colour = vec4(clamp(texelFetch(accumulation, ivec2(gl_FragCoord.xy), 0).rgb * scale, 0.0, 1.0), 1.0);
}
)";

// Throws with the object's info log (and deletes it) unless its `status` is true.
void require_status(GLuint object, GLenum status, bool is_shader, const char* failure) {
    GLint ok = 0;
    is_shader ? glGetShaderiv(object, status, &ok) : glGetProgramiv(object, status, &ok);
    if (ok) return;
    char log[2048] = "";
    if (is_shader) {
        glGetShaderInfoLog(object, sizeof log, nullptr, log);
        glDeleteShader(object);
    } else {
        glGetProgramInfoLog(object, sizeof log, nullptr, log);
        glDeleteProgram(object);
    }
    throw std::runtime_error(std::string("GPU PBVR: ") + failure + ": " + log);
}

unsigned compile(GLenum type, const std::string& source) {
    const GLuint shader = glCreateShader(type);
    const char* text = source.c_str();
    glShaderSource(shader, 1, &text, nullptr);
    glCompileShader(shader);
    require_status(shader, GL_COMPILE_STATUS, true, "a shader does not compile");
    return shader;
}

unsigned program(const std::string& vertex, const std::string& fragment) {
    const GLuint v = compile(GL_VERTEX_SHADER, vertex), f = compile(GL_FRAGMENT_SHADER, fragment);
    const GLuint p = glCreateProgram();
    glAttachShader(p, v);
    glAttachShader(p, f);
    glLinkProgram(p);
    glDeleteShader(v);
    glDeleteShader(f);
    require_status(p, GL_LINK_STATUS, false, "a program does not link");
    return p;
}

unsigned framebuffer(unsigned colour, unsigned depth) {
    GLuint f = 0;
    glGenFramebuffers(1, &f);
    glBindFramebuffer(GL_FRAMEBUFFER, f);
    glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, colour, 0);
    if (depth)
        glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, depth);
    if (glCheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE)
        throw std::runtime_error("GPU PBVR: a framebuffer is incomplete");
    return f;
}

// Restores what the GUI's renderer expects: the window's framebuffer, no depth test or
// blending, its viewport.
class StateGuard {
  public:
    StateGuard() {
        glGetIntegerv(GL_VIEWPORT, viewport_);
        glGetIntegerv(GL_FRAMEBUFFER_BINDING, &framebuffer_);
        glGetIntegerv(GL_CURRENT_PROGRAM, &program_);
        glGetIntegerv(GL_VERTEX_ARRAY_BINDING, &vao_);
        glGetIntegerv(GL_ACTIVE_TEXTURE, &active_texture_);
        depth_test_ = glIsEnabled(GL_DEPTH_TEST);
        blend_ = glIsEnabled(GL_BLEND);
        scissor_ = glIsEnabled(GL_SCISSOR_TEST);
        glDisable(GL_SCISSOR_TEST);
    }
    ~StateGuard() {
        glBindFramebuffer(GL_FRAMEBUFFER, GLuint(framebuffer_));
        glViewport(viewport_[0], viewport_[1], viewport_[2], viewport_[3]);
        glUseProgram(GLuint(program_));
        glBindVertexArray(GLuint(vao_));
        glActiveTexture(GLenum(active_texture_));
        depth_test_ ? glEnable(GL_DEPTH_TEST) : glDisable(GL_DEPTH_TEST);
        blend_ ? glEnable(GL_BLEND) : glDisable(GL_BLEND);
        scissor_ ? glEnable(GL_SCISSOR_TEST) : glDisable(GL_SCISSOR_TEST);
    }
    StateGuard(const StateGuard&) = delete;
    StateGuard& operator=(const StateGuard&) = delete;

  private:
    GLint viewport_[4] = {0, 0, 0, 0}, framebuffer_ = 0, program_ = 0, vao_ = 0,
          active_texture_ = GL_TEXTURE0;
    GLboolean depth_test_ = GL_FALSE, blend_ = GL_FALSE, scissor_ = GL_FALSE;
};

}  // namespace

unsigned texture_2d(int internal, int width, int height, unsigned format, unsigned type,
                    const void* data, bool linear, unsigned reuse) {
    GLuint t = reuse;
    if (!t) glGenTextures(1, &t);
    glBindTexture(GL_TEXTURE_2D, t);
    const GLint filter = linear ? GL_LINEAR : GL_NEAREST;
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, filter);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, filter);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
    glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
    glTexImage2D(GL_TEXTURE_2D, 0, internal, width, height, 0, format, type, data);
    return t;
}

GlPbvr::GlPbvr(int width, int height, int subpixel_level, const glm::vec3& background)
    : width_(width),
      height_(height),
      level_(subpixel_level),
      sub_width_(width * subpixel_level + 2 * kMargin),
      sub_height_(height * subpixel_level + 2 * kMargin),
      background_(background) {
    if (width < 1 || height < 1 || subpixel_level < 1)
        throw std::invalid_argument("GlPbvr: empty image");
    GLint max_size = 0;
    glGetIntegerv(GL_MAX_TEXTURE_SIZE, &max_size);
    if (sub_width_ > max_size || sub_height_ > max_size)
        throw std::runtime_error("the sub-pixel image (" + std::to_string(sub_width_) + " x " +
                                 std::to_string(sub_height_) +
                                 " with its margin) exceeds this OpenGL's largest texture (" +
                                 std::to_string(max_size) + ")");
    const StateGuard guard;
    const std::string header = "#version 330 core\n" + std::string(kRowMapping);
    splat_program_ = program(kSplatVertex, kSplatFragment);
    overlay_program_ = program(kFullScreenVertex, header + kOverlayFragment);
    accumulate_program_ = program(kFullScreenVertex, header + kAccumulateFragment);
    display_program_ = program(kFullScreenVertex, kDisplayFragment);
    GLfloat range[2] = {1.0f, 1.0f};
    glGetFloatv(GL_ALIASED_POINT_SIZE_RANGE, range);
    point_size_max_ = range[1];

    glGenVertexArrays(1, &empty_vao_);
    glGenVertexArrays(1, &splat_vao_);
    glGenBuffers(1, &splat_buffer_);
    glBindVertexArray(splat_vao_);
    glBindBuffer(GL_ARRAY_BUFFER, splat_buffer_);
    using imaging::pbvr::Splat;
    glEnableVertexAttribArray(0);
    glVertexAttribPointer(0, 4, GL_FLOAT, GL_FALSE, sizeof(Splat), nullptr);
    // The colour's bytes in memory (little endian): B, G, R, unused.
    glEnableVertexAttribArray(1);
    glVertexAttribPointer(1, GL_BGRA, GL_UNSIGNED_BYTE, GL_TRUE, sizeof(Splat),
                          reinterpret_cast<const void*>(offsetof(Splat, rgb)));
    glBindVertexArray(0);

    sub_colour_ = texture_2d(GL_RGBA32F, sub_width_, sub_height_, GL_RGBA, GL_FLOAT, nullptr);
    glGenRenderbuffers(1, &sub_depth_);
    glBindRenderbuffer(GL_RENDERBUFFER, sub_depth_);
    glRenderbufferStorage(GL_RENDERBUFFER, GL_DEPTH_COMPONENT32F, sub_width_, sub_height_);
    sub_fbo_ = framebuffer(sub_colour_, sub_depth_);
    accumulation_ = texture_2d(GL_RGBA32F, width, height, GL_RGBA, GL_FLOAT, nullptr);
    accumulation_fbo_ = framebuffer(accumulation_, 0);
    display_texture_ =
        texture_2d(GL_RGBA8, width, height, GL_RGBA, GL_UNSIGNED_BYTE, nullptr, true);
    display_fbo_ = framebuffer(display_texture_, 0);
    glBindFramebuffer(GL_FRAMEBUFFER, display_fbo_);
    glViewport(0, 0, width_, height_);
    glClearColor(background_.x, background_.y, background_.z, 1.0f);
    glClear(GL_COLOR_BUFFER_BIT);
}

GlPbvr::~GlPbvr() {
    const GLuint textures[] = {sub_colour_, accumulation_, display_texture_, overlay_depth_,
                               overlay_colour_};
    glDeleteTextures(5, textures);
    glDeleteRenderbuffers(1, &sub_depth_);
    const GLuint framebuffers[] = {sub_fbo_, accumulation_fbo_, display_fbo_};
    glDeleteFramebuffers(3, framebuffers);
    glDeleteBuffers(1, &splat_buffer_);
    const GLuint arrays[] = {empty_vao_, splat_vao_};
    glDeleteVertexArrays(2, arrays);
    for (GLuint p : {splat_program_, overlay_program_, accumulate_program_, display_program_})
        glDeleteProgram(p);
}

void GlPbvr::set_overlay(const std::vector<uint64_t>& layer) {
    has_overlay_ = !layer.empty();
    if (!has_overlay_) return;
    const int w = width_ * level_, h = height_ * level_;
    if (layer.size() != std::size_t(w) * std::size_t(h))
        throw std::invalid_argument("GlPbvr::set_overlay: one entry per sub-pixel");
    std::vector<float> depth(layer.size());
    std::vector<uint8_t> rgba(4 * layer.size());
    for (std::size_t s = 0; s < layer.size(); ++s) {
        const uint64_t e = layer[s];
        const bool empty = e == imaging::pbvr::kEmptyEntry;
        depth[s] = empty ? 0.0f : std::bit_cast<float>(uint32_t(e >> 32));
        rgba[4 * s] = uint8_t(e >> 24), rgba[4 * s + 1] = uint8_t(e >> 16);
        rgba[4 * s + 2] = uint8_t(e >> 8), rgba[4 * s + 3] = empty ? 0 : 255;
    }
    const StateGuard guard;
    glDeleteTextures(1, &overlay_depth_);
    glDeleteTextures(1, &overlay_colour_);
    overlay_depth_ = texture_2d(GL_R32F, w, h, GL_RED, GL_FLOAT, depth.data());
    overlay_colour_ = texture_2d(GL_RGBA8, w, h, GL_RGBA, GL_UNSIGNED_BYTE, rgba.data());
}

void GlPbvr::add_repetition(const std::vector<imaging::pbvr::Splat>& splats) {
    const StateGuard guard;
    // -- the sub-pixels: background, overlay, particles (nearest wins)
    glBindFramebuffer(GL_FRAMEBUFFER, sub_fbo_);
    glViewport(0, 0, sub_width_, sub_height_);
    glClearColor(background_.x, background_.y, background_.z, 1.0f);
    glClearDepth(1.0);
    glDisable(GL_BLEND);
    glEnable(GL_DEPTH_TEST);
    glDepthFunc(GL_LESS);
    glDepthMask(GL_TRUE);
    glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
    if (has_overlay_) {
        glUseProgram(overlay_program_);
        glActiveTexture(GL_TEXTURE0);
        glBindTexture(GL_TEXTURE_2D, overlay_depth_);
        glActiveTexture(GL_TEXTURE1);
        glBindTexture(GL_TEXTURE_2D, overlay_colour_);
        glUniform1i(glGetUniformLocation(overlay_program_, "overlay_depth"), 0);
        glUniform1i(glGetUniformLocation(overlay_program_, "overlay_colour"), 1);
        glUniform2i(glGetUniformLocation(overlay_program_, "image"), width_ * level_,
                    height_ * level_);
        glUniform1i(glGetUniformLocation(overlay_program_, "total_height"), sub_height_);
        glUniform1i(glGetUniformLocation(overlay_program_, "margin"), kMargin);
        glUniform1f(glGetUniformLocation(overlay_program_, "inverse_far"), 1.0f / kFar);
        glBindVertexArray(empty_vao_);
        glDrawArrays(GL_TRIANGLES, 0, 3);
    }
    for (const imaging::pbvr::Splat& s : splats)
        clipped_ +=
            s.radius + 1.0f > float(kMargin) || 2.0f * std::ceil(s.radius) + 2.0f > point_size_max_;
    glEnable(GL_PROGRAM_POINT_SIZE);
    glUseProgram(splat_program_);
    glUniform2f(glGetUniformLocation(splat_program_, "total"), float(sub_width_),
                float(sub_height_));
    glUniform1f(glGetUniformLocation(splat_program_, "margin"), float(kMargin));
    glUniform1f(glGetUniformLocation(splat_program_, "max_point"), point_size_max_);
    glUniform1f(glGetUniformLocation(splat_program_, "inverse_far"), 1.0f / kFar);
    glBindVertexArray(splat_vao_);
    glBindBuffer(GL_ARRAY_BUFFER, splat_buffer_);
    glBufferData(GL_ARRAY_BUFFER, GLsizeiptr(splats.size() * sizeof(imaging::pbvr::Splat)),
                 splats.data(), GL_STREAM_DRAW);
    glDrawArrays(GL_POINTS, 0, GLsizei(splats.size()));
    glDisable(GL_DEPTH_TEST);

    // -- their mean per pixel into the ensemble
    glBindFramebuffer(GL_FRAMEBUFFER, accumulation_fbo_);
    glViewport(0, 0, width_, height_);
    if (repetitions_ == 0) {
        glClearColor(0.0f, 0.0f, 0.0f, 0.0f);
        glClear(GL_COLOR_BUFFER_BIT);
    }
    glEnable(GL_BLEND);
    glBlendFunc(GL_ONE, GL_ONE);
    glBlendEquation(GL_FUNC_ADD);
    glUseProgram(accumulate_program_);
    glActiveTexture(GL_TEXTURE0);
    glBindTexture(GL_TEXTURE_2D, sub_colour_);
    glUniform1i(glGetUniformLocation(accumulate_program_, "subpixels"), 0);
    glUniform1i(glGetUniformLocation(accumulate_program_, "level"), level_);
    glUniform1i(glGetUniformLocation(accumulate_program_, "total_height"), sub_height_);
    glUniform1i(glGetUniformLocation(accumulate_program_, "margin"), kMargin);
    glBindVertexArray(empty_vao_);
    glDrawArrays(GL_TRIANGLES, 0, 3);
    glDisable(GL_BLEND);
    ++repetitions_;

    // -- the average for the screen
    glBindFramebuffer(GL_FRAMEBUFFER, display_fbo_);
    glUseProgram(display_program_);
    glBindTexture(GL_TEXTURE_2D, accumulation_);
    glUniform1i(glGetUniformLocation(display_program_, "accumulation"), 0);
    glUniform1f(glGetUniformLocation(display_program_, "scale"), 1.0f / float(repetitions_));
    glDrawArrays(GL_TRIANGLES, 0, 3);
}

imaging::pbvr::RgbImage GlPbvr::image() const {
    imaging::pbvr::RgbImage out{width_, height_, {}};
    out.pixels.assign(std::size_t(width_) * std::size_t(height_), background_);
    if (repetitions_ == 0) return out;
    const StateGuard guard;
    std::vector<float> rgba(4 * out.pixels.size());
    glBindFramebuffer(GL_FRAMEBUFFER, accumulation_fbo_);
    glPixelStorei(GL_PACK_ALIGNMENT, 1);
    glReadPixels(0, 0, width_, height_, GL_RGBA, GL_FLOAT, rgba.data());
    const float scale = 1.0f / float(repetitions_);
    for (std::size_t p = 0; p < out.pixels.size(); ++p)
        out.pixels[p] = glm::vec3(rgba[4 * p], rgba[4 * p + 1], rgba[4 * p + 2]) * scale;
    return out;
}

}  // namespace sonotrace::gl
