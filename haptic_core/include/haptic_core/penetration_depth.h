#pragma once
// Directional penetration depth of two textured patches on an N×N grid (DESIGN.md §4).
// This CPU path is the reference that the GPU backend must match.

#include <array>
#include <cstddef>
#include <cstdint>
#include <glm/vec3.hpp>
#include <limits>
#include <memory>
#include <optional>
#include <span>
#include <vector>

#include "haptic_core/contact_windows.h"
#include "haptic_core/haptic_model.h"
#include "haptic_core/height_field_batch.h"
#include "haptic_core/spatial.h"

namespace ht {

/// Which envelope of a patch a height buffer keeps.
enum class PatchSide {
  kEnvironment,  ///< B: keeps the largest height along n per cell (surface facing +n).
  kTool,         ///< A: keeps the smallest height along n per cell (surface facing −n).
};

/// A triangle faces the other side when its unit face normal · n exceeds this for B (environment),
/// or is below its negative for A (tool). Triangles closer to edge-on are not rendered.
inline constexpr double kPatchFacingThreshold = 0.05;

/// Appends to `triangles_out` the triangles of `model` (posed at X_WO) that may contribute to
/// `window`: facing the other side (face normal·n > kPatchFacingThreshold − facing_slack for B,
/// < −(kPatchFacingThreshold − facing_slack) for A), overlapping the window grown by `margin_m` on
/// the plane, and within ±(R + margin) of the plane along n. A conservative pre-filter: a slack of
/// sin(θ) keeps every triangle that may face the other side after a rotation by θ.
/// `triangles_out` is cleared first; it does not allocate once its capacity reaches the model's
/// triangle count. With `vertex_scratch` whose capacity holds one double per vertex, each
/// vertex's coordinate along the window's u axis is computed once instead of once per triangle
/// corner (the same triangles; measured: docs/measurements.md); it is not grown.
///
/// With `tree` built from `model` (TriangleBoxTree::Build; the caller keeps the two together),
/// only the triangles of the tree's leaves whose boxes reach the window grown by the margin (and
/// its box along n, grown likewise) are tested, with the same tests and the same arithmetic: the
/// same triangles in the same (increasing) order as the whole scan (tested), at a cost that grows
/// with the triangles near the window rather than with the model. A tree whose triangle or
/// vertex count differs from the model's (TriangleBoxTree::Fits) is ignored (the scan); a tree of
/// another model with the same counts is not caught. The tree path does not use
/// `vertex_scratch`.
///
/// With `margin_per_radius` k > 0, each triangle's margin is margin_m + k·r, r the distance of its
/// farthest corner from the model frame's origin (m): the reach of a rotation by up to k radians
/// about that origin (chord ≤ k·r), for a caller whose renders turn the model about it. A triangle
/// near the origin then gets a smaller margin than the model's farthest vertex would give it.
class TriangleBoxTree;
void SelectPatchTriangles(const HapticModel& model, const RigidTransform& X_WO,
                          const ContactWindow& window, PatchSide side, double margin_m,
                          std::vector<int>& triangles_out, double facing_slack = 0.0,
                          std::vector<double>* vertex_scratch = nullptr,
                          const TriangleBoxTree* tree = nullptr,
                          double margin_per_radius = 0.0) noexcept;

/// SelectPatchTriangles() restricted to `subset`: the same tests on the listed triangles only
/// (indices out of range are skipped; a triangle listed twice is picked twice), the result sorted
/// increasing, so that a subset holding
/// every triangle the scan would pick gives the scan's list. With subset.all, SelectPatchTriangles
/// itself, through `tree`, else subset.tree (`vertex_scratch` and the tree are only used then).
/// noexcept; `triangles_out` does not allocate once its capacity reaches the model's triangle
/// count.
void SelectPatchTrianglesIn(TriangleSubset subset, const HapticModel& model,
                            const RigidTransform& X_WO, const ContactWindow& window, PatchSide side,
                            double margin_m, std::vector<int>& triangles_out,
                            double facing_slack = 0.0,
                            std::vector<double>* vertex_scratch = nullptr,
                            const TriangleBoxTree* tree = nullptr,
                            double margin_per_radius = 0.0) noexcept;

/// An axis-aligned box tree over a model's coarse triangles, in its frame O (m), for
/// SelectPatchTriangles: each node's box holds every corner of its triangles (exact minima and
/// maxima of the corners' coordinates), leaves hold up to kLeafTriangles triangles, and a node
/// splits its triangles at the median of their centroids along its box's longest axis (so the
/// depth is at most log2(#F / kLeafTriangles) + 2). Build allocates; queries never do. The
/// hull hierarchy (HapticModel::hull_hierarchy) is not used: the procedural models have none.
class TriangleBoxTree {
 public:
  static constexpr int kLeafTriangles = 8;
  /// Models of fewer triangles get no tree (ForModel): the scan costs less than the walk.
  static constexpr std::size_t kMinTriangles = 64;
  /// Builds the tree over `model`'s triangles (replacing any earlier one): derived data of the
  /// model, built with it; a model edited afterwards needs a new Build. Throws std::bad_alloc
  /// only; a model without triangles gives an empty tree (SelectPatchTriangles then finds none).
  /// Triangle corners out of the vertex range are not checked (HapticModel::Validate does).
  void Build(const HapticModel& model);
  /// The tree of `model`, or null for a model of fewer than kMinTriangles triangles. Throws
  /// std::bad_alloc only.
  static std::unique_ptr<TriangleBoxTree> ForModel(const HapticModel& model);
  /// True when the tree was built over as many triangles and vertices as `model` has: the check
  /// SelectPatchTriangles makes before reading it, which keeps its indices in range; it cannot
  /// tell another model of the same counts, or this one edited in place.
  bool Fits(const HapticModel& model) const noexcept;
  /// Forgets the triangles (Fits false for every model); keeps the storage.
  void Clear() noexcept;

