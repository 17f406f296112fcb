#pragma once
// Texture penetration depth on the GPU (DESIGN.md §4) [S][L]: per remote step one batch for all
// contacts and all gradient samples. Per contact the environment patch B is rendered once and the
// tool patch A at its kGradientSamples poses (one instanced draw where the context allows; only
// the patch triangles the CPU path would draw), with orthographic projection along n into depth
// tiles of an atlas (heights as depth, B keeping the maximum, A the minimum, both displaced by
// their haptic textures per fragment at the mip level matching the grid cell). A compute shader
// takes b − a per cell and reduces each tile to its maximum and cell; one small readback per
// step. Same conventions as the CPU reference (penetration_depth.h), which it matches to within
// one depth quantum.

#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <unordered_map>
#include <vector>

#include "haptic_core/contact_model.h"
#include "haptic_core/egl_context.h"
#include "haptic_core/penetration_depth.h"
#include "haptic_core/penetration_depth_backend.h"

namespace ht {

/// Options of the GPU backend.
struct GpuPenetrationDepthOptions {
  /// Depth buffer precision: 16 (fixed point, like the seed) or 32 (float).
  int depth_bits = 16;
  /// Largest number of contacts in one batch (the atlases are sized for it at start).
  int max_contacts = kMaxContacts;
  /// Largest grid N (tiles are N×N texels).
  int max_resolution = 128;
  /// Time the stages (upload, draw, reduction, readback) with glFinish between them. Costs
  /// throughput; for benchmarks only.
  bool profile_stages = false;
  EglContextOptions egl;
  /// One instanced draw per side (per environment model) for the whole batch: an instance per
  /// render (each contact's environment, each of its tool poses), each clipped to its own atlas
  /// tile by four clip planes and drawing the union of the batch's patch triangles, where the
  /// context has GL_EXT_clip_cull_distance, a 16 KiB uniform block and a viewport that can span
  /// the atlases (instanced_draws() says whether it is used); else, or when false, one draw per
  /// render, 12 per contact. The same cells either way, depths within a quantum
  /// plus the float geometry's error (tested).
  bool instanced_draws = true;
  /// Testing hook: break the fragment shader's source so that compiling it fails.
  bool inject_shader_compile_error = false;
};

/// Wall time of the stages of the last batch (µs), filled when profile_stages is on.
struct GpuStageTimes {
  /// CPU-side preparation: model lookup (a first-seen model is uploaded here, once), the
  /// gradient sample poses, and each contact's patch triangles (SelectPatchTriangles, as the CPU
  /// path chooses them) into the element buffer. Per-draw uniforms are set inside the draw stage.
  double upload_us = 0.0;
  double draw_us = 0.0;      ///< Rasterizing B and A patches into the depth atlases.
  double reduce_us = 0.0;    ///< Compute shader: b − a and per-tile max.
  double readback_us = 0.0;  ///< Mapping the result buffer.
};

/// The GPU penetration-depth backend. Owns its EGL context (current on the creating thread).
class GpuPenetrationDepthBackend final : public PenetrationDepthBackend {
 public:
  /// Starts a headless context, compiles the shaders and allocates the atlases and buffers.
  /// Throws GpuError with a clear message (no EGL display, no ES 3.1, shader compile or link log,
  /// incomplete framebuffer) and std::invalid_argument for options out of range.
  static std::unique_ptr<GpuPenetrationDepthBackend> Create(
      const GpuPenetrationDepthOptions& options = {});
  ~GpuPenetrationDepthBackend() override;

  std::string_view name() const noexcept override { return "gpu"; }
  /// "<GL_RENDERER> (<GL_VERSION>, <platform>, <bits>-bit depth[, instanced draws])".
  std::string description() const override;
  /// See PenetrationDepthBackend. The models of the scene given to UseScene are uploaded (vertex
  /// buffer and texture with its mip chain) and later batches only set uniforms; any other model
  /// is uploaded when a batch first meets it and kept by its address, until the next UseScene or
  /// ForgetModels (a caller that frees such a model and makes another must call one of them).
  /// Returns false on a GL error or lost context, more queries than max_contacts, a grid larger
  /// than max_resolution, or mixed grid resolutions or window extents in one batch.
  bool LinearizeBatch(const HapticModel& tool, const RigidTransform& X_WT,
                      std::span<const ContactQuery> queries, std::span<ContactLinearization> out,
                      std::span<DepthSample> samples_out = {}) noexcept override;
  const std::string& last_error() const noexcept override { return last_error_; }
  const LinearizationFaults& faults() const noexcept override { return faults_; }

  /// See PenetrationDepthBackend: uploads the scene's tool and touchables (a model already
  /// uploaded for this scene or the last one, and held since, is kept), holding them, and frees
  /// every other upload; makes the backend's context current first. Throws GpuError when the
  /// context cannot be made current or an upload fails.
  void UseScene(const HapticScene& scene) override;
  /// Frees every uploaded model; the next batch or UseScene uploads again.
  void ForgetModels() noexcept;

