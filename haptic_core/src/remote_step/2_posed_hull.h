// Stage 2's geometry of two convex hulls (hull_proximity.h): a hull posed in a query frame, the
// GJK distance between two, and the contact of a touching or penetrating pair. Internal to the
// remote step (2_gjk_distance.cc, 2_hull_penetration.cc, 2_hull_proximity.cc).
#pragma once

#include <cmath>
#include <cstddef>
#include <glm/geometric.hpp>
#include <glm/gtc/quaternion.hpp>
#include <limits>

#include "haptic_core/hull_pair_contact.h"
#include "haptic_core/spatial.h"

namespace ht::hull_geometry {

inline constexpr double kInf = std::numeric_limits<double>::infinity();
// Below this GJK distance (m) a pair counts as touching, and the penetration route gives its
// normal (closest points that coincide give no direction).
inline constexpr double kTouch_m = 1e-12;

inline bool IsFiniteVec(const glm::dvec3& v) noexcept {
  return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}

// One hull posed in a query frame, named W here: the world for leaf pairs, and the frame of
// Query's first model for the traversal, where that model's hulls need no transform. A view of
// its vertices and planes in O, and the pose.
struct PosedHull {
  const glm::dvec3* vertices_O = nullptr;
  std::size_t vertex_count = 0;
  const glm::dvec4* planes_O = nullptr;
  std::size_t plane_count = 0;
  // How O maps to W: not at all (O is W), by rotation matrices made once per query (a
  // matrix–vector product costs about half a quaternion rotation, and the support functions do
  // two per call), or by the world pose's quaternion (QuaternionPath).
  enum class Map : unsigned char { kIdentity, kMatrix, kQuaternion };
  Map map = Map::kMatrix;
  const glm::dmat3* R_WO = nullptr;     // kMatrix
  const glm::dmat3* R_OW = nullptr;     // kMatrix: R_WOᵀ
  glm::dquat q_OW{1.0, 0.0, 0.0, 0.0};  // kQuaternion
  glm::dvec3 p_WO{0.0};                 // the frame's origin in W (0 for kIdentity)
  glm::dvec3 center_W{0.0};
  double radius_m = 0.0;
  // The pose in the world and the centre in O, for QuaternionPath.
  const RigidTransform* X_WO = nullptr;
  glm::dvec3 center_O{0.0};

  // The same hull in the world, its support functions and centre computed with the world pose's
  // quaternion: the arithmetic of leaf pairs (GJK, and libccd's MPR, whose path follows the last
  // bits of its supports), whose contacts are the query's output.
  PosedHull QuaternionPath() const noexcept {
    PosedHull h = *this;
    h.map = Map::kQuaternion;
    h.q_OW = glm::conjugate(X_WO->rotation);
    h.p_WO = X_WO->translation;
    h.center_W = *X_WO * center_O;
    return h;
  }

  glm::dvec3 DirectionInO(const glm::dvec3& d_W) const noexcept {
    switch (map) {
      case Map::kIdentity:
        return d_W;
      case Map::kMatrix:
        return *R_OW * d_W;
      case Map::kQuaternion:
        break;
    }
    return q_OW * d_W;
  }

  // Support point p_WV of the hull along d_W (any length): its vertex farthest along d_W.
  glm::dvec3 Support(const glm::dvec3& d_W) const noexcept {
    const glm::dvec3 d_O = DirectionInO(d_W);
    std::size_t best = 0;
    double best_dot = glm::dot(vertices_O[0], d_O);
    for (std::size_t i = 1; i < vertex_count; ++i) {
      const double s = glm::dot(vertices_O[i], d_O);
      if (s > best_dot) {
        best_dot = s;
        best = i;
      }
    }
    switch (map) {
      case Map::kIdentity:
        return vertices_O[best];
      case Map::kMatrix:
        return *R_WO * vertices_O[best] + p_WO;
      case Map::kQuaternion:
        break;
    }
    return *X_WO * vertices_O[best];
  }
  // Support value h(d_W) = max_v d_W·p_WV.
  double SupportValue(const glm::dvec3& d_W) const noexcept {
    const glm::dvec3 d_O = DirectionInO(d_W);
    double best = -kInf, best_odd = -kInf;  // two chains: each max waits for half as many
    std::size_t i = 0;
    for (; i + 1 < vertex_count; i += 2) {
      best = std::max(best, glm::dot(vertices_O[i], d_O));
      best_odd = std::max(best_odd, glm::dot(vertices_O[i + 1], d_O));
    }
    if (i < vertex_count) best = std::max(best, glm::dot(vertices_O[i], d_O));
    best = std::max(best, best_odd);
    return map == Map::kIdentity ? best : best + glm::dot(d_W, p_WO);
  }
};

// Overlap (m) of the two hulls' support intervals along the unit n (from B towards A):
// h_B(n) + h_A(−n). Any such n separates the hulls when A moves by the overlap along n.
inline double Overlap(const PosedHull& A, const PosedHull& B, const glm::dvec3& n) noexcept {
  return B.SupportValue(n) + A.SupportValue(-n);
}

enum class GjkStatus { kFar, kNear, kSeparated, kTouching };

struct GjkResult {
  GjkStatus status = GjkStatus::kFar;
  /// Distance (m) for kSeparated; a lower bound for kFar and kNear; 0 for kTouching.
  double distance_m = 0.0;
  glm::dvec3 v{0.0};  // p_A − p_B (W)
  glm::dvec3 p_A{0.0};
  glm::dvec3 p_B{0.0};
};

// Distance between two posed hulls (GJK: Gilbert, Johnson & Keerthi 1988), stopping early (kFar)
// once a lower bound exceeds far_m, or (kNear, with near_m ≥ 0) once an upper bound, |v| (the
// distance between two points of the hulls), is at most near_m: the distance is then known to be
// within near_m and r.distance_m is the lower bound v·w/|v| (≥ 0) reached so far. `guess` is an
// initial estimate of p_A − p_B (any length; zero → centre difference). 2_gjk_distance.cc.
GjkResult GjkDistance(const PosedHull& A, const PosedHull& B, glm::dvec3 guess, double far_m,
                      double near_m = -1.0) noexcept;

// Contact of a touching or penetrating pair (the method: HullProximityQuery::Query's docs).
// A and B must be on the quaternion path (PosedHull::QuaternionPath), in W.
// 2_hull_penetration.cc.
HullPairContact PenetrationContact(const PosedHull& A, const PosedHull& B,
                                   const glm::dvec3* previous_normal_W) noexcept;

inline bool IsFiniteContact(const HullPairContact& c) noexcept {
  return std::isfinite(c.signed_distance_m) && IsFiniteVec(c.normal_W) &&
         IsFiniteVec(c.point_A_W) && IsFiniteVec(c.point_B_W);
}

}  // namespace ht::hull_geometry
