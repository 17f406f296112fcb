// The operator's display window (display_window.h): GLFW, one OpenGL ES 3.0 context, a texture
// and a full-viewport quad.
#include "master_station/display_window.h"

#include <EGL/egl.h>
#include <GLES3/gl3.h>

#include <algorithm>
#include <cstdlib>
#include <cstring>
#include <mutex>
#include <string>
#include <utility>

#define GLFW_INCLUDE_NONE  // GL comes from GLES3/gl3.h above, not GLFW's choice of header
#include <GLFW/glfw3.h>

namespace ht {
namespace {

constexpr int kMaxSize = 16384;

// Vertices 0..3 of a triangle strip covering the viewport; row 0 of the texture (the image's top)
// at the top of the viewport.
constexpr const char* kVertexShader = R"(#version 300 es
out highp vec2 uv;
void main() {
  vec2 p = vec2(float(gl_VertexID & 1), float(gl_VertexID >> 1));
  uv = vec2(p.x, 1.0 - p.y);
  gl_Position = vec4(2.0 * p - 1.0, 0.0, 1.0);
}
)";

constexpr const char* kFragmentShader = R"(#version 300 es
precision highp float;
in highp vec2 uv;
uniform sampler2D image;
out vec4 colour;
void main() { colour = vec4(texture(image, uv).rgb, 1.0); }
)";

bool Set(const char* name) {
  const char* v = std::getenv(name);
  return v != nullptr && v[0] != '\0';
}

std::string EnvText(const char* name) {
  const char* v = std::getenv(name);
  if (v == nullptr) return std::string(name) + " unset";
  return std::string(name) + "=\"" + v + "\"";
}

// GLFW's last error on this thread ("" when none), cleared.
std::string TakeGlfwError() {
  const char* description = nullptr;
  const int code = glfwGetError(&description);
  if (code == GLFW_NO_ERROR) return "";
  return description != nullptr ? description : "GLFW error " + std::to_string(code);
}

// libglvnd lets only one window-system API (EGL or GLX) have a context current on a thread, and
// the renderer's headless EGL context usually is: release it before the window's is made current.
void ReleaseCurrentEglContext() {
  if (eglGetCurrentContext() != EGL_NO_CONTEXT) {
    eglMakeCurrent(eglGetCurrentDisplay(), EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
  }
}

// glfwInit/glfwTerminate counted over the windows alive.
std::mutex glfw_mutex;
int glfw_users = 0;

void ReleaseGlfw() {
  std::lock_guard lock(glfw_mutex);
  if (--glfw_users == 0) glfwTerminate();
}

const char* kWhatToDo =
    "run it inside a desktop session (X11, or Wayland with XWayland), under xvfb-run, or with "
    "--display headless (PNG frames, no display server needed)";

GLuint Compile(GLenum type, const char* source, std::string* log) {
  const GLuint s = glCreateShader(type);
  glShaderSource(s, 1, &source, nullptr);
  glCompileShader(s);
  GLint ok = GL_FALSE;
  glGetShaderiv(s, GL_COMPILE_STATUS, &ok);
  if (ok != GL_TRUE) {
    char buffer[1024] = {};
    glGetShaderInfoLog(s, sizeof buffer, nullptr, buffer);
    *log += buffer;
    glDeleteShader(s);
    return 0;
  }
  return s;
}

}  // namespace

struct DisplayWindow::Impl {
  GLFWwindow* window = nullptr;
  GLuint program = 0;
  GLuint vao = 0;
  GLuint texture = 0;
  int texture_width = 0;
  int texture_height = 0;
  bool has_image = false;

  // Makes the window's context current on this thread, or throws.
  void Enter() {
    ReleaseCurrentEglContext();
    TakeGlfwError();
    glfwMakeContextCurrent(window);
    if (glfwGetCurrentContext() != window) {
      const std::string why = TakeGlfwError();
      glfwMakeContextCurrent(nullptr);
      throw DisplayWindowError(
          "display window: its OpenGL ES context cannot be made current on this thread (" +
          (why.empty() ? std::string("no reason given") : why) +
          "); is another GL context current here?");
    }
  }
  static void Leave() noexcept { glfwMakeContextCurrent(nullptr); }

