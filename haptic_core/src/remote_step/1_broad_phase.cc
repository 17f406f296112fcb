#include <glm/geometric.hpp>
#include <limits>

#include "haptic_core/broad_phase.h"

namespace ht {

double BoundingSphereGap(const glm::dvec4& sphere_A, const RigidTransform& X_WA,
                         const glm::dvec4& sphere_B, const RigidTransform& X_WB) noexcept {
  return glm::length(X_WA * glm::dvec3(sphere_A) - X_WB * glm::dvec3(sphere_B)) - sphere_A.w -
         sphere_B.w;
}

namespace {

/// The largest gap along P's face normals between P's planes and Q's vertices, P at X_WP and Q at
/// X_WQ: max over planes (n, d) of min over q of n·(X_PQ q) − d.
double FaceSeparation(const ConvexHull& P, const RigidTransform& X_WP, const ConvexHull& Q,
                      const RigidTransform& X_WQ) noexcept {
  const RigidTransform X_QP = X_WQ.Inverse() * X_WP;
  double best = -std::numeric_limits<double>::infinity();
  for (const glm::dvec4& plane : P.planes_O) {
    const glm::dvec3 n_P(plane);
    const glm::dvec3 n_Q = X_QP.rotation * n_P;  // the normal in Q's frame
    // Offset of P's plane along n_Q in Q's frame: n·p − d = 0 for p on the plane (frame P).
    const double offset = plane.w + glm::dot(n_Q, X_QP.translation);
    double lowest = std::numeric_limits<double>::infinity();
    for (const glm::dvec3& q : Q.vertices_O) lowest = std::min(lowest, glm::dot(n_Q, q));
    best = std::max(best, lowest - offset);
  }
  return best;
}

}  // namespace

double HullSeparationBound(const ConvexHull& A, const RigidTransform& X_WA, const ConvexHull& B,
                           const RigidTransform& X_WB, std::size_t max_work) noexcept {
  if (A.vertices_O.empty() || B.vertices_O.empty() || A.planes_O.empty() || B.planes_O.empty() ||
      A.planes_O.size() * B.vertices_O.size() + B.planes_O.size() * A.vertices_O.size() >
          max_work) {
    return -std::numeric_limits<double>::infinity();
  }
  double best = std::max(FaceSeparation(A, X_WA, B, X_WB), FaceSeparation(B, X_WB, A, X_WA));
  // One more axis: from B's centre towards A's (the separating direction of two round hulls).
  const glm::dvec3 d_W = X_WA * A.center_O - X_WB * B.center_O;
  const double len = glm::length(d_W);
  if (len > 0.0) {
    const glm::dvec3 n_W = d_W / len;
    const glm::dvec3 n_A = glm::inverse(X_WA.rotation) * n_W;
    const glm::dvec3 n_B = glm::inverse(X_WB.rotation) * n_W;
    double low_A = std::numeric_limits<double>::infinity();
    double high_B = -std::numeric_limits<double>::infinity();
    for (const glm::dvec3& a : A.vertices_O) low_A = std::min(low_A, glm::dot(n_A, a));
    for (const glm::dvec3& b : B.vertices_O) high_B = std::max(high_B, glm::dot(n_B, b));
    best = std::max(best, (low_A + glm::dot(n_W, X_WA.translation)) -
                              (high_B + glm::dot(n_W, X_WB.translation)));
  }
  return best;
}

}  // namespace ht
