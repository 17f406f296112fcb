#include "haptic_core/gpu_penetration_depth.h"

#include <GLES3/gl31.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <glm/geometric.hpp>
#include <glm/gtc/quaternion.hpp>
#include <limits>
#include <stdexcept>
#include <string>

namespace ht {
namespace {

// Heights h (m, along n, relative to the window centre) are stored as depth z = 0.5 + h/(2R'),
// R' = R·(1 + 1/1024) with R the window's depth range, so that every stored sample lies strictly
// inside (0, 1): the clear values 0 (environment) and 1 (tool) mark empty cells.
constexpr double kRangeSlack = 1.0 + 1.0 / 1024.0;
constexpr int kFloatsPerCorner = 12;  // position 3, normal 3, face normal 3, uv 2, texel size 1

// Vertex stages. Both take a corner from object frame O to the window frame (u, v, n) with
// rows (xyz: the axis in O; w: axis·(p_WO − c_W)) and pass the fragment stage its height,
// texture coordinates, mip level, interpolated normal and n; triangles that do not face the other
// side are moved outside the clip volume (all three corners share the face normal). This part,
// after "#version 310 es" and any extension line, is shared.
constexpr const char* kVertexCommon = R"(
precision highp float;
precision highp int;
layout(location = 0) in vec3 a_position_O;
layout(location = 1) in vec3 a_normal_O;
layout(location = 2) in vec3 a_face_normal_O;
layout(location = 3) in vec2 a_uv;
layout(location = 4) in float a_texel_size;  // < 0: smooth face (no texture)
uniform float u_half_extent;  // W/2 (m)
uniform float u_cell_size;    // W/N (m)
uniform float u_facing_sign;  // +1 environment B, −1 tool A
uniform int u_num_levels;
out vec2 v_uv;
out float v_height;
out vec3 v_normal_O;  // interpolated corner normal (renormalized per fragment)
flat out int v_level;
flat out vec3 v_row_n;  // n in O, for the fragment's N·n
// The corner's window coordinates over W/2 (the window spans [−1, 1]²) in xy; false where its
// triangle does not face the other side.
bool ProjectCorner(vec4 row_u, vec4 row_v, vec4 row_n, out vec2 xy) {
  v_row_n = row_n.xyz;
  float facing = u_facing_sign * dot(a_face_normal_O, row_n.xyz);
  float s = dot(row_u.xyz, a_position_O) + row_u.w;
  float t = dot(row_v.xyz, a_position_O) + row_v.w;
  v_height = dot(row_n.xyz, a_position_O) + row_n.w;
  v_normal_O = a_normal_O;
  v_uv = a_uv;
  int level = -1;
  if (a_texel_size >= 0.0) {
    level = 0;
    if (a_texel_size > 0.0 && u_cell_size > a_texel_size) {
      level = clamp(int(floor(log2(u_cell_size / a_texel_size))), 0, u_num_levels - 1);
    }
  }
  v_level = level;
  xy = vec2(s / u_half_extent, t / u_half_extent);
  return facing > 0.05;
}
)";

// One draw per render: per-draw rows; the viewport is the render's tile.
constexpr const char* kRenderVertexMain = R"(
uniform vec4 u_row_u;
uniform vec4 u_row_v;
uniform vec4 u_row_n;
void main() {
  vec2 xy;
  bool faces = ProjectCorner(u_row_u, u_row_v, u_row_n, xy);
  gl_Position = faces ? vec4(xy, 0.0, 1.0) : vec4(2.0, 2.0, 2.0, 1.0);
}
)";

// The instanced draws (GL_EXT_clip_cull_distance): one draw per side (per environment model) for
// a whole batch, an instance per render (a contact's environment, or one of its tool poses), with
// its rows and atlas tile from the Instances block; the viewport is the whole atlas. Each
// instance draws the union of the batch's patch triangles (of that side and model); the window's
// edges are clip planes, so a triangle is cut where a per-render draw's viewport and scissor cut
// it, and the pixel mapping is the viewport transform's, origin + (x + 1)·N/2.
constexpr const char* kInstancedVertexMain = R"(
// Instance i: its u, v and n rows at 4i, 4i + 1, 4i + 2 and its atlas tile at 4i + 3 (x).
layout(std140) uniform Instances { vec4 u_instances[4 * 256]; };
uniform int u_columns;        // tiles per atlas row
uniform float u_tile_stride;  // texels between tile origins
uniform float u_cells;        // N
uniform vec2 u_atlas_size;    // texels
out float gl_ClipDistance[4];
void main() {
  int i = 4 * gl_InstanceID;
  vec2 xy;
  bool faces = ProjectCorner(u_instances[i], u_instances[i + 1], u_instances[i + 2], xy);
  gl_ClipDistance[0] = 1.0 + xy.x;
  gl_ClipDistance[1] = 1.0 - xy.x;
  gl_ClipDistance[2] = 1.0 + xy.y;
  gl_ClipDistance[3] = 1.0 - xy.y;
  int tile = int(u_instances[i + 3].x);
  vec2 origin = u_tile_stride * vec2(float(tile % u_columns), float(tile / u_columns));
  vec2 pixel = origin + (xy + 1.0) * (0.5 * u_cells);
  gl_Position = faces ? vec4(pixel / u_atlas_size * 2.0 - 1.0, 0.0, 1.0)
                      : vec4(2.0, 2.0, 2.0, 1.0);
}
)";

// Fragment stage: coarse height plus texture height times N·n, bilinear at the chosen mip level
// exactly as HeightField::Sample does (texelFetch, so no fixed-point filter weights).
constexpr const char* kRenderFragmentShader = R"(#version 310 es
precision highp float;
precision highp int;
uniform highp sampler2D u_texture;
uniform ivec2 u_wrap;
uniform float u_depth_range;  // R (m)
uniform float u_depth_scale;  // 1 / (2 R')
in vec2 v_uv;
in float v_height;
in vec3 v_normal_O;
flat in vec3 v_row_n;
flat in int v_level;
int Address(int i, int n, int wrap) {
  if (wrap != 0) {
    if (i < 0) i += n * ((-i) / n + 1);
    return i % n;
  }
  return clamp(i, 0, n - 1);
}
float SampleHeight(int level, vec2 uv) {
  ivec2 size = textureSize(u_texture, level);
  float fx = clamp(uv.x * float(size.x) - 0.5, -1e6, 1e6);
  float fy = clamp(uv.y * float(size.y) - 0.5, -1e6, 1e6);
  float x0f = floor(fx), y0f = floor(fy);
  float tx = fx - x0f, ty = fy - y0f;
  int x0 = int(x0f), y0 = int(y0f);
  int xa = Address(x0, size.x, u_wrap.x), xb = Address(x0 + 1, size.x, u_wrap.x);
  int ya = Address(y0, size.y, u_wrap.y), yb = Address(y0 + 1, size.y, u_wrap.y);
  float aa = texelFetch(u_texture, ivec2(xa, ya), level).r;
  float ba = texelFetch(u_texture, ivec2(xb, ya), level).r;
  float ab = texelFetch(u_texture, ivec2(xa, yb), level).r;
  float bb = texelFetch(u_texture, ivec2(xb, yb), level).r;
  float top = aa + tx * (ba - aa);
  float bottom = ab + tx * (bb - ab);
  return top + ty * (bottom - top);
}
void main() {
  float h = v_height;
  if (v_level >= 0) {
    // Height along the unit interpolated normal N (HapticModel: p = p_coarse + h·N), projected on n.
    float len = length(v_normal_O);
    float ndotn = len > 1e-6 ? dot(v_normal_O, v_row_n) / len : 0.0;
    h += SampleHeight(v_level, v_uv) * ndotn;
  }
  if (!(abs(h) <= u_depth_range)) discard;
  gl_FragDepth = 0.5 + h * u_depth_scale;
}
)";

