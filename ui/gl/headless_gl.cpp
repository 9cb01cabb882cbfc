#include "ui/gl/headless_gl.h"

#include <EGL/egl.h>
#include <EGL/eglext.h>
#include <GL/gl.h>

#include <cstdio>
#include <stdexcept>

namespace sonotrace::gl {

namespace {

std::string egl_error(const char* what) {
    char code[16];
    std::snprintf(code, sizeof code, "0x%04x", unsigned(eglGetError()));
    return std::string("no headless OpenGL context: ") + what + " (EGL error " + code + ")";
}

std::string gl_string(GLenum name) {
    const auto* s = reinterpret_cast<const char*>(glGetString(name));
    return s ? s : "";
}

}  // namespace

HeadlessGl::HeadlessGl() {
    // The surfaceless platform needs no display server; without the extension, the
    // default display (which may need one).
    const auto get_platform_display = reinterpret_cast<PFNEGLGETPLATFORMDISPLAYEXTPROC>(
        eglGetProcAddress("eglGetPlatformDisplayEXT"));
    EGLDisplay display = get_platform_display ? get_platform_display(EGL_PLATFORM_SURFACELESS_MESA,
                                                                     EGL_DEFAULT_DISPLAY, nullptr)
                                              : EGL_NO_DISPLAY;
    if (display == EGL_NO_DISPLAY) display = eglGetDisplay(EGL_DEFAULT_DISPLAY);
    if (display == EGL_NO_DISPLAY) throw std::runtime_error(egl_error("no EGL display"));
    EGLint major = 0, minor = 0;
    if (!eglInitialize(display, &major, &minor))
        throw std::runtime_error(egl_error("EGL did not initialise"));
    display_ = display;
    auto fail = [&](const char* what) {
        const std::string message = egl_error(what);
        eglTerminate(display);
        throw std::runtime_error(message);
    };
    if (!eglBindAPI(EGL_OPENGL_API)) fail("EGL has no desktop OpenGL");
    // No surface: the renderer draws into its own framebuffers (KHR_surfaceless_context),
    // so no config either (KHR_no_config_context).
    const EGLint attributes[] = {EGL_CONTEXT_MAJOR_VERSION,
                                 3,
                                 EGL_CONTEXT_MINOR_VERSION,
                                 3,
                                 EGL_CONTEXT_OPENGL_PROFILE_MASK,
                                 EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT,
                                 EGL_NONE};
    EGLContext context = eglCreateContext(display, EGL_NO_CONFIG_KHR, EGL_NO_CONTEXT, attributes);
    if (context == EGL_NO_CONTEXT) fail("no OpenGL 3.3 core context");
    if (!eglMakeCurrent(display, EGL_NO_SURFACE, EGL_NO_SURFACE, context)) {
        eglDestroyContext(display, context);
        fail("the context cannot be made current without a surface");
    }
    context_ = context;
    renderer_ = gl_string(GL_RENDERER);
    version_ = gl_string(GL_VERSION);
}

HeadlessGl::~HeadlessGl() {
    eglMakeCurrent(display_, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
    eglDestroyContext(display_, context_);
    eglTerminate(display_);
}

}  // namespace sonotrace::gl
