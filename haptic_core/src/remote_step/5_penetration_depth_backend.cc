#include <oneapi/tbb/blocked_range.h>
#include <oneapi/tbb/parallel_for.h>
#include <oneapi/tbb/task_arena.h>

#include <algorithm>
#include <limits>

#include "../task_pools.h"
#include "haptic_core/penetration_depth_backend.h"

namespace ht {

struct CpuPenetrationDepthBackend::Arena {
  explicit Arena(int threads) : arena(threads) {}
  oneapi::tbb::task_arena arena;
};

CpuPenetrationDepthBackend::CpuPenetrationDepthBackend(int max_resolution, TextureStagePath path,
                                                       int threads) {
  const int n = std::max(threads, 1);
  solvers_.reserve(static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i) {
    solvers_.emplace_back(max_resolution, 4096, path);
  }
  if (n > 1) {
    arena_ = std::make_unique<Arena>(n);
    internal::WarmTaskPools(arena_->arena);  // so that a batch's tasks do not allocate
    // Renders of one contact as tasks too, so that a step with fewer contacts than threads uses
    // them all (each render has its own buffer: the same results).
    for (TexturePenetrationSolver& s : solvers_) s.set_parallel_renders(true);
  }
}

CpuPenetrationDepthBackend::~CpuPenetrationDepthBackend() = default;

std::string CpuPenetrationDepthBackend::description() const {
  std::string d = solvers_.front().path() == TextureStagePath::kFast ? "CPU rasterizer (fast path)"
                                                                     : "CPU reference rasterizer";
  if (threads() > 1) d += ", " + std::to_string(threads()) + " threads (oneTBB)";
  return d;
}

void CpuPenetrationDepthBackend::set_keep_base_overlap(int max_resolution) {
  keep_resolution_ = std::max(max_resolution, 0);
  base_overlap_cells_.fill(0);
  const auto slot = static_cast<std::size_t>(keep_resolution_) * keep_resolution_;
  base_overlaps_.assign(base_overlap_cells_.size() * slot, 0.0f);
  if (keep_resolution_ == 0) base_overlaps_.shrink_to_fit();
}

std::span<const float> CpuPenetrationDepthBackend::base_overlap(std::size_t i) const noexcept {
  if (i >= base_overlap_cells_.size() || base_overlap_cells_[i] == 0) return {};
  const auto slot_cells = static_cast<std::size_t>(keep_resolution_) * keep_resolution_;
  return std::span<const float>(base_overlaps_).subspan(i * slot_cells, base_overlap_cells_[i]);
}

bool CpuPenetrationDepthBackend::LinearizeBatch(const HapticModel& tool, const RigidTransform& X_WT,
                                                std::span<const ContactQuery> queries,
                                                std::span<ContactLinearization> out,
                                                std::span<DepthSample> samples_out) noexcept {
  if (out.size() < queries.size()) return false;
  const bool want_samples = samples_out.size() >= queries.size() * kGradientSamples;
  base_overlap_cells_.fill(0);
  const auto slot_cells = static_cast<std::size_t>(keep_resolution_) * keep_resolution_;
  const auto one = [&](TexturePenetrationSolver& solver, std::size_t i) {
    const ContactQuery& q = queries[i];
    const auto cells = static_cast<std::size_t>(q.window.resolution) * q.window.resolution;
    const bool keep = keep_resolution_ > 0 && i < base_overlap_cells_.size() && cells <= slot_cells;
    out[i] =
        solver.Linearize(tool, X_WT, *q.environment, q.X_WO, q.window, q.stiffness_n_per_m,
                         want_samples ? samples_out.subspan(i * kGradientSamples, kGradientSamples)
                                      : std::span<DepthSample>{},
                         q.environment_triangles, q.tool_triangles,
                         keep ? std::span<float>(base_overlaps_).subspan(i * slot_cells, cells)
                              : std::span<float>{});
    // Linearize writes the field exactly when both sides have surface there (δ0 > −∞).
    if (keep && out[i].depth_m > -std::numeric_limits<double>::infinity()) {
      base_overlap_cells_[i] = cells;
    }
  };
  bool done = false;
  if (arena_ && !queries.empty()) {
    try {
      arena_->arena.execute([&] {
        oneapi::tbb::parallel_for(
            oneapi::tbb::blocked_range<std::size_t>(0, queries.size(), 1),
            [&](const oneapi::tbb::blocked_range<std::size_t>& r) {
              // One solver per thread of the arena: a slot is never used by two at once.
              const int slot = oneapi::tbb::this_task_arena::current_thread_index();
              TexturePenetrationSolver& solver =
                  solvers_[static_cast<std::size_t>(std::clamp(slot, 0, threads() - 1))];
              for (std::size_t i = r.begin(); i != r.end(); ++i) one(solver, i);
            });
      });
      done = true;
    } catch (...) {
      done = false;  // the pool could not run the batch (out of memory): the calling thread does
    }
  }
  if (!done) {
    // The calling thread alone, so its renders must not become tasks of the global arena.
    TexturePenetrationSolver& solver = solvers_.front();
    solver.set_parallel_renders(false);
    for (std::size_t i = 0; i < queries.size(); ++i) one(solver, i);
    solver.set_parallel_renders(threads() > 1);
  }
  faults_ = {};
  for (const TexturePenetrationSolver& s : solvers_) {
    faults_.missing_overlap += s.faults().missing_overlap;
  }
  return true;
}

}  // namespace ht
