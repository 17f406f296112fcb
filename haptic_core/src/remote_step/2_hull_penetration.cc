// The contact of a touching or penetrating hull pair: the direction of least overlap among
// libccd MPR's, both hulls' face normals, the previous call's normal and, for a touching pair,
// GJK's direction with the hulls moved a hair apart (HullProximityQuery::Query gives the method
// and its accuracy).
#include <ccd/ccd.h>

#include <cmath>
#include <glm/geometric.hpp>

#include "2_posed_hull.h"

namespace ht::hull_geometry {
namespace {

// Largest plane × vertex product for the face-normal candidates of a penetrating pair (bounds
// the cost for big single hulls; leaf hulls are far below it).
constexpr std::size_t kMaxFaceCandidateWork = 65536;

// How far a touching pair is moved apart to find its contact normal, relative to the pair's size
// (the hulls' radii and their centres' distance): far above GJK's kTouch_m on any model between a
// millimetre and a few metres, far below what moves the closest features.
constexpr double kTouchNudge = 1e-7;

// ------------------------------------------------------------------------------------------------
// libccd callbacks on PosedHull (for MPR on touching/penetrating leaf pairs).

void CcdSupport(const void* obj, const ccd_vec3_t* dir, ccd_vec3_t* out) {
  const auto* h = static_cast<const PosedHull*>(obj);
  const glm::dvec3 p = h->Support(glm::dvec3(ccdVec3X(dir), ccdVec3Y(dir), ccdVec3Z(dir)));
  ccdVec3Set(out, p.x, p.y, p.z);
}

void CcdCenter(const void* obj, ccd_vec3_t* out) {
  const auto* h = static_cast<const PosedHull*>(obj);
  ccdVec3Set(out, h->center_W.x, h->center_W.y, h->center_W.z);
}

}  // namespace

HullPairContact PenetrationContact(const PosedHull& A, const PosedHull& B,
                                   const glm::dvec3* previous_normal_W) noexcept {
  double best_overlap = kInf;
  glm::dvec3 best_n(0.0, 0.0, 1.0);
  auto consider = [&](const glm::dvec3& n, double overlap) {
    if (overlap < best_overlap) {
      best_overlap = overlap;
      best_n = n;
    }
  };

  ccd_t ccd;
  CCD_INIT(&ccd);
  ccd.support1 = CcdSupport;
  ccd.support2 = CcdSupport;
  ccd.center1 = CcdCenter;
  ccd.center2 = CcdCenter;
  ccd.max_iterations = 100;
  ccd.mpr_tolerance = 1e-12;
  ccd_real_t depth = 0;
  ccd_vec3_t dir, pos;
  // obj1 = B, obj2 = A: the direction moves A out of B, i.e. points from B towards A.
  const int rc = ccdMPRPenetration(&B, &A, &ccd, &depth, &dir, &pos);
  glm::dvec3 q_W = 0.5 * (A.center_W + B.center_W);
  bool have_point = false;
  if (rc == 0) {
    const glm::dvec3 n(ccdVec3X(&dir), ccdVec3Y(&dir), ccdVec3Z(&dir));
    const double len = glm::length(n);
    if (len > 0.0 && std::isfinite(len)) consider(n / len, Overlap(A, B, n / len));
    const glm::dvec3 p(ccdVec3X(&pos), ccdVec3Y(&pos), ccdVec3Z(&pos));
    if (IsFiniteVec(p)) q_W = p, have_point = true;
  }
  if (A.plane_count * B.vertex_count + B.plane_count * A.vertex_count <= kMaxFaceCandidateWork) {
    for (std::size_t i = 0; i < B.plane_count; ++i) {
      const glm::dvec4& pl = B.planes_O[i];
      const glm::dvec3 n = B.X_WO->rotation * glm::dvec3(pl.x, pl.y, pl.z);
      consider(n, pl.w + glm::dot(n, B.p_WO) + A.SupportValue(-n));
    }
    for (std::size_t j = 0; j < A.plane_count; ++j) {
      const glm::dvec4& pl = A.planes_O[j];
      const glm::dvec3 m = A.X_WO->rotation * glm::dvec3(pl.x, pl.y, pl.z);
      consider(-m, pl.w + glm::dot(m, A.p_WO) + B.SupportValue(-m));
    }
  }
  if (previous_normal_W != nullptr) consider(*previous_normal_W, Overlap(A, B, *previous_normal_W));
  if (rc != 0) {
    // MPR found no overlap: the hulls touch (GJK's distance is below kTouch_m; leaf pairs come on
    // the quaternion path, whose pose the copy below moves). Where they touch
    // edge to edge no face normal realizes the contact (a face's overlap is the other hull's
    // whole reach past the edge), so A is moved off B a hair along the centres' direction, which
    // separates two touching hulls (their separating plane's normal n has n·(c_A − c_B) > 0), and
    // GJK's direction there, the closest features' normal (for two edges their cross product),
    // is a candidate with its overlap taken on the pair as posed.
    const glm::dvec3 c = A.center_W - B.center_W;
    const double len = glm::length(c);
    if (len > 0.0 && std::isfinite(len) && A.map == PosedHull::Map::kQuaternion) {
      const double hair = kTouchNudge * (A.radius_m + B.radius_m + len);
      const glm::dvec3 shift = (hair / len) * c;
      RigidTransform X_WO_moved = *A.X_WO;
      X_WO_moved.translation += shift;
      PosedHull moved = A;
      moved.X_WO = &X_WO_moved;
      moved.p_WO += shift;
      moved.center_W += shift;
      const GjkResult g = GjkDistance(moved, B, c, kInf);
      if (g.status == GjkStatus::kSeparated && g.distance_m > 0.0) {
        const glm::dvec3 n = g.v / g.distance_m;
        if (IsFiniteVec(n)) consider(n, Overlap(A, B, n));
      }
    }
  }
  if (!(best_overlap < kInf)) {
    // Nothing usable (no planes and MPR failed): the centre direction.
    glm::dvec3 n = A.center_W - B.center_W;
    const double len = glm::length(n);
    n = len > 0.0 ? n / len : glm::dvec3(0.0, 0.0, 1.0);
    consider(n, Overlap(A, B, n));
  }
  const glm::dvec3 n = best_n / glm::length(best_n);
  const glm::dvec3 s_A = A.Support(-n);
  const glm::dvec3 s_B = B.Support(n);
  if (!have_point) q_W = 0.5 * (s_A + s_B);
  HullPairContact c;
  c.normal_W = n;
  c.signed_distance_m = -best_overlap;
  c.point_A_W = q_W + glm::dot(s_A - q_W, n) * n;
  c.point_B_W = q_W + glm::dot(s_B - q_W, n) * n;
  return c;
}

}  // namespace ht::hull_geometry