  const GpuInfo& info() const noexcept { return context_->info(); }
  int depth_bits() const noexcept { return options_.depth_bits; }
  /// True when the batch is drawn instanced (GpuPenetrationDepthOptions::instanced_draws).
  bool instanced_draws() const noexcept { return instanced_program_ != 0; }
  /// Height resolution of the depth buffer for `window` (m): 2R'/(2^16 − 1) at 16 bits, with R'
  /// slightly above the window's depth range R; at 32 bits the float spacing near the middle of
  /// the range, 2R'·2^−24.
  double DepthQuantum(const ContactWindow& window) const noexcept;
  const GpuStageTimes& stage_times() const noexcept { return stage_times_; }

  /// Testing hook: deletes the tile program behind the backend's back, so that the next batch
  /// meets a real GL error (as after a lost context) and must fail cleanly.
  void BreakProgramForTesting() noexcept;

 private:
  struct GpuModel;  // src/gpu/gpu_model.h
  struct Batch;     // one LinearizeBatch call's steps (src/gpu/gpu_batch.cc)
  explicit GpuPenetrationDepthBackend(const GpuPenetrationDepthOptions& options);
  void Initialize();
  GpuModel* ModelFor(const HapticModel& model);
  /// Deletes m's GL objects (the context is current).
  static void DeleteModel(GpuModel& m) noexcept;
  bool Fail(std::string why) noexcept;

  GpuPenetrationDepthOptions options_;
  std::unique_ptr<EglContext> context_;
  std::unordered_map<const HapticModel*, std::unique_ptr<GpuModel>> models_;
  // GL objects (names), all created in Initialize().
  unsigned render_program_ = 0, reduce_program_ = 0;
  unsigned env_depth_ = 0, tool_depth_ = 0, env_fbo_ = 0, tool_fbo_ = 0, results_ = 0;
  int env_columns_ = 1, tool_columns_ = 1;
  int tile_stride_location_ = -1;
  struct RenderUniforms {
    int row_u = -1, row_v = -1, row_n = -1, half_extent = -1, cell_size = -1, facing_sign = -1,
        num_levels = -1, wrap = -1, depth_range = -1, depth_scale = -1, texture = -1;
  } ru_;
  unsigned instanced_program_ = 0;               // 0: a draw per render
  unsigned instance_ubo_ = 0;                    // the Instances block: 4 vec4 per instance
  static constexpr int kInstancesPerDraw = 256;  // 16 KiB, the smallest GL_MAX_UNIFORM_BLOCK_SIZE
  int tool_atlas_width_ = 0, tool_atlas_height_ = 0, env_atlas_width_ = 0, env_atlas_height_ = 0;
  struct InstancedUniforms {
    int half_extent = -1, cell_size = -1, facing_sign = -1, num_levels = -1, wrap = -1,
        depth_range = -1, depth_scale = -1, texture = -1, columns = -1, tile_stride = -1,
        cells = -1, atlas_size = -1;
  } iu_;
  std::vector<float> instance_data_;  // scratch: the Instances block of one draw
  struct ReduceUniforms {
    int env_depth = -1, tool_depth = -1, resolution = -1, env_columns = -1, tool_columns = -1,
        samples_per_contact = -1, height_scale = -1;
  } rd_;
  // The patch triangles of a batch's contacts (SelectPatchTriangles) as corner index ranges of
  // patch_ebo_ (first index and count): one per contact and side, or (instanced) one per
  // environment model and one for the tool.
  struct PatchRange {
    int first = 0, count = 0;
  };
  unsigned patch_ebo_ = 0;
  std::vector<unsigned> patch_indices_;               // scratch: the element buffer's contents
  std::vector<int> patch_triangles_;                  // scratch
  std::vector<PatchRange> env_ranges_, tool_ranges_;  // #max_contacts (a draw per render)
  // Instanced: the union of the batch's patch triangles per environment model and for the tool.
  struct EnvGroup {
    int first_contact = 0;
    PatchRange range;
  };
  std::vector<EnvGroup> env_groups_;
  PatchRange tool_union_;
  std::vector<std::uint32_t> union_mark_;     // per triangle: the stamp of the range holding it
  std::uint32_t union_stamp_ = 0;             // the range being gathered
  std::vector<RigidTransform> sample_poses_;  // scratch, #max_contacts*kGradientSamples
  std::vector<DepthSample> samples_;          // scratch, same size
  LinearizationFaults faults_;
  GpuStageTimes stage_times_;
  std::string last_error_;
  bool broken_ = false;
};

/// Which penetration-depth backend the remote node uses.
enum class PdBackendChoice { kCpu, kGpu, kAuto };

/// Parses "cpu", "gpu" or "auto"; throws std::invalid_argument naming the bad value.
PdBackendChoice ParsePdBackendChoice(const std::string& text);
const char* ToString(PdBackendChoice choice) noexcept;

/// Makes the backend for `choice`. kCpu: the CPU backend (fast path). kGpu: the GPU backend on any
/// context that starts (a real GPU first, else llvmpipe). kAuto: the GPU backend on a hardware GPU
/// only, since a software rasterizer is slower than the CPU backend for this stage. When the GPU
/// cannot start or its shaders do not build: the CPU backend, with the reason in `message`
/// (which always says what was chosen and why), on `cpu_threads` threads. Never throws for a GPU
/// failure.
std::unique_ptr<PenetrationDepthBackend> MakePenetrationDepthBackend(
    PdBackendChoice choice, const GpuPenetrationDepthOptions& gpu_options, int grid_resolution,
    std::string& message, int cpu_threads = 1);

}  // namespace ht
