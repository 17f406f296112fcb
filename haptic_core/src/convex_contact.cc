#include "haptic_core/convex_contact.h"

#include <ccd/ccd.h>

#include <cmath>
#include <glm/geometric.hpp>
#include <limits>

namespace ht {
namespace {

struct CcdHull {
  std::span<const glm::dvec3> vertices_O;
  RigidTransform X_WO;
  glm::dquat R_OW;
  double inflation_m;
  glm::dvec3 center_W;
};

void Support(const void* obj, const ccd_vec3_t* dir, ccd_vec3_t* out) {
  const auto* h = static_cast<const CcdHull*>(obj);
  const glm::dvec3 d_W(ccdVec3X(dir), ccdVec3Y(dir), ccdVec3Z(dir));
  const glm::dvec3 d_O = h->R_OW * d_W;
  double best = -std::numeric_limits<double>::infinity();
  glm::dvec3 best_O = h->vertices_O[0];
  for (const auto& v : h->vertices_O) {
    const double s = glm::dot(v, d_O);
    if (s > best) {
      best = s;
      best_O = v;
    }
  }
  glm::dvec3 p_W = h->X_WO * best_O;
  const double len = glm::length(d_W);
  if (h->inflation_m > 0.0 && len > 0.0) p_W += (h->inflation_m / len) * d_W;
  ccdVec3Set(out, p_W.x, p_W.y, p_W.z);
}

void Center(const void* obj, ccd_vec3_t* out) {
  const auto* h = static_cast<const CcdHull*>(obj);
  ccdVec3Set(out, h->center_W.x, h->center_W.y, h->center_W.z);
}

CcdHull MakeHull(std::span<const glm::dvec3> vertices_O, const RigidTransform& X_WO,
                 double inflation_m) {
  glm::dvec3 c(0.0);
  for (const auto& v : vertices_O) c += v;
  c /= static_cast<double>(vertices_O.size());
  return {vertices_O, X_WO, glm::conjugate(X_WO.rotation), inflation_m, X_WO * c};
}

}  // namespace

std::optional<ConvexContact> QueryConvexContact(std::span<const glm::dvec3> hull_A_O,
                                                const RigidTransform& X_WA,
                                                std::span<const glm::dvec3> hull_B_O,
                                                const RigidTransform& X_WB, double tolerance_m) {
  if (hull_A_O.empty() || hull_B_O.empty()) return std::nullopt;
  if (!IsFiniteRigidTransform(X_WA) || !IsFiniteRigidTransform(X_WB)) return std::nullopt;
  if (!(tolerance_m >= 0.0) || !std::isfinite(tolerance_m)) return std::nullopt;
  const CcdHull a = MakeHull(hull_A_O, X_WA, tolerance_m);
  const CcdHull b = MakeHull(hull_B_O, X_WB, 0.0);

  ccd_t ccd;
  CCD_INIT(&ccd);
  ccd.support1 = Support;
  ccd.support2 = Support;
  ccd.center1 = Center;
  ccd.center2 = Center;
  ccd.max_iterations = 200;
  ccd.epa_tolerance = 1e-9;
  ccd.mpr_tolerance = 1e-9;
  ccd.dist_tolerance = 1e-12;

  ccd_real_t depth = 0;
  ccd_vec3_t dir, pos;
  // obj1 = B, obj2 = A: the returned direction moves A out of B, i.e. points from B towards A.
  int rc = ccdGJKPenetration(&b, &a, &ccd, &depth, &dir, &pos);
  if (rc == -2) rc = ccdMPRPenetration(&b, &a, &ccd, &depth, &dir, &pos);
  if (rc != 0) return std::nullopt;
  const glm::dvec3 n(ccdVec3X(&dir), ccdVec3Y(&dir), ccdVec3Z(&dir));
  const double len = glm::length(n);
  if (!(len > 0.0) || !std::isfinite(depth)) return std::nullopt;
  ConvexContact c;
  c.normal_W = n / len;
  c.signed_distance_m = tolerance_m - depth;
  // EPA's point lies mid-way inside the grown overlap; shift by half the growth so it sits
  // between the true hulls.
  c.point_W =
      glm::dvec3(ccdVec3X(&pos), ccdVec3Y(&pos), ccdVec3Z(&pos)) + 0.5 * tolerance_m * c.normal_W;
  return c;
}

}  // namespace ht
