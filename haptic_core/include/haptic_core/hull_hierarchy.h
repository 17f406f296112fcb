#pragma once
// The bounding volume hierarchy of convex hulls over a coarse mesh (DESIGN.md §2, seed: "a BVH of
// convex hulls ... equivalent to CLODs where all levels are free"; Otaduy & Lin, SIGGRAPH 2003,
// after Ehmann & Lin's convex surface decomposition, Eurographics 2001). Leaves are convex surface
// patches of the coarse mesh; every node's hull bounds its whole subtree.
//
// This header holds the data and the queries only (no qhull): the contact query reads it near the
// 1 kHz loop, e.g. through libccd support functions. The builder is in
// haptic_core/model_build/hull_hierarchy_build.h.

#include <glm/vec3.hpp>
#include <glm/vec4.hpp>
#include <vector>

namespace ht {

/// A convex polytope in an object frame O (metres), kept in both forms: its vertices (for support
/// functions: GJK, MPR, EPA) and its outward face planes (for a cheap distance bound).
///
/// Invariant kept by the builder: every vertex satisfies every plane (n·p − d ≤ 0 up to rounding),
/// so the planes' intersection contains the convex hull of the vertices.
struct ConvexHull {
  /// Hull vertices p_OV (extreme points only), #H.
  std::vector<glm::dvec3> vertices_O;
  /// Outward face planes (n_x, n_y, n_z, d): unit outward normal n (expressed in O) and offset d
  /// (m), such that n·p − d ≤ 0 for p inside, #P.
  std::vector<glm::dvec4> planes_O;
  /// A point inside the hull, p_OC (the vertex centroid), m.
  glm::dvec3 center_O{0.0};

  /// Signed distance bound (m) of the point p_OQ: max_i (n_i·p − d_i). ≤ 0 when p is inside the
  /// planes; > 0 is a lower bound of p's Euclidean distance to the hull (exact when the nearest
  /// hull point lies inside a face, smaller near edges and corners). +infinity when the hull has
  /// no planes (an empty hull); NaN when p or a plane holds NaN (never a false "inside").
  /// Allocation-free, safe for the haptic loop.
  double SignedDistanceBound(const glm::dvec3& p_OQ) const noexcept;

  /// The vertex farthest along `direction_O` (any length, not normalized), p_OV in m: the support
  /// point used by GJK / MPR / EPA. Ties go to the first such vertex; center_O when the hull has no
  /// vertices. Allocation-free.
  glm::dvec3 Support(const glm::dvec3& direction_O) const noexcept;
};

/// One node of a ConvexHullHierarchy.
struct HullNode {
  /// Bounds every coarse triangle of the subtree (and the hulls of both children).
  ConvexHull hull;
  /// Indices into ConvexHullHierarchy::nodes; both −1 for a leaf, both valid otherwise.
  int children[2] = {-1, -1};
  /// Leaf only: indices of the coarse triangles forming this leaf's convex surface patch
  /// (connected through shared edges, lying on their own convex hull). Empty for internal nodes.
  std::vector<int> triangles;

  /// True when the node has no children.
  bool is_leaf() const noexcept { return children[0] < 0 && children[1] < 0; }
};

/// A binary tree of convex hulls over a coarse triangle mesh (frame O, metres). A convex mesh gives
/// a single node (root = leaf).
struct ConvexHullHierarchy {
  /// All nodes; nodes[0] is the root. Empty means no hierarchy (a mesh without triangles).
  /// Nodes are in depth-first pre-order: a parent comes before its children.
  std::vector<HullNode> nodes;

  /// Number of leaves (0 for an empty hierarchy).
  int LeafCount() const noexcept;
  /// Number of levels: 0 for an empty hierarchy, 1 for a single node. Follows child links only
  /// to valid indices and stops at nodes.size() levels, so it terminates on a corrupt tree too.
  /// Allocates a scratch list (throws only std::bad_alloc): not for the step.
  int Depth() const;

  /// Checks the hierarchy against the coarse mesh it was built from: `vertices_O` (#V, m) and
  /// `triangles` (#F, indices into vertices_O). Throws std::invalid_argument naming the first
  /// failure among: tolerance_m negative or not finite; a triangle index out of range; child
  /// indices out of range, only one child set, a node reached twice (a cycle or a shared child) or
  /// never reached from the root; an empty hull, a non-finite number or a normal not of unit
  /// length; a hull vertex outside its own planes by more than tolerance_m; an internal node
  /// holding triangles, or a leaf holding none; a coarse triangle in no leaf or in more than one;
  /// a vertex of a leaf's triangle outside the leaf's hull by more than tolerance_m; a child
  /// hull's vertex outside its parent's hull by more than tolerance_m. "Outside" is measured with
  /// SignedDistanceBound(). An empty hierarchy is valid only for a mesh without triangles.
  void Validate(const std::vector<glm::dvec3>& vertices_O, const std::vector<glm::ivec3>& triangles,
                double tolerance_m) const;
};

}  // namespace ht
