#pragma once
// What `master_station --display window` shows: a window on a display server (X11, or Wayland
// through XWayland: Debian 12's libglfw3 is built for X11 only) that presents each RGBA8 frame
// the SceneRenderer produced, scaled to the window, until the operator closes it. GLFW makes the
// window and an OpenGL ES 3.0 context for it (through EGL where that works, else GLX).
//
// Contexts on the display thread: the SceneRenderer's headless EGL context lives on the same
// thread. libglvnd refuses to make a GLX context current while an EGL one is (and the other way
// round), so every call here that needs the window's context first releases whatever EGL context
// is current on the thread, and leaves no context current when it returns. The renderer makes
// its own context current again at the start of each call (SceneRenderer::Render does), so the
// two simply alternate: nothing has to be restored.

#include <cstdint>
#include <memory>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

namespace ht {

/// Thrown when no window can be opened or drawn into: no display server (neither DISPLAY nor
/// WAYLAND_DISPLAY set, or set to one that cannot be reached), GLFW failing to initialise, or no
/// OpenGL ES 3 context for the window. The message says what was tried and what to do instead
/// (e.g. run with `--display headless`, or under `xvfb-run`).
class DisplayWindowError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// A window that shows RGBA8 images, each scaled to fill the window while keeping its aspect
/// ratio (black bars where the window's shape differs; linear filtering; 1:1 when the window's
/// framebuffer has the image's size). No vertical-sync wait: the caller paces the frames.
///
/// Threading: create, use and destroy it on one thread (the display thread), the same one for
/// every DisplayWindow alive in the process: GLFW's events and window calls are not thread-safe
/// (GLFW asks for the main thread; on X11, the only platform here, any one thread works). Not for
/// the 1 kHz loop: Show uploads and draws (milliseconds). Open, Show, ReadBack and the destructor
/// each leave no GL context current on the calling thread (they release a current EGL context,
/// such as SceneRenderer's, before using the window's); the caller makes its own current again.
class DisplayWindow {
 public:
  /// Opens a `width` x `height` window (screen coordinates, i.e. pixels without display scaling)
  /// titled `title` on the display server named by DISPLAY (or WAYLAND_DISPLAY; an empty value
  /// counts as unset), with its own OpenGL ES 3.0 context: GLFW's EGL context API first, then the
  /// native one (GLX). Throws std::invalid_argument when width or height is outside [1, 16384];
  /// DisplayWindowError when neither DISPLAY nor WAYLAND_DISPLAY is set, when GLFW cannot
  /// initialise (e.g. the X server cannot be reached), or when no window with an OpenGL ES 3
  /// context can be made (the message lists each attempt and GLFW's reason).
  static std::unique_ptr<DisplayWindow> Open(int width, int height, const std::string& title);
  /// Destroys the window and its context (no context is current afterwards); the last window
  /// alive terminates GLFW.
  ~DisplayWindow();
  DisplayWindow(const DisplayWindow&) = delete;
  DisplayWindow& operator=(const DisplayWindow&) = delete;

  /// Processes the window's pending events, then uploads `rgba_top_down` (RGBA8, row 0 the top of
  /// the image, width·height·4 bytes; `width` x `height` are the image's size in pixels, not
  /// necessarily the window's) and presents it scaled to the window (alpha ignored: the window
  /// is opaque). Returns true when shown; false once the operator has closed the window (the
  /// window is then destroyed and every later call returns false at once). Throws
  /// std::invalid_argument, before anything else, when width or height is outside [1, 16384] or
  /// the span's size is not width·height·4; DisplayWindowError when the window's context cannot
  /// be made current (e.g. a GLX context of someone else's is current on this thread).
  bool Show(std::span<const std::uint8_t> rgba_top_down, int width, int height);

  /// True once the operator has closed the window (seen by Show's event processing).
  bool closed() const noexcept { return closed_; }

  /// What the window shows now, for tests: the last image shown, drawn again (not presented) into
  /// the window's back buffer and read back. RGBA8, row 0 the top, alpha 255; *width x *height is
  /// the window's framebuffer size in pixels (the window's size without display scaling; 0 x 0,
  /// and an empty result, when the window is closed or minimised). Black before the first Show.
  /// Throws std::invalid_argument for a null width or height, DisplayWindowError as Show.
  std::vector<std::uint8_t> ReadBack(int* width, int* height);

 private:
  struct Impl;
  DisplayWindow();
  std::unique_ptr<Impl> impl_;
  bool closed_ = false;
};

}  // namespace ht
