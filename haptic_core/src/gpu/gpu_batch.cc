// One batch of the GPU penetration depth (gpu_penetration_depth.h, DESIGN.md §4): the contacts'
// patch triangles into one element buffer, the environment patches and the tool patches at every
// gradient sample pose rendered into the depth atlases, the compute shader's reduction per tile,
// one readback, and each contact's linearization.
#include <GLES3/gl31.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cstdint>
#include <cstring>
#include <glm/geometric.hpp>
#include <glm/gtc/quaternion.hpp>
#include <limits>
#include <string>

#include "gpu_model.h"
#include "gpu_shaders.h"
#include "haptic_core/gl_program.h"
#include "haptic_core/gpu_penetration_depth.h"

namespace ht {
namespace {

using gpu::kRangeSlack;

// Rows of the map from object frame O to window coordinates (s, t, height) for a body at X_WO:
// xyz the window's axis in O, w the axis · (p_WO − c_W) (the vertex stages' row_u/v/n).
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

constexpr GLenum kClipDistance0 = 0x3000;  // GL_CLIP_DISTANCE0_EXT

void DrawRange(int first, int count) {
  if (count == 0) return;
  glDrawElements(
      GL_TRIANGLES, count, GL_UNSIGNED_INT,
      reinterpret_cast<const void*>(static_cast<std::uintptr_t>(first) * sizeof(GLuint)));
}

}  // namespace

// One LinearizeBatch call on the backend's context: its contacts, their models, the grid N and
// depth range shared by all, and the steps in the order LinearizeBatch calls them.
struct GpuPenetrationDepthBackend::Batch {
  Batch(GpuPenetrationDepthBackend& backend, const HapticModel& tool_model_in,
        const RigidTransform& X_WT_in, std::span<const ContactQuery> queries_in) noexcept
      : b(backend),
        tool(tool_model_in),
        X_WT(X_WT_in),
        queries(queries_in),
        count(static_cast<int>(queries_in.size())),
        n(queries_in[0].window.resolution),
        stride(queries_in[0].window.resolution),
        range(queries_in[0].window.depth_range_m()) {
    // The instanced draws render a side's union of the batch's lists into every contact's tile,
    // which would render one cluster's triangles in another's window: a batch whose contacts
    // carry their clusters' own triangles (TriangleSubset) is drawn one contact at a time.
    const bool own_triangles = std::any_of(queries.begin(), queries.end(), [](const auto& q) {
      return !q.environment_triangles.all || !q.tool_triangles.all;
    });
    instanced = b.instanced_program_ != 0 && !own_triangles;
  }

  // The uploaded tool and environment models (a model seen for the first time is uploaded).
  bool FindModels() noexcept {
    try {
      tool_model = b.ModelFor(tool);
      for (int c = 0; c < count; ++c) env_models[c] = b.ModelFor(*queries[c].environment);
    } catch (const std::exception& e) {  // allocation failure on a first upload
      return b.Fail(std::string("model upload: ") + e.what());
    }
    if (tool_model == nullptr) return false;
    for (int c = 0; c < count; ++c) {
      if (env_models[c] == nullptr) return false;
    }
    return true;
  }

  // Each contact's kGradientSamples tool poses (GradientSamplePoses), in contact order.
  void ComputeSamplePoses() noexcept {
    for (int c = 0; c < count; ++c) {
      const auto poses = GradientSamplePoses(X_WT, queries[c].window);
      std::copy(poses.begin(), poses.end(), b.sample_poses_.begin() + c * kGradientSamples);
    }
  }