  // Draws the last image letterboxed into the back buffer, whose size is fb_width x fb_height.
  void Draw(int fb_width, int fb_height) const {
    glBindFramebuffer(GL_FRAMEBUFFER, 0);
    glViewport(0, 0, fb_width, fb_height);
    glDisable(GL_DEPTH_TEST);
    glDisable(GL_BLEND);
    glDisable(GL_SCISSOR_TEST);
    glClearColor(0.f, 0.f, 0.f, 1.f);
    glClear(GL_COLOR_BUFFER_BIT);
    if (!has_image) return;
    // The largest viewport of the image's aspect ratio that fits, centred.
    const double scale = std::min(static_cast<double>(fb_width) / texture_width,
                                  static_cast<double>(fb_height) / texture_height);
    const int w = std::max(1, static_cast<int>(texture_width * scale + 0.5));
    const int h = std::max(1, static_cast<int>(texture_height * scale + 0.5));
    glViewport((fb_width - w) / 2, (fb_height - h) / 2, w, h);
    glUseProgram(program);
    glBindVertexArray(vao);
    glActiveTexture(GL_TEXTURE0);
    glBindTexture(GL_TEXTURE_2D, texture);
    glDrawArrays(GL_TRIANGLE_STRIP, 0, 4);
    glBindVertexArray(0);
  }

  // Frees the GL objects (context current) and the window; no context current afterwards.
  void Destroy() noexcept {
    if (window == nullptr) return;
    ReleaseCurrentEglContext();
    glfwMakeContextCurrent(window);
    if (glfwGetCurrentContext() == window) {
      if (texture != 0) glDeleteTextures(1, &texture);
      if (vao != 0) glDeleteVertexArrays(1, &vao);
      if (program != 0) glDeleteProgram(program);
    }
    glfwMakeContextCurrent(nullptr);
    glfwDestroyWindow(window);
    window = nullptr;
    texture = vao = program = 0;
    has_image = false;
  }
};

DisplayWindow::DisplayWindow() : impl_(std::make_unique<Impl>()) {}

DisplayWindow::~DisplayWindow() {
  if (impl_->window != nullptr) {
    impl_->Destroy();
    ReleaseGlfw();
  }
}

std::unique_ptr<DisplayWindow> DisplayWindow::Open(int width, int height,
                                                   const std::string& title) {
  if (width < 1 || width > kMaxSize || height < 1 || height > kMaxSize) {
    throw std::invalid_argument("display window: size " + std::to_string(width) + "x" +
                                std::to_string(height) + " outside [1, " +
                                std::to_string(kMaxSize) + "]");
  }
  if (!Set("DISPLAY") && !Set("WAYLAND_DISPLAY")) {
    throw DisplayWindowError(
        std::string("display window: no display server: neither DISPLAY nor WAYLAND_DISPLAY is "
                    "set; ") +
        kWhatToDo);
  }
  {
    std::lock_guard lock(glfw_mutex);
    if (glfw_users == 0) {
      TakeGlfwError();
      if (glfwInit() != GLFW_TRUE) {
        const std::string why = TakeGlfwError();
        throw DisplayWindowError("display window: GLFW (" + std::string(glfwGetVersionString()) +
                                 ") could not initialise: " + why + " (" + EnvText("DISPLAY") +
                                 ", " + EnvText("WAYLAND_DISPLAY") +
                                 "; this GLFW reaches Wayland only through XWayland's DISPLAY); " +
                                 kWhatToDo);
      }
    }
    ++glfw_users;
  }
  std::unique_ptr<DisplayWindow> out(new DisplayWindow());
  Impl& g = *out->impl_;

  // GLFW makes a new context current while it creates it: release the renderer's first.
  ReleaseCurrentEglContext();
  std::string tried;
  const std::pair<int, const char*> apis[] = {{GLFW_EGL_CONTEXT_API, "EGL"},
                                              {GLFW_NATIVE_CONTEXT_API, "GLX"}};
  for (const auto& [api, name] : apis) {
    glfwDefaultWindowHints();
    glfwWindowHint(GLFW_CLIENT_API, GLFW_OPENGL_ES_API);
    glfwWindowHint(GLFW_CONTEXT_CREATION_API, api);
    glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 3);
    glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 0);
    glfwWindowHint(GLFW_DEPTH_BITS, 0);
    glfwWindowHint(GLFW_STENCIL_BITS, 0);
    glfwWindowHint(GLFW_RESIZABLE, GLFW_TRUE);
    TakeGlfwError();
    g.window = glfwCreateWindow(width, height, title.c_str(), nullptr, nullptr);
    if (g.window != nullptr) break;
    tried += std::string(tried.empty() ? "" : "; ") + name + ": " + TakeGlfwError();
  }
  if (g.window == nullptr) {
    ReleaseGlfw();
    throw DisplayWindowError("display window: no window with an OpenGL ES 3.0 context on " +
                             EnvText("DISPLAY") + " (" + tried + "); " + kWhatToDo);
  }
  // From here on, ~DisplayWindow releases the window and GLFW.
  g.Enter();
  glfwSwapInterval(0);
  std::string log;
  const GLuint vs = Compile(GL_VERTEX_SHADER, kVertexShader, &log);
  const GLuint fs = Compile(GL_FRAGMENT_SHADER, kFragmentShader, &log);
  if (vs != 0 && fs != 0) {
    g.program = glCreateProgram();
    glAttachShader(g.program, vs);
    glAttachShader(g.program, fs);
    glLinkProgram(g.program);
    GLint ok = GL_FALSE;
    glGetProgramiv(g.program, GL_LINK_STATUS, &ok);
    if (ok != GL_TRUE) {
      char buffer[1024] = {};
      glGetProgramInfoLog(g.program, sizeof buffer, nullptr, buffer);
      log += buffer;
    }
  }
  if (vs != 0) glDeleteShader(vs);
  if (fs != 0) glDeleteShader(fs);
  if (!log.empty()) {
    Impl::Leave();
    throw DisplayWindowError("display window: its shaders do not build: " + log);
  }
  glUseProgram(g.program);
  glUniform1i(glGetUniformLocation(g.program, "image"), 0);
  glGenVertexArrays(1, &g.vao);
  glGenTextures(1, &g.texture);
  glBindTexture(GL_TEXTURE_2D, g.texture);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
  const GLenum error = glGetError();
  Impl::Leave();
  if (error != GL_NO_ERROR) {
    throw DisplayWindowError("display window: GL error " + std::to_string(error) +
                             " while setting up its texture");
  }
  return out;
}

