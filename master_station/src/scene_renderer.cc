#include "master_station/scene_renderer.h"

#include <GLES3/gl31.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <glm/ext/matrix_clip_space.hpp>
#include <glm/ext/matrix_transform.hpp>
#include <glm/geometric.hpp>
#include <glm/gtc/type_ptr.hpp>
#include <glm/mat3x3.hpp>
#include <numbers>
#include <span>
#include <stdexcept>
#include <string>

#include "haptic_core/gl_program.h"
#include "master_station/png_image.h"
#include "render_geometry.h"

namespace ht {
namespace {

using render::AlongAxis;
using render::CameraFromWorld;
using render::CheckCamera;
using render::Finite;
using render::Projection;
using render::Str;
using render::UnitCone;
using render::UnitCylinder;
using render::UnitOctahedron;

// Who the GL helpers name in their errors.
constexpr const char* kWho = "scene renderer";
constexpr int kMaxSide = 4096;
constexpr std::size_t kMaxTriangles = std::size_t{1} << 24;
constexpr int kFloatsPerVertex = 8;                    // position_N 3, face normal_N 3, uv 2
constexpr int kMaxTextureSide = kMaxDecodedImageSide;  // what DecodeImage() gives at most

// Shading terms: items are lit fully, arrows and markers lightly so that their colour stays
// recognisable (shade in [0.7, 1]).
constexpr float kItemAmbient = 0.3f, kItemDiffuse = 0.7f;
constexpr float kArrowAmbient = 0.7f, kArrowDiffuse = 0.3f;
constexpr float kGhostAlpha = 0.3f;

// Arrow proportions (fractions of its length L) and screen-size floors (pixels at the arrow's
// point) so that short arrows and contact markers stay visible.
constexpr double kShaftRadius = 0.03, kHeadRadius = 0.08, kHeadLength = 0.25;
constexpr double kMinShaftRadiusPx = 1.5, kHeadOverShaft = 2.5, kMarkerRadiusPx = 3.0;

// Vertex stage: node frame N → camera frame C (X_CN computed in double on the CPU), face normal
// by the cofactor of X_CN's linear part (the inverse transpose up to a positive scale when
// det > 0; the sign does not matter, lighting is two-sided).
constexpr const char* kVertexShader = R"(#version 300 es
precision highp float;
layout(location = 0) in vec3 a_position_N;
layout(location = 1) in vec3 a_normal_N;
layout(location = 2) in vec2 a_uv;
uniform mat4 u_X_CN;
uniform mat3 u_normal_CN;
uniform mat4 u_projection;
out vec3 v_position_C;
flat out vec3 v_normal_C;
out vec2 v_uv;
invariant gl_Position;  // the same depth in a translucent item's depth and colour passes
void main() {
  vec4 p_C = u_X_CN * vec4(a_position_N, 1.0);
  v_position_C = p_C.xyz;
  v_normal_C = u_normal_CN * a_normal_N;
  v_uv = a_uv;
  gl_Position = u_projection * p_C;
}
)";

// Fragment stage: headlight at the eye plus ambient, two-sided Lambert on the flat normal, times
// the base colour: u_colour, times the texel when textured (an sRGB texture: the sampled value
// is linear). The texel's alpha is ignored (glTF alphaMode OPAQUE).
constexpr const char* kFragmentShader = R"(#version 300 es
precision highp float;
uniform vec4 u_colour;
uniform float u_ambient;
uniform float u_diffuse;
uniform bool u_textured;
uniform sampler2D u_texture;
in vec3 v_position_C;
flat in vec3 v_normal_C;
in vec2 v_uv;
out vec4 o_colour;
void main() {
  float len = length(v_normal_C);
  float lambert = 1.0;
  if (len > 0.0) lambert = abs(dot(v_normal_C / len, normalize(-v_position_C)));
  float shade = u_ambient + u_diffuse * lambert;
  vec3 base = u_colour.rgb;
  if (u_textured) base *= texture(u_texture, v_uv).rgb;
  o_colour = vec4(clamp(base * shade, 0.0, 1.0), u_colour.a);
}
)";