  // Each contact's patch triangles, chosen as the CPU path chooses them (SelectPatchTriangles:
  // the environment's on the window grown by a cell; the tool's with the margins of all eleven
  // sample poses), as ranges of one element buffer of corner indices, uploaded: the draws process
  // those triangles, not whole models. Instanced: one range per environment model (in order of
  // its first contact) and one for the tool, each the union of its contacts' lists; else one per
  // contact and side.
  bool GatherPatchTriangles() noexcept {
    b.patch_indices_.clear();
    b.env_groups_.clear();
    try {
      if (instanced) {
        for (int c = 0; c < count; ++c) {
          bool seen = false;
          for (const EnvGroup& g : b.env_groups_) {
            seen = seen || env_models[g.first_contact] == env_models[c];
          }
          if (seen) continue;
          const int first = BeginRange();
          for (int k = c; k < count; ++k) {
            if (env_models[k] != env_models[c]) continue;
            SelectEnvironment(k);
            Append(queries[k].environment->triangles.size());
          }
          b.env_groups_.push_back({c, EndRange(first)});
        }
        const int first = BeginRange();
        for (int c = 0; c < count; ++c) {
          SelectTool(c);
          Append(tool.triangles.size());
        }
        b.tool_union_ = EndRange(first);
      } else {
        for (int c = 0; c < count; ++c) {
          int first = BeginRange();
          SelectEnvironment(c);
          Append(queries[c].environment->triangles.size());
          b.env_ranges_[static_cast<std::size_t>(c)] = EndRange(first);
          first = BeginRange();
          SelectTool(c);
          Append(tool.triangles.size());
          b.tool_ranges_[static_cast<std::size_t>(c)] = EndRange(first);
        }
      }
    } catch (const std::exception& e) {  // allocation failure while the lists grow
      return b.Fail(std::string("patch triangle lists: ") + e.what());
    }
    glBindVertexArray(0);
    glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, b.patch_ebo_);
    glBufferData(GL_ELEMENT_ARRAY_BUFFER,
                 static_cast<GLsizeiptr>(b.patch_indices_.size() * sizeof(GLuint)),
                 b.patch_indices_.data(), GL_STREAM_DRAW);
    return true;
  }

  // The render state both sides share: the per-render program, depth test, scissor, and the
  // instanced draws' clip planes.
  void BeginRenders() noexcept {
    glUseProgram(b.render_program_);
    glUniform1i(b.ru_.texture, 0);
    glEnable(GL_DEPTH_TEST);
    glEnable(GL_SCISSOR_TEST);
    glDisable(GL_CULL_FACE);
    glDisable(GL_BLEND);
    glDepthMask(GL_TRUE);
    if (instanced) {
      for (GLenum plane = 0; plane < 4; ++plane) glEnable(kClipDistance0 + plane);
    }
  }

  // Environment patches B, one tile per contact: the largest height per cell.
  void RenderEnvironment() noexcept {
    glBindFramebuffer(GL_FRAMEBUFFER, b.env_fbo_);
    glDepthFunc(GL_GREATER);
    glClearDepthf(0.0f);
    if (instanced) {
      ClearTiles(count, b.env_columns_);
      glViewport(0, 0, b.env_atlas_width_, b.env_atlas_height_);
      glUseProgram(b.instanced_program_);
      SetInstancedUniforms(queries[0].window, 1.0f, b.env_columns_, b.env_atlas_width_,
                           b.env_atlas_height_);
      for (const EnvGroup& g : b.env_groups_) {
        const GpuModel& m = *env_models[g.first_contact];
        BindGeometry(m);
        glUniform1i(b.iu_.num_levels, m.num_levels);
        glUniform2i(b.iu_.wrap, m.wrap_u, m.wrap_v);
        int instances = 0;
        b.instance_data_.clear();
        for (int c = g.first_contact; c < count; ++c) {
          if (env_models[c] != env_models[g.first_contact]) continue;
          AddInstance(queries[c].X_WO, queries[c].window, c);
          if (++instances == kInstancesPerDraw) {
            DrawInstances(g.range, instances);
            instances = 0;
          }
        }
        DrawInstances(g.range, instances);
      }
      glUseProgram(b.render_program_);
    } else {
      for (int c = 0; c < count; ++c) {
        const ContactQuery& q = queries[c];
        Tile(c, b.env_columns_);
        BindModel(*env_models[c]);
        SetWindowUniforms(q.X_WO, q.window, 1.0f);
        const PatchRange& r = b.env_ranges_[static_cast<std::size_t>(c)];
        DrawRange(r.first, r.count);
      }
    }
  }

