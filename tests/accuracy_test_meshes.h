#pragma once
// Meshes and poses shared by the accuracy tests (ground_truth_depth_test,
// contact_patch_truth_test).

#include <glm/gtc/quaternion.hpp>

#include "haptic_core/haptic_model.h"
#include "haptic_core/spatial.h"

namespace ht::test {

/// Closed box [lo, hi] (m), 12 triangles, counter-clockwise seen from outside.
inline TriangleMesh Box(const glm::dvec3& lo, const glm::dvec3& hi) {
  TriangleMesh m;
  for (int i = 0; i < 8; ++i) {
    m.vertices.push_back({(i & 1) ? hi.x : lo.x, (i & 2) ? hi.y : lo.y, (i & 4) ? hi.z : lo.z});
  }
  const int faces[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4},
                           {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  for (const auto& f : faces) {
    m.triangles.push_back({f[0], f[1], f[2]});
    m.triangles.push_back({f[0], f[2], f[3]});
  }
  return m;
}

/// The pose with translation p (m) and rotation R.
inline RigidTransform At(const glm::dvec3& p, const glm::dquat& R = glm::dquat(1, 0, 0, 0)) {
  RigidTransform X;
  X.translation = p;
  X.rotation = R;
  return X;
}

}  // namespace ht::test
