#pragma once
// The direction of a contact from its region: for a leaf hull pair of the
// coarse query, the area-weighted normals of the coarse triangles that lie in contact, instead of
// the smallest support overlap of the two hulls (which on a thin hull is a side face). After Kim,
// Otaduy, Lin & Manocha, "Six-degree-of-freedom haptic display using localized contact
// computations" (HAPTICS 2002 / IEEE TVCG 2003), who compute one penetration direction per cluster
// from its contact region.
//
// Why this direction: for two closed solids T (tool) and O (object) whose intersection has volume
// V, moving the tool by Δx changes V by ∫_{∂T∩O} n_T·Δx dA, so −∇ₓV = −∫_{∂T∩O} n_T dA =
// ∫_{∂O∩T} n_O dA (the intersection's boundary integrates n to zero). The region vector below
// approximates the mean of both integrals on the coarse meshes, with each leaf's convex hull
// standing in for its solid and widened by a margin, so that surfaces that touch only through
// their textures (coarse meshes a fraction of a millimetre apart) still give a direction.

#include <glm/vec3.hpp>
#include <optional>
#include <span>

#include "haptic_core/haptic_model.h"
#include "haptic_core/hull_hierarchy.h"
#include "haptic_core/spatial.h"

namespace ht {

/// The region vector of one leaf pair (m², W): ½(Σ_{t ∈ leaf B} a(t ∩ H_A⁺)·n_t −
/// Σ_{t ∈ leaf A} a(t ∩ H_B⁺)·n_t), where leaf A (node `node_A` of `tool`'s hierarchy, posed at
/// X_WT) and leaf B (node `node_B` of `object`'s, at X_WO) are convex surface patches, n_t a
/// coarse triangle's outward unit normal, H⁺ the other leaf's convex hull with every face plane
/// moved out by `margin_m` (≥ 0, m), and a(t ∩ H⁺) the area of the part of t inside it
/// (Sutherland–Hodgman clipping). Its direction is the contact region's penetration direction,
/// from the object towards the tool; its length the region's area (projected). Returns the zero
/// vector when a node is not a leaf of its hierarchy (−1: a model without hierarchy, which has no
/// face planes), when no triangle lies in the other's widened hull, or for non-finite input; the
/// caller then keeps the pair's own normal. Never throws, never allocates (a triangle whose
/// clipped polygon would exceed 64 vertices is skipped).
glm::dvec3 LeafPairRegionVector(const HapticModel& tool, const RigidTransform& X_WT, int node_A,
                                const HapticModel& object, const RigidTransform& X_WO, int node_B,
                                double margin_m) noexcept;

/// A contact region's extent on a window's axes: u and v coordinates (m) from the window's origin.
struct RegionBounds {
  double min_u = 0.0;
  double max_u = 0.0;
  double min_v = 0.0;
  double max_v = 0.0;
};

/// The hull of a convex coarse mesh (a model without hierarchy, whose coarse mesh is its single
/// hull: the built-in procedural models): its hull vertices and one outward plane per distinct
/// face plane of its triangles (frame O, m). nullopt when the mesh is not convex (a vertex more
/// than `tolerance_m` outside a face plane), has no triangles, or holds a bad index. Allocates:
/// call at set-up (the remote step builds one per such model at construction).
std::optional<ConvexHull> ConvexMeshHull(const HapticModel& model, double tolerance_m = 1e-9);

/// The extent of one hull pair's contact region on a window's axes (the window is centred on the
/// region, not on a witness corner, and sized from it): the coarse triangles
/// `triangles_B` of `object` (posed at X_WO) clipped to the tool's hull `hull_A` widened by
/// `margin_m` (each face plane moved out; the pair's texture reach), and the tool's `triangles_A`
/// (posed at X_WT) clipped to `hull_B` widened alike, each part's box on the unit axes u_W, v_W
/// from origin_W (m, W), and `out` the overlap of the two boxes (their union when they miss each
/// other). Hulls in their model's frame O. Returns false (out zeroed) when either part is empty or
/// for non-finite input. Never throws, never allocates.
bool PairRegionBounds(const HapticModel& tool, const RigidTransform& X_WT, const ConvexHull& hull_A,
                      std::span<const int> triangles_A, const HapticModel& object,
                      const RigidTransform& X_WO, const ConvexHull& hull_B,
                      std::span<const int> triangles_B, double margin_m, const glm::dvec3& origin_W,
                      const glm::dvec3& u_W, const glm::dvec3& v_W, RegionBounds& out) noexcept;

}  // namespace ht