// Reduction: one work group per tool tile; per cell covered by both patches b − a, then the
// maximum and its lowest cell index (ties as in DirectionalPenetrationDepth).
constexpr const char* kReduceComputeShader = R"(#version 310 es
precision highp float;
precision highp int;
layout(local_size_x = 256) in;
uniform highp sampler2D u_env_depth;
uniform highp sampler2D u_tool_depth;
uniform int u_resolution;
uniform int u_tile_stride;
uniform int u_env_columns;
uniform int u_tool_columns;
uniform int u_samples_per_contact;
uniform float u_height_scale;  // 2 R' (m)
struct Result { float depth; int cell; };
layout(std430, binding = 0) writeonly buffer Results { Result results[]; };
shared float s_depth[256];
shared int s_cell[256];
void main() {
  int tile = int(gl_WorkGroupID.x);
  int contact = tile / u_samples_per_contact;
  ivec2 env_origin = u_tile_stride * ivec2(contact % u_env_columns, contact / u_env_columns);
  ivec2 tool_origin = u_tile_stride * ivec2(tile % u_tool_columns, tile / u_tool_columns);
  int lid = int(gl_LocalInvocationID.x);
  float best = 0.0;
  int cell = -1;
  int cells = u_resolution * u_resolution;
  for (int k = lid; k < cells; k += 256) {
    ivec2 ij = ivec2(k % u_resolution, k / u_resolution);
    float b = texelFetch(u_env_depth, env_origin + ij, 0).r;
    float a = texelFetch(u_tool_depth, tool_origin + ij, 0).r;
    if (b > 0.0 && a < 1.0) {
      float d = (b - a) * u_height_scale;
      if (cell < 0 || d > best) { best = d; cell = k; }
    }
  }
  s_depth[lid] = best;
  s_cell[lid] = cell;
  barrier();
  for (int stride = 128; stride > 0; stride >>= 1) {
    if (lid < stride) {
      float od = s_depth[lid + stride];
      int oc = s_cell[lid + stride];
      int mc = s_cell[lid];
      if (oc >= 0 && (mc < 0 || od > s_depth[lid] || (od == s_depth[lid] && oc < mc))) {
        s_depth[lid] = od;
        s_cell[lid] = oc;
      }
    }
    barrier();
  }
  if (lid == 0) results[tile] = Result(s_depth[0], s_cell[0]);
}
)";

const char* GlErrorName(GLenum e) {
  switch (e) {
    case GL_INVALID_ENUM:
      return "GL_INVALID_ENUM";
    case GL_INVALID_VALUE:
      return "GL_INVALID_VALUE";
    case GL_INVALID_OPERATION:
      return "GL_INVALID_OPERATION";
    case GL_INVALID_FRAMEBUFFER_OPERATION:
      return "GL_INVALID_FRAMEBUFFER_OPERATION";
    case GL_OUT_OF_MEMORY:
      return "GL_OUT_OF_MEMORY";
    default:
      return "GL error";
  }
}

// Returns "" when no GL error is pending, else the names of the pending errors.
std::string DrainGlErrors() {
  std::string errors;
  for (int i = 0; i < 16; ++i) {
    const GLenum e = glGetError();
    if (e == GL_NO_ERROR) break;
    if (!errors.empty()) errors += ", ";
    errors += GlErrorName(e);
  }
  return errors;
}

GLuint CompileShader(GLenum stage, const std::string& source, const char* what) {
  const GLuint shader = glCreateShader(stage);
  const char* text = source.c_str();
  glShaderSource(shader, 1, &text, nullptr);
  glCompileShader(shader);
  GLint ok = GL_FALSE;
  glGetShaderiv(shader, GL_COMPILE_STATUS, &ok);
  if (ok != GL_TRUE) {
    GLint length = 0;
    glGetShaderiv(shader, GL_INFO_LOG_LENGTH, &length);
    std::string log(static_cast<size_t>(std::max(length, 1)), '\0');
    glGetShaderInfoLog(shader, length, nullptr, log.data());
    glDeleteShader(shader);
    throw GpuError(std::string("GPU penetration depth: the ") + what +
                   " failed to compile: " + log.c_str());
  }
  return shader;
}

GLuint LinkProgram(std::initializer_list<GLuint> shaders, const char* what) {
  const GLuint program = glCreateProgram();
  for (GLuint s : shaders) glAttachShader(program, s);
  glLinkProgram(program);
  for (GLuint s : shaders) glDeleteShader(s);
  GLint ok = GL_FALSE;
  glGetProgramiv(program, GL_LINK_STATUS, &ok);
  if (ok != GL_TRUE) {
    GLint length = 0;
    glGetProgramiv(program, GL_INFO_LOG_LENGTH, &length);
    std::string log(static_cast<size_t>(std::max(length, 1)), '\0');
    glGetProgramInfoLog(program, length, nullptr, log.data());
    glDeleteProgram(program);
    throw GpuError(std::string("GPU penetration depth: the ") + what +
                   " failed to link: " + log.c_str());
  }
  return program;
}

// Rows of the map from object frame O to window coordinates (s, t, height) for a body at X_WO.
struct WindowRows {
  float u[4], v[4], n[4];
};