void ThrowOnGlError(const char* where) {
  if (const std::string e = gl::DrainGlErrors(); !e.empty()) {
    throw GpuError(std::string("scene renderer: ") + where + ": " + e);
  }
}

GLuint BuildProgram() {
  const GLuint vs = gl::CompileShader(GL_VERTEX_SHADER, kVertexShader, kWho, "vertex shader");
  GLuint fs = 0;
  try {
    fs = gl::CompileShader(GL_FRAGMENT_SHADER, kFragmentShader, kWho, "fragment shader");
  } catch (...) {
    glDeleteShader(vs);
    throw;
  }
  return gl::LinkProgram({vs, fs}, kWho, "shader program");
}

}  // namespace

struct SceneRenderer::Impl {
  struct GpuMesh {
    GLuint vao = 0;
    GLuint vbo = 0;
    GLsizei vertices = 0;
    glm::dvec3 centre_N{0.0};  // bounding-box centre, for back-to-front order
    bool has_uv = false;
  };
  struct Translucent {
    const RenderItem* item;
    float alpha;
    double depth_C;  // z of the mesh centre in C (more negative: farther)
  };

  // Declared first: destroyed last, after ~Impl has deleted the GL objects.
  std::unique_ptr<EglContext> context;
  GLuint program = 0;
  GLuint fbo = 0;
  GLuint colour_rb = 0;
  GLuint depth_rb = 0;
  GLint u_X_CN = -1, u_normal_CN = -1, u_projection = -1, u_colour = -1, u_ambient = -1,
        u_diffuse = -1, u_textured = -1, u_texture = -1;
  std::vector<GpuMesh> meshes;   // user meshes, by AddMesh index
  std::vector<GLuint> textures;  // by AddTexture index
  GpuMesh cylinder, cone, octahedron;
  std::vector<std::uint8_t> bottom_up;  // glReadPixels' rows, bottom first
  std::vector<Translucent> translucent;
  std::vector<float> upload;

  ~Impl() {
    if (!context || !context->MakeCurrent()) return;  // eglDestroyContext frees them then
    for (GpuMesh* m : {&cylinder, &cone, &octahedron}) Free(*m);
    for (GpuMesh& m : meshes) Free(m);
    if (!textures.empty()) glDeleteTextures(static_cast<GLsizei>(textures.size()), textures.data());
    glDeleteFramebuffers(1, &fbo);
    glDeleteRenderbuffers(1, &colour_rb);
    glDeleteRenderbuffers(1, &depth_rb);
    glDeleteProgram(program);
  }

  static void Free(GpuMesh& m) {
    glDeleteVertexArrays(1, &m.vao);
    glDeleteBuffers(1, &m.vbo);
    m = {};
  }

  void MakeCurrent() {
    if (!context->MakeCurrent()) {
      throw GpuError(
          "scene renderer: its EGL context cannot be made current on this thread (is it current "
          "on another thread? use the renderer on the thread that created it)");
    }
  }

