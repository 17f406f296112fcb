// The GPU penetration depth backend's set-up (gpu_penetration_depth.h): the context, programs,
// atlases and buffers, and the models' uploads. A batch's renders and reduction: gpu_batch.cc.
#include "haptic_core/gpu_penetration_depth.h"

#include <GLES3/gl31.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <string>

#include "gpu_model.h"
#include "gpu_shaders.h"
#include "haptic_core/gl_program.h"

namespace ht {

using gl::CompileShader;
using gl::DrainGlErrors;
using gl::LinkProgram;
using gpu::kFloatsPerCorner;
using gpu::kInstancedVertexMain;
using gpu::kRangeSlack;
using gpu::kReduceComputeShader;
using gpu::kRenderFragmentShader;
using gpu::kRenderVertexMain;
using gpu::kVertexCommon;

// Who the GL helpers name in their errors.
constexpr const char* kWho = "GPU penetration depth";

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
                     std::string("#version 310 es\n") + kVertexCommon + kRenderVertexMain, kWho,
                     "height vertex shader"),
       CompileShader(GL_FRAGMENT_SHADER, fragment, kWho, "height fragment shader")},
      kWho, "height program");
  reduce_program_ = LinkProgram(
      {CompileShader(GL_COMPUTE_SHADER, kReduceComputeShader, kWho, "reduction compute shader")},
      kWho, "reduction program");

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
                         kWho, "instanced vertex shader"),
           CompileShader(GL_FRAGMENT_SHADER, fragment, kWho, "height fragment shader")},
          kWho, "instanced height program");
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
    for (auto& [key, m] : models_) DeleteModel(*m);
  }
  models_.clear();
}

void GpuPenetrationDepthBackend::DeleteModel(GpuModel& m) noexcept {
  glDeleteVertexArrays(1, &m.vao);
  glDeleteBuffers(1, &m.vbo);
  glDeleteTextures(1, &m.texture);
  m = GpuModel{};
}

void GpuPenetrationDepthBackend::UseScene(const HapticScene& scene) {
  if (!context_ || !context_->MakeCurrent()) {
    throw GpuError(
        "GPU penetration depth: cannot make its EGL context current for the scene's "
        "models");
  }
  std::vector<std::shared_ptr<const HapticModel>> wanted;
  if (scene.tool) wanted.push_back(scene.tool);
  for (const TouchableObject& t : scene.touchables) {
    if (t.model) wanted.push_back(t.model);
  }
  // Kept: the uploads of the scene's models that were held since they were made (a held model
  // is the one at its address); freed: every other, a batch's first-sight uploads among them
  // (their model may be gone and its address another's).
  for (auto it = models_.begin(); it != models_.end();) {
    const bool keep = it->second->held != nullptr &&
                      std::any_of(wanted.begin(), wanted.end(), [&](const auto& p) {
                        return p.get() == it->first && p == it->second->held;
                      });
    if (keep) {
      ++it;
      continue;
    }
    DeleteModel(*it->second);
    it = models_.erase(it);
  }
  for (const std::shared_ptr<const HapticModel>& model : wanted) {
    GpuModel* m = ModelFor(*model);
    if (m == nullptr) {
      throw GpuError("GPU penetration depth: upload of model '" + model->name +
                     "' failed: " + last_error_);
    }
    m->held = model;
  }
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

}  // namespace ht
