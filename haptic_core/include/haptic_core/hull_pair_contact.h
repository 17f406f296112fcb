#pragma once
// One leaf pair found by the coarse proximity query between two convex-hull hierarchies
// (DESIGN.md §3): the input of contact clustering.

#include <glm/vec3.hpp>

namespace ht {

/// A pair of leaf hulls (convex surface patches) of the tool A and an object B that are within the
/// query tolerance ε of each other, or penetrate.
struct HullPairContact {
  /// Leaf node indices into A's and B's ConvexHullHierarchy::nodes (−1 when a model has no
  /// hierarchy and its single hull stood in for it).
  int node_A = -1;
  int node_B = -1;
  /// Signed distance (m): > 0 separated by that much, < 0 penetrating by −signed_distance_m,
  /// 0 touching.
  double signed_distance_m = 0.0;
  /// Unit contact normal in W, from B towards A (A moves along it to separate).
  glm::dvec3 normal_W{0.0, 0.0, 1.0};
  /// Witness points on A's and B's hull (m, W): the closest points when separated; when
  /// penetrating, the deepest points along normal_W (p_A − p_B = signed_distance_m · normal_W
  /// within the solver's accuracy).
  glm::dvec3 point_A_W{0.0};
  glm::dvec3 point_B_W{0.0};
};

}  // namespace ht