  // Tool patches A at every gradient sample pose, one tile per contact and pose: the smallest
  // height per cell.
  void RenderTool() noexcept {
    glBindFramebuffer(GL_FRAMEBUFFER, b.tool_fbo_);
    glDepthFunc(GL_LESS);
    glClearDepthf(1.0f);
    BindModel(*tool_model);
    if (instanced) {
      ClearTiles(count * kGradientSamples, b.tool_columns_);
      glViewport(0, 0, b.tool_atlas_width_, b.tool_atlas_height_);
      glUseProgram(b.instanced_program_);
      SetInstancedUniforms(queries[0].window, -1.0f, b.tool_columns_, b.tool_atlas_width_,
                           b.tool_atlas_height_);
      glUniform1i(b.iu_.num_levels, tool_model->num_levels);
      glUniform2i(b.iu_.wrap, tool_model->wrap_u, tool_model->wrap_v);
      int instances = 0;
      b.instance_data_.clear();
      for (int index = 0; index < count * kGradientSamples; ++index) {
        AddInstance(b.sample_poses_[static_cast<std::size_t>(index)],
                    queries[index / kGradientSamples].window, index);
        if (++instances == kInstancesPerDraw) {
          DrawInstances(b.tool_union_, instances);
          instances = 0;
        }
      }
      DrawInstances(b.tool_union_, instances);
      glUseProgram(b.render_program_);
    } else {
      for (int c = 0; c < count; ++c) {
        for (int s = 0; s < kGradientSamples; ++s) {
          const int index = c * kGradientSamples + s;
          Tile(index, b.tool_columns_);
          SetWindowUniforms(b.sample_poses_[index], queries[c].window, -1.0f);
          const PatchRange& r = b.tool_ranges_[static_cast<std::size_t>(c)];
          DrawRange(r.first, r.count);
        }
      }
    }
  }

  // Back to the default framebuffer and state after the renders.
  void EndRenders() noexcept {
    glBindFramebuffer(GL_FRAMEBUFFER, 0);
    glBindVertexArray(0);
    glDisable(GL_SCISSOR_TEST);
    if (instanced) {
      for (GLenum plane = 0; plane < 4; ++plane) glDisable(kClipDistance0 + plane);
      glBindBufferBase(GL_UNIFORM_BUFFER, 0, 0);
    }
  }

