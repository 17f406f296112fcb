#pragma once
// Building the convex-hull hierarchy of a coarse mesh at start-up (DESIGN.md §2): convex surface
// patches by greedy region growing (the convex surface decomposition of Ehmann & Lin,
// Eurographics 2001, as used for Otaduy & Lin's CLODs, SIGGRAPH 2003), a binary tree over the
// patches by median splits, and hulls through qhull (reentrant C API; Barber, Dobkin & Huhdanpaa,
// ACM TOMS 1996).

#include <glm/vec3.hpp>
#include <vector>

#include "haptic_core/hull_hierarchy.h"

namespace ht {

/// Parameters of BuildConvexHullHierarchy().
struct HullHierarchyParams {
  /// How far (m) a patch vertex may lie in front of a patch triangle's plane for the patch to count
  /// as convex. 0 = automatic: 1e-3 × the diagonal of the mesh's bounding box. It sets only the
  /// granularity (leaf hulls bound their triangles whatever it is): a coarse mesh decimated from a
  /// textured convex object is convex only up to about the texture amplitude, so a caller that
  /// knows the model's TextureReach() may pass it here to get one leaf for such an object.
  double convexity_tolerance_m = 0.0;
  /// Largest number of triangles in one leaf patch; 0 = unlimited. A convex mesh with more
  /// triangles than this is split too.
  int max_leaf_triangles = 0;
  /// Largest angle (degrees, in (0, 180]) between a patch triangle's normal and the normal of the
  /// patch's first (seed) triangle. It bounds how far a leaf hull's closing ("virtual") faces reach
  /// away from the surface: at 90° a patch may be the outer half of a torus ring, whose hull spans
  /// the hole (a false contact for a tool in the hole); 60° keeps such hulls inside the tube.
  /// It also keeps the two sides of a zero-thickness fin apart (their normals are 180° apart,
  /// while each side's vertices lie on the other's plane). Not applied when the whole mesh is
  /// convex.
  double max_normal_deviation_deg = 60.0;
  /// Largest gap (m) between the shadow of a patch's hull and the shadow of the patch itself,
  /// both projected along the seed triangle's normal (sampled at the midpoints of the hull
  /// shadow's edges and at its centroid). Keeps patches from wrapping around holes and notches:
  /// a flat annulus is convex, but its hull is a disk over the hole. 0 = automatic: 2 % of the
  /// mesh's bounding-box diagonal; +infinity disables. Not applied when the whole mesh is convex.
  double max_shadow_gap_m = 0.0;
  /// Leaf patches thinner than this (m) along their mean outward normal (flat patches, single
  /// triangles) get each vertex copied this far inward (along −normal) before their hull is
  /// taken, so every leaf hull has volume while its outer face stays on the surface.
  /// 0 = automatic: the convexity tolerance.
  double leaf_thickness_m = 0.0;
};

/// Builds the convex-hull hierarchy of a coarse mesh in frame O (metres).
///
/// `vertices_O`: #V vertex positions; `triangles`: #F triangles indexing them, counter-clockwise
/// seen from outside (outward normals). Triangles need not form a closed or manifold surface.
///
/// 1. Whole mesh convex (every used vertex on or behind every triangle's plane within the
///    convexity tolerance) and within max_leaf_triangles: one node, root = leaf.
/// 2. Otherwise leaves are convex surface patches grown greedily: a seed triangle (lowest
///    unassigned index), then edge-adjacent unassigned triangles, best first (the normal closest
///    to the seed's), each accepted when (a) every patch vertex stays on or behind every patch
///    triangle's plane within the tolerance (the patch lies on its own convex hull), (b) its
///    normal is within max_normal_deviation_deg of the seed's, (c) the shadow gap stays within
///    max_shadow_gap_m, and (d) max_leaf_triangles holds. (a) and (b) only get stricter
///    as a patch grows, so a triangle failing them is not retried for that patch; one failing (c)
///    is retried when another of its neighbours joins. Zero-area triangles have no plane and no
///    normal: they join any neighbouring patch whose vertices allow it.
/// 3. The tree is built top-down: a set of leaves is split at the median of the leaf centres
///    along the longest axis of their bounding box (balanced: depth ⌈log2 L⌉ + 1, 2L − 1 nodes).
///    An internal node's hull is the qhull hull of its children's hull vertices, so each hull
///    contains its children's hulls.
///
/// Leaf hulls are the hulls of their patch vertices (thin patches thickened inward, see
/// HullHierarchyParams::leaf_thickness_m). The result passes
/// ConvexHullHierarchy::Validate(vertices_O, triangles, tolerance) for a tolerance of about 1e-9 ×
/// the mesh diagonal.
///
/// Throws std::invalid_argument when there are no triangles, a triangle indexes a vertex out of
/// range, a used vertex is not finite, or a parameter is out of range (a negative or non-finite
/// convexity_tolerance_m or leaf_thickness_m, a negative or NaN max_shadow_gap_m, a negative
/// max_leaf_triangles, an angle outside (0, 180]).
ConvexHullHierarchy BuildConvexHullHierarchy(const std::vector<glm::dvec3>& vertices_O,
                                             const std::vector<glm::ivec3>& triangles,
                                             const HullHierarchyParams& params = {});

/// Convex hull of `points_O` (#N, frame O, m) through qhull (default options: exact merging of
/// coplanar facets, so a face is one plane however many triangles it would take).
///
/// Planes: qhull's facet hyperplanes, each offset pushed out to the largest n·p over all input
/// points, so every input point satisfies every plane exactly (qhull alone allows a rounding
/// margin) and SignedDistanceBound() is a true lower bound of the distance to the points' hull.
///
/// Degenerate sets: the extents along the principal axes of the points (covariance
/// eigenvectors) are measured first. Along each axis where the extent is below
/// t = max(thickness_m, 1e-7 × the largest extent) (less a 1e-6 relative slack, so that a set
/// already thickened to t is left alone), every point gets two copies offset by ±t/2, so
/// flat (coplanar, a single triangle) and collinear sets give a slab or a prism of thickness ≥ t
/// that contains the points; qhull then never sees a flat input. A single point (or all points
/// equal) with thickness_m = 0 gives that point as the only vertex and six axis-aligned planes
/// through it. Should qhull still fail, it is retried with joggled input ('QJ'), and at last the
/// principal-axes bounding box (widened by t/2 where thin) is returned: always finite, always
/// containing the points.
///
/// Throws std::invalid_argument when `points_O` is empty or holds a non-finite coordinate, or
/// thickness_m is negative or not finite.
ConvexHull ComputeConvexHull(const std::vector<glm::dvec3>& points_O, double thickness_m);

}  // namespace ht
