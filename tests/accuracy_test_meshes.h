#pragma once
// Meshes and poses shared by the accuracy tests (ground_truth_depth_test,
// contact_patch_truth_test).

#include <cmath>
#include <glm/gtc/quaternion.hpp>
#include <numbers>

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

/// A UV sphere of radius r (m) about the origin: closed, 2·n_lon·(n_lat−1) triangles,
/// counter-clockwise seen from outside.
inline TriangleMesh UvSphere(double r, int n_lat, int n_lon) {
  TriangleMesh m;
  m.vertices.emplace_back(0, 0, r);
  for (int i = 1; i < n_lat; ++i) {
    const double th = std::numbers::pi * i / n_lat;
    for (int j = 0; j < n_lon; ++j) {
      const double ph = 2 * std::numbers::pi * j / n_lon;
      m.vertices.emplace_back(r * std::sin(th) * std::cos(ph), r * std::sin(th) * std::sin(ph),
                              r * std::cos(th));
    }
  }
  m.vertices.emplace_back(0, 0, -r);
  const int south = static_cast<int>(m.vertices.size()) - 1;
  const auto ring = [&](int i, int j) { return 1 + (i - 1) * n_lon + (j % n_lon); };
  for (int j = 0; j < n_lon; ++j) m.triangles.emplace_back(0, ring(1, j), ring(1, j + 1));
  for (int i = 1; i < n_lat - 1; ++i) {
    for (int j = 0; j < n_lon; ++j) {
      m.triangles.emplace_back(ring(i, j), ring(i + 1, j), ring(i + 1, j + 1));
      m.triangles.emplace_back(ring(i, j), ring(i + 1, j + 1), ring(i, j + 1));
    }
  }
  for (int j = 0; j < n_lon; ++j) {
    m.triangles.emplace_back(south, ring(n_lat - 1, j + 1), ring(n_lat - 1, j));
  }
  return m;
}

}  // namespace ht::test
