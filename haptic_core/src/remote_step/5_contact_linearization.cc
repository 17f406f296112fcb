// Stage 5 of the remote step (contact_linearization.h): the CPU texture solver's renders and
// its linearization of one contact. The finite differences:
// 5_linearization_assembly.cc; the overlap's regions: 5_overlap_regions.cc.
#include <oneapi/tbb/parallel_for.h>
#include <oneapi/tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "haptic_core/contact_linearization.h"

namespace ht {

TexturePenetrationSolver::TexturePenetrationSolver(int max_resolution, int max_triangles,
                                                   TextureStagePath path)
    : path_(path), links_(max_resolution) {
  const size_t cells = static_cast<size_t>(max_resolution) * max_resolution;
  env_heights_.reserve(cells);
  tool_heights_.reserve(cells);
  tool_ext_heights_.reserve(static_cast<size_t>(max_resolution + 2) * (max_resolution + 2));
  max_resolution_ = max_resolution;
  env_triangles_.reserve(static_cast<size_t>(max_triangles));
  tool_triangles_.reserve(static_cast<size_t>(max_triangles));
  vertex_scratch_.reserve(static_cast<size_t>(max_triangles));  // a closed mesh: V ≈ F/2
  first_triangles_.reserve(64);
  env_max_.Reserve(max_resolution);
  env_row_max_.Reserve(max_resolution);
  tool_bounds_.Reserve(static_cast<size_t>(max_triangles));
  region_parent_.reserve(cells);
  overlap_depth_.reserve(cells);
  bridge_level_.reserve(cells);
}

void TexturePenetrationSolver::RenderEnvironment(const HapticModel& environment,
                                                 const RigidTransform& X_WO, const ContactWindow& w,
                                                 TriangleSubset subset) noexcept {
  const size_t cells = static_cast<size_t>(w.resolution) * w.resolution;
  env_heights_.assign(cells, -std::numeric_limits<float>::infinity());
  SelectPatchTrianglesIn(subset, environment, X_WO, w, PatchSide::kEnvironment, w.cell_size_m(),
                         env_triangles_, 0.0, &vertex_scratch_);
  if (path_ == TextureStagePath::kFast) {
    RenderPatchHeightsFast(environment, X_WO, env_triangles_, w, PatchSide::kEnvironment, 0,
                           env_heights_);
  } else {
    RenderPatchHeights(environment, X_WO, env_triangles_, w, PatchSide::kEnvironment, env_heights_);
  }
}

DepthSample TexturePenetrationSolver::EvaluateTool(const HapticModel& tool,
                                                   const RigidTransform& X_WT,
                                                   const ContactWindow& w) noexcept {
  const size_t cells = static_cast<size_t>(w.resolution) * w.resolution;
  tool_heights_.assign(cells, std::numeric_limits<float>::infinity());
  if (path_ == TextureStagePath::kFast) {
    RenderPatchHeightsFast(tool, X_WT, tool_triangles_, w, PatchSide::kTool, 0, tool_heights_);
  } else {
    RenderPatchHeights(tool, X_WT, tool_triangles_, w, PatchSide::kTool, tool_heights_);
  }
  return DirectionalPenetrationDepth(env_heights_, tool_heights_);
}

DepthSample TexturePenetrationSolver::Depth(const HapticModel& tool, const RigidTransform& X_WT,
                                            const HapticModel& environment,
                                            const RigidTransform& X_WO, const ContactWindow& w,
                                            TriangleSubset environment_triangles,
                                            TriangleSubset tool_triangles) noexcept {
  RenderEnvironment(environment, X_WO, w, environment_triangles);
  SelectPatchTrianglesIn(tool_triangles, tool, X_WT, w, PatchSide::kTool, w.cell_size_m(),
                         tool_triangles_, 0.0, &vertex_scratch_);
  return EvaluateTool(tool, X_WT, w);
}

ContactLinearization TexturePenetrationSolver::Linearize(
    const HapticModel& tool, const RigidTransform& X_WT, const HapticModel& environment,
    const RigidTransform& X_WO, const ContactWindow& w, double stiffness_n_per_m,
    std::span<DepthSample> samples_out, TriangleSubset environment_triangles,
    TriangleSubset tool_triangles, std::span<float> base_overlap_out) noexcept {
  const GradientSteps h = GradientSteps::For(w);
  // The base pose's b − a (base_overlap_out), from the tool heights `t` (stride, border cells).
  const auto keep_base_overlap = [&](const std::vector<float>& t, int stride, int border) {
    const int n = w.resolution;
    if (base_overlap_out.size() < static_cast<std::size_t>(n) * n) return;
    for (int j = 0; j < n; ++j) {
      const float* a = t.data() + static_cast<std::size_t>(j + border) * stride + border;
      const float* b = env_heights_.data() + static_cast<std::size_t>(j) * n;
      float* o = base_overlap_out.data() + static_cast<std::size_t>(j) * n;
      for (int i = 0; i < n; ++i) o[i] = b[i] - a[i];
    }
  };

  RenderEnvironment(environment, X_WO, w, environment_triangles);
  // Tool triangles are chosen once, with margins that cover every perturbed pose (the render
  // re-checks facing at each pose).
  SelectPatchTrianglesIn(tool_triangles, tool, X_WT, w, PatchSide::kTool, 2.0 * h.h_x,
                         tool_triangles_, h.h_theta + 1e-9, &vertex_scratch_, nullptr, h.h_theta);
  std::array<DepthSample, kGradientSamples> samples;
  for (DepthSample& s : samples) s = {-std::numeric_limits<double>::infinity(), -1};
  if (path_ == TextureStagePath::kFast) {
    // The base pose on the window grown by one cell gives the four translations (RenderGrownBase);
    // the six rotations are rendered.
    const size_t cells = static_cast<size_t>(w.resolution) * w.resolution;
    const auto poses = GradientSamplePoses(X_WT, w);
    bool done = false;
    if (parallel_renders_) {
      // The seven renders at once, each into its own buffer. The rotations start with the base
      // (measured faster on two threads than the base first: 211 against 259 µs on fig75), so
      // when the base finds no overlap they are computed and discarded below, renders the
      // serial path never makes.
      try {
        // Isolated: while this thread waits for the seven, it must not pick up another contact
        // of the batch, which would run on this same solver (one solver per thread).
        oneapi::tbb::this_task_arena::isolate([&] {
          oneapi::tbb::parallel_for(0, 7, [&](int task) {
            if (task == 0) {
              RenderGrownBase(tool, X_WT, w, samples);
              return;
            }
            std::vector<float>& heights = rotation_heights_[static_cast<size_t>(task - 1)];
            const RigidTransform& pose = poses[static_cast<size_t>(task + 4)];
            if (cull_rotations_ == CullRotations::kAlways) {
              // No first cell: the base is rendered at the same time.
              heights.resize(cells);
              ToolDepthCull hints;
              samples[static_cast<size_t>(task + 4)] =
                  RenderToolDepth(tool, pose, tool_triangles_, w, env_heights_, heights, hints);
              return;
            }
            heights.assign(cells, std::numeric_limits<float>::infinity());
            RenderPatchHeightsFast(tool, pose, tool_triangles_, w, PatchSide::kTool, 0, heights);
            samples[static_cast<size_t>(task + 4)] =
                DirectionalPenetrationDepth(env_heights_, heights);
          });
        });
        done = true;
      } catch (...) {
        done = false;  // could not spawn the tasks: the serial path below
      }
    }
    if (!done) {
      RenderGrownBase(tool, X_WT, w, samples);
      if (samples[0].cell >= 0) {
        // Each rotation's depth alone, its render culled to the cells that can matter
        // (RenderToolDepth), from the cells around the unrotated pose's deepest cell; under
        // kWhenItPays, only while the first rotation drew few enough cells for it to pay.
        tool_heights_.resize(cells);
        bool cull = cull_rotations_ != CullRotations::kNever;
        // The environment's max pyramid skips whole tool triangles; building it (about a
        // microsecond) pays where the tool brings many (fig77's file: 131-142 against 146-151 µs
        // per contact), not for a few large ones (the block on the gear).
        const bool pyramid = cull && tool_triangles_.size() > kPyramidTriangles;
        if (pyramid) env_max_.Build(env_heights_, w.resolution);
        if (cull) env_row_max_.Build(env_heights_, w.resolution);
        tool_bounds_.Reset(tool, w.cell_size_m());
        for (int i = 5; i < kGradientSamples; ++i) {
          if (!cull) {
            samples[i] = EvaluateTool(tool, poses[i], w);
            continue;
          }
          // The first rotation's first pass finds the triangles around the deepest cell; the
          // other five start from those.
          ToolDepthCull hints;
          hints.first_cell = samples[0].cell;
          hints.env_max = pyramid ? &env_max_ : nullptr;
          hints.env_row_max = &env_row_max_;
          hints.bounds = &tool_bounds_;
          if (i == 5) {
            hints.first_triangles_out = &first_triangles_;
          } else {
            hints.first_triangles = first_triangles_;
          }
          samples[i] = RenderToolDepth(tool, poses[i], tool_triangles_, w, env_heights_,
                                       tool_heights_, hints);
          if (i == 5 && cull_rotations_ == CullRotations::kWhenItPays &&
              hints.cells_drawn > kCullPaysFraction * static_cast<double>(cells)) {
            cull = false;
          }
        }
        if (cull) ++culled_contacts_;
      }
    }
    if (samples[0].cell >= 0) keep_base_overlap(tool_ext_heights_, w.resolution + 2, 1);
  } else {
    samples[0] = EvaluateTool(tool, X_WT, w);
    if (samples[0].cell >= 0) {
      keep_base_overlap(tool_heights_, w.resolution, 0);
      const auto poses = GradientSamplePoses(X_WT, w);
      for (int i = 1; i < kGradientSamples; ++i) samples[i] = EvaluateTool(tool, poses[i], w);
    }
  }
  if (samples[0].cell < 0) {
    for (int i = 1; i < kGradientSamples; ++i) samples[i] = samples[0];
  }
  if (samples_out.size() >= samples.size())
    std::copy(samples.begin(), samples.end(), samples_out.begin());
  return AssembleLinearization(w, samples, stiffness_n_per_m, faults_);
}

void TexturePenetrationSolver::RenderGrownBase(const HapticModel& tool, const RigidTransform& X_WT,
                                               const ContactWindow& w,
                                               std::span<DepthSample> samples) noexcept {
  // The translations by ±h_x = ±one cell along u and v are this render read one cell over (the
  // tool moved +u is, at window cell i, what the unmoved tool has at cell i − 1).
  const int n = w.resolution, nt = n + 2;
  tool_ext_heights_.assign(static_cast<size_t>(nt) * nt, std::numeric_limits<float>::infinity());
  RenderPatchHeightsFast(tool, X_WT, tool_triangles_, w, PatchSide::kTool, 1, tool_ext_heights_);
  samples[0] = DirectionalPenetrationDepthShifted(env_heights_, n, tool_ext_heights_, 1, 0, 0);
  samples[1] = DirectionalPenetrationDepthShifted(env_heights_, n, tool_ext_heights_, 1, -1, 0);
  samples[2] = DirectionalPenetrationDepthShifted(env_heights_, n, tool_ext_heights_, 1, 1, 0);
  samples[3] = DirectionalPenetrationDepthShifted(env_heights_, n, tool_ext_heights_, 1, 0, -1);
  samples[4] = DirectionalPenetrationDepthShifted(env_heights_, n, tool_ext_heights_, 1, 0, 1);
}

}  // namespace ht
