#pragma once
// Coarse contact query between two convex vertex sets through libccd (GJK + EPA, MPR fallback).

#include <glm/vec3.hpp>
#include <optional>
#include <span>

#include "haptic_core/spatial.h"

namespace ht {

/// Result of a tolerant convex proximity query.
struct ConvexContact {
  /// Signed distance between the two hulls (m): positive when separated, negative when
  /// penetrating (−penetration depth).
  double signed_distance_m = 0.0;
  /// Unit direction from B towards A (A must move along it to separate), world frame.
  glm::dvec3 normal_W{0.0, 0.0, 1.0};
  /// A point of the region where the hulls touch or overlap (m), world frame; laterally within
  /// the contact region, its position along the normal only approximate (libccd EPA).
  glm::dvec3 point_W{0.0};
};

/// Contact of the convex hulls of `hull_A_O` (posed at X_WA) and `hull_B_O` (posed at X_WB) when
/// they are closer than `tolerance_m` (≥ 0): A's hull is grown by a sphere of that radius and the
/// penetration depth d of the grown pair is found with libccd's GJK+EPA (MPR when EPA fails);
/// then signed_distance = tolerance − d.
/// Returns std::nullopt when the hulls are farther apart than the tolerance, when a vertex set
/// is empty, or when a pose or the tolerance is not finite. Allocates inside libccd (EPA): call it
/// from the remote node's step, never from the 1 kHz loop.
std::optional<ConvexContact> QueryConvexContact(std::span<const glm::dvec3> hull_A_O,
                                                const RigidTransform& X_WA,
                                                std::span<const glm::dvec3> hull_B_O,
                                                const RigidTransform& X_WB, double tolerance_m);

}  // namespace ht
