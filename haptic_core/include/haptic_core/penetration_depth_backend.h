#pragma once
// Where the texture penetration depth of a remote step is computed (DESIGN.md §4): the CPU
// reference, or the GPU (haptic_core_gpu). Both take the same batch and give the same numbers to
// within the GPU's depth quantum.

#include <array>
#include <cstddef>
#include <limits>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "haptic_core/contact_linearization.h"
#include "haptic_core/contact_model.h"
#include "haptic_core/contact_windows.h"
#include "haptic_core/haptic_model.h"
#include "haptic_core/penetration_depth.h"
#include "haptic_core/spatial.h"

namespace ht {

struct HapticScene;  // haptic_scene.h

/// Computes, for all contacts of one remote step, δ and its gradient (kGradientSamples depth
/// evaluations each). Implementations preallocate at construction; a batch does not allocate.
class PenetrationDepthBackend {
 public:
  virtual ~PenetrationDepthBackend() = default;

  /// "cpu" or "gpu".
  virtual std::string_view name() const noexcept = 0;
  /// What runs it, for logs and summaries: "CPU rasterizer (fast path)", "CPU reference
  /// rasterizer" or the GL renderer string.
  virtual std::string description() const = 0;

  /// Linearizes every query for `tool` posed at X_WT (frame T at the tool's centre of mass) into
  /// `out` (#queries). When `samples_out` holds #queries × kGradientSamples entries, the raw depth
  /// samples are written there too (query-major, in GradientSamplePoses() order). Returns false
  /// when the backend failed (lost GPU context, GL error, more queries than it was sized for);
  /// `last_error()` then says why and `out` is unspecified. Must be called from the thread that
  /// created the backend.
  virtual bool LinearizeBatch(const HapticModel& tool, const RigidTransform& X_WT,
                              std::span<const ContactQuery> queries,
                              std::span<ContactLinearization> out,
                              std::span<DepthSample> samples_out = {}) noexcept = 0;

  /// The scene the next batches run on (HapticTexturePipeline's constructor calls it with its
  /// scene): a backend that keeps data per model (the GPU backend's uploads) makes it now for the
  /// scene's tool and touchables, holds each of those models (so that no other model takes its
  /// address while the data is kept), and frees what it kept for any other model. The default
  /// (the CPU backend, which keeps nothing per model) does nothing. Allocates; throws what making
  /// the data throws (GpuError for a failed upload). Call it from the thread that created the
  /// backend.
  virtual void UseScene(const HapticScene& scene) { (void)scene; }

  /// Whether LinearizeBatch keeps each query's overlap field at the base pose for base_overlap(),
  /// for windows of up to `max_resolution`² cells (0, the default: off; stages 5a and 5c of the
  /// remote step turn it on so as not to render the base pose again). Turning it
  /// on reserves the fields (allocates: call it at set-up). A backend that cannot keep them
  /// ignores it (the default; the GPU backend).
  virtual void set_keep_base_overlap(int max_resolution) { (void)max_resolution; }
  /// Query i's overlap field at the base pose from the last LinearizeBatch: N² floats of b − a
  /// (m along the window normal, row-major j·N + i; TexturePenetrationSolver::Linearize's
  /// `base_overlap_out`). Empty where not kept: keeping off or not supported, i past the last
  /// batch or the reserve, or a side without surface on the window (depth −∞). Valid until the next
  /// batch.
  virtual std::span<const float> base_overlap(std::size_t i) const noexcept {
    (void)i;
    return {};
  }

  /// Why the last failed batch failed ("" when none failed).
  virtual const std::string& last_error() const noexcept = 0;
  /// Numerical faults met while linearizing (counted, never thrown).
  virtual const LinearizationFaults& faults() const noexcept = 0;
};

/// The CPU penetration depth (software rasterizer, DESIGN.md §4): the contacts of a batch one
/// after the other, or spread over `threads` worker threads (oneTBB, one solver per thread, so
/// that each contact's result is the same whichever thread computes it).
class CpuPenetrationDepthBackend final : public PenetrationDepthBackend {
 public:
  /// Preallocates for grids of up to `max_resolution`² cells; `path` picks the fast texture stage
  /// (the default) or the reference one (same results within float rounding);
  /// `threads` ≥ 1 (values below 1 count as 1): with more than one, every batch runs in a oneTBB
  /// task arena of that many threads (the calling thread among them): its contacts, and each
  /// contact's tool renders, are tasks.
  explicit CpuPenetrationDepthBackend(int max_resolution = 128,
                                      TextureStagePath path = TextureStagePath::kFast,
                                      int threads = 1);
  ~CpuPenetrationDepthBackend() override;

  std::string_view name() const noexcept override { return "cpu"; }
  std::string description() const override;
  bool LinearizeBatch(const HapticModel& tool, const RigidTransform& X_WT,
                      std::span<const ContactQuery> queries, std::span<ContactLinearization> out,
                      std::span<DepthSample> samples_out = {}) noexcept override;
  /// Reserves kMaxContacts fields of max_resolution² floats (a batch's queries past those, and
  /// larger windows, are not kept); max_resolution ≤ 0 turns keeping off and frees them.
  void set_keep_base_overlap(int max_resolution) override;
  std::span<const float> base_overlap(std::size_t i) const noexcept override;
  const std::string& last_error() const noexcept override { return last_error_; }
  const LinearizationFaults& faults() const noexcept override { return faults_; }
  /// Worker threads of a batch (1 = the calling thread alone).
  int threads() const noexcept { return static_cast<int>(solvers_.size()); }

 private:
  struct Arena;  // the oneTBB task arena, kept out of this header
  std::vector<TexturePenetrationSolver> solvers_;
  std::unique_ptr<Arena> arena_;
  /// set_keep_base_overlap: kMaxContacts slots of keep_resolution_² floats (0: off), and each
  /// slot's cell count in the last batch (0: not kept).
  int keep_resolution_ = 0;
  std::vector<float> base_overlaps_;
  std::array<std::size_t, kMaxContacts> base_overlap_cells_{};
  LinearizationFaults faults_;
  std::string last_error_;
};

}  // namespace ht