  /// One node: its box (centre and half extents, m, in O, widened by a relative 1e-12 so that
  /// centre ± half holds the corners despite rounding) and either a leaf's range of triangles()
  /// or the index of its second child (the first follows it).
  struct Node {
    glm::dvec3 center_O, half_O;
    int begin = 0, end = 0;  ///< leaf: triangles()[begin, end)
    int second = -1;         ///< internal: the second child's index; −1 for a leaf
  };
  std::span<const Node> nodes() const noexcept { return nodes_; }
  /// A triangle (its index in the model) with its corners and the terms of SelectPatchTriangles'
  /// tests that do not depend on the window, computed with the same expressions as the scan (so
  /// the same bits): its corners p_O (m), the cross product (p1 − p0) × (p2 − p0) and its length
  /// (m²), and the distance of its farthest corner from the origin (m).
  struct Triangle {
    glm::dvec3 p0_O, p1_O, p2_O;
    glm::dvec3 cross_O;
    double cross_length;
    double radius_m;
    int index;
  };
  /// Every triangle of the model once, in leaf order.
  std::span<const Triangle> triangles() const noexcept { return triangles_data_; }

 private:
  // Appends the node over order[begin, end) (permuting that range into leaf order) and its
  // subtree; returns its index.
  int BuildNode(const HapticModel& model, const std::vector<glm::dvec3>& centroids,
                std::vector<int>& order, int begin, int end);
  std::vector<Node> nodes_;
  std::vector<Triangle> triangles_data_;  // in leaf order
  std::size_t vertex_count_ = 0, triangle_count_ = 0;
  bool built_ = false;
};

/// Renders the heights along n (m, relative to the window centre) of the textured surface of
/// `model` posed at X_WO into `heights` (#N*N). Only triangles of `triangles` that face the other
/// side at this pose (kPatchFacingThreshold) are drawn. Per covered cell: coarse height
/// d + h(uv)·(N·n), with N the interpolated normal and h sampled at the mip level whose texel
/// matches the cell (the GPU path does the same per fragment) [L][R]; samples with
/// |height| > depth_range_m() are outside the window's box and ignored. `heights` must be
/// initialised by the caller (−∞ for kEnvironment, +∞ for kTool); cells no triangle covers keep
/// that value. `depth_range_m` > 0 replaces the box's half-depth R (tests compare a grid grown
/// around a window with that window's box). Never allocates.
void RenderPatchHeights(const HapticModel& model, const RigidTransform& X_WO,
                        std::span<const int> triangles, const ContactWindow& window, PatchSide side,
                        std::span<float> heights, double depth_range_m = 0.0) noexcept;

/// The fast path of RenderPatchHeights, on the window's grid extended by
/// `margin_cells` (m ≥ 0) cells on every side: `heights` holds (N+2m)² cells, window cell (i, j)
/// (i, j ∈ [−m, N+m)) at index (j+m)·(N+2m) + (i+m), so that m = 0 is the window itself. Within
/// float rounding it writes what RenderPatchHeights writes on a window of (N+2m)² cells of the
/// same cell size and centre (the same cells; heights within a few ulps). It is faster:
/// - the window's axes are brought into the model's frame once;
/// - barycentrics are affine in the cell centre per triangle, and each row is clipped to the
///   triangle's span (by reciprocals, widened by far more than their rounding) before the exact
///   per-cell test; on a CPU with AVX2 (and `kernel` not kScalar), the spans are computed four
///   rows at a time and a row's cells tested four at a time, eight with AVX-512 (kernel kBest);
/// - a textured triangle's covered cells are gathered, then their texture coordinates, normal
///   factors and heights computed eight at a time (AVX-512 with kBest; AVX2 four, SSE2 two) and
///   their texture samples taken together (SampleLevelBatch with `kernel`; measured:
///   docs/measurements.md);
/// - every SIMD step writes the bits of the scalar code (no FMA), which kScalar runs; kAvx2 runs
///   the AVX2 steps where the CPU also has AVX-512 (the tests compare both with kScalar);
/// - flat-shaded triangles (equal corner normals) skip the normal's per-cell length (a 1e-16
///   relative difference from the reference).
/// Same preconditions; never allocates. m = 1 lets one render serve the four in-plane
/// translation samples of the gradient (exact shifts by one cell).
void RenderPatchHeightsFast(const HapticModel& model, const RigidTransform& X_WO,
                            std::span<const int> triangles, const ContactWindow& window,
                            PatchSide side, int margin_cells, std::span<float> heights,
                            SampleKernel kernel = SampleKernel::kBest) noexcept;

/// Result of one directional penetration-depth evaluation.
struct DepthSample {
  /// δ = max over cells covered by both patches of (b − a) (m). Signed: negative means the
  /// patches are separated along n by −δ. −∞ when no cell is covered by both.
  double depth_m;
  /// Index j*N + i of the deepest cell, or −1 when no cell is covered by both.
  int cell;
};

/// The largest environment height over square blocks of an N×N render: level k ≥ 1 holds the
/// maximum of each 2^k × 2^k block (−∞ where empty), so that the largest height over any cell box
/// is read from at most 2×2 entries of one level. RenderToolDepth skips a triangle whose cells
/// all fall short before it tests them. Built once per window, for the rotation renders that
/// share its environment.
class EnvironmentMaxPyramid {
 public:
  /// Reserves for windows up to `max_resolution` cells a side (Build then never allocates).
  void Reserve(int max_resolution);
  /// The pyramid of `env_heights` (N×N, N = resolution); builds nothing (resolution() 0) when
  /// env_heights is too short or the reserve too small. Never allocates.
  void Build(std::span<const float> env_heights, int resolution) noexcept;
  /// N of the last Build (0: none).
  int resolution() const noexcept { return resolution_; }
  /// The largest height over cells i ∈ [i0, i1], j ∈ [j0, j1] (clamped to the window), or more
  /// (the blocks read may reach past the box); −∞ for an empty box. Precondition: resolution() > 0.
  float MaxOver(int i0, int i1, int j0, int j1) const noexcept;

