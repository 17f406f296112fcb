#include "haptic_core/broad_phase.h"

#include <glm/geometric.hpp>

namespace ht {

double BoundingSphereGap(const glm::dvec4& sphere_A, const RigidTransform& X_WA,
                         const glm::dvec4& sphere_B, const RigidTransform& X_WB) noexcept {
  return glm::length(X_WA * glm::dvec3(sphere_A) - X_WB * glm::dvec3(sphere_B)) - sphere_A.w -
         sphere_B.w;
}

}  // namespace ht