WindowRows RowsFor(const RigidTransform& X_WO, const ContactWindow& w) {
  const glm::dquat q_inv = glm::conjugate(X_WO.rotation);
  const glm::dvec3 offset = X_WO.translation - w.center_W;
  WindowRows r{};
  const auto fill = [&](float* row, const glm::dvec3& axis_W) {
    const glm::dvec3 axis_O = q_inv * axis_W;
    row[0] = static_cast<float>(axis_O.x);
    row[1] = static_cast<float>(axis_O.y);
    row[2] = static_cast<float>(axis_O.z);
    row[3] = static_cast<float>(glm::dot(axis_W, offset));
  };
  fill(r.u, w.axis_u_W);
  fill(r.v, w.axis_v_W);
  fill(r.n, w.normal_W);
  return r;
}

}  // namespace

struct GpuPenetrationDepthBackend::GpuModel {
  GLuint vao = 0, vbo = 0, texture = 0;
  GLsizei corners = 0;
  int num_levels = 1;
  int wrap_u = 0, wrap_v = 0;
};

GpuPenetrationDepthBackend::GpuPenetrationDepthBackend(const GpuPenetrationDepthOptions& options)
    : options_(options) {}

std::unique_ptr<GpuPenetrationDepthBackend> GpuPenetrationDepthBackend::Create(
    const GpuPenetrationDepthOptions& options) {
  if (options.depth_bits != 16 && options.depth_bits != 32) {
    throw std::invalid_argument("depth bits must be 16 or 32, got " +
                                std::to_string(options.depth_bits));
  }
  if (options.max_contacts < 1 || options.max_contacts > 256) {
    throw std::invalid_argument("max contacts must be in [1, 256], got " +
                                std::to_string(options.max_contacts));
  }
  if (options.max_resolution < 2 || options.max_resolution > 1024) {
    throw std::invalid_argument("max resolution must be in [2, 1024], got " +
                                std::to_string(options.max_resolution));
  }
  std::unique_ptr<GpuPenetrationDepthBackend> backend(new GpuPenetrationDepthBackend(options));
  backend->context_ = EglContext::Create(options.egl);
  backend->Initialize();
  return backend;
}

void GpuPenetrationDepthBackend::Initialize() {
  const GpuInfo& info = context_->info();
  int major = 0, minor = 0;
  glGetIntegerv(GL_MAJOR_VERSION, &major);
  glGetIntegerv(GL_MINOR_VERSION, &minor);
  if (major < 3 || (major == 3 && minor < 1)) {
    throw GpuError("GPU penetration depth: OpenGL ES 3.1 needed (compute shaders), got " +
                   info.version);
  }
  std::string fragment = kRenderFragmentShader;
  if (options_.inject_shader_compile_error) fragment += "\nthis is not GLSL;\n";
  render_program_ = LinkProgram(
      {CompileShader(GL_VERTEX_SHADER,
                     std::string("#version 310 es\n") + kVertexCommon + kRenderVertexMain,
                     "height vertex shader"),
       CompileShader(GL_FRAGMENT_SHADER, fragment, "height fragment shader")},
      "height program");
  reduce_program_ = LinkProgram(
      {CompileShader(GL_COMPUTE_SHADER, kReduceComputeShader, "reduction compute shader")},
      "reduction program");

  const auto loc = [](GLuint p, const char* name) { return glGetUniformLocation(p, name); };
  ru_ = {loc(render_program_, "u_row_u"),       loc(render_program_, "u_row_v"),
         loc(render_program_, "u_row_n"),       loc(render_program_, "u_half_extent"),
         loc(render_program_, "u_cell_size"),   loc(render_program_, "u_facing_sign"),
         loc(render_program_, "u_num_levels"),  loc(render_program_, "u_wrap"),
         loc(render_program_, "u_depth_range"), loc(render_program_, "u_depth_scale"),
         loc(render_program_, "u_texture")};
  rd_ = {loc(reduce_program_, "u_env_depth"),    loc(reduce_program_, "u_tool_depth"),
         loc(reduce_program_, "u_resolution"),   loc(reduce_program_, "u_env_columns"),
         loc(reduce_program_, "u_tool_columns"), loc(reduce_program_, "u_samples_per_contact"),
         loc(reduce_program_, "u_height_scale")};
  tile_stride_location_ = loc(reduce_program_, "u_tile_stride");

  // Depth atlases: one N_max × N_max tile per environment render and per tool render.
  const int stride = options_.max_resolution;
  const auto layout = [&](int tiles, int& columns) {
    columns = std::max(1, static_cast<int>(std::ceil(std::sqrt(static_cast<double>(tiles)))));
    const int rows = (tiles + columns - 1) / columns;
    if (columns * stride > info.max_texture_size || rows * stride > info.max_texture_size) {
      throw GpuError("GPU penetration depth: an atlas of " + std::to_string(tiles) + " tiles of " +
                     std::to_string(stride) + "² exceeds GL_MAX_TEXTURE_SIZE " +
                     std::to_string(info.max_texture_size) + "; lower max contacts or grid");
    }
    return std::pair{columns * stride, rows * stride};
  };
  const GLenum depth_format =
      options_.depth_bits == 16 ? GL_DEPTH_COMPONENT16 : GL_DEPTH_COMPONENT32F;
  const auto make_atlas = [&](int tiles, int& columns, GLuint& texture, GLuint& fbo) {
    const auto [width, height] = layout(tiles, columns);
    glGenTextures(1, &texture);
    glBindTexture(GL_TEXTURE_2D, texture);
    glTexStorage2D(GL_TEXTURE_2D, 1, depth_format, width, height);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_COMPARE_MODE, GL_NONE);
    glGenFramebuffers(1, &fbo);
    glBindFramebuffer(GL_FRAMEBUFFER, fbo);
    glFramebufferTexture2D(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_TEXTURE_2D, texture, 0);
    const GLenum none = GL_NONE;
    glDrawBuffers(1, &none);
    glReadBuffer(GL_NONE);
    const GLenum status = glCheckFramebufferStatus(GL_FRAMEBUFFER);
    if (status != GL_FRAMEBUFFER_COMPLETE) {
      char hex[16];
      std::snprintf(hex, sizeof hex, "0x%04x", status);
      throw GpuError(std::string("GPU penetration depth: depth atlas framebuffer incomplete (") +
                     hex + ") for " + std::to_string(options_.depth_bits) + "-bit depth");
    }
  };
  make_atlas(options_.max_contacts, env_columns_, env_depth_, env_fbo_);
  make_atlas(options_.max_contacts * kGradientSamples, tool_columns_, tool_depth_, tool_fbo_);
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
  {
    const auto [width, height] = layout(options_.max_contacts * kGradientSamples, tool_columns_);
    tool_atlas_width_ = width;
    tool_atlas_height_ = height;
    const auto [env_width, env_height] = layout(options_.max_contacts, env_columns_);
    env_atlas_width_ = env_width;
    env_atlas_height_ = env_height;
  }

  // The tool's eleven poses in one instanced draw per contact where the context can clip each
  // instance to its tile (GL_EXT_clip_cull_distance, four planes) and the viewport can span the
  // tool atlas; else eleven draws.
  if (options_.instanced_draws) {
    bool clip_distance = false;
    GLint extensions = 0;
    glGetIntegerv(GL_NUM_EXTENSIONS, &extensions);
    for (GLint i = 0; i < extensions; ++i) {
      const auto* name = reinterpret_cast<const char*>(glGetStringi(GL_EXTENSIONS, i));
      if (name != nullptr && std::strcmp(name, "GL_EXT_clip_cull_distance") == 0) {
        clip_distance = true;
      }
    }
    constexpr GLenum kMaxClipDistances = 0x0D32;  // GL_MAX_CLIP_DISTANCES_EXT
    GLint planes = 0;
    GLint viewport[2] = {0, 0};
    if (clip_distance) glGetIntegerv(kMaxClipDistances, &planes);
    glGetIntegerv(GL_MAX_VIEWPORT_DIMS, viewport);
    DrainGlErrors();
    GLint block_size = 0;
    glGetIntegerv(GL_MAX_UNIFORM_BLOCK_SIZE, &block_size);
    if (clip_distance && planes >= 4 && viewport[0] >= tool_atlas_width_ &&
        viewport[1] >= tool_atlas_height_ && viewport[0] >= env_atlas_width_ &&
        viewport[1] >= env_atlas_height_ &&
        block_size >= static_cast<GLint>(kInstancesPerDraw * 16 * sizeof(float))) {
      instanced_program_ = LinkProgram(
          {CompileShader(GL_VERTEX_SHADER,
                         std::string("#version 310 es\n#extension GL_EXT_clip_cull_distance : "
                                     "require\n") +
                             kVertexCommon + kInstancedVertexMain,
                         "instanced vertex shader"),
           CompileShader(GL_FRAGMENT_SHADER, fragment, "height fragment shader")},
          "instanced height program");
      const auto iloc = [&](const char* name) {
        return glGetUniformLocation(instanced_program_, name);
      };
      iu_ = {iloc("u_half_extent"), iloc("u_cell_size"), iloc("u_facing_sign"),
             iloc("u_num_levels"),  iloc("u_wrap"),      iloc("u_depth_range"),
             iloc("u_depth_scale"), iloc("u_texture"),   iloc("u_columns"),
             iloc("u_tile_stride"), iloc("u_cells"),     iloc("u_atlas_size")};
      const GLuint block = glGetUniformBlockIndex(instanced_program_, "Instances");
      glUniformBlockBinding(instanced_program_, block, 0);
      glGenBuffers(1, &instance_ubo_);
      glBindBuffer(GL_UNIFORM_BUFFER, instance_ubo_);
      glBufferData(GL_UNIFORM_BUFFER, kInstancesPerDraw * 16 * sizeof(float), nullptr,
                   GL_STREAM_DRAW);
      glBindBuffer(GL_UNIFORM_BUFFER, 0);
      instance_data_.reserve(static_cast<std::size_t>(kInstancesPerDraw) * 16);
      if (const std::string e = DrainGlErrors(); !e.empty()) {
        glDeleteProgram(instanced_program_);
        glDeleteBuffers(1, &instance_ubo_);
        instanced_program_ = instance_ubo_ = 0;  // a draw per render, as without the extension
      }
    }
  }

  glGenBuffers(1, &patch_ebo_);
  patch_indices_.reserve(static_cast<size_t>(options_.max_contacts) * 2 * 3 * 256);
  patch_triangles_.reserve(4096);
  env_ranges_.resize(static_cast<size_t>(options_.max_contacts));
  tool_ranges_.resize(static_cast<size_t>(options_.max_contacts));
  glGenBuffers(1, &results_);
  glBindBuffer(GL_SHADER_STORAGE_BUFFER, results_);
  glBufferData(GL_SHADER_STORAGE_BUFFER,
               static_cast<GLsizeiptr>(options_.max_contacts) * kGradientSamples * 8, nullptr,
               GL_DYNAMIC_READ);
  glBindBuffer(GL_SHADER_STORAGE_BUFFER, 0);

  sample_poses_.resize(static_cast<size_t>(options_.max_contacts) * kGradientSamples);
  samples_.resize(sample_poses_.size());
  if (const std::string e = DrainGlErrors(); !e.empty()) {
    throw GpuError("GPU penetration depth: GL error while setting up: " + e);
  }
}