 private:
  const float* env_ = nullptr;
  int resolution_ = 0;
  std::vector<float> storage_;
  std::vector<int> offset_, size_;  // level k ≥ 1 at storage_[offset_[k]], size_[k]² entries
};

/// The environment's largest height over each row's blocks of kBlock cells (window cell j·N + i
/// in block i / kBlock of row j), for RenderToolDepth's cull of whole rows: a tool triangle's row
/// whose largest environment height over its covered span, less the row's smallest coarse tool
/// height there (at one end of the span: the coarse height is affine along a row), cannot reach
/// the cut (the lower bound less the triangle's texture bound and the rounding margin) holds no
/// cell the per-cell test would keep, and is skipped before its cells are covered. Heights in
/// the window's frame along n (m), as the render's.
class EnvironmentRowMax {
 public:
  static constexpr int kBlock = 8;
  /// Reserves for windows up to `max_resolution` cells a side (Build then never allocates).
  void Reserve(int max_resolution);
  /// The row blocks of `env_heights` (N×N, N = resolution); builds nothing (resolution() 0)
  /// when env_heights is too short or the reserve too small. NaN heights are passed over (the
  /// per-cell test drops those cells). Never allocates.
  void Build(std::span<const float> env_heights, int resolution) noexcept;
  /// N of the last Build (0: none).
  int resolution() const noexcept { return resolution_; }
  /// The largest height over cells [i0, i1] of row j (clamped to the window), or more (whole
  /// blocks are read); −∞ for an empty span. Precondition: resolution() > 0, 0 ≤ j < N.
  float MaxOver(int j, int i0, int i1) const noexcept {
    i0 = i0 < 0 ? 0 : i0;
    i1 = i1 > resolution_ - 1 ? resolution_ - 1 : i1;
    float m = -std::numeric_limits<float>::infinity();
    const float* row = storage_.data() + static_cast<std::size_t>(j) * blocks_;
    for (int b = i0 / kBlock; b <= i1 / kBlock && i0 <= i1; ++b) m = row[b] > m ? row[b] : m;
    return m;
  }