  // Validates `mesh`, un-indexes it with face normals into `upload`, and uploads it into `gpu`
  // (creating its buffers on first use). `gpu` is unchanged when validation fails.
  void Upload(const RenderMesh& mesh, GpuMesh& gpu) {
    const std::size_t nv = mesh.positions_N.size();
    const bool has_uv = !mesh.uv.empty();
    if (has_uv && mesh.uv.size() != nv) {
      throw std::invalid_argument("render mesh: " + std::to_string(mesh.uv.size()) +
                                  " texture coordinates for " + std::to_string(nv) +
                                  " positions (need one per position, or none)");
    }
    for (std::size_t i = 0; i < mesh.uv.size(); ++i) {
      if (!std::isfinite(mesh.uv[i].x) || !std::isfinite(mesh.uv[i].y)) {
        throw std::invalid_argument("render mesh: texture coordinate " + std::to_string(i) +
                                    " is not finite");
      }
    }
    if (mesh.triangles.size() > kMaxTriangles) {
      throw std::invalid_argument("render mesh: " + std::to_string(mesh.triangles.size()) +
                                  " triangles, at most " + std::to_string(kMaxTriangles));
    }
    glm::dvec3 lo(0.0), hi(0.0);
    for (std::size_t i = 0; i < nv; ++i) {
      const glm::dvec3 p(mesh.positions_N[i]);
      if (!Finite(p)) {
        throw std::invalid_argument("render mesh: position " + std::to_string(i) + " is " + Str(p) +
                                    ", not finite");
      }
      lo = i == 0 ? p : glm::min(lo, p);
      hi = i == 0 ? p : glm::max(hi, p);
    }
    upload.clear();
    upload.reserve(mesh.triangles.size() * 3 * kFloatsPerVertex);
    for (std::size_t t = 0; t < mesh.triangles.size(); ++t) {
      const glm::uvec3& tri = mesh.triangles[t];
      for (int k = 0; k < 3; ++k) {
        if (tri[k] >= nv) {
          throw std::invalid_argument("render mesh: triangle " + std::to_string(t) +
                                      " names vertex " + std::to_string(tri[k]) + " of " +
                                      std::to_string(nv));
        }
      }
      const glm::dvec3 a(mesh.positions_N[tri[0]]), b(mesh.positions_N[tri[1]]),
          c(mesh.positions_N[tri[2]]);
      const glm::dvec3 n = glm::cross(b - a, c - a);
      const double len = glm::length(n);
      if (!(len > 0.0)) continue;  // zero area: draws nothing
      const glm::vec3 n_N(n / len);
      for (int k = 0; k < 3; ++k) {
        const glm::vec3& p = mesh.positions_N[tri[k]];
        const glm::vec2 uv = has_uv ? mesh.uv[tri[k]] : glm::vec2(0.0f);
        upload.insert(upload.end(), {p.x, p.y, p.z, n_N.x, n_N.y, n_N.z, uv.x, uv.y});
      }
    }
    if (gpu.vao == 0) {
      glGenVertexArrays(1, &gpu.vao);
      glGenBuffers(1, &gpu.vbo);
      glBindVertexArray(gpu.vao);
      glBindBuffer(GL_ARRAY_BUFFER, gpu.vbo);
      const GLsizei stride = kFloatsPerVertex * sizeof(float);
      glEnableVertexAttribArray(0);
      glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, stride, nullptr);
      glEnableVertexAttribArray(1);
      glVertexAttribPointer(1, 3, GL_FLOAT, GL_FALSE, stride,
                            reinterpret_cast<const void*>(3 * sizeof(float)));
      glEnableVertexAttribArray(2);
      glVertexAttribPointer(2, 2, GL_FLOAT, GL_FALSE, stride,
                            reinterpret_cast<const void*>(6 * sizeof(float)));
      glBindVertexArray(0);
    }
    glBindBuffer(GL_ARRAY_BUFFER, gpu.vbo);
    glBufferData(GL_ARRAY_BUFFER, static_cast<GLsizeiptr>(upload.size() * sizeof(float)),
                 upload.empty() ? nullptr : upload.data(), GL_STATIC_DRAW);
    glBindBuffer(GL_ARRAY_BUFFER, 0);
    ThrowOnGlError("mesh upload");
    gpu.vertices = static_cast<GLsizei>(upload.size() / kFloatsPerVertex);
    gpu.centre_N = 0.5 * (lo + hi);
    gpu.has_uv = has_uv;
  }

  // The GL texture item `item` is drawn with on `mesh`: 0 for none (no texture, or no uv).
  GLuint TextureOf(const RenderItem& item, const GpuMesh& mesh) const {
    return item.texture >= 0 && mesh.has_uv ? textures[static_cast<std::size_t>(item.texture)] : 0;
  }

  void Draw(const GpuMesh& m, const glm::dmat4& X_CN, const glm::vec4& colour, float ambient,
            float diffuse, GLuint texture = 0) {
    if (m.vertices == 0) return;
    glUniform1i(u_textured, texture != 0 ? 1 : 0);
    if (texture != 0) glBindTexture(GL_TEXTURE_2D, texture);
    const glm::dvec3 a(X_CN[0]), b(X_CN[1]), c(X_CN[2]);
    const glm::mat3 normal_CN(glm::dmat3(glm::cross(b, c), glm::cross(c, a), glm::cross(a, b)));
    const glm::mat4 X(X_CN);
    glUniformMatrix4fv(u_X_CN, 1, GL_FALSE, glm::value_ptr(X));
    glUniformMatrix3fv(u_normal_CN, 1, GL_FALSE, glm::value_ptr(normal_CN));
    glUniform4fv(u_colour, 1, glm::value_ptr(colour));
    glUniform1f(u_ambient, ambient);
    glUniform1f(u_diffuse, diffuse);
    glBindVertexArray(m.vao);
    glDrawArrays(GL_TRIANGLES, 0, m.vertices);
  }
};