GpuPenetrationDepthBackend::~GpuPenetrationDepthBackend() {
  if (!context_ || !context_->MakeCurrent()) return;
  ForgetModels();
  glDeleteBuffers(1, &results_);
  glDeleteBuffers(1, &patch_ebo_);
  glDeleteFramebuffers(1, &env_fbo_);
  glDeleteFramebuffers(1, &tool_fbo_);
  glDeleteTextures(1, &env_depth_);
  glDeleteTextures(1, &tool_depth_);
  if (!broken_) glDeleteProgram(render_program_);
  glDeleteProgram(instanced_program_);
  glDeleteBuffers(1, &instance_ubo_);
  glDeleteProgram(reduce_program_);
}

void GpuPenetrationDepthBackend::ForgetModels() noexcept {
  if (context_ && context_->MakeCurrent()) {
    for (auto& [key, m] : models_) {
      glDeleteVertexArrays(1, &m->vao);
      glDeleteBuffers(1, &m->vbo);
      glDeleteTextures(1, &m->texture);
    }
  }
  models_.clear();
}

std::string GpuPenetrationDepthBackend::description() const {
  const GpuInfo& i = context_->info();
  return i.renderer + " (" + i.version + ", " + i.platform + " platform, " +
         std::to_string(options_.depth_bits) + "-bit depth" +
         (instanced_program_ != 0 ? ", instanced draws)" : ")");
}

double GpuPenetrationDepthBackend::DepthQuantum(const ContactWindow& w) const noexcept {
  const double span = 2.0 * w.depth_range_m() * kRangeSlack;
  return options_.depth_bits == 16 ? span / 65535.0 : span * std::ldexp(1.0, -24);
}

void GpuPenetrationDepthBackend::BreakProgramForTesting() noexcept {
  glDeleteProgram(render_program_);
  glDeleteProgram(instanced_program_);
  broken_ = true;
}

void GpuPenetrationDepthBackend::Upload(const HapticModel& model) {
  if (ModelFor(model) == nullptr) {
    throw GpuError("GPU penetration depth: upload of model '" + model.name +
                   "' failed: " + last_error_);
  }
}