 private:
  int resolution_ = 0, blocks_ = 0;
  std::vector<float> storage_;
};

/// What RenderToolDepth's cull computes per tool triangle that does not change with the tool's
/// pose: the triangle's mip level for the window's cell size (HeightField::LevelForFootprint) and
/// the largest |h| under its texture coordinates at that level (HeightField::MaxAbsOver), kept for
/// the renders of one window (the six rotated poses share them). Entries fill as the renders meet
/// the triangles; the values are those the render would compute, so the renders' results are the
/// same with or without it. Reserve allocates; the rest never does.
class TriangleBoundCache {
 public:
  /// Room for models of up to `max_triangles` triangles (larger ones are not cached).
  void Reserve(std::size_t max_triangles);
  /// Starts a window of cell size `cell_size_m` (m) on `model`: forgets every entry, in O(1)
  /// (entries carry the window's stamp). The cache stays unused (Matches false) when the model
  /// has more triangles than reserved.
  void Reset(const HapticModel& model, double cell_size_m) noexcept;
  /// True when the last Reset was for this model and cell size and the cache has room for it.
  bool Matches(const HapticModel& model, double cell_size_m) const noexcept {
    return model_ == &model && cell_size_m_ == cell_size_m && usable_;
  }
  /// Triangle f's level and texture bound (m) if cached since the last Reset; false otherwise.
  /// Precondition: Matches() for the model f belongs to, and 0 ≤ f < its triangle count.
  bool Find(int f, int& level, double& texture_bound_m) const noexcept {
    const Entry& e = entries_[static_cast<std::size_t>(f)];
    if (e.stamp != stamp_) return false;
    level = e.level;
    texture_bound_m = e.texture_bound_m;
    return true;
  }
  /// Caches triangle f's level and texture bound (m) until the next Reset. Precondition (as for
  /// Find): Matches() for the model f belongs to, and 0 ≤ f < its triangle count.
  void Store(int f, int level, double texture_bound_m) noexcept {
    entries_[static_cast<std::size_t>(f)] = {texture_bound_m, level, stamp_};
  }

