// Two small helpers of the convex hulls (convex_hull_build.cc) and their hierarchy
// (hull_hierarchy_build.cc). Internal to src/model_build/.
#pragma once

#include <cmath>
#include <glm/vec3.hpp>
#include <glm/vec4.hpp>

namespace ht::hull_build {

inline bool IsFinite(const glm::dvec3& v) {
  return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}

// Plane value n·p − d, written exactly as ConvexHull::SignedDistanceBound() evaluates it so that
// offsets set from these values make the defining points lie exactly on or behind the plane.
inline double PlaneValue(const glm::dvec4& plane, const glm::dvec3& p) {
  return plane.x * p.x + plane.y * p.y + plane.z * p.z - plane.w;
}

}  // namespace ht::hull_build