GpuPenetrationDepthBackend::GpuModel* GpuPenetrationDepthBackend::ModelFor(
    const HapticModel& model) {
  if (auto it = models_.find(&model); it != models_.end()) return it->second.get();
  auto m = std::make_unique<GpuModel>();
  const size_t nf = model.triangles.size();
  std::vector<float> corners(nf * 3 * kFloatsPerCorner);
  const bool has_texture = !model.texture.empty();
  for (size_t f = 0; f < nf; ++f) {
    const glm::ivec3 t = model.triangles[f];
    const glm::dvec3 p0 = model.vertices_O[t[0]], p1 = model.vertices_O[t[1]],
                     p2 = model.vertices_O[t[2]];
    const glm::dvec3 cr = glm::cross(p1 - p0, p2 - p0);
    const double len = glm::length(cr);
    const glm::dvec3 face = len > 0.0 ? cr / len : glm::dvec3(0.0);
    const bool textured = has_texture && model.textured[f] != 0;
    for (int c = 0; c < 3; ++c) {
      float* o = &corners[(3 * f + c) * kFloatsPerCorner];
      const glm::dvec3 p = model.vertices_O[t[c]];
      const glm::dvec3 nrm = model.corner_normals_O[3 * f + c];
      const glm::vec2 uv = model.corner_uvs[3 * f + c];
      const float values[kFloatsPerCorner] = {
          static_cast<float>(p.x),
          static_cast<float>(p.y),
          static_cast<float>(p.z),
          static_cast<float>(nrm.x),
          static_cast<float>(nrm.y),
          static_cast<float>(nrm.z),
          static_cast<float>(face.x),
          static_cast<float>(face.y),
          static_cast<float>(face.z),
          uv.x,
          uv.y,
          textured ? static_cast<float>(model.texel_size_m[f]) : -1.0f};
      std::memcpy(o, values, sizeof values);
    }
  }
  m->corners = static_cast<GLsizei>(nf * 3);
  glGenVertexArrays(1, &m->vao);
  glBindVertexArray(m->vao);
  glGenBuffers(1, &m->vbo);
  glBindBuffer(GL_ARRAY_BUFFER, m->vbo);
  glBufferData(GL_ARRAY_BUFFER, static_cast<GLsizeiptr>(corners.size() * sizeof(float)),
               corners.data(), GL_STATIC_DRAW);
  const GLsizei stride = kFloatsPerCorner * sizeof(float);
  const int sizes[5] = {3, 3, 3, 2, 1};
  size_t offset = 0;
  for (GLuint a = 0; a < 5; ++a) {
    glEnableVertexAttribArray(a);
    glVertexAttribPointer(a, sizes[a], GL_FLOAT, GL_FALSE, stride,
                          reinterpret_cast<const void*>(offset * sizeof(float)));
    offset += static_cast<size_t>(sizes[a]);
  }
  glBindVertexArray(0);

  glGenTextures(1, &m->texture);
  glBindTexture(GL_TEXTURE_2D, m->texture);
  if (has_texture) {
    const HeightField& hf = model.texture;
    m->num_levels = hf.num_levels();
    glTexStorage2D(GL_TEXTURE_2D, m->num_levels, GL_R32F, hf.level(0).width, hf.level(0).height);
    glPixelStorei(GL_UNPACK_ALIGNMENT, 4);
    for (int l = 0; l < m->num_levels; ++l) {
      const HeightFieldLevel& L = hf.level(l);
      glTexSubImage2D(GL_TEXTURE_2D, l, 0, 0, L.width, L.height, GL_RED, GL_FLOAT, L.texels.data());
    }
    m->wrap_u = hf.wrap_u() ? 1 : 0;
    m->wrap_v = hf.wrap_v() ? 1 : 0;
  } else {
    const float zero = 0.0f;
    glTexStorage2D(GL_TEXTURE_2D, 1, GL_R32F, 1, 1);
    glTexSubImage2D(GL_TEXTURE_2D, 0, 0, 0, 1, 1, GL_RED, GL_FLOAT, &zero);
  }
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST_MIPMAP_NEAREST);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAX_LEVEL, m->num_levels - 1);
  if (const std::string e = DrainGlErrors(); !e.empty()) {
    last_error_ = "GL error while uploading model '" + model.name + "': " + e;
    glDeleteVertexArrays(1, &m->vao);
    glDeleteBuffers(1, &m->vbo);
    glDeleteTextures(1, &m->texture);
    return nullptr;
  }
  GpuModel* raw = m.get();
  models_.emplace(&model, std::move(m));
  return raw;
}

bool GpuPenetrationDepthBackend::Fail(std::string why) noexcept {
  last_error_ = std::move(why);
  return false;
}

