#pragma once
// Stage 1 of the remote step (remote_step.h): the broad phase. Each model's root bounding sphere
// (the one its hull hierarchy's query uses anyway) rules out, with one distance test, the
// tool–object pairs too far apart for the coarse query (hull_proximity.h) to find anything.

#include <glm/vec4.hpp>

#include "haptic_core/spatial.h"

namespace ht {

/// Gap (m) between two bounding spheres placed in W: sphere_A in frame A (centre in xyz, radius
/// in w, m) at pose X_WA, and sphere_B likewise. Negative when the spheres overlap. A pair whose
/// gap exceeds the coarse query's tolerance cannot have a leaf pair within it. noexcept; NaN in,
/// NaN out (and NaN > tolerance is false, so a NaN pose is never culled here: the pipeline rejects
/// non-finite poses before this stage).
double BoundingSphereGap(const glm::dvec4& sphere_A, const RigidTransform& X_WA,
                         const glm::dvec4& sphere_B, const RigidTransform& X_WB) noexcept;

}  // namespace ht
