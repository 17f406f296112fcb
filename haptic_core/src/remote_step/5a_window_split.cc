// Stage 5a of the remote step (remote_step.h): a window whose overlap falls apart into separated
// regions is split into one window per region
// (PipelineOptions::split_windows_at_separated_overlap), the regions' weights faded in by depth and
// out across bridges (5a_overlap_links.cc gives the regions' single linkage and bridge levels).
#include <algorithm>
#include <cmath>
#include <glm/geometric.hpp>
#include <limits>

#include "0_remote_step_data.h"
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
  RemoteStepData& d = *data_;
  int m = std::min(count, static_cast<int>(d.regions.size()));
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
        OverlapRegion& a = d.regions[static_cast<std::size_t>(p)];
        const OverlapRegion& b = d.regions[static_cast<std::size_t>(q)];
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
        d.regions[static_cast<std::size_t>(q)] = d.regions[static_cast<std::size_t>(m - 1)];
        --m;
        merged = true;
      }
    }
  }
  return m;
}

int HapticTexturePipeline::SplitSeparatedOverlap(const RigidTransform& X_WT, int n) noexcept {
  RemoteStepData& d = *data_;
  // The GPU backend takes one window size per batch (LinearizeContacts); the split windows are
  // sized to their regions, so this stage runs with the CPU backend only.
  d.split_count = 0;
  d.split_family.fill(-1);
  if (backend_->name() == "gpu") return n;
  const HapticModel& tool = *scene_.tool;
  int num_new = 0;
  int kept = 0;
  for (int i = 0; i < n; ++i) {
    const ContactQuery& q = d.last_queries[static_cast<std::size_t>(i)];
    int regions = 0;
    const double parent_depth = d.last_results[static_cast<std::size_t>(i)].depth_m;
    if (std::isfinite(parent_depth) && parent_depth > 0.0) {
      // With a fade per depth, the floor reaches the deepest region's fade (the window's refined
      // δ bounds every region's cell samples from above, up to the refinement's few µm).
      const double relative = options_.split_bridge_fade_per_depth;
      const double floor =
          relative > 0.0 ? relative * parent_depth * 1.1 : options_.split_bridge_fade_m;
      const double link =
          options_.split_link_m > 0.0 ? options_.split_link_m : options_.clustering_distance_m;
      // Stage 5's base render where the backend kept it (the CPU backend), else rendered again.
      const std::span<const float> base = d.base_fields[static_cast<std::size_t>(i)];
      regions = !base.empty()
                    ? d.region_solver->OverlapRegions(base, q.window, link, d.regions, floor)
                    : d.region_solver->OverlapRegions(tool, X_WT, *q.environment, q.X_WO, q.window,
                                                      link, d.regions, q.environment_triangles,
                                                      q.tool_triangles, floor);
    }
    const bool parent_window = options_.split_keeps_parent_window;
    if (!parent_window) regions = MergeRegionsInOneWindow(regions, q.window.cell_size_m());
    const int kept_after = kept + (n - i - 1);  // the windows still to keep, at least
    const bool split = regions >= 2 && regions <= static_cast<int>(d.regions.size()) &&
                       kept_after + num_new + regions <= options_.max_contacts;
    if (!split || parent_window) {
      // Kept: moved down over the split ones, with its results and samples.
      if (kept != i) {
        d.base_fields[static_cast<std::size_t>(kept)] = d.base_fields[static_cast<std::size_t>(i)];
        d.last_queries[static_cast<std::size_t>(kept)] = q;
        d.last_results[static_cast<std::size_t>(kept)] =
            d.last_results[static_cast<std::size_t>(i)];
        std::copy_n(d.last_samples.begin() + static_cast<std::ptrdiff_t>(i) * kGradientSamples,
                    kGradientSamples,
                    d.last_samples.begin() + static_cast<std::ptrdiff_t>(kept) * kGradientSamples);
      }
      ++kept;
      if (!split) continue;
    }
    // With split_keeps_parent_window the deepest region is the parent's window as linearized
    // (kept above), so a window whose other regions fade out is the unsplit window.
    const ContactWindow& w = q.window;
    const double cell = w.cell_size_m();
    // The regions are sorted deepest first (OverlapRegions): d.regions[0] holds the window's d_max.
    const double ramp = std::min(options_.split_birth_ramp_m, d.regions[0].depth_m);
    for (int r = parent_window ? 1 : 0; r < regions; ++r) {
      const OverlapRegion& g = d.regions[static_cast<std::size_t>(r)];
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
        ++d.step_faults.bad_windows;  // the region stays out of the model, counted
        continue;
      }
      d.split_weights[static_cast<std::size_t>(num_new)] = weight;
      d.split_parent[static_cast<std::size_t>(num_new)] = parent_window ? kept - 1 : -1;
      ContactQuery& nq = d.split_queries[static_cast<std::size_t>(num_new++)];
      nq = q;
      nq.window = *sub;
      if (options_.split_keeps_parent_rotation_step) {
        nq.window.gradient_extent_m = w.gradient_lever_extent_m();
      }
    }
  }
  if (num_new == 0) return n;
  d.split_first = kept;
  d.split_count = num_new;
  for (int k = 0; k < num_new; ++k) {
    const int parent = d.split_parent[static_cast<std::size_t>(k)];
    if (parent < 0) continue;
    d.split_family[static_cast<std::size_t>(parent)] = parent;
    d.split_family[static_cast<std::size_t>(kept + k)] = parent;
  }
  std::copy_n(d.split_queries.begin(), num_new, d.last_queries.begin() + kept);
  // The split windows' batch overwrites the backend's first num_new fields: the kept contacts'
  // fields are copied out first (a few thousand floats each), into slots of their own (a field
  // there is only with reuse_base_render, which reserves the slots).
  const auto slot = d.base_field_store.size() / static_cast<std::size_t>(kMaxContacts);
  for (int k = 0; k < kept; ++k) {
    std::span<const float>& f = d.base_fields[static_cast<std::size_t>(k)];
    if (f.empty() || f.size() > slot) {
      f = {};  // rendered again in 5c
      continue;
    }
    float* to = d.base_field_store.data() + static_cast<std::size_t>(k) * slot;
    std::copy(f.begin(), f.end(), to);
    f = {to, f.size()};
  }
  const std::size_t per = kGradientSamples;
  const bool ok = backend_->LinearizeBatch(
      tool, X_WT, {d.last_queries.data() + kept, static_cast<std::size_t>(num_new)},
      {d.last_results.data() + kept, static_cast<std::size_t>(num_new)},
      {d.last_samples.data() + static_cast<std::size_t>(kept) * per,
       static_cast<std::size_t>(num_new) * per});
  for (int k = 0; k < num_new; ++k) {
    d.base_fields[static_cast<std::size_t>(kept + k)] =
        ok && ReusesBaseRender() ? backend_->base_overlap(static_cast<std::size_t>(k))
                                 : std::span<const float>{};
  }
  if (!ok) {
    for (int k = kept; k < kept + num_new; ++k) {
      d.last_results[static_cast<std::size_t>(k)].depth_m =
          -std::numeric_limits<double>::infinity();
    }
  }
  return kept + num_new;
}

}  // namespace ht