SceneRenderer::SceneRenderer(int width, int height) : width_(width), height_(height) {}

SceneRenderer::~SceneRenderer() = default;

const GpuInfo& SceneRenderer::gpu() const noexcept { return impl_->context->info(); }

std::unique_ptr<SceneRenderer> SceneRenderer::Create(int width, int height,
                                                     ColourEncoding encoding) {
  if (width < 1 || width > kMaxSide || height < 1 || height > kMaxSide) {
    throw std::invalid_argument("scene renderer: image size must be in [1, " +
                                std::to_string(kMaxSide) + "] each, got " + std::to_string(width) +
                                " x " + std::to_string(height));
  }
  std::unique_ptr<SceneRenderer> r(new SceneRenderer(width, height));
  r->impl_ = std::make_unique<Impl>();
  Impl& g = *r->impl_;
  g.context = EglContext::Create();
  GLint max_rb = 0;
  glGetIntegerv(GL_MAX_RENDERBUFFER_SIZE, &max_rb);
  if (width > max_rb || height > max_rb) {
    throw GpuError("scene renderer: " + std::to_string(width) + " x " + std::to_string(height) +
                   " exceeds GL_MAX_RENDERBUFFER_SIZE " + std::to_string(max_rb) + " of " +
                   g.context->info().renderer);
  }
  glGenRenderbuffers(1, &g.colour_rb);
  glBindRenderbuffer(GL_RENDERBUFFER, g.colour_rb);
  // An sRGB colour buffer encodes on write and blends in linear (OpenGL ES 3.0 §4.1.8);
  // glReadPixels returns its stored (encoded) bytes.
  glRenderbufferStorage(GL_RENDERBUFFER,
                        encoding == ColourEncoding::kSrgb ? GL_SRGB8_ALPHA8 : GL_RGBA8, width,
                        height);
  glGenRenderbuffers(1, &g.depth_rb);
  glBindRenderbuffer(GL_RENDERBUFFER, g.depth_rb);
  glRenderbufferStorage(GL_RENDERBUFFER, GL_DEPTH_COMPONENT24, width, height);
  glBindRenderbuffer(GL_RENDERBUFFER, 0);
  glGenFramebuffers(1, &g.fbo);
  glBindFramebuffer(GL_FRAMEBUFFER, g.fbo);
  glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, g.colour_rb);
  glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, g.depth_rb);
  if (const GLenum status = glCheckFramebufferStatus(GL_FRAMEBUFFER);
      status != GL_FRAMEBUFFER_COMPLETE) {
    throw GpuError(std::string("scene renderer: ") +
                   (encoding == ColourEncoding::kSrgb ? "SRGB8_ALPHA8" : "RGBA8") +
                   " + depth24 framebuffer incomplete (status " + std::to_string(status) + ") on " +
                   g.context->info().renderer);
  }
  g.program = BuildProgram();
  g.u_X_CN = glGetUniformLocation(g.program, "u_X_CN");
  g.u_normal_CN = glGetUniformLocation(g.program, "u_normal_CN");
  g.u_projection = glGetUniformLocation(g.program, "u_projection");
  g.u_colour = glGetUniformLocation(g.program, "u_colour");
  g.u_ambient = glGetUniformLocation(g.program, "u_ambient");
  g.u_diffuse = glGetUniformLocation(g.program, "u_diffuse");
  g.u_textured = glGetUniformLocation(g.program, "u_textured");
  g.u_texture = glGetUniformLocation(g.program, "u_texture");
  glUseProgram(g.program);
  glUniform1i(g.u_texture, 0);  // texture unit 0, the only one used
  glUseProgram(0);
  g.Upload(UnitCylinder(), g.cylinder);
  g.Upload(UnitCone(), g.cone);
  g.Upload(UnitOctahedron(), g.octahedron);
  g.bottom_up.resize(static_cast<std::size_t>(width) * height * 4);
  ThrowOnGlError("set-up");
  return r;
}