 private:
  struct Entry {
    double texture_bound_m = 0.0;
    int level = 0;
    std::uint32_t stamp = 0;
  };
  std::vector<Entry> entries_;
  std::uint32_t stamp_ = 0;
  const HapticModel* model_ = nullptr;
  double cell_size_m_ = 0.0;
  bool usable_ = false;
};

/// RenderToolDepth's hints and what it reports about its cull.
struct ToolDepthCull {
  /// Window cell j·N + i whose neighbourhood (±2 cells) the first pass draws: a good guess at the
  /// deepest cell, such as the unrotated pose's; −1 for none (one pass).
  int first_cell = -1;
  /// The first pass's triangles, a subset of the render's (a triangle outside them would be
  /// drawn where the whole render does not draw it); empty: all of them. The triangles a render
  /// at a nearby pose drew there (first_triangles_out) spare the first pass the others.
  std::span<const int> first_triangles;
  /// When not null, gets the triangles the first pass drew (cleared first; up to its capacity).
  std::vector<int>* first_triangles_out = nullptr;
  /// The environment's max pyramid (built from env_heights), or nullptr: with it, a triangle
  /// whose largest environment height over its cell box, less its smallest corner height, cannot
  /// reach the lower bound is skipped whole.
  const EnvironmentMaxPyramid* env_max = nullptr;
  /// The environment's row blocks (built from env_heights), or nullptr: with it, a triangle's
  /// row whose largest environment height over its span, less its smallest coarse height there,
  /// cannot reach the cut (as for a cell: the lower bound less the triangle's texture bound and
  /// the margin) is skipped whole. The same cells are drawn either way.
  const EnvironmentRowMax* env_row_max = nullptr;
  /// Each triangle's level and texture bound, shared by the renders of one window (Reset for
  /// this window and the tool), or nullptr: computed per render.
  TriangleBoundCache* bounds = nullptr;
  /// Out: how many cells were textured and drawn.
  int cells_drawn = 0;
  /// Out: how many rows of triangles env_row_max skipped whole.
  int rows_skipped = 0;
};

/// DirectionalPenetrationDepth(env_heights, tool render) for the tool render that
/// RenderPatchHeightsFast(tool, X_WT, triangles, window, kTool, 0, ·, kernel) would make, the
/// same cell and bits, drawing only the cells that can matter (the texture stage's rendered
/// rotation samples). A first pass draws the cells around hints.first_cell (with
/// hints.first_triangles); from its cells on, the largest b − a drawn so far is a lower bound L
/// of the depth (a cell's tool height only falls as triangles are drawn), and a covered cell
/// whose bound env − (b·d) + max|h| (its coarse height b·d; max|h| the largest |height| under
/// its triangle's texture coordinates, HeightField::MaxAbsOver at the triangle's mip level;
/// |N·n| ≤ 1) is below L by more than a margin for float rounding is not textured or drawn: it
/// cannot be the deepest cell nor tie with it. `heights` (#N*N, scratch) holds the partial render
/// afterwards: the drawn cells have their RenderPatchHeightsFast values or above, the others +∞
/// or above. How much is culled depends on the texture's amplitude against the depth's spread
/// over the window (hints.cells_drawn reports it). Returns {−∞, −1} when env_heights or heights
/// hold fewer than N*N cells. Never allocates.
DepthSample RenderToolDepth(const HapticModel& tool, const RigidTransform& X_WT,
                            std::span<const int> triangles, const ContactWindow& window,
                            std::span<const float> env_heights, std::span<float> heights,
                            ToolDepthCull& hints,
                            SampleKernel kernel = SampleKernel::kBest) noexcept;

/// δ of heights `b` (environment, −∞ where empty) and `a` (tool, +∞ where empty), both #N*N.
/// Ties keep the lowest index. Never allocates. One scan in SIMD lanes (sixteen with AVX-512,
/// eight with AVX2, else four with SSE2), each keeping the first cell of its largest difference:
/// the cell and bits of the plain one-cell-at-a-time scan.
DepthSample DirectionalPenetrationDepth(std::span<const float> b,
                                        std::span<const float> a) noexcept;

/// δ of `b` (environment, N×N, −∞ where empty) against the tool heights of an extended buffer
/// `a_ext` ((N+2m)², as RenderPatchHeightsFast with margin m) read with an offset: window cell
/// (i, j) pairs with a_ext at window cell (i + di, j + dj), |di|, |dj| ≤ m. This is the tool
/// moved by (−di, −dj) cells along (u, v) without another render. Cells index b (j·N + i); ties
/// keep the lowest index, as DirectionalPenetrationDepth. Never allocates.
DepthSample DirectionalPenetrationDepthShifted(std::span<const float> b, int resolution,
                                               std::span<const float> a_ext, int margin_cells,
                                               int di, int dj) noexcept;

}  // namespace ht