bool GpuPenetrationDepthBackend::LinearizeBatch(const HapticModel& tool, const RigidTransform& X_WT,
                                                std::span<const ContactQuery> queries,
                                                std::span<ContactLinearization> out,
                                                std::span<DepthSample> samples_out) noexcept {
  using Clock = std::chrono::steady_clock;
  const auto us = [](Clock::duration d) {
    return std::chrono::duration<double, std::micro>(d).count();
  };
  const int count = static_cast<int>(queries.size());
  if (count == 0) return true;
  if (out.size() < queries.size()) return Fail("output span shorter than the batch");
  if (count > options_.max_contacts) {
    return Fail(std::to_string(count) + " contacts in one batch, sized for " +
                std::to_string(options_.max_contacts));
  }
  const int n = queries[0].window.resolution;
  for (const ContactQuery& q : queries) {
    if (q.environment == nullptr) return Fail("a query without an environment model");
    if (q.window.resolution != n) return Fail("mixed grid resolutions in one batch");
  }
  // One depth encoding per batch (the reduction decodes all tiles alike): one window extent W.
  const double range = queries[0].window.depth_range_m();
  for (const ContactQuery& q : queries) {
    if (q.window.depth_range_m() != range) return Fail("mixed window extents in one batch");
  }
  if (n > options_.max_resolution) {
    return Fail("grid " + std::to_string(n) + " larger than the backend's maximum " +
                std::to_string(options_.max_resolution));
  }
  const auto t0 = Clock::now();
  GpuModel* tool_model;
  std::array<GpuModel*, 256> env_models{};
  try {
    tool_model = ModelFor(tool);
    for (int c = 0; c < count; ++c) env_models[c] = ModelFor(*queries[c].environment);
  } catch (const std::exception& e) {  // allocation failure on a first upload
    return Fail(std::string("model upload: ") + e.what());
  }
  if (tool_model == nullptr) return false;
  for (int c = 0; c < count; ++c) {
    if (env_models[c] == nullptr) return false;
  }

  // Tiles packed at the batch's N (the atlases are sized for N_max tiles, so N×N ones fit), so
  // that the tiles a batch uses are close together (one clear below covers them).
  const int stride = n;
  const auto set_window_uniforms = [&](const RigidTransform& X, const ContactWindow& w,
                                       float facing_sign) {
    const WindowRows r = RowsFor(X, w);
    glUniform4fv(ru_.row_u, 1, r.u);
    glUniform4fv(ru_.row_v, 1, r.v);
    glUniform4fv(ru_.row_n, 1, r.n);
    glUniform1f(ru_.half_extent, static_cast<float>(0.5 * w.extent_m));
    glUniform1f(ru_.cell_size, static_cast<float>(w.cell_size_m()));
    glUniform1f(ru_.facing_sign, facing_sign);
    glUniform1f(ru_.depth_range, static_cast<float>(w.depth_range_m()));
    glUniform1f(ru_.depth_scale, static_cast<float>(1.0 / (2.0 * w.depth_range_m() * kRangeSlack)));
  };
  // A model's vertices, the batch's element buffer and the model's texture; with the
  // per-render program current, its texture uniforms too.
  const auto bind_geometry = [&](const GpuModel& m) {
    glBindVertexArray(m.vao);
    glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, patch_ebo_);  // part of the VAO's state
    glActiveTexture(GL_TEXTURE0);
    glBindTexture(GL_TEXTURE_2D, m.texture);
  };
  const auto bind_model = [&](const GpuModel& m) {
    bind_geometry(m);
    glUniform1i(ru_.num_levels, m.num_levels);
    glUniform2i(ru_.wrap, m.wrap_u, m.wrap_v);
  };
  const auto tile = [&](int index, int columns) {
    const int x = (index % columns) * stride, y = (index / columns) * stride;
    glViewport(x, y, n, n);
    glScissor(x, y, n, n);
    glClear(GL_DEPTH_BUFFER_BIT);
  };

  for (int c = 0; c < count; ++c) {
    const auto poses = GradientSamplePoses(X_WT, queries[c].window);
    std::copy(poses.begin(), poses.end(), sample_poses_.begin() + c * kGradientSamples);
  }
  // Each contact's patch triangles, chosen as the CPU path chooses them (SelectPatchTriangles:
  // the environment's on the window grown by a cell; the tool's with the margins of all eleven
  // sample poses), as ranges of one element buffer of corner indices: the draws below process
  // those triangles, not whole models.
  patch_indices_.clear();
  // The instanced draws render a side's union of the batch's lists into every contact's tile,
  // which would render one cluster's triangles in another's window: a batch whose contacts carry
  // their clusters' own triangles (issue 31, TriangleSubset) is drawn one contact at a time.
  const bool own_triangles = std::any_of(
      queries.begin(), queries.begin() + count,
      [](const ContactQuery& q) { return !q.environment_triangles.all || !q.tool_triangles.all; });
  const bool instanced = instanced_program_ != 0 && !own_triangles;
  const auto select_env = [&](int c) {
    const ContactQuery& q = queries[c];
    SelectPatchTrianglesIn(q.environment_triangles, *q.environment, q.X_WO, q.window,
                           PatchSide::kEnvironment, q.window.cell_size_m(), patch_triangles_, 0.0,
                           nullptr, trees_.For(*q.environment));
  };
  const auto select_tool = [&](int c) {
    const ContactWindow& w = queries[c].window;
    const GradientSteps h = GradientSteps::For(w);
    SelectPatchTrianglesIn(queries[c].tool_triangles, tool, X_WT, w, PatchSide::kTool, 2.0 * h.h_x,
                           patch_triangles_, h.h_theta + 1e-9, nullptr, trees_.For(tool),
                           h.h_theta);
  };
  // A range of the element buffer: begun, then patch_triangles_ appended to it one or more times
  // (each triangle once: a triangle is marked with the range's stamp when it enters, so that
  // an instanced range holds the union of its contacts' lists), then ended.
  const auto begin_range = [&] {
    if (++union_stamp_ == 0) {  // wrapped: no triangle may carry the new stamp by accident
      std::fill(union_mark_.begin(), union_mark_.end(), 0u);
      union_stamp_ = 1;
    }
    return static_cast<int>(patch_indices_.size());
  };
  const auto append = [&](std::size_t triangle_count) {
    if (union_mark_.size() < triangle_count) union_mark_.resize(triangle_count, 0);
    for (const int f : patch_triangles_) {
      std::uint32_t& mark = union_mark_[static_cast<std::size_t>(f)];
      if (mark == union_stamp_) continue;
      mark = union_stamp_;
      const auto corner = static_cast<GLuint>(3 * f);
      patch_indices_.push_back(corner);
      patch_indices_.push_back(corner + 1);
      patch_indices_.push_back(corner + 2);
    }
  };
  const auto end_range = [&](int first) {
    return PatchRange{first, static_cast<int>(patch_indices_.size()) - first};
  };
  env_groups_.clear();
  try {
    if (instanced) {
      // One group per environment model (in order of its first contact), then the tool.
      for (int c = 0; c < count; ++c) {
        bool seen = false;
        for (const EnvGroup& g : env_groups_) {
          seen = seen || env_models[g.first_contact] == env_models[c];
        }
        if (seen) continue;
        const int first = begin_range();
        for (int k = c; k < count; ++k) {
          if (env_models[k] != env_models[c]) continue;
          select_env(k);
          append(queries[k].environment->triangles.size());
        }
        env_groups_.push_back({c, end_range(first)});
      }
      const int first = begin_range();
      for (int c = 0; c < count; ++c) {
        select_tool(c);
        append(tool.triangles.size());
      }
      tool_union_ = end_range(first);
    } else {
      for (int c = 0; c < count; ++c) {
        int first = begin_range();
        select_env(c);
        append(queries[c].environment->triangles.size());
        env_ranges_[static_cast<std::size_t>(c)] = end_range(first);
        first = begin_range();
        select_tool(c);
        append(tool.triangles.size());
        tool_ranges_[static_cast<std::size_t>(c)] = end_range(first);
      }
    }
  } catch (const std::exception& e) {  // allocation failure while the lists grow
    return Fail(std::string("patch triangle lists: ") + e.what());
  }
  glBindVertexArray(0);
  glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, patch_ebo_);
  glBufferData(GL_ELEMENT_ARRAY_BUFFER,
               static_cast<GLsizeiptr>(patch_indices_.size() * sizeof(GLuint)),
               patch_indices_.data(), GL_STREAM_DRAW);
  const auto draw_range = [](const PatchRange& r) {
    if (r.count == 0) return;
    glDrawElements(
        GL_TRIANGLES, r.count, GL_UNSIGNED_INT,
        reinterpret_cast<const void*>(static_cast<std::uintptr_t>(r.first) * sizeof(GLuint)));
  };
  // The instanced draws' helpers: a clear of the first `tiles` tiles of an atlas at once (whole
  // rows), the per-batch uniforms (one window extent and N per batch), an instance's rows and
  // tile, and a draw of the instances gathered (then none).
  const auto clear_tiles = [&](int tiles, int columns) {
    const int rows = (tiles + columns - 1) / columns;
    glEnable(GL_SCISSOR_TEST);
    glScissor(0, 0, std::min(tiles, columns) * stride, rows * stride);
    glClear(GL_DEPTH_BUFFER_BIT);
    glDisable(GL_SCISSOR_TEST);
  };
  const auto set_instanced_uniforms = [&](const ContactWindow& w, float facing_sign, int columns,
                                          int width, int height) {
    glUniform1i(iu_.texture, 0);
    glUniform1f(iu_.half_extent, static_cast<float>(0.5 * w.extent_m));
    glUniform1f(iu_.cell_size, static_cast<float>(w.cell_size_m()));
    glUniform1f(iu_.facing_sign, facing_sign);
    glUniform1f(iu_.depth_range, static_cast<float>(w.depth_range_m()));
    glUniform1f(iu_.depth_scale, static_cast<float>(1.0 / (2.0 * w.depth_range_m() * kRangeSlack)));
    glUniform1i(iu_.columns, columns);
    glUniform1f(iu_.tile_stride, static_cast<float>(stride));
    glUniform1f(iu_.cells, static_cast<float>(n));
    glUniform2f(iu_.atlas_size, static_cast<float>(width), static_cast<float>(height));
  };
  const auto add_instance = [&](const RigidTransform& X, const ContactWindow& w, int tile_index) {
    const WindowRows r = RowsFor(X, w);
    instance_data_.insert(instance_data_.end(), r.u, r.u + 4);
    instance_data_.insert(instance_data_.end(), r.v, r.v + 4);
    instance_data_.insert(instance_data_.end(), r.n, r.n + 4);
    const float tile_row[4] = {static_cast<float>(tile_index), 0.0f, 0.0f, 0.0f};
    instance_data_.insert(instance_data_.end(), tile_row, tile_row + 4);
  };
  const auto draw_instances = [&](const PatchRange& patch, int instances) {
    if (instances > 0 && patch.count > 0) {
      glBindBuffer(GL_UNIFORM_BUFFER, instance_ubo_);
      // A fresh store (the previous draw may still read the old one), then the instances.
      glBufferData(GL_UNIFORM_BUFFER, kInstancesPerDraw * 16 * sizeof(float), nullptr,
                   GL_STREAM_DRAW);
      glBufferSubData(GL_UNIFORM_BUFFER, 0,
                      static_cast<GLsizeiptr>(instance_data_.size() * sizeof(float)),
                      instance_data_.data());
      glBindBufferBase(GL_UNIFORM_BUFFER, 0, instance_ubo_);
      glDrawElementsInstanced(
          GL_TRIANGLES, patch.count, GL_UNSIGNED_INT,
          reinterpret_cast<const void*>(static_cast<std::uintptr_t>(patch.first) * sizeof(GLuint)),
          instances);
    }
    instance_data_.clear();
  };
  constexpr GLenum kClipDistance0 = 0x3000;  // GL_CLIP_DISTANCE0_EXT
  const auto t1 = Clock::now();

  glUseProgram(render_program_);
  glUniform1i(ru_.texture, 0);
  glEnable(GL_DEPTH_TEST);
  glEnable(GL_SCISSOR_TEST);
  glDisable(GL_CULL_FACE);
  glDisable(GL_BLEND);
  glDepthMask(GL_TRUE);
  if (instanced) {
    for (GLenum plane = 0; plane < 4; ++plane) glEnable(kClipDistance0 + plane);
  }
  // Environment patches B: keep the largest height per cell.
  glBindFramebuffer(GL_FRAMEBUFFER, env_fbo_);
  glDepthFunc(GL_GREATER);
  glClearDepthf(0.0f);
  if (instanced) {
    clear_tiles(count, env_columns_);
    glViewport(0, 0, env_atlas_width_, env_atlas_height_);
    glUseProgram(instanced_program_);
    set_instanced_uniforms(queries[0].window, 1.0f, env_columns_, env_atlas_width_,
                           env_atlas_height_);
    for (const EnvGroup& g : env_groups_) {
      const GpuModel& m = *env_models[g.first_contact];
      bind_geometry(m);
      glUniform1i(iu_.num_levels, m.num_levels);
      glUniform2i(iu_.wrap, m.wrap_u, m.wrap_v);
      int instances = 0;
      instance_data_.clear();
      for (int c = g.first_contact; c < count; ++c) {
        if (env_models[c] != env_models[g.first_contact]) continue;
        add_instance(queries[c].X_WO, queries[c].window, c);
        if (++instances == kInstancesPerDraw) {
          draw_instances(g.range, instances);
          instances = 0;
        }
      }
      draw_instances(g.range, instances);
    }
    glUseProgram(render_program_);
  } else {
    for (int c = 0; c < count; ++c) {
      const ContactQuery& q = queries[c];
      tile(c, env_columns_);
      bind_model(*env_models[c]);
      set_window_uniforms(q.X_WO, q.window, 1.0f);
      draw_range(env_ranges_[static_cast<std::size_t>(c)]);
    }
  }
  // Tool patches A at every gradient sample pose: keep the smallest height per cell.
  glBindFramebuffer(GL_FRAMEBUFFER, tool_fbo_);
  glDepthFunc(GL_LESS);
  glClearDepthf(1.0f);
  bind_model(*tool_model);
  if (instanced) {
    clear_tiles(count * kGradientSamples, tool_columns_);
    glViewport(0, 0, tool_atlas_width_, tool_atlas_height_);
    glUseProgram(instanced_program_);
    set_instanced_uniforms(queries[0].window, -1.0f, tool_columns_, tool_atlas_width_,
                           tool_atlas_height_);
    glUniform1i(iu_.num_levels, tool_model->num_levels);
    glUniform2i(iu_.wrap, tool_model->wrap_u, tool_model->wrap_v);
    int instances = 0;
    instance_data_.clear();
    for (int index = 0; index < count * kGradientSamples; ++index) {
      add_instance(sample_poses_[static_cast<std::size_t>(index)],
                   queries[index / kGradientSamples].window, index);
      if (++instances == kInstancesPerDraw) {
        draw_instances(tool_union_, instances);
        instances = 0;
      }
    }
    draw_instances(tool_union_, instances);
    glUseProgram(render_program_);
  } else {
    for (int c = 0; c < count; ++c) {
      for (int s = 0; s < kGradientSamples; ++s) {
        const int index = c * kGradientSamples + s;
        tile(index, tool_columns_);
        set_window_uniforms(sample_poses_[index], queries[c].window, -1.0f);
        draw_range(tool_ranges_[static_cast<std::size_t>(c)]);
      }
    }
  }
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
  glBindVertexArray(0);
  glDisable(GL_SCISSOR_TEST);
  if (instanced) {
    for (GLenum plane = 0; plane < 4; ++plane) glDisable(kClipDistance0 + plane);
    glBindBufferBase(GL_UNIFORM_BUFFER, 0, 0);
  }
  if (options_.profile_stages) glFinish();
  const auto t2 = Clock::now();

  // Reduction: one work group per tool tile.
  glUseProgram(reduce_program_);
  glActiveTexture(GL_TEXTURE1);
  glBindTexture(GL_TEXTURE_2D, env_depth_);
  glActiveTexture(GL_TEXTURE2);
  glBindTexture(GL_TEXTURE_2D, tool_depth_);
  glActiveTexture(GL_TEXTURE0);
  glUniform1i(rd_.env_depth, 1);
  glUniform1i(rd_.tool_depth, 2);
  glUniform1i(rd_.resolution, n);
  glUniform1i(tile_stride_location_, stride);
  glUniform1i(rd_.env_columns, env_columns_);
  glUniform1i(rd_.tool_columns, tool_columns_);
  glUniform1i(rd_.samples_per_contact, kGradientSamples);
  glUniform1f(rd_.height_scale, static_cast<float>(2.0 * range * kRangeSlack));
  glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 0, results_);
  glDispatchCompute(static_cast<GLuint>(count * kGradientSamples), 1, 1);
  glMemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);
  if (options_.profile_stages) glFinish();
  const auto t3 = Clock::now();
  if (const std::string e = DrainGlErrors(); !e.empty()) {
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 0, 0);
    return Fail("GL error during the batch: " + e);
  }

  // One small readback: kGradientSamples (depth, cell) pairs per contact.
  const GLsizeiptr bytes = static_cast<GLsizeiptr>(count) * kGradientSamples * 8;
  glBindBuffer(GL_SHADER_STORAGE_BUFFER, results_);
  const void* mapped = glMapBufferRange(GL_SHADER_STORAGE_BUFFER, 0, bytes, GL_MAP_READ_BIT);
  if (mapped == nullptr) {
    const std::string e = DrainGlErrors();
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 0, 0);
    return Fail("cannot map the result buffer (" + (e.empty() ? std::string("no GL error") : e) +
                ")");
  }
  const auto* bytes_in = static_cast<const unsigned char*>(mapped);
  for (int i = 0; i < count * kGradientSamples; ++i) {
    float depth;
    std::int32_t cell;
    std::memcpy(&depth, bytes_in + 8 * i, 4);
    std::memcpy(&cell, bytes_in + 8 * i + 4, 4);
    samples_[i] = cell >= 0 ? DepthSample{static_cast<double>(depth), cell}
                            : DepthSample{-std::numeric_limits<double>::infinity(), -1};
  }
  const GLboolean unmapped = glUnmapBuffer(GL_SHADER_STORAGE_BUFFER);
  glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 0, 0);
  if (unmapped != GL_TRUE) return Fail("result buffer contents lost while mapped");
  const auto t4 = Clock::now();

  const bool want_samples = samples_out.size() >= queries.size() * kGradientSamples;
  for (int c = 0; c < count; ++c) {
    const std::span<const DepthSample> s(samples_.data() + c * kGradientSamples, kGradientSamples);
    out[c] = AssembleLinearization(queries[c].window, s, queries[c].stiffness_n_per_m, faults_);
    if (want_samples) std::copy(s.begin(), s.end(), samples_out.begin() + c * kGradientSamples);
  }
  stage_times_ = {us(t1 - t0), us(t2 - t1), us(t3 - t2), us(t4 - t3)};
  return true;
}