bool DisplayWindow::Show(std::span<const std::uint8_t> rgba_top_down, int width, int height) {
  if (width < 1 || width > kMaxSize || height < 1 || height > kMaxSize) {
    throw std::invalid_argument("display window: image size " + std::to_string(width) + "x" +
                                std::to_string(height) + " outside [1, " +
                                std::to_string(kMaxSize) + "]");
  }
  const std::size_t expected = static_cast<std::size_t>(width) * height * 4;
  if (rgba_top_down.size() != expected) {
    throw std::invalid_argument("display window: " + std::to_string(rgba_top_down.size()) +
                                " bytes for a " + std::to_string(width) + "x" +
                                std::to_string(height) + " RGBA8 image (" +
                                std::to_string(expected) + " expected)");
  }
  if (closed_) return false;
  Impl& g = *impl_;
  glfwPollEvents();
  if (glfwWindowShouldClose(g.window)) {
    closed_ = true;
    g.Destroy();
    ReleaseGlfw();
    return false;
  }
  g.Enter();
  glActiveTexture(GL_TEXTURE0);
  glBindTexture(GL_TEXTURE_2D, g.texture);
  glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
  glPixelStorei(GL_UNPACK_ROW_LENGTH, 0);
  if (width != g.texture_width || height != g.texture_height) {
    glTexImage2D(GL_TEXTURE_2D, 0, GL_RGBA8, width, height, 0, GL_RGBA, GL_UNSIGNED_BYTE,
                 rgba_top_down.data());
    g.texture_width = width;
    g.texture_height = height;
  } else {
    glTexSubImage2D(GL_TEXTURE_2D, 0, 0, 0, width, height, GL_RGBA, GL_UNSIGNED_BYTE,
                    rgba_top_down.data());
  }
  g.has_image = true;
  int fb_width = 0, fb_height = 0;
  glfwGetFramebufferSize(g.window, &fb_width, &fb_height);
  if (fb_width > 0 && fb_height > 0) {  // 0 x 0 while minimised: nothing to draw
    g.Draw(fb_width, fb_height);
    glfwSwapBuffers(g.window);
  }
  Impl::Leave();
  return true;
}

std::vector<std::uint8_t> DisplayWindow::ReadBack(int* width, int* height) {
  if (width == nullptr || height == nullptr) {
    throw std::invalid_argument("display window: ReadBack needs width and height outputs");
  }
  *width = 0;
  *height = 0;
  if (closed_) return {};
  Impl& g = *impl_;
  int fb_width = 0, fb_height = 0;
  glfwGetFramebufferSize(g.window, &fb_width, &fb_height);
  if (fb_width <= 0 || fb_height <= 0) return {};
  g.Enter();
  g.Draw(fb_width, fb_height);
  std::vector<std::uint8_t> bottom_up(static_cast<std::size_t>(fb_width) * fb_height * 4);
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glReadPixels(0, 0, fb_width, fb_height, GL_RGBA, GL_UNSIGNED_BYTE, bottom_up.data());
  const GLenum error = glGetError();
  Impl::Leave();
  if (error != GL_NO_ERROR) {
    throw DisplayWindowError("display window: GL error " + std::to_string(error) +
                             " reading the window back");
  }
  const std::size_t row = static_cast<std::size_t>(fb_width) * 4;
  std::vector<std::uint8_t> top_down(bottom_up.size());
  for (int y = 0; y < fb_height; ++y) {
    std::memcpy(top_down.data() + row * y, bottom_up.data() + row * (fb_height - 1 - y), row);
  }
  *width = fb_width;
  *height = fb_height;
  return top_down;
}

}  // namespace ht
