// The overlap of a contact's window in regions (contact_linearization.h, TexturePenetrationSolver::
// OverlapRegions, OverlapOccupancy): the cells where b − a > 0, linked by single linkage and
// bridge levels (5a_overlap_links.cc), for stages 5a and 5c.
#include <algorithm>
#include <cmath>
#include <limits>

#include "haptic_core/contact_linearization.h"

namespace ht {

int TexturePenetrationSolver::OverlapRegions(const HapticModel& tool, const RigidTransform& X_WT,
                                             const HapticModel& environment,
                                             const RigidTransform& X_WO, const ContactWindow& w,
                                             double link_m, std::span<OverlapRegion> out,
                                             TriangleSubset environment_triangles,
                                             TriangleSubset tool_triangles,
                                             double bridge_floor_m) noexcept {
  const int n = w.resolution;
  const auto cells = static_cast<std::size_t>(n) * static_cast<std::size_t>(n);
  if (n > max_resolution_ || !(link_m >= 0.0)) return 0;
  Depth(tool, X_WT, environment, X_WO, w, environment_triangles, tool_triangles);
  overlap_depth_.resize(cells);
  for (std::size_t c = 0; c < cells; ++c) overlap_depth_[c] = env_heights_[c] - tool_heights_[c];
  return OverlapRegions(overlap_depth_, w, link_m, out, bridge_floor_m);
}

int TexturePenetrationSolver::OverlapRegions(std::span<const float> overlap, const ContactWindow& w,
                                             double link_m, std::span<OverlapRegion> out,
                                             double bridge_floor_m) noexcept {
  const int n = w.resolution;
  const auto cells = static_cast<std::size_t>(n) * static_cast<std::size_t>(n);
  if (n > max_resolution_ || !(link_m >= 0.0) || overlap.size() < cells) return 0;
  overlap = overlap.first(cells);
  // Single linkage over the overlapping cells (overlap_links.h): region_parent_[c] is the first
  // cell of c's region, −1 where b − a ≤ 0.
  region_parent_.resize(cells);
  const double reach = link_m / w.cell_size_m();
  if (links_.Components(overlap, n, reach, region_parent_) < 0) return 0;
  // Regions in order of their roots (the first cell of each), then the kept ones sorted deepest
  // first.
  int count = 0;
  const auto keep = out.size();
  for (std::size_t k = 0; k < keep; ++k) out[k] = OverlapRegion{};
  // A root's slot is found by a scan of the roots met so far (few regions; at most 64 counted).
  std::array<int, 64> roots{};
  for (std::size_t c = 0; c < cells; ++c) {
    if (region_parent_[c] < 0) continue;
    const int root = region_parent_[c];
    int slot = -1;
    for (int k = 0; k < count; ++k) {
      if (roots[static_cast<std::size_t>(k)] == root) slot = k;
    }
    if (slot < 0) {
      if (count == static_cast<int>(roots.size())) continue;  // past 64: not counted further
      roots[static_cast<std::size_t>(count)] = root;
      slot = count++;
    }
    const int i = static_cast<int>(c % static_cast<std::size_t>(n));
    const int j = static_cast<int>(c / static_cast<std::size_t>(n));
    const double depth = overlap[c];
    // Collected in slot order into `out` while it has room; the rest are only counted.
    if (static_cast<std::size_t>(slot) >= keep) continue;
    OverlapRegion& g = out[static_cast<std::size_t>(slot)];
    if (g.cells == 0) {
      g = {i, i, j, j, 0, depth, static_cast<int>(c)};
    }
    g.i0 = std::min(g.i0, i);
    g.i1 = std::max(g.i1, i);
    g.j0 = std::min(g.j0, j);
    g.j1 = std::max(g.j1, j);
    g.cells += 1;
    if (depth > g.depth_m) {
      g.depth_m = depth;
      g.peak_cell = static_cast<int>(c);
    }
  }
  const auto kept = std::min<std::size_t>(keep, static_cast<std::size_t>(count));
  if (bridge_floor_m > 0.0 && count >= 2) {
    bridge_level_.resize(cells);
    // Only the kept regions' peaks are read: the pass stops once each has its level.
    std::array<int, 64> peaks{};
    for (std::size_t k = 0; k < kept; ++k) peaks[k] = out[k].peak_cell;
    links_.BridgeLevels(overlap, n, reach, static_cast<float>(-bridge_floor_m), bridge_level_,
                        std::span<const int>(peaks.data(), kept));
    for (std::size_t k = 0; k < kept; ++k) {
      OverlapRegion& g = out[k];
      const float level = bridge_level_[static_cast<std::size_t>(g.peak_cell)];
      g.bridge_m = std::isfinite(level) ? static_cast<double>(level)
                                        : -std::numeric_limits<double>::infinity();
    }
  }
  std::sort(out.begin(), out.begin() + static_cast<std::ptrdiff_t>(kept),
            [](const OverlapRegion& a, const OverlapRegion& b) { return a.depth_m > b.depth_m; });
  return count;
}

int TexturePenetrationSolver::OverlapOccupancy(const HapticModel& tool, const RigidTransform& X_WT,
                                               const HapticModel& environment,
                                               const RigidTransform& X_WO, const ContactWindow& w,
                                               int block_cells, std::span<std::uint8_t> occupancy,
                                               TriangleSubset environment_triangles,
                                               TriangleSubset tool_triangles) noexcept {
  const int n = w.resolution;
  if (block_cells < 1 || n > max_resolution_) return -1;
  const int nb = (n + block_cells - 1) / block_cells;
  if (occupancy.size() < static_cast<std::size_t>(nb) * static_cast<std::size_t>(nb)) return -1;
  Depth(tool, X_WT, environment, X_WO, w, environment_triangles, tool_triangles);
  const auto cells = static_cast<std::size_t>(n) * static_cast<std::size_t>(n);
  overlap_depth_.resize(cells);
  for (std::size_t c = 0; c < cells; ++c) overlap_depth_[c] = env_heights_[c] - tool_heights_[c];
  return OverlapOccupancy(overlap_depth_, w, block_cells, occupancy);
}

int TexturePenetrationSolver::OverlapOccupancy(std::span<const float> overlap,
                                               const ContactWindow& w, int block_cells,
                                               std::span<std::uint8_t> occupancy) const noexcept {
  const int n = w.resolution;
  if (block_cells < 1 || n > max_resolution_) return -1;
  const int nb = (n + block_cells - 1) / block_cells;
  const auto blocks = static_cast<std::size_t>(nb) * static_cast<std::size_t>(nb);
  if (occupancy.size() < blocks ||
      overlap.size() < static_cast<std::size_t>(n) * static_cast<std::size_t>(n)) {
    return -1;
  }
  std::fill_n(occupancy.begin(), blocks, std::uint8_t{0});
  int occupied = 0;
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      const auto c =
          static_cast<std::size_t>(j) * static_cast<std::size_t>(n) + static_cast<std::size_t>(i);
      if (!(overlap[c] > 0.0f)) continue;
      std::uint8_t& b = occupancy[static_cast<std::size_t>(j / block_cells) * nb +
                                  static_cast<std::size_t>(i / block_cells)];
      occupied += b == 0 ? 1 : 0;
      b = 1;
    }
  }
  return occupied;
}

}  // namespace ht
