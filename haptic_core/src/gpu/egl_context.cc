#include "haptic_core/egl_context.h"

#include <EGL/egl.h>
#include <EGL/eglext.h>
#include <GLES3/gl31.h>

#include <array>
#include <cstring>
#include <string>
#include <vector>

#ifndef EGL_PLATFORM_SURFACELESS_MESA
#define EGL_PLATFORM_SURFACELESS_MESA 0x31DD
#endif

namespace ht {
namespace {

bool HasExtension(const char* list, const char* name) {
  if (list == nullptr) return false;
  const size_t len = std::strlen(name);
  for (const char* p = list; (p = std::strstr(p, name)) != nullptr; p += len) {
    const bool starts = p == list || p[-1] == ' ';
    const bool ends = p[len] == '\0' || p[len] == ' ';
    if (starts && ends) return true;
  }
  return false;
}

std::string EglErrorName(EGLint e) {
  switch (e) {
    case EGL_SUCCESS:
      return "EGL_SUCCESS";
    case EGL_NOT_INITIALIZED:
      return "EGL_NOT_INITIALIZED";
    case EGL_BAD_ACCESS:
      return "EGL_BAD_ACCESS";
    case EGL_BAD_ALLOC:
      return "EGL_BAD_ALLOC";
    case EGL_BAD_ATTRIBUTE:
      return "EGL_BAD_ATTRIBUTE";
    case EGL_BAD_CONFIG:
      return "EGL_BAD_CONFIG";
    case EGL_BAD_CONTEXT:
      return "EGL_BAD_CONTEXT";
    case EGL_BAD_DISPLAY:
      return "EGL_BAD_DISPLAY";
    case EGL_BAD_MATCH:
      return "EGL_BAD_MATCH";
    case EGL_BAD_PARAMETER:
      return "EGL_BAD_PARAMETER";
    default:
      return "EGL error 0x" + [&] {
        char b[16];
        std::snprintf(b, sizeof b, "%04x", static_cast<unsigned>(e));
        return std::string(b);
      }();
  }
}

const char* GlString(GLenum name) {
  const auto* s = reinterpret_cast<const char*>(glGetString(name));
  return s ? s : "";
}

struct Candidate {
  std::string label;
  EGLenum platform;
  void* native;
  bool software;
};

}  // namespace

std::unique_ptr<EglContext> EglContext::Create(const EglContextOptions& options) {
  const char* client = eglQueryString(EGL_NO_DISPLAY, EGL_EXTENSIONS);
  if (client == nullptr) {
    throw GpuError(
        "EGL: no client extensions (EGL 1.5 / EGL_EXT_client_extensions needed; is "
        "libegl1 with a vendor library such as libegl-mesa0 installed?)");
  }
  auto get_platform_display = reinterpret_cast<PFNEGLGETPLATFORMDISPLAYEXTPROC>(
      eglGetProcAddress("eglGetPlatformDisplayEXT"));
  if (get_platform_display == nullptr || !HasExtension(client, "EGL_EXT_platform_base")) {
    throw GpuError("EGL: EGL_EXT_platform_base missing: cannot open a headless display");
  }

  std::vector<Candidate> hardware, software, surfaceless;
  std::string tried;
  if (HasExtension(client, "EGL_EXT_platform_device") &&
      (HasExtension(client, "EGL_EXT_device_enumeration") ||
       HasExtension(client, "EGL_EXT_device_base"))) {
    auto query_devices =
        reinterpret_cast<PFNEGLQUERYDEVICESEXTPROC>(eglGetProcAddress("eglQueryDevicesEXT"));
    auto query_device_string = reinterpret_cast<PFNEGLQUERYDEVICESTRINGEXTPROC>(
        eglGetProcAddress("eglQueryDeviceStringEXT"));
    std::array<EGLDeviceEXT, 16> devices{};
    EGLint count = 0;
    if (query_devices &&
        query_devices(static_cast<EGLint>(devices.size()), devices.data(), &count)) {
      for (EGLint i = 0; i < count; ++i) {
        const char* ext =
            query_device_string ? query_device_string(devices[i], EGL_EXTENSIONS) : nullptr;
        const bool is_software = HasExtension(ext, "EGL_MESA_device_software");
        Candidate c{"EGL device " + std::to_string(i) + (is_software ? " (software)" : ""),
                    EGL_PLATFORM_DEVICE_EXT, devices[i], is_software};
        (is_software ? software : hardware).push_back(c);
      }
    } else {
      tried += "eglQueryDevicesEXT failed; ";
    }
  } else {
    tried += "no EGL_EXT_platform_device; ";
  }
  if (HasExtension(client, "EGL_MESA_platform_surfaceless")) {
    surfaceless.push_back(
        {"Mesa surfaceless platform", EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, true});
  }
  std::vector<Candidate> order = hardware;
  if (options.allow_software) {
    order.insert(order.end(), surfaceless.begin(), surfaceless.end());
    order.insert(order.end(), software.begin(), software.end());
  }
  if (order.empty()) {
    throw GpuError("EGL: no display to try (" + tried + std::to_string(hardware.size()) +
                   " hardware device(s), software " +
                   (options.allow_software ? "allowed" : "not allowed") + ")");
  }

  for (const Candidate& c : order) {
    EGLDisplay dpy = get_platform_display(c.platform, c.native, nullptr);
    if (dpy == EGL_NO_DISPLAY) {
      tried += c.label + ": no display (" + EglErrorName(eglGetError()) + "); ";
      continue;
    }
    EGLint major = 0, minor = 0;
    if (!eglInitialize(dpy, &major, &minor)) {
      tried += c.label + ": eglInitialize failed (" + EglErrorName(eglGetError()) + "); ";
      continue;
    }
    const auto fail = [&](const std::string& why) {
      tried += c.label + ": " + why + " (" + EglErrorName(eglGetError()) + "); ";
      eglTerminate(dpy);
    };
    const char* dpy_ext = eglQueryString(dpy, EGL_EXTENSIONS);
    if (!HasExtension(dpy_ext, "EGL_KHR_surfaceless_context")) {
      fail("no EGL_KHR_surfaceless_context");
      continue;
    }
    if (!eglBindAPI(EGL_OPENGL_ES_API)) {
      fail("eglBindAPI(OpenGL ES) failed");
      continue;
    }
    // No surface is ever made: any surface type will do (the default would demand windows).
    const EGLint config_attribs[] = {EGL_RENDERABLE_TYPE, EGL_OPENGL_ES3_BIT, EGL_SURFACE_TYPE, 0,
                                     EGL_NONE};
    EGLConfig config = nullptr;
    EGLint num_configs = 0;
    if (!eglChooseConfig(dpy, config_attribs, &config, 1, &num_configs) || num_configs < 1) {
      fail("no OpenGL ES 3 config");
      continue;
    }
    const EGLint context_attribs[] = {EGL_CONTEXT_MAJOR_VERSION, 3, EGL_CONTEXT_MINOR_VERSION, 1,
                                      EGL_NONE};
    EGLContext ctx = eglCreateContext(dpy, config, EGL_NO_CONTEXT, context_attribs);
    if (ctx == EGL_NO_CONTEXT) {
      fail("no OpenGL ES 3.1 context");
      continue;
    }
    if (!eglMakeCurrent(dpy, EGL_NO_SURFACE, EGL_NO_SURFACE, ctx)) {
      eglDestroyContext(dpy, ctx);
      fail("eglMakeCurrent without a surface failed");
      continue;
    }
    std::unique_ptr<EglContext> out(new EglContext());
    out->display_ = dpy;
    out->context_ = ctx;
    out->info_.platform = c.platform == EGL_PLATFORM_DEVICE_EXT ? "device" : "surfaceless";
    out->info_.vendor = GlString(GL_VENDOR);
    out->info_.renderer = GlString(GL_RENDERER);
    out->info_.version = GlString(GL_VERSION);
    GLint max_size = 0;
    glGetIntegerv(GL_MAX_TEXTURE_SIZE, &max_size);
    out->info_.max_texture_size = max_size;
    out->info_.software = c.software || out->info_.renderer.find("llvmpipe") != std::string::npos ||
                          out->info_.renderer.find("softpipe") != std::string::npos;
    return out;
  }
  throw GpuError("EGL: no OpenGL ES 3.1 context could be made; tried: " + tried);
}

bool EglContext::MakeCurrent() noexcept {
  return eglMakeCurrent(static_cast<EGLDisplay>(display_), EGL_NO_SURFACE, EGL_NO_SURFACE,
                        static_cast<EGLContext>(context_)) == EGL_TRUE;
}

EglContext::~EglContext() {
  auto dpy = static_cast<EGLDisplay>(display_);
  if (dpy == EGL_NO_DISPLAY) return;
  eglMakeCurrent(dpy, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
  if (context_ != nullptr) eglDestroyContext(dpy, static_cast<EGLContext>(context_));
  // No eglTerminate: the display handle is shared by every context made on the same device in
  // this process, and terminating it would break the others.
}

}  // namespace ht