int SceneRenderer::AddMesh(const RenderMesh& mesh) {
  Impl& g = *impl_;
  g.MakeCurrent();
  Impl::GpuMesh gpu;
  try {
    g.Upload(mesh, gpu);
  } catch (...) {
    Impl::Free(gpu);
    throw;
  }
  g.meshes.push_back(gpu);
  return static_cast<int>(g.meshes.size()) - 1;
}

int SceneRenderer::AddTexture(std::span<const std::uint8_t> rgba_top_down, int width, int height) {
  Impl& g = *impl_;
  if (width < 1 || height < 1 || width > kMaxTextureSide || height > kMaxTextureSide) {
    throw std::invalid_argument("scene renderer: texture size must be in [1, " +
                                std::to_string(kMaxTextureSide) + "] each, got " +
                                std::to_string(width) + " x " + std::to_string(height));
  }
  const std::size_t expected =
      static_cast<std::size_t>(width) * static_cast<std::size_t>(height) * 4;
  if (rgba_top_down.size() != expected) {
    throw std::invalid_argument("scene renderer: a " + std::to_string(width) + " x " +
                                std::to_string(height) + " RGBA8 texture needs " +
                                std::to_string(expected) + " bytes, got " +
                                std::to_string(rgba_top_down.size()));
  }
  g.MakeCurrent();
  GLint max_size = 0;
  glGetIntegerv(GL_MAX_TEXTURE_SIZE, &max_size);
  if (width > max_size || height > max_size) {
    throw GpuError("scene renderer: a " + std::to_string(width) + " x " + std::to_string(height) +
                   " texture exceeds GL_MAX_TEXTURE_SIZE " + std::to_string(max_size) + " of " +
                   g.context->info().renderer);
  }
  int levels = 1;
  while ((std::max(width, height) >> levels) > 0) ++levels;
  GLuint texture = 0;
  glGenTextures(1, &texture);
  glBindTexture(GL_TEXTURE_2D, texture);
  // Row 0 of the image (its top) is GL's t = 0, which is glTF's v = 0: no flip.
  glTexStorage2D(GL_TEXTURE_2D, levels, GL_SRGB8_ALPHA8, width, height);
  glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
  glTexSubImage2D(GL_TEXTURE_2D, 0, 0, 0, width, height, GL_RGBA, GL_UNSIGNED_BYTE,
                  rgba_top_down.data());
  glGenerateMipmap(GL_TEXTURE_2D);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_LINEAR_MIPMAP_LINEAR);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_REPEAT);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_REPEAT);
  glBindTexture(GL_TEXTURE_2D, 0);
  if (const std::string e = gl::DrainGlErrors(); !e.empty()) {
    glDeleteTextures(1, &texture);
    throw GpuError("scene renderer: texture upload: " + e);
  }
  g.textures.push_back(texture);
  return static_cast<int>(g.textures.size()) - 1;
}

void SceneRenderer::ReplaceMesh(int index, const RenderMesh& mesh) {
  Impl& g = *impl_;
  if (index < 0 || index >= static_cast<int>(g.meshes.size())) {
    throw std::invalid_argument("scene renderer: ReplaceMesh of mesh " + std::to_string(index) +
                                ", but " + std::to_string(g.meshes.size()) + " were added");
  }
  g.MakeCurrent();
  g.Upload(mesh, g.meshes[static_cast<std::size_t>(index)]);
}

