#pragma once
// A headless OpenGL ES 3.1+ context through EGL, without a window or a display server: the
// device platform (EGL_EXT_platform_device) on a real GPU, or Mesa's surfaceless platform
// (llvmpipe, the software rasterizer) where there is none. See DEPENDENCIES.md trap 3.

#include <memory>
#include <stdexcept>
#include <string>

namespace ht {

/// Thrown when no usable context can be made; the message says what was tried and what failed.
class GpuError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// How to choose the EGL display.
struct EglContextOptions {
  /// Accept a software renderer (llvmpipe) when no hardware device works. Default true.
  bool allow_software = true;
};

/// What the context runs on, as reported by EGL and GL at start.
struct GpuInfo {
  std::string platform;   ///< "device" or "surfaceless".
  std::string vendor;     ///< GL_VENDOR.
  std::string renderer;   ///< GL_RENDERER (e.g. "llvmpipe (LLVM 15.0.6, 256 bits)").
  std::string version;    ///< GL_VERSION (e.g. "OpenGL ES 3.2 Mesa 22.3.6").
  bool software = false;  ///< True for a software rasterizer (EGL_MESA_device_software, llvmpipe).
  int max_texture_size = 0;  ///< GL_MAX_TEXTURE_SIZE (texels).
};

/// An OpenGL ES 3.1+ context current on the creating thread, with no surface
/// (EGL_KHR_surfaceless_context). Order tried: EGL devices without EGL_MESA_device_software (real
/// GPUs), then Mesa's surfaceless platform, then software devices. Not copyable; the destructor
/// releases and destroys the context.
class EglContext {
 public:
  /// Creates the context and makes it current on this thread. Throws GpuError naming every
  /// display tried and why it failed (no EGL client extensions, no device, no ES 3.1, ...).
  static std::unique_ptr<EglContext> Create(const EglContextOptions& options = {});
  ~EglContext();
  EglContext(const EglContext&) = delete;
  EglContext& operator=(const EglContext&) = delete;

  const GpuInfo& info() const noexcept { return info_; }
  /// Makes the context current on the calling thread again; false when EGL refuses.
  bool MakeCurrent() noexcept;

 private:
  EglContext() = default;
  void* display_ = nullptr;  // EGLDisplay
  void* context_ = nullptr;  // EGLContext
  GpuInfo info_;
};

}  // namespace ht
