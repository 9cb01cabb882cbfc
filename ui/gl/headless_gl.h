#pragma once
// An OpenGL 3.3 core context without a window or a display server, through EGL: what
// `sonotrace render --renderer gpu` and the GPU tests draw in. Mesa's surfaceless
// platform opens the GPU's render node where there is one and its software rasteriser
// (llvmpipe) where there is none; renderer() says which.
#include <string>

namespace sonotrace::gl {

class HeadlessGl {
  public:
    // Creates the context and makes it current on the calling thread. Throws
    // std::runtime_error naming what EGL could not do (no EGL display, no OpenGL 3.3 core
    // context, ...).
    HeadlessGl();
    ~HeadlessGl();
    HeadlessGl(const HeadlessGl&) = delete;
    HeadlessGl& operator=(const HeadlessGl&) = delete;

    // GL_RENDERER and GL_VERSION of the context, e.g. "llvmpipe (LLVM 15.0.6, 256 bits)".
    const std::string& renderer() const { return renderer_; }
    const std::string& version() const { return version_; }

  private:
    void* display_ = nullptr;  // EGLDisplay
    void* context_ = nullptr;  // EGLContext
    std::string renderer_, version_;
};

}  // namespace sonotrace::gl