void SceneRenderer::Render(const RenderFrame& frame, std::vector<std::uint8_t>* rgba_top_down) {
  Impl& g = *impl_;
  // Validate everything before touching GL, so that a bad frame draws nothing.
  if (rgba_top_down == nullptr) throw std::invalid_argument("scene renderer: null output image");
  CheckCamera(frame.camera);
  if (!(frame.arrow_m_per_n >= 0.0 && std::isfinite(frame.arrow_m_per_n))) {
    throw std::invalid_argument("scene renderer: arrow_m_per_n must be finite and >= 0, got " +
                                std::to_string(frame.arrow_m_per_n));
  }
  if (!Finite(frame.background_rgba)) {
    throw std::invalid_argument("scene renderer: background colour is not finite");
  }
  for (std::size_t i = 0; i < frame.items.size(); ++i) {
    const RenderItem& item = frame.items[i];
    if (item.mesh < 0 || item.mesh >= static_cast<int>(g.meshes.size())) {
      throw std::invalid_argument("scene renderer: item " + std::to_string(i) + " names mesh " +
                                  std::to_string(item.mesh) + ", but " +
                                  std::to_string(g.meshes.size()) + " were added");
    }
    if (item.texture < -1 || item.texture >= static_cast<int>(g.textures.size())) {
      throw std::invalid_argument("scene renderer: item " + std::to_string(i) + " names texture " +
                                  std::to_string(item.texture) + ", but " +
                                  std::to_string(g.textures.size()) + " were added (-1: none)");
    }
    if (!Finite(item.X_WN) || !Finite(item.colour_rgba)) {
      throw std::invalid_argument("scene renderer: item " + std::to_string(i) +
                                  " has a non-finite pose or colour");
    }
  }
  for (std::size_t i = 0; i < frame.arrows.size(); ++i) {
    if (!Finite(frame.arrows[i].point_W) || !Finite(frame.arrows[i].force_W)) {
      throw std::invalid_argument("scene renderer: arrow " + std::to_string(i) + " at " +
                                  Str(frame.arrows[i].point_W) + " with force " +
                                  Str(frame.arrows[i].force_W) + " is not finite");
    }
  }

  g.MakeCurrent();
  const RenderCamera& cam = frame.camera;
  const glm::dmat4 X_CW = CameraFromWorld(cam);
  const glm::mat4 projection(Projection(cam, width_, height_));
  // Size of one pixel (m) at distance `depth` in front of the eye.
  const double pixel_per_depth = 2.0 * std::tan(0.5 * cam.yfov_rad) / height_;

  glBindFramebuffer(GL_FRAMEBUFFER, g.fbo);
  glViewport(0, 0, width_, height_);
  const glm::vec4 bg = glm::clamp(frame.background_rgba, 0.0f, 1.0f);
  glClearColor(bg.r, bg.g, bg.b, bg.a);
  glClearDepthf(1.0f);
  glDepthMask(GL_TRUE);
  glColorMask(GL_TRUE, GL_TRUE, GL_TRUE, GL_TRUE);
  glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LESS);
  glDisable(GL_CULL_FACE);
  glDisable(GL_BLEND);
  glUseProgram(g.program);
  glUniformMatrix4fv(g.u_projection, 1, GL_FALSE, glm::value_ptr(projection));
  glActiveTexture(GL_TEXTURE0);

  // 1. Opaque items; translucent ones are kept for the last pass.
  g.translucent.clear();
  for (const RenderItem& item : frame.items) {
    const Impl::GpuMesh& mesh = g.meshes[static_cast<std::size_t>(item.mesh)];
    const glm::dmat4 X_CN = X_CW * item.X_WN;
    glm::vec4 colour = glm::clamp(item.colour_rgba, 0.0f, 1.0f);
    if (item.ghost) colour.a *= kGhostAlpha;
    if (colour.a >= 1.0f) {
      g.Draw(mesh, X_CN, colour, kItemAmbient, kItemDiffuse, g.TextureOf(item, mesh));
    } else if (colour.a > 0.0f) {
      g.translucent.push_back({&item, colour.a, (X_CN * glm::dvec4(mesh.centre_N, 1.0)).z});
    }
  }

  // 2. Translucent items, farthest first, depth-tested against everything opaque. Each writes
  // depth in a depth-only pass before its colour pass (one blended layer per pixel); that depth
  // hides only translucent items drawn after it, which are nearer (sorted), except where
  // translucent items interpenetrate.
  if (!g.translucent.empty()) {
    std::stable_sort(g.translucent.begin(), g.translucent.end(),
                     [](const Impl::Translucent& a, const Impl::Translucent& b) {
                       return a.depth_C < b.depth_C;
                     });
    glBlendFuncSeparate(GL_SRC_ALPHA, GL_ONE_MINUS_SRC_ALPHA, GL_ONE, GL_ONE_MINUS_SRC_ALPHA);
    glDepthFunc(GL_LEQUAL);
    for (const Impl::Translucent& t : g.translucent) {
      const Impl::GpuMesh& mesh = g.meshes[static_cast<std::size_t>(t.item->mesh)];
      const glm::dmat4 X_CN = X_CW * t.item->X_WN;
      glm::vec4 colour = glm::clamp(t.item->colour_rgba, 0.0f, 1.0f);
      colour.a = t.alpha;
      // Depth only first, so that the colour pass blends each pixel once, with the item's nearest
      // surface (else a closed mesh blends its back and front layers, twice as opaque).
      glDisable(GL_BLEND);
      glColorMask(GL_FALSE, GL_FALSE, GL_FALSE, GL_FALSE);
      glDepthMask(GL_TRUE);
      g.Draw(mesh, X_CN, colour, kItemAmbient, kItemDiffuse);
      glEnable(GL_BLEND);
      glColorMask(GL_TRUE, GL_TRUE, GL_TRUE, GL_TRUE);
      glDepthMask(GL_FALSE);
      g.Draw(mesh, X_CN, colour, kItemAmbient, kItemDiffuse, g.TextureOf(*t.item, mesh));
    }
    glDepthMask(GL_TRUE);
    glDisable(GL_BLEND);
    glDepthFunc(GL_LESS);
  }
  // 3. Arrows (shaft + cone) and a contact marker at each point of application, over everything
  // drawn so far (the depth buffer is cleared first, so that an arrow inside the tool or under a
  // ghost still shows; arrows still hide one another by depth).
  glClear(GL_DEPTH_BUFFER_BIT);
  for (const RenderArrow& arrow : frame.arrows) {
    const double depth = std::max(-(X_CW * glm::dvec4(arrow.point_W, 1.0)).z, cam.near_m);
    const double pixel_m = depth * pixel_per_depth;
    const double marker = kMarkerRadiusPx * pixel_m;
    g.Draw(g.octahedron, X_CW * AlongAxis(arrow.point_W, {0, 0, 1}, marker, marker),
           kForceArrowColour, kArrowAmbient, kArrowDiffuse);
    const double force = glm::length(arrow.force_W);
    const double length = force * frame.arrow_m_per_n;
    if (!(length > 0.0) || !std::isfinite(length)) continue;
    const glm::dvec3 axis_W = arrow.force_W / force;
    const double shaft_radius = std::max(kShaftRadius * length, kMinShaftRadiusPx * pixel_m);
    const double head_radius = std::max(kHeadRadius * length, kHeadOverShaft * shaft_radius);
    const double head_length = kHeadLength * length;
    const double shaft_length = length - head_length;
    g.Draw(g.cylinder, X_CW * AlongAxis(arrow.point_W, axis_W, shaft_length, shaft_radius),
           kForceArrowColour, kArrowAmbient, kArrowDiffuse);
    g.Draw(
        g.cone,
        X_CW * AlongAxis(arrow.point_W + shaft_length * axis_W, axis_W, head_length, head_radius),
        kForceArrowColour, kArrowAmbient, kArrowDiffuse);
  }

  glBindVertexArray(0);
  glBindTexture(GL_TEXTURE_2D, 0);

  // 4. Read back (GL's row 0 is the bottom) and flip to top-down.
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glReadPixels(0, 0, width_, height_, GL_RGBA, GL_UNSIGNED_BYTE, g.bottom_up.data());
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
  ThrowOnGlError("render");
  const std::size_t row = static_cast<std::size_t>(width_) * 4;
  rgba_top_down->resize(row * static_cast<std::size_t>(height_));
  for (int j = 0; j < height_; ++j) {
    std::memcpy(rgba_top_down->data() + row * static_cast<std::size_t>(j),
                g.bottom_up.data() + row * static_cast<std::size_t>(height_ - 1 - j), row);
  }
}

}  // namespace ht
