#pragma once
// Single linkage over a window's cells (stage 5a of the remote step, remote_step.h): the regions
// of a window's overlap and their bridge levels (TexturePenetrationSolver::OverlapRegions). Two
// cells link when their centres are at most `reach` cells apart, a disc of about π·reach² cells;
// at a 10 mm link on a 0.4 mm grid that is about 2,000 neighbours a cell. Both passes here visit
// one cell of each run of set cells a row instead: cells next to each other in a row are within
// any reach ≥ 1, so a run is already one component and linking one of its cells links them all.
// Components also scans once per run rather than per cell: a row's cells within reach of some
// cell of the run [i0, i1] are those in [i0 − w, i1 + w], w the disc's half width at that row.
// The components and levels are those of the cell-by-cell passes, bit for bit
// (tests/overlap_links_test.cc checks them against the cell-by-cell form on random grids).

#include <cstdint>
#include <span>
#include <vector>

namespace ht {

/// Union-finds over an n × n grid of cells (cell c = j·n + i, i along u, j along v), with their
/// scratch reserved for grids up to `max_resolution` a side: neither call allocates within it
/// (larger grids allocate on first use).
class OverlapCellLinks {
 public:
  explicit OverlapCellLinks(int max_resolution = 0);

  /// The single-linkage components of the cells with depth[c] > 0, two cells linked when
  /// di² + dj² ≤ reach² (reach in cells, ≥ 0; below 1 no two cells link). Writes parent[c] = the
  /// component's first cell (its smallest index) for those cells and −1 for the others (NaN
  /// depths included). `depth` and `parent` hold n² entries (n ≥ 1); returns the number of
  /// components, or −1, writing nothing, on a size mismatch or a negative or NaN reach.
  int Components(std::span<const float> depth, int n, double reach, std::span<int> parent) noexcept;

  /// The bridge levels of the cells' merge tree: the cells with depth[c] > floor are added in
  /// decreasing depth (ties: smaller index first), each linked to the cells already added within
  /// `reach` as Components links them. Where a cell joins two components, the one whose peak
  /// (deepest cell) is shallower ends there (the elder rule), and if that peak has depth > 0 and
  /// the joining cell's depth is ≤ 0, level[peak] = the joining cell's depth: the highest level
  /// t ≤ 0 at which the region of that peak joins a deeper one (the saddle). Every other entry of
  /// `level` is −∞. `depth` and `level` hold n² entries; returns false, writing nothing, on a size
  /// mismatch or a negative or NaN reach.
  ///
  /// With `peaks` (cells whose level is wanted, e.g. the regions' peak cells) the pass stops as
  /// soon as each of them other than the deepest cell has its level: their levels are the full
  /// pass's, other entries may stay −∞. On a wide floor most cells lie below the saddles.
  bool BridgeLevels(std::span<const float> depth, int n, double reach, float floor,
                    std::span<float> level, std::span<const int> peaks = {}) noexcept;

 private:
  /// Sets up the row bitsets (all clear) and the half widths for a reach; false on bad input.
  bool Prepare(int n, double reach, std::size_t cells) noexcept;
  int Find(std::span<int> parent, int c) const noexcept;

  int words_ = 0;  ///< 64-bit words a row.
  int r_ = 0;      ///< floor(reach).
  std::vector<std::uint64_t> rows_;
  /// half_width_[|dj|]: the largest di with di² + dj² ≤ reach², for |dj| ≤ r_.
  std::vector<int> half_width_;
  std::vector<int> order_;
  std::vector<int> parent_;
  std::vector<int> peak_;
};

}  // namespace ht
