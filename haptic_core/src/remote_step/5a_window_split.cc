// Stage 5a of the remote step (remote_step.h): a window whose overlap falls apart into separated
// regions is split into one window per region
// (PipelineOptions::split_windows_at_separated_overlap), the regions' weights faded in by depth and
// out across bridges (5a_overlap_links.cc gives the regions' single linkage and bridge levels).
#include <algorithm>
#include <cmath>
#include <glm/geometric.hpp>
#include <limits>

#include "haptic_core/contact_region.h"
#include "haptic_core/remote_step.h"

namespace ht {
namespace {

// Stage 5a with split_keeps_parent_window: a region whose weight is below this gets no window
// (its force would be under 0.1 % of its k·δ).
constexpr double kSplitNegligibleWeight = 1e-3;

// 3x² − 2x³ of x clamped to [0, 1]: 0 below, 1 above, with zero slope at both ends.
double Smoothstep(double x) noexcept {
  x = std::clamp(x, 0.0, 1.0);
  return x * x * (3.0 - 2.0 * x);
}

}  // namespace

int HapticTexturePipeline::MergeRegionsInOneWindow(int count, double cell_m) noexcept {
  int m = std::min(count, static_cast<int>(regions_.size()));
  if (count > m) return count;  // more than kept: not split anyway
  // A region's window: the square of its box's larger side plus the margins, about its centre
  // (in cells along u and v).
  const double margin_cells = options_.split_window_margin_m / cell_m;
  const auto half = [&](const OverlapRegion& g) {
    return 0.5 * std::max(g.i1 - g.i0 + 1, g.j1 - g.j0 + 1) + margin_cells;
  };
  bool merged = true;
  while (merged && m >= 2) {
    merged = false;
    for (int p = 0; p < m && !merged; ++p) {
      for (int q = 0; q < m && !merged; ++q) {
        if (p == q) continue;
        OverlapRegion& a = regions_[static_cast<std::size_t>(p)];
        const OverlapRegion& b = regions_[static_cast<std::size_t>(q)];
        const double ds = 0.5 * ((b.i0 + b.i1) - (a.i0 + a.i1));
        const double dt = 0.5 * ((b.j0 + b.j1) - (a.j0 + a.j1));
        if (std::abs(ds) > half(a) || std::abs(dt) > half(a)) continue;
        a.i0 = std::min(a.i0, b.i0);
        a.i1 = std::max(a.i1, b.i1);
        a.j0 = std::min(a.j0, b.j0);
        a.j1 = std::max(a.j1, b.j1);
        a.cells += b.cells;
        if (b.depth_m > a.depth_m) {  // the merged region goes on as the deeper one
          a.depth_m = b.depth_m;
          a.peak_cell = b.peak_cell;
          a.bridge_m = b.bridge_m;
        }
        regions_[static_cast<std::size_t>(q)] = regions_[static_cast<std::size_t>(m - 1)];
        --m;
        merged = true;
      }
    }
  }
  return m;
}

int HapticTexturePipeline::SplitSeparatedOverlap(const RigidTransform& X_WT, int n) noexcept {
  // The GPU backend takes one window size per batch (LinearizeContacts); the split windows are
  // sized to their regions, so this stage runs with the CPU backend only.
  split_count_ = 0;
  split_family_.fill(-1);
  if (backend_->name() == "gpu") return n;
  const HapticModel& tool = *scene_.tool;
  int num_new = 0;
  int kept = 0;
  for (int i = 0; i < n; ++i) {
    const ContactQuery& q = last_queries_[static_cast<std::size_t>(i)];
    int regions = 0;
    const double parent_depth = last_results_[static_cast<std::size_t>(i)].depth_m;
    if (std::isfinite(parent_depth) && parent_depth > 0.0) {
      // With a fade per depth, the floor reaches the deepest region's fade (the window's refined
      // δ bounds every region's cell samples from above, up to the refinement's few µm).
      const double relative = options_.split_bridge_fade_per_depth;
      const double floor =
          relative > 0.0 ? relative * parent_depth * 1.1 : options_.split_bridge_fade_m;
      const double link =
          options_.split_link_m > 0.0 ? options_.split_link_m : options_.clustering_distance_m;
      // Stage 5's base render where the backend kept it (the CPU backend), else rendered again.
      const std::span<const float> base = base_fields_[static_cast<std::size_t>(i)];
      regions = !base.empty()
                    ? region_solver_->OverlapRegions(base, q.window, link, regions_, floor)
                    : region_solver_->OverlapRegions(tool, X_WT, *q.environment, q.X_WO, q.window,
                                                     link, regions_, q.environment_triangles,
                                                     q.tool_triangles, floor);
    }
    const bool parent_window = options_.split_keeps_parent_window;
    if (!parent_window) regions = MergeRegionsInOneWindow(regions, q.window.cell_size_m());
    const int kept_after = kept + (n - i - 1);  // the windows still to keep, at least
    const bool split = regions >= 2 && regions <= static_cast<int>(regions_.size()) &&
                       kept_after + num_new + regions <= options_.max_contacts;
    if (!split || parent_window) {
      // Kept: moved down over the split ones, with its results and samples.
      if (kept != i) {
        base_fields_[static_cast<std::size_t>(kept)] = base_fields_[static_cast<std::size_t>(i)];
        last_queries_[static_cast<std::size_t>(kept)] = q;
        last_results_[static_cast<std::size_t>(kept)] = last_results_[static_cast<std::size_t>(i)];
        std::copy_n(last_samples_.begin() + static_cast<std::ptrdiff_t>(i) * kGradientSamples,
                    kGradientSamples,
                    last_samples_.begin() + static_cast<std::ptrdiff_t>(kept) * kGradientSamples);
      }
      ++kept;
      if (!split) continue;
    }
    // With split_keeps_parent_window the deepest region is the parent's window as linearized
    // (kept above), so a window whose other regions fade out is the unsplit window.
    const ContactWindow& w = q.window;
    const double cell = w.cell_size_m();
    // The regions are sorted deepest first (OverlapRegions): regions_[0] holds the window's d_max.
    const double ramp = std::min(options_.split_birth_ramp_m, regions_[0].depth_m);
    for (int r = parent_window ? 1 : 0; r < regions; ++r) {
      const OverlapRegion& g = regions_[static_cast<std::size_t>(r)];
      double weight = 1.0;
      if (r > 0 && ramp > 0.0) weight *= Smoothstep(g.depth_m / ramp);
      const double fade = options_.split_bridge_fade_per_depth > 0.0
                              ? options_.split_bridge_fade_per_depth * g.depth_m
                              : options_.split_bridge_fade_m;
      if (r > 0 && fade > 0.0) weight *= Smoothstep(-g.bridge_m / fade);
      if (parent_window && weight < kSplitNegligibleWeight) continue;  // pushes nothing
      // The region's box on the window plane (m from the window's centre), its margin, and the
      // parent's cell size.
      const double s_mid = (0.5 * (g.i0 + g.i1 + 1)) * cell - 0.5 * w.extent_m;
      const double t_mid = (0.5 * (g.j0 + g.j1 + 1)) * cell - 0.5 * w.extent_m;
      const double side =
          std::max(g.i1 - g.i0 + 1, g.j1 - g.j0 + 1) * cell + 2.0 * options_.split_window_margin_m;
      const int resolution = std::clamp(static_cast<int>(std::ceil(side / cell)), 8, w.resolution);
      const auto sub = ContactWindow::TryMake(w.center_W + s_mid * w.axis_u_W + t_mid * w.axis_v_W,
                                              w.normal_W, resolution * cell, resolution);
      if (!sub) {
        ++step_faults_.bad_windows;  // the region stays out of the model, counted
        continue;
      }
      split_weights_[static_cast<std::size_t>(num_new)] = weight;
      split_parent_[static_cast<std::size_t>(num_new)] = parent_window ? kept - 1 : -1;
      ContactQuery& nq = split_queries_[static_cast<std::size_t>(num_new++)];
      nq = q;
      nq.window = *sub;
      if (options_.split_keeps_parent_rotation_step) {
        nq.window.gradient_extent_m = w.gradient_lever_extent_m();
      }
    }
  }
  if (num_new == 0) return n;
  split_first_ = kept;
  split_count_ = num_new;
  for (int k = 0; k < num_new; ++k) {
    const int parent = split_parent_[static_cast<std::size_t>(k)];
    if (parent < 0) continue;
    split_family_[static_cast<std::size_t>(parent)] = parent;
    split_family_[static_cast<std::size_t>(kept + k)] = parent;
  }
  std::copy_n(split_queries_.begin(), num_new, last_queries_.begin() + kept);
  // The split windows' batch overwrites the backend's first num_new fields: the kept contacts'
  // fields are copied out first (a few thousand floats each), into slots of their own (a field
  // there is only with reuse_base_render, which reserves the slots).
  const auto slot = base_field_store_.size() / static_cast<std::size_t>(kMaxContacts);
  for (int k = 0; k < kept; ++k) {
    std::span<const float>& f = base_fields_[static_cast<std::size_t>(k)];
    if (f.empty() || f.size() > slot) {
      f = {};  // rendered again in 5c
      continue;
    }
    float* to = base_field_store_.data() + static_cast<std::size_t>(k) * slot;
    std::copy(f.begin(), f.end(), to);
    f = {to, f.size()};
  }
  const std::size_t per = kGradientSamples;
  const bool ok = backend_->LinearizeBatch(
      tool, X_WT, {last_queries_.data() + kept, static_cast<std::size_t>(num_new)},
      {last_results_.data() + kept, static_cast<std::size_t>(num_new)},
      {last_samples_.data() + static_cast<std::size_t>(kept) * per,
       static_cast<std::size_t>(num_new) * per});
  for (int k = 0; k < num_new; ++k) {
    base_fields_[static_cast<std::size_t>(kept + k)] =
        ok && ReusesBaseRender() ? backend_->base_overlap(static_cast<std::size_t>(k))
                                 : std::span<const float>{};
  }
  if (!ok) {
    for (int k = kept; k < kept + num_new; ++k) {
      last_results_[static_cast<std::size_t>(k)].depth_m = -std::numeric_limits<double>::infinity();
    }
  }
  return kept + num_new;
}

}  // namespace ht
