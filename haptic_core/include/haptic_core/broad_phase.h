#pragma once
// Stage 1 of the remote step (remote_step.h): the broad phase. Each model's root bounding sphere
// (the one its hull hierarchy's query uses anyway) rules out, with one distance test, the
// tool–object pairs too far apart for the coarse query (hull_proximity.h) to find anything.

#include <glm/vec4.hpp>

#include "haptic_core/hull_hierarchy.h"
#include "haptic_core/spatial.h"

namespace ht {

/// Gap (m) between two bounding spheres placed in W: sphere_A in frame A (centre in xyz, radius
/// in w, m) at pose X_WA, and sphere_B likewise. Negative when the spheres overlap. A pair whose
/// gap exceeds the coarse query's tolerance cannot have a leaf pair within it. noexcept; NaN in,
/// NaN out (and NaN > tolerance is false, so a NaN pose is never culled here: the pipeline rejects
/// non-finite poses before this stage).
double BoundingSphereGap(const glm::dvec4& sphere_A, const RigidTransform& X_WA,
                         const glm::dvec4& sphere_B, const RigidTransform& X_WB) noexcept;

/// A lower bound (m) of the Euclidean distance between two convex hulls, A (frame A, posed at
/// X_WA) and B (frame B, at X_WB): the largest gap along any of either hull's outward face
/// normals between its plane and the other hull's support (separating-axis bound; exact for a
/// vertex–face or face–face separation, smaller across edges). ≤ 0 when no face plane separates
/// them (touching, overlapping, or separated only across an edge pair). Returns −∞ when a hull
/// has no vertices or no planes, or when |planes_A|·|vertices_B| + |planes_B|·|vertices_A|
/// exceeds `max_work` (a bound too costly to take). Allocation-free; NaN poses give NaN.
/// Used by the remote step to tell how much free space surrounds the tool.
double HullSeparationBound(const ConvexHull& A, const RigidTransform& X_WA, const ConvexHull& B,
                           const RigidTransform& X_WB, std::size_t max_work = 65536) noexcept;

}  // namespace ht