  // The reduction: one work group per tool tile takes b − a per cell and keeps the largest and
  // its cell.
  void Reduce() noexcept {
    glUseProgram(b.reduce_program_);
    glActiveTexture(GL_TEXTURE1);
    glBindTexture(GL_TEXTURE_2D, b.env_depth_);
    glActiveTexture(GL_TEXTURE2);
    glBindTexture(GL_TEXTURE_2D, b.tool_depth_);
    glActiveTexture(GL_TEXTURE0);
    glUniform1i(b.rd_.env_depth, 1);
    glUniform1i(b.rd_.tool_depth, 2);
    glUniform1i(b.rd_.resolution, n);
    glUniform1i(b.tile_stride_location_, stride);
    glUniform1i(b.rd_.env_columns, b.env_columns_);
    glUniform1i(b.rd_.tool_columns, b.tool_columns_);
    glUniform1i(b.rd_.samples_per_contact, kGradientSamples);
    glUniform1f(b.rd_.height_scale, static_cast<float>(2.0 * range * kRangeSlack));
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 0, b.results_);
    glDispatchCompute(static_cast<GLuint>(count * kGradientSamples), 1, 1);
    glMemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);
  }

  // One small readback: kGradientSamples (depth, cell) pairs per contact into samples_.
  bool ReadBack() noexcept {
    const GLsizeiptr bytes = static_cast<GLsizeiptr>(count) * kGradientSamples * 8;
    glBindBuffer(GL_SHADER_STORAGE_BUFFER, b.results_);
    const void* mapped = glMapBufferRange(GL_SHADER_STORAGE_BUFFER, 0, bytes, GL_MAP_READ_BIT);
    if (mapped == nullptr) {
      const std::string e = gl::DrainGlErrors();
      glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 0, 0);
      return b.Fail("cannot map the result buffer (" +
                    (e.empty() ? std::string("no GL error") : e) + ")");
    }
    const auto* bytes_in = static_cast<const unsigned char*>(mapped);
    for (int i = 0; i < count * kGradientSamples; ++i) {
      float depth;
      std::int32_t cell;
      std::memcpy(&depth, bytes_in + 8 * i, 4);
      std::memcpy(&cell, bytes_in + 8 * i + 4, 4);
      b.samples_[i] = cell >= 0 ? DepthSample{static_cast<double>(depth), cell}
                                : DepthSample{-std::numeric_limits<double>::infinity(), -1};
    }
    const GLboolean unmapped = glUnmapBuffer(GL_SHADER_STORAGE_BUFFER);
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 0, 0);
    if (unmapped != GL_TRUE) return b.Fail("result buffer contents lost while mapped");
    return true;
  }

 private:
  void SelectEnvironment(int c) {
    const ContactQuery& q = queries[c];
    SelectPatchTrianglesIn(q.environment_triangles, *q.environment, q.X_WO, q.window,
                           PatchSide::kEnvironment, q.window.cell_size_m(), b.patch_triangles_);
  }
  void SelectTool(int c) {
    const ContactWindow& w = queries[c].window;
    const GradientSteps h = GradientSteps::For(w);
    SelectPatchTrianglesIn(queries[c].tool_triangles, tool, X_WT, w, PatchSide::kTool, 2.0 * h.h_x,
                           b.patch_triangles_, h.h_theta + 1e-9, nullptr, nullptr, h.h_theta);
  }
  // A range of the element buffer: begun, then patch_triangles_ appended to it one or more times
  // (each triangle once: a triangle is marked with the range's stamp when it enters, so that an
  // instanced range holds the union of its contacts' lists), then ended.
  int BeginRange() noexcept {
    if (++b.union_stamp_ == 0) {  // wrapped: no triangle may carry the new stamp by accident
      std::fill(b.union_mark_.begin(), b.union_mark_.end(), 0u);
      b.union_stamp_ = 1;
    }
    return static_cast<int>(b.patch_indices_.size());
  }
  void Append(std::size_t triangle_count) {
    if (b.union_mark_.size() < triangle_count) b.union_mark_.resize(triangle_count, 0);
    for (const int f : b.patch_triangles_) {
      std::uint32_t& mark = b.union_mark_[static_cast<std::size_t>(f)];
      if (mark == b.union_stamp_) continue;
      mark = b.union_stamp_;
      const auto corner = static_cast<GLuint>(3 * f);
      b.patch_indices_.push_back(corner);
      b.patch_indices_.push_back(corner + 1);
      b.patch_indices_.push_back(corner + 2);
    }
  }
  PatchRange EndRange(int first) const noexcept {
    return PatchRange{first, static_cast<int>(b.patch_indices_.size()) - first};
  }

  // A draw per render: the window's rows and extents into the per-render program.
  void SetWindowUniforms(const RigidTransform& X, const ContactWindow& w,
                         float facing_sign) noexcept {
    const WindowRows r = RowsFor(X, w);
    glUniform4fv(b.ru_.row_u, 1, r.u);
    glUniform4fv(b.ru_.row_v, 1, r.v);
    glUniform4fv(b.ru_.row_n, 1, r.n);
    glUniform1f(b.ru_.half_extent, static_cast<float>(0.5 * w.extent_m));
    glUniform1f(b.ru_.cell_size, static_cast<float>(w.cell_size_m()));
    glUniform1f(b.ru_.facing_sign, facing_sign);
    glUniform1f(b.ru_.depth_range, static_cast<float>(w.depth_range_m()));
    glUniform1f(b.ru_.depth_scale,
                static_cast<float>(1.0 / (2.0 * w.depth_range_m() * kRangeSlack)));
  }
  // A model's vertices, the batch's element buffer and the model's texture.
  void BindGeometry(const GpuModel& m) noexcept {
    glBindVertexArray(m.vao);
    glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, b.patch_ebo_);  // part of the VAO's state
    glActiveTexture(GL_TEXTURE0);
    glBindTexture(GL_TEXTURE_2D, m.texture);
  }
  // BindGeometry, and the per-render program's texture uniforms (that program current).
  void BindModel(const GpuModel& m) noexcept {
    BindGeometry(m);
    glUniform1i(b.ru_.num_levels, m.num_levels);
    glUniform2i(b.ru_.wrap, m.wrap_u, m.wrap_v);
  }
  // Tiles are packed at the batch's N (the atlases are sized for N_max tiles, so N×N ones fit),
  // so that the tiles a batch uses are close together (one clear covers them).
  void Tile(int index, int columns) const noexcept {
    const int x = (index % columns) * stride, y = (index / columns) * stride;
    glViewport(x, y, n, n);
    glScissor(x, y, n, n);
    glClear(GL_DEPTH_BUFFER_BIT);
  }
  // The instanced draws' clear of the first `tiles` tiles of an atlas at once (whole rows).
  void ClearTiles(int tiles, int columns) const noexcept {
    const int rows = (tiles + columns - 1) / columns;
    glEnable(GL_SCISSOR_TEST);
    glScissor(0, 0, std::min(tiles, columns) * stride, rows * stride);
    glClear(GL_DEPTH_BUFFER_BIT);
    glDisable(GL_SCISSOR_TEST);
  }
  // The instanced program's per-batch uniforms (one window extent and N per batch).
  void SetInstancedUniforms(const ContactWindow& w, float facing_sign, int columns, int width,
                            int height) const noexcept {
    glUniform1i(b.iu_.texture, 0);
    glUniform1f(b.iu_.half_extent, static_cast<float>(0.5 * w.extent_m));
    glUniform1f(b.iu_.cell_size, static_cast<float>(w.cell_size_m()));
    glUniform1f(b.iu_.facing_sign, facing_sign);
    glUniform1f(b.iu_.depth_range, static_cast<float>(w.depth_range_m()));
    glUniform1f(b.iu_.depth_scale,
                static_cast<float>(1.0 / (2.0 * w.depth_range_m() * kRangeSlack)));
    glUniform1i(b.iu_.columns, columns);
    glUniform1f(b.iu_.tile_stride, static_cast<float>(stride));
    glUniform1f(b.iu_.cells, static_cast<float>(n));
    glUniform2f(b.iu_.atlas_size, static_cast<float>(width), static_cast<float>(height));
  }
  // An instance's rows and tile, gathered for the next DrawInstances.
  void AddInstance(const RigidTransform& X, const ContactWindow& w, int tile_index) {
    const WindowRows r = RowsFor(X, w);
    b.instance_data_.insert(b.instance_data_.end(), r.u, r.u + 4);
    b.instance_data_.insert(b.instance_data_.end(), r.v, r.v + 4);
    b.instance_data_.insert(b.instance_data_.end(), r.n, r.n + 4);
    const float tile_row[4] = {static_cast<float>(tile_index), 0.0f, 0.0f, 0.0f};
    b.instance_data_.insert(b.instance_data_.end(), tile_row, tile_row + 4);
  }
  // A draw of the instances gathered (then none).
  void DrawInstances(const PatchRange& patch, int instances) {
    if (instances > 0 && patch.count > 0) {
      glBindBuffer(GL_UNIFORM_BUFFER, b.instance_ubo_);
      // A fresh store (the previous draw may still read the old one), then the instances.
      glBufferData(GL_UNIFORM_BUFFER, kInstancesPerDraw * 16 * sizeof(float), nullptr,
                   GL_STREAM_DRAW);
      glBufferSubData(GL_UNIFORM_BUFFER, 0,
                      static_cast<GLsizeiptr>(b.instance_data_.size() * sizeof(float)),
                      b.instance_data_.data());
      glBindBufferBase(GL_UNIFORM_BUFFER, 0, b.instance_ubo_);
      glDrawElementsInstanced(
          GL_TRIANGLES, patch.count, GL_UNSIGNED_INT,
          reinterpret_cast<const void*>(static_cast<std::uintptr_t>(patch.first) * sizeof(GLuint)),
          instances);
    }
    b.instance_data_.clear();
  }

 public:
  GpuPenetrationDepthBackend& b;
  const HapticModel& tool;
  const RigidTransform& X_WT;
  const std::span<const ContactQuery> queries;
  const int count;
  const int n;         // every window's grid N
  const int stride;    // tiles' spacing in the atlases (N)
  const double range;  // every window's depth range R (m): one depth encoding per batch
  GpuModel* tool_model = nullptr;
  std::array<GpuModel*, 256> env_models{};
  bool instanced = false;  // one instanced draw per side (GpuPenetrationDepthOptions)
};

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
  Batch batch(*this, tool, X_WT, queries);
  if (!batch.FindModels()) return false;
  batch.ComputeSamplePoses();
  if (!batch.GatherPatchTriangles()) return false;
  const auto t1 = Clock::now();

  batch.BeginRenders();
  batch.RenderEnvironment();
  batch.RenderTool();
  batch.EndRenders();
  if (options_.profile_stages) glFinish();
  const auto t2 = Clock::now();

  batch.Reduce();
  if (options_.profile_stages) glFinish();
  const auto t3 = Clock::now();
  if (const std::string e = gl::DrainGlErrors(); !e.empty()) {
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 0, 0);
    return Fail("GL error during the batch: " + e);
  }
  if (!batch.ReadBack()) return false;
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

}  // namespace ht
