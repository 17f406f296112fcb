// Stage 5a of the remote step (remote_step.h, PipelineOptions): a window whose overlap falls
// apart into separated regions keeps its whole window for its deepest region and adds one window
// per other region, the regions' weights faded in by depth and out across bridges
// (5a_overlap_links.cc gives the regions' single linkage and bridge levels).
#include <algorithm>
#include <cmath>
#include <glm/geometric.hpp>
#include <limits>

#include "0_remote_step_data.h"
#include "haptic_core/contact_region.h"
#include "haptic_core/remote_step.h"

namespace ht {
namespace {

// The regions' linking distance (m): overlaps closer than this are one region.
constexpr double kSplitLinkM = 10e-3;
// A region's window: its box plus this much on each side (m), at the parent's cell size.
constexpr double kSplitWindowMarginM = 1e-3;
// The birth ramp and the bridge fade (m): a region other than the window's deepest pushes with
// k·smoothstep(d_r / min(ramp, d_max))·smoothstep(−t / fade) (remote_step.h). Narrower fades
// follow the truth more closely on the frontier but rock the loop (docs/measurements.md).
constexpr double kSplitBirthRampM = 400e-6;
constexpr double kSplitBridgeFadeM = 400e-6;
// A region whose weight is below this gets no window (its force would be under 0.1 % of its
// k·δ).
constexpr double kSplitNegligibleWeight = 1e-3;

// 3x² − 2x³ of x clamped to [0, 1]: 0 below, 1 above, with zero slope at both ends.
double Smoothstep(double x) noexcept {
  x = std::clamp(x, 0.0, 1.0);
  return x * x * (3.0 - 2.0 * x);
}

}  // namespace

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
      const double floor = kSplitBridgeFadeM;
      const double link = kSplitLinkM;
      // Stage 5's base render where the backend kept it (the CPU backend), else rendered again.
      const std::span<const float> base = d.base_fields[static_cast<std::size_t>(i)];
      regions = !base.empty()
                    ? d.region_solver->OverlapRegions(base, q.window, link, d.regions, floor)
                    : d.region_solver->OverlapRegions(tool, X_WT, *q.environment, q.X_WO, q.window,
                                                      link, d.regions, q.environment_triangles,
                                                      q.tool_triangles, floor);
    }
    const int kept_after = kept + (n - i - 1);  // the windows still to keep, at least
    const bool split = regions >= 2 && regions <= static_cast<int>(d.regions.size()) &&
                       kept_after + num_new + regions <= options_.max_contacts;
    {
      // Kept (the deepest region's window when split): moved down over the split ones, with its
      // results and samples.
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
    // The deepest region is the parent's window as linearized (kept above), so a window whose
    // other regions fade out is the unsplit window.
    const ContactWindow& w = q.window;
    const double cell = w.cell_size_m();
    // The regions are sorted deepest first (OverlapRegions): d.regions[0] holds the window's d_max.
    const double ramp = std::min(kSplitBirthRampM, d.regions[0].depth_m);
    for (int r = 1; r < regions; ++r) {
      const OverlapRegion& g = d.regions[static_cast<std::size_t>(r)];
      double weight = 1.0;
      if (ramp > 0.0) weight *= Smoothstep(g.depth_m / ramp);
      weight *= Smoothstep(-g.bridge_m / kSplitBridgeFadeM);
      if (weight < kSplitNegligibleWeight) continue;  // pushes nothing
      // The region's box on the window plane (m from the window's centre), its margin, and the
      // parent's cell size.
      const double s_mid = (0.5 * (g.i0 + g.i1 + 1)) * cell - 0.5 * w.extent_m;
      const double t_mid = (0.5 * (g.j0 + g.j1 + 1)) * cell - 0.5 * w.extent_m;
      const double side =
          std::max(g.i1 - g.i0 + 1, g.j1 - g.j0 + 1) * cell + 2.0 * kSplitWindowMarginM;
      const int resolution = std::clamp(static_cast<int>(std::ceil(side / cell)), 8, w.resolution);
      const auto sub = ContactWindow::TryMake(w.center_W + s_mid * w.axis_u_W + t_mid * w.axis_v_W,
                                              w.normal_W, resolution * cell, resolution);
      if (!sub) {
        ++d.step_faults.bad_windows;  // the region stays out of the model, counted
        continue;
      }
      d.split_weights[static_cast<std::size_t>(num_new)] = weight;
      d.split_parent[static_cast<std::size_t>(num_new)] = kept - 1;
      ContactQuery& nq = d.split_queries[static_cast<std::size_t>(num_new++)];
      nq = q;
      nq.window = *sub;
      nq.window.gradient_extent_m = w.gradient_lever_extent_m();  // the parent's rotation step
    }
  }
  if (num_new == 0) return n;
  d.split_first = kept;
  d.split_count = num_new;
  for (int k = 0; k < num_new; ++k) {
    const int parent = d.split_parent[static_cast<std::size_t>(k)];
    d.split_family[static_cast<std::size_t>(parent)] = parent;
    d.split_family[static_cast<std::size_t>(kept + k)] = parent;
  }
  std::copy_n(d.split_queries.begin(), num_new, d.last_queries.begin() + kept);
  // The split windows' batch overwrites the backend's first num_new fields: the kept contacts'
  // fields are copied out first (a few thousand floats each), into slots of their own.
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