PdBackendChoice ParsePdBackendChoice(const std::string& text) {
  if (text == "cpu") return PdBackendChoice::kCpu;
  if (text == "gpu") return PdBackendChoice::kGpu;
  if (text == "auto") return PdBackendChoice::kAuto;
  throw std::invalid_argument("penetration-depth backend must be cpu, gpu or auto, got '" + text +
                              "'");
}

const char* ToString(PdBackendChoice choice) noexcept {
  switch (choice) {
    case PdBackendChoice::kCpu:
      return "cpu";
    case PdBackendChoice::kGpu:
      return "gpu";
    case PdBackendChoice::kAuto:
      return "auto";
  }
  return "?";
}

std::unique_ptr<PenetrationDepthBackend> MakePenetrationDepthBackend(
    PdBackendChoice choice, const GpuPenetrationDepthOptions& gpu_options, int grid_resolution,
    std::string& message, int cpu_threads, RotationGradient cpu_rotation) {
  const int cpu_resolution = std::max(grid_resolution, 2);
  if (choice == PdBackendChoice::kCpu) {
    auto cpu = std::make_unique<CpuPenetrationDepthBackend>(cpu_resolution, TextureStagePath::kFast,
                                                            cpu_threads, cpu_rotation);
    message = "penetration depth on the CPU (requested): " + cpu->description();
    return cpu;
  }
  try {
    GpuPenetrationDepthOptions options = gpu_options;
    options.max_resolution = std::max(options.max_resolution, grid_resolution);
    // A software rasterizer (llvmpipe) is slower than the CPU backend on this stage (see the
    // benchmark): auto takes hardware only; gpu takes whatever starts.
    if (choice == PdBackendChoice::kAuto) options.egl.allow_software = false;
    auto gpu = GpuPenetrationDepthBackend::Create(options);
    message = std::string("penetration depth on the GPU (") + ToString(choice) +
              "): " + gpu->description() + ", vendor " + gpu->info().vendor;
    return gpu;
  } catch (const std::exception& e) {
    message = choice == PdBackendChoice::kGpu
                  ? std::string("GPU penetration depth was requested but cannot start: ") +
                        e.what() + "; falling back to the CPU backend"
                  : std::string("no hardware GPU (") + e.what() +
                        "); penetration depth on the CPU backend (--pd-backend gpu forces a "
                        "software renderer such as llvmpipe)";
    return std::make_unique<CpuPenetrationDepthBackend>(cpu_resolution, TextureStagePath::kFast,
                                                        cpu_threads, cpu_rotation);
  }
}

}  // namespace ht
