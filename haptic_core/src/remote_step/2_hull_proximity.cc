#include <ccd/ccd.h>
#include <oneapi/tbb/blocked_range.h>
#include <oneapi/tbb/parallel_for.h>
#include <oneapi/tbb/task_arena.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <glm/geometric.hpp>
#include <limits>
#include <stdexcept>
#include <string>

#include "../task_pools.h"
#include "haptic_core/broad_phase.h"
#include "haptic_core/hull_proximity.h"

namespace ht {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
// GJK stops when the gap between its upper (|v|) and lower (v·w/|v|) distance bounds is below
// kGjkAbsTol_m + kGjkRelTol·|v|.
constexpr double kGjkAbsTol_m = 1e-12;
constexpr double kGjkRelTol = 1e-10;
// Below this GJK distance (m) a pair counts as touching, and the penetration route gives its
// normal (closest points that coincide give no direction).
constexpr double kTouch_m = 1e-12;
constexpr int kGjkMaxIterations = 64;
// Internal node pairs get a GJK test only when their hulls have at most this many vertices in all
// (measured on the seed scenes: 64 beats always (1.1–2×) and never (0.7–2.7×)).
constexpr int kInternalGjkMaxVertices = 64;
// Largest plane × vertex product for the face-normal candidates of a penetrating pair (bounds
// the cost for big single hulls; leaf hulls are far below it).
constexpr std::size_t kMaxFaceCandidateWork = 65536;
// A node pair's oriented boxes cull it only when they are this much (m) farther apart than its
// tolerance: far above the rounding of the box test (1e-16 of the models' size), so that a culled
// pair is certainly one the exact test would have dropped.
constexpr double kBoxSlack_m = 1e-9;
// Room for a front (node pairs; front tracking stops for a call whose front would not fit).
constexpr std::size_t kFrontCapacity = 16384;

bool IsFiniteVec(const glm::dvec3& v) noexcept {
  return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}

// One hull posed in a query frame, named W in this file: the world for leaf pairs, and the frame
// of Query's first model for the traversal, where that model's hulls need no transform. A view of
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

  // The same hull in the world, its support functions and centre computed with the quaternion:
  // leaf pairs (GJK, and libccd's MPR, whose path follows the last bits of its supports) keep
  // the arithmetic they had before the traversal moved to A's frame, so the query's contacts are
  // the same bit for bit.
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

// ------------------------------------------------------------------------------------------------
// GJK distance (Gilbert, Johnson & Keerthi 1988) on the Minkowski difference A − B, with the
// closest point of each simplex found by Voronoi-region tests (Ericson, Real-Time Collision
// Detection §5.1.5, §5.1.6) and the barycentric coordinates kept for the witness points.

struct SimplexPoint {
  glm::dvec3 w;  // a − b
  glm::dvec3 a;
  glm::dvec3 b;
};

struct Simplex {
  SimplexPoint p[4];
  double lambda[4] = {0, 0, 0, 0};
  int n = 0;
};

// Keeps the points `idx[0..count)` of s with barycentric weights `lam`; returns the closest point.
glm::dvec3 Reduce(Simplex& s, const int* idx, const double* lam, int count) noexcept {
  SimplexPoint kept[4];
  for (int i = 0; i < count; ++i) kept[i] = s.p[idx[i]];
  glm::dvec3 v(0.0);
  for (int i = 0; i < count; ++i) {
    s.p[i] = kept[i];
    s.lambda[i] = lam[i];
    v += lam[i] * kept[i].w;
  }
  s.n = count;
  return v;
}

// Closest point to the origin of triangle (a, b, c) = s.p[i0], s.p[i1], s.p[i2]: the indices and
// weights of the supporting sub-simplex (Ericson's ClosestPtPointTriangle with p = 0).
int ClosestOnTriangle(const Simplex& s, int i0, int i1, int i2, int* idx, double* lam) noexcept {
  const glm::dvec3& a = s.p[i0].w;
  const glm::dvec3& b = s.p[i1].w;
  const glm::dvec3& c = s.p[i2].w;
  const glm::dvec3 ab = b - a, ac = c - a;
  const double d1 = -glm::dot(ab, a), d2 = -glm::dot(ac, a);
  if (d1 <= 0.0 && d2 <= 0.0) {
    idx[0] = i0;
    lam[0] = 1.0;
    return 1;
  }
  const double d3 = -glm::dot(ab, b), d4 = -glm::dot(ac, b);
  if (d3 >= 0.0 && d4 <= d3) {
    idx[0] = i1;
    lam[0] = 1.0;
    return 1;
  }
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) {
    const double t = d1 / (d1 - d3);
    idx[0] = i0, idx[1] = i1, lam[0] = 1.0 - t, lam[1] = t;
    return 2;
  }
  const double d5 = -glm::dot(ab, c), d6 = -glm::dot(ac, c);
  if (d6 >= 0.0 && d5 <= d6) {
    idx[0] = i2;
    lam[0] = 1.0;
    return 1;
  }
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) {
    const double t = d2 / (d2 - d6);
    idx[0] = i0, idx[1] = i2, lam[0] = 1.0 - t, lam[1] = t;
    return 2;
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0) {
    const double t = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    idx[0] = i1, idx[1] = i2, lam[0] = 1.0 - t, lam[1] = t;
    return 2;
  }
  const double denom = va + vb + vc;
  if (!(denom > 0.0)) {
    // Degenerate (collinear) triangle that passed every region test through rounding: the best
    // of its edges.
    double best = kInf;
    int count = 0;
    const int edges[3][2] = {{i0, i1}, {i0, i2}, {i1, i2}};
    for (const auto& e : edges) {
      const glm::dvec3& p = s.p[e[0]].w;
      const glm::dvec3 q = s.p[e[1]].w - p;
      const double qq = glm::dot(q, q);
      const double t = qq > 0.0 ? std::clamp(-glm::dot(p, q) / qq, 0.0, 1.0) : 0.0;
      const glm::dvec3 x = p + t * q;
      const double dd = glm::dot(x, x);
      if (dd < best) {
        best = dd;
        idx[0] = e[0], idx[1] = e[1], lam[0] = 1.0 - t, lam[1] = t;
        count = 2;
      }
    }
    return count;
  }
  const double v = vb / denom, w = vc / denom;
  idx[0] = i0, idx[1] = i1, idx[2] = i2;
  lam[0] = 1.0 - v - w, lam[1] = v, lam[2] = w;
  return 3;
}

// Replaces s by its sub-simplex closest to the origin; returns that closest point, and sets
// *contains_origin when the tetrahedron encloses the origin.
glm::dvec3 ClosestOnSimplex(Simplex& s, bool* contains_origin) noexcept {
  *contains_origin = false;
  int idx[4];
  double lam[4];
  switch (s.n) {
    case 1: {
      idx[0] = 0;
      lam[0] = 1.0;
      return Reduce(s, idx, lam, 1);
    }
    case 2: {
      const glm::dvec3& a = s.p[0].w;
      const glm::dvec3 ab = s.p[1].w - a;
      const double abab = glm::dot(ab, ab);
      const double t = abab > 0.0 ? -glm::dot(a, ab) / abab : 0.0;
      if (t <= 0.0) {
        idx[0] = 0, lam[0] = 1.0;
        return Reduce(s, idx, lam, 1);
      }
      if (t >= 1.0) {
        idx[0] = 1, lam[0] = 1.0;
        return Reduce(s, idx, lam, 1);
      }
      idx[0] = 0, idx[1] = 1, lam[0] = 1.0 - t, lam[1] = t;
      return Reduce(s, idx, lam, 2);
    }
    case 3: {
      const int count = ClosestOnTriangle(s, 0, 1, 2, idx, lam);
      return Reduce(s, idx, lam, count);
    }
    default: {
      // Tetrahedron: test each face whose plane separates the origin from the opposite vertex
      // (all faces when the tetrahedron is flat); none → the origin is inside.
      const int faces[4][4] = {{0, 1, 2, 3}, {0, 2, 3, 1}, {0, 3, 1, 2}, {1, 3, 2, 0}};
      double best = kInf;
      int best_idx[3] = {0, 0, 0};
      double best_lam[3] = {0, 0, 0};
      int best_count = 0;
      bool any = false;
      for (const auto& f : faces) {
        const glm::dvec3& a = s.p[f[0]].w;
        const glm::dvec3 n = glm::cross(s.p[f[1]].w - a, s.p[f[2]].w - a);
        const double sign_origin = -glm::dot(a, n);
        const double sign_opposite = glm::dot(s.p[f[3]].w - a, n);
        const double scale = glm::length(n) * glm::length(s.p[f[3]].w - a);
        const bool flat = !(std::abs(sign_opposite) > 1e-12 * scale);
        if (!flat && sign_origin * sign_opposite >= 0.0) continue;
        any = true;
        int fi[3];
        double fl[3];
        const int count = ClosestOnTriangle(s, f[0], f[1], f[2], fi, fl);
        glm::dvec3 x(0.0);
        for (int i = 0; i < count; ++i) x += fl[i] * s.p[fi[i]].w;
        const double dd = glm::dot(x, x);
        if (dd < best) {
          best = dd;
          best_count = count;
          for (int i = 0; i < count; ++i) best_idx[i] = fi[i], best_lam[i] = fl[i];
        }
      }
      if (!any) {
        *contains_origin = true;
        return glm::dvec3(0.0);
      }
      return Reduce(s, best_idx, best_lam, best_count);
    }
  }
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

// Distance between two posed hulls, stopping early (kFar) once a lower bound exceeds far_m, or
// (kNear, with near_m ≥ 0) once an upper bound, |v| (the distance between two points of the
// hulls), is at most near_m: the distance is then known to be within near_m and r.distance_m is
// the lower bound v·w/|v| (≥ 0) reached so far. `guess` is an initial estimate of p_A − p_B (any
// length; zero → centre difference).
GjkResult GjkDistance(const PosedHull& A, const PosedHull& B, glm::dvec3 guess, double far_m,
                      double near_m = -1.0) noexcept {
  GjkResult r;
  if (!(glm::dot(guess, guess) > 0.0)) guess = A.center_W - B.center_W;
  if (!(glm::dot(guess, guess) > 0.0)) guess = glm::dvec3(1.0, 0.0, 0.0);
  Simplex s;
  {
    SimplexPoint& p = s.p[0];
    p.a = A.Support(-guess);
    p.b = B.Support(guess);
    p.w = p.a - p.b;
    s.lambda[0] = 1.0;
    s.n = 1;
  }
  glm::dvec3 v = s.p[0].w;
  for (int it = 0; it < kGjkMaxIterations; ++it) {
    const double vv = glm::dot(v, v);
    if (vv <= kTouch_m * kTouch_m) {
      r.status = GjkStatus::kTouching;
      break;
    }
    const double v_len = std::sqrt(vv);
    SimplexPoint w;
    w.a = A.Support(-v);
    w.b = B.Support(v);
    w.w = w.a - w.b;
    const double vw = glm::dot(v, w.w);
    if (vw > far_m * v_len) {
      r.status = GjkStatus::kFar;
      r.distance_m = vw / v_len;
      r.v = v;
      return r;
    }
    if (v_len <= near_m) {
      r.status = GjkStatus::kNear;
      r.distance_m = std::max(0.0, vw / v_len);
      r.v = v;
      return r;
    }
    r.status = GjkStatus::kSeparated;
    if (vv - vw <= v_len * (kGjkAbsTol_m + kGjkRelTol * v_len)) break;
    bool duplicate = false;
    for (int i = 0; i < s.n; ++i) {
      const glm::dvec3 d = s.p[i].w - w.w;
      if (glm::dot(d, d) <= 1e-30) duplicate = true;
    }
    if (duplicate) break;
    const Simplex before = s;
    s.p[s.n++] = w;
    bool inside = false;
    const glm::dvec3 v_new = ClosestOnSimplex(s, &inside);
    if (inside) {
      r.status = GjkStatus::kTouching;
      v = glm::dvec3(0.0);
      break;
    }
    if (!(glm::dot(v_new, v_new) < vv)) {
      // No progress (rounding): keep the previous simplex and its closest point.
      s = before;
      break;
    }
    v = v_new;
  }
  if (r.status == GjkStatus::kTouching) {
    r.distance_m = 0.0;
    r.v = glm::dvec3(0.0);
    return r;
  }
  r.v = v;
  r.distance_m = glm::length(v);
  r.p_A = glm::dvec3(0.0);
  r.p_B = glm::dvec3(0.0);
  for (int i = 0; i < s.n; ++i) {
    r.p_A += s.lambda[i] * s.p[i].a;
    r.p_B += s.lambda[i] * s.p[i].b;
  }
  if (r.distance_m <= kTouch_m) r.status = GjkStatus::kTouching;
  return r;
}

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

// Overlap (m) of the two hulls' support intervals along the unit n (from B towards A):
// h_B(n) + h_A(−n). Any such n separates the hulls when A moves by the overlap along n.
double Overlap(const PosedHull& A, const PosedHull& B, const glm::dvec3& n) noexcept {
  return B.SupportValue(n) + A.SupportValue(-n);
}

// Contact of a touching or penetrating pair (see HullProximityQuery::Query for the method).
// A and B must be on the quaternion path (PosedHull::QuaternionPath), in W.
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

bool IsFiniteContact(const HullPairContact& c) noexcept {
  return std::isfinite(c.signed_distance_m) && IsFiniteVec(c.normal_W) &&
         IsFiniteVec(c.point_A_W) && IsFiniteVec(c.point_B_W);
}

// Min-heap order on the key.
bool HeapAfter(const HullProximityQuery::QueueEntry& x,
               const HullProximityQuery::QueueEntry& y) noexcept {
  return x.key_m > y.key_m;
}

// Order of node pairs (CoherentPair, FrontPair) by node_A, then node_B.
template <typename Pair>
bool PairLess(const Pair& x, const Pair& y) noexcept {
  return x.node_A != y.node_A ? x.node_A < y.node_A : x.node_B < y.node_B;
}

// The entry of (node_A, node_B) in `pairs` (sorted by PairLess), or null.
template <typename Pair>
const Pair* FindPair(const std::vector<Pair>& pairs, int node_A, int node_B) noexcept {
  const Pair probe{node_A, node_B, glm::dvec3(0.0)};
  auto it = std::lower_bound(pairs.begin(), pairs.end(), probe, PairLess<Pair>);
  return it != pairs.end() && it->node_A == node_A && it->node_B == node_B ? &*it : nullptr;
}

}  // namespace

HullProximityQuery::HullProximityQuery(int max_pairs) : capacity_(max_pairs) {
  if (max_pairs < 1) {
    throw std::invalid_argument("HullProximityQuery: max_pairs must be >= 1, got " +
                                std::to_string(max_pairs));
  }
  results_.reserve(static_cast<std::size_t>(max_pairs));
  previous_.reserve(static_cast<std::size_t>(max_pairs));
  current_.reserve(static_cast<std::size_t>(max_pairs));
  previous_far_.reserve(static_cast<std::size_t>(max_pairs));
  current_far_.reserve(static_cast<std::size_t>(max_pairs));
  front_.reserve(kFrontCapacity);
  next_front_.reserve(kFrontCapacity);
  queue_.reserve(4096);
}

struct HullProximityQuery::Arena {
  explicit Arena(int threads) : arena(threads) {}
  oneapi::tbb::task_arena arena;
};

void HullProximityQuery::SetThreads(int threads) {
  if (threads < 1 || threads > 256) {
    throw std::invalid_argument("HullProximityQuery: threads must be in [1, 256], got " +
                                std::to_string(threads));
  }
  if (threads == 1) {
    arena_.reset();
    workers_.clear();
    return;
  }
  std::vector<Worker> workers(static_cast<std::size_t>(threads));
  for (Worker& w : workers) {
    w.queue.reserve(4096);
    w.results.reserve(static_cast<std::size_t>(capacity_));
    w.current.reserve(static_cast<std::size_t>(capacity_));
    w.current_far.reserve(static_cast<std::size_t>(capacity_));
    w.front.reserve(kFrontCapacity);
  }
  arena_ = std::make_shared<Arena>(threads);
  internal::WarmTaskPools(arena_->arena);  // so that a query's tasks do not allocate
  workers_ = std::move(workers);
}

void HullProximityQuery::ClearCache() noexcept {
  for (ModelEntry& e : cache_) {
    e.model = nullptr;
    e.nodes_data = nullptr;
    e.node_count = 0;
    e.hull_vertex_count = 0;
    e.spheres_O.clear();
  }
  previous_.clear();
  previous_far_.clear();
  front_.clear();
  front_valid_ = false;
  previous_A_ = previous_B_ = nullptr;
}

namespace {

// Per node of `model`'s hierarchy (or one value for a model without one): the largest positive
// level-0 texture height over the node's triangles, each triangle's texel box grown by a texel
// (bilinear samples reach that far), capped at the model's OutwardReach(). A triangle whose box
// touches a wrapped border counts the cap. Allocates `out` (warm-up only).
void ComputeNodeReach(const HapticModel& model, std::vector<double>& out) {
  const double cap = model.OutwardReach();
  const auto& nodes = model.hull_hierarchy.nodes;
  out.assign(std::max<std::size_t>(nodes.size(), 1), cap);
  if (nodes.empty()) return;
  const bool have_texture = !model.texture.empty();
  const std::size_t nf = model.triangles.size();
  std::vector<double> tri(nf, 0.0);
  if (have_texture && model.corner_uvs.size() >= 3 * nf && model.textured.size() >= nf) {
    const HeightFieldLevel& L = model.texture.level(0);
    for (std::size_t f = 0; f < nf; ++f) {
      if (model.textured[f] == 0) continue;
      float umin = 1e30f, umax = -1e30f, vmin = 1e30f, vmax = -1e30f;
      for (int c = 0; c < 3; ++c) {
        const glm::vec2 uv = model.corner_uvs[3 * f + c];
        umin = std::min(umin, uv.x);
        umax = std::max(umax, uv.x);
        vmin = std::min(vmin, uv.y);
        vmax = std::max(vmax, uv.y);
      }
      if (!(std::isfinite(umin) && std::isfinite(umax) && std::isfinite(vmin) &&
            std::isfinite(vmax))) {
        tri[f] = cap;
        continue;
      }
      const int x0 = static_cast<int>(std::floor(umin * static_cast<float>(L.width) - 0.5f)) - 1;
      const int x1 = static_cast<int>(std::ceil(umax * static_cast<float>(L.width) - 0.5f)) + 1;
      const int y0 = static_cast<int>(std::floor(vmin * static_cast<float>(L.height) - 0.5f)) - 1;
      const int y1 = static_cast<int>(std::ceil(vmax * static_cast<float>(L.height) - 0.5f)) + 1;
      if ((model.texture.wrap_u() && (x0 < 0 || x1 >= L.width)) ||
          (model.texture.wrap_v() && (y0 < 0 || y1 >= L.height))) {
        tri[f] = cap;
        continue;
      }
      double h = 0.0;
      for (int y = std::max(y0, 0); y <= std::min(y1, L.height - 1); ++y) {
        const float* row = &L.texels[static_cast<std::size_t>(y) * L.width];
        for (int x = std::max(x0, 0); x <= std::min(x1, L.width - 1); ++x) {
          h = std::max(h, static_cast<double>(row[x]));
        }
      }
      tri[f] = std::min(h, cap);
    }
  }
  // Leaves from their triangles; internal nodes from their children (pre-order: children come
  // after their parent, so a reverse sweep sees them first).
  for (std::size_t k = nodes.size(); k-- > 0;) {
    const HullNode& node = nodes[k];
    double r = 0.0;
    if (node.is_leaf()) {
      for (const int f : node.triangles) {
        if (f >= 0 && static_cast<std::size_t>(f) < nf) r = std::max(r, tri[f]);
      }
    } else {
      for (const int child : node.children) {
        if (child > static_cast<int>(k) && static_cast<std::size_t>(child) < nodes.size()) {
          r = std::max(r, out[static_cast<std::size_t>(child)]);
        } else {
          r = cap;  // not pre-order: stay conservative
        }
      }
    }
    out[k] = std::min(r, cap);
  }
}

// The box of `vertices` (frame O) along their principal axes (the eigenvectors of their
// covariance; Gottschalk, Lin & Manocha 1996), its extents the vertices' range along each axis,
// padded by 1e-9 of the box's size (and 1e-12 m) so that rounding in the query's box tests can
// never leave a vertex outside. No vertices: a box too big to cull anything.
HullProximityQuery::OrientedBox FitOrientedBox(const std::vector<glm::dvec3>& vertices) {
  HullProximityQuery::OrientedBox box;
  if (vertices.empty()) {  // a box that culls nothing
    box.half_extents_m = glm::dvec3(1e30);
    return box;
  }
  glm::dvec3 mean(0.0);
  for (const glm::dvec3& v : vertices) mean += v;
  mean /= static_cast<double>(vertices.size());
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
  for (const glm::dvec3& v : vertices) {
    const Eigen::Vector3d d(v.x - mean.x, v.y - mean.y, v.z - mean.z);
    covariance += d * d.transpose();
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(covariance);
  glm::dmat3 axes(1.0);
  if (solver.info() == Eigen::Success && solver.eigenvectors().allFinite()) {
    const Eigen::Matrix3d& e = solver.eigenvectors();
    for (int c = 0; c < 3; ++c) axes[c] = glm::normalize(glm::dvec3(e(0, c), e(1, c), e(2, c)));
    axes[2] = glm::normalize(glm::cross(axes[0], axes[1]));  // orthonormal to rounding
    axes[1] = glm::cross(axes[2], axes[0]);
  }
  glm::dvec3 lo(kInf), hi(-kInf);
  for (const glm::dvec3& v : vertices) {
    for (int c = 0; c < 3; ++c) {
      const double s = glm::dot(v, axes[c]);
      lo[c] = std::min(lo[c], s);
      hi[c] = std::max(hi[c], s);
    }
  }
  const glm::dvec3 mid = 0.5 * (lo + hi), half = 0.5 * (hi - lo);
  const double size = std::max({half.x, half.y, half.z, glm::length(mean)});
  box.axes_O = axes;
  box.center_O = mid.x * axes[0] + mid.y * axes[1] + mid.z * axes[2];
  box.half_extents_m = half + glm::dvec3(1e-9 * size + 1e-12);
  return box;
}

}  // namespace

const HullProximityQuery::ModelEntry& HullProximityQuery::Entry(const HapticModel& model) {
  ++use_counter_;
  const auto& nodes = model.hull_hierarchy.nodes;
  for (ModelEntry& e : cache_) {
    if (e.model == &model && e.nodes_data == static_cast<const void*>(nodes.data()) &&
        e.node_count == nodes.size() && e.hull_vertex_count == model.hull_vertices_O.size()) {
      e.last_use = use_counter_;
      return e;
    }
  }
  ModelEntry* slot = &cache_[0];
  for (ModelEntry& e : cache_) {
    if (e.last_use < slot->last_use) slot = &e;
  }
  // The slot is named for `model` only once its spheres are complete: if their allocation throws,
  // the slot stays empty rather than claiming a model it holds no spheres for.
  slot->model = nullptr;
  auto sphere = [](const std::vector<glm::dvec3>& vertices, const glm::dvec3* center) {
    glm::dvec3 c(0.0);
    if (center != nullptr) {
      c = *center;
    } else if (!vertices.empty()) {
      for (const auto& v : vertices) c += v;
      c /= static_cast<double>(vertices.size());
    }
    double r2 = 0.0;
    for (const auto& v : vertices) r2 = std::max(r2, glm::dot(v - c, v - c));
    return glm::dvec4(c, std::sqrt(r2));
  };
  slot->spheres_O.clear();
  slot->boxes_O.clear();
  if (nodes.empty()) {
    slot->spheres_O.push_back(sphere(model.hull_vertices_O, nullptr));
    slot->boxes_O.push_back(FitOrientedBox(model.hull_vertices_O));
  } else {
    slot->spheres_O.reserve(nodes.size());
    slot->boxes_O.reserve(nodes.size());
    for (const HullNode& node : nodes) {
      slot->spheres_O.push_back(sphere(node.hull.vertices_O, &node.hull.center_O));
      slot->boxes_O.push_back(FitOrientedBox(node.hull.vertices_O));
    }
  }
  ComputeNodeReach(model, slot->reach_m);
  ++entry_builds_;
  slot->model = &model;
  slot->nodes_data = nodes.data();
  slot->node_count = nodes.size();
  slot->hull_vertex_count = model.hull_vertices_O.size();
  slot->last_use = use_counter_;
  return *slot;
}

double HullProximityQuery::NodeReach(const HapticModel& model, int node) {
  const ModelEntry& e = Entry(model);
  return e.reach_m.at(node < 0 ? 0 : static_cast<std::size_t>(node));
}

HullProximityQuery::OrientedBox HullProximityQuery::BoundingBox(const HapticModel& model,
                                                                int node) {
  const ModelEntry& e = Entry(model);
  return e.boxes_O.at(node < 0 ? 0 : static_cast<std::size_t>(node));
}

glm::dvec4 HullProximityQuery::BoundingSphere(const HapticModel& model, int node) {
  const ModelEntry& e = Entry(model);
  return e.spheres_O.at(node < 0 ? 0 : static_cast<std::size_t>(node));
}

std::span<const HullPairContact> HullProximityQuery::Query(const HapticModel& A,
                                                           const RigidTransform& X_WA,
                                                           const HapticModel& B,
                                                           const RigidTransform& X_WB,
                                                           const ProximityQueryOptions& options,
                                                           ProximityQueryStats* stats) noexcept {
  using Clock = std::chrono::steady_clock;
  const Clock::time_point t0 = Clock::now();
  ProximityQueryStats st;
  results_.clear();
  queue_.clear();
  current_.clear();
  current_far_.clear();
  next_front_.clear();
  const double eps = options.tolerance_m;

  auto finish = [&]() {
    st.pairs_found = static_cast<int>(results_.size());
    st.query_us = std::chrono::duration<double, std::micro>(Clock::now() - t0).count();
    if (stats != nullptr) *stats = st;
    return std::span<const HullPairContact>(results_.data(), results_.size());
  };

  if (!IsFiniteRigidTransform(X_WA) || !IsFiniteRigidTransform(X_WB) || !(eps >= 0.0) ||
      !std::isfinite(eps) || !std::isfinite(options.time_budget_us)) {
    st.invalid_input = 1;
    previous_.clear();
    previous_far_.clear();
    front_valid_ = false;
    return finish();
  }
  const bool a_single = A.hull_hierarchy.nodes.empty();
  const bool b_single = B.hull_hierarchy.nodes.empty();
  if ((a_single && A.hull_vertices_O.empty()) || (b_single && B.hull_vertices_O.empty())) {
    previous_.clear();
    previous_far_.clear();
    front_valid_ = false;
    return finish();
  }
  // Warm-up allocations happen here only (first sight of a model).
  const ModelEntry* entry_A;
  const ModelEntry* entry_B;
  const std::uint64_t entry_builds = entry_builds_;
  try {
    entry_A = &Entry(A);
    entry_B = &Entry(B);
  } catch (...) {
    st.numerical_faults = 1;
    front_valid_ = false;
    return finish();
  }
  const bool coherent = options.temporal_coherence && previous_A_ == &A && previous_B_ == &B;
  const bool coherent_next = options.temporal_coherence;
  const std::size_t max_pairs =
      static_cast<std::size_t>(std::clamp(options.max_pairs, 0, capacity_));
  const double budget_us = options.time_budget_us > 0.0 ? options.time_budget_us : kInf;

  // The traversal (bounding spheres, centre-line overlaps, internal GJK: culling and keys only)
  // works in A's frame: A's hulls need no transform there, and B's one matrix product per
  // support call (R_AB, p_AB) instead of two quaternion rotations. Leaf pairs, whose contacts are
  // the output, are tested in W as before (PosedHull::QuaternionPath).
  const glm::dmat3 R_WA = glm::mat3_cast(X_WA.rotation), R_AW = glm::transpose(R_WA);
  const glm::dmat3 R_AB = R_AW * glm::mat3_cast(X_WB.rotation), R_BA = glm::transpose(R_AB);
  const glm::dvec3 p_AB = R_AW * (X_WB.translation - X_WA.translation);
  auto posed = [&](const HapticModel& m, const ModelEntry& e, const RigidTransform& X_WO,
                   const glm::dmat3* R_QO, const glm::dmat3* R_OQ, const glm::dvec3& p_QO,
                   int node) {
    PosedHull h;
    const glm::dvec4& sph = e.spheres_O[node < 0 ? 0 : static_cast<std::size_t>(node)];
    if (node < 0) {
      h.vertices_O = m.hull_vertices_O.data();
      h.vertex_count = m.hull_vertices_O.size();
    } else {
      const ConvexHull& hull = m.hull_hierarchy.nodes[static_cast<std::size_t>(node)].hull;
      h.vertices_O = hull.vertices_O.data();
      h.vertex_count = hull.vertices_O.size();
      h.planes_O = hull.planes_O.data();
      h.plane_count = hull.planes_O.size();
    }
    h.map = R_QO == nullptr ? PosedHull::Map::kIdentity : PosedHull::Map::kMatrix;
    h.R_WO = R_QO;
    h.R_OW = R_OQ;
    h.p_WO = p_QO;
    h.center_W = R_QO == nullptr ? glm::dvec3(sph) : *R_QO * glm::dvec3(sph) + p_QO;
    h.X_WO = &X_WO;
    h.center_O = glm::dvec3(sph);
    h.radius_m = sph.w;
    return h;
  };
  auto is_leaf = [](const HapticModel& m, int node) {
    return node < 0 || m.hull_hierarchy.nodes[static_cast<std::size_t>(node)].is_leaf();
  };
  auto sphere_bound = [&](int node_A, int node_B) {
    // BoundingSphereGap, in A's frame.
    const glm::dvec4& a = entry_A->spheres_O[node_A < 0 ? 0 : static_cast<std::size_t>(node_A)];
    const glm::dvec4& b = entry_B->spheres_O[node_B < 0 ? 0 : static_cast<std::size_t>(node_B)];
    return glm::length(glm::dvec3(a) - (R_AB * glm::dvec3(b) + p_AB)) - a.w - b.w;
  };
  // A lower bound (m) of the distance between the two nodes' oriented boxes, and so of their
  // hulls' (the boxes hold them): the largest gap along the boxes' six face normals, the face
  // axes of the separating-axis test of Gottschalk, Lin & Manocha (1996), in A's frame, or the
  // first three's largest where it is above `stop` (m). Negative when the boxes overlap along all
  // six. The test's nine edge-pair axes are left out: on the seed scenes they culled a few more
  // pairs (file and CAD part at ε = 1 mm: 313 node pairs tested instead of 364) but cost more
  // than they saved (hammer on torus: 57 µs with them, 51.5 µs without; the file and CAD part
  // the same within the noise).
  auto box_gap = [&](int node_A, int node_B, double stop) {
    const OrientedBox& a = entry_A->boxes_O[node_A < 0 ? 0 : static_cast<std::size_t>(node_A)];
    const OrientedBox& b = entry_B->boxes_O[node_B < 0 ? 0 : static_cast<std::size_t>(node_B)];
    const glm::dmat3 R = glm::transpose(a.axes_O) * (R_AB * b.axes_O);  // R[j][i] = a_i · b_j
    const glm::dvec3 t = (R_AB * b.center_O + p_AB - a.center_O) * a.axes_O;  // along a_i
    const glm::dvec3& ea = a.half_extents_m;
    const glm::dvec3& eb = b.half_extents_m;
    glm::dmat3 Q;  // |R|
    for (int j = 0; j < 3; ++j) Q[j] = glm::abs(R[j]);
    double gap = -kInf;
    for (int i = 0; i < 3; ++i) {  // A's face normals a_i
      const double rb = eb.x * Q[0][i] + eb.y * Q[1][i] + eb.z * Q[2][i];
      gap = std::max(gap, std::abs(t[i]) - ea[i] - rb);
    }
    if (gap > stop) return gap;
    for (int j = 0; j < 3; ++j) {  // B's face normals b_j
      const double ra = glm::dot(ea, Q[j]);
      gap = std::max(gap, std::abs(glm::dot(t, R[j])) - ra - eb[j]);
    }
    return gap;
  };
  const bool local_reach = options.local_reach_margin_m >= 0.0;
  // The tolerance of a node pair: ε, or with local reach the pair's own (never larger).
  auto pair_eps = [&](int node_A, int node_B) {
    if (!local_reach) return eps;
    const double ra = entry_A->reach_m[node_A < 0 ? 0 : static_cast<std::size_t>(node_A)];
    const double rb = entry_B->reach_m[node_B < 0 ? 0 : static_cast<std::size_t>(node_B)];
    return std::min(eps, ra + rb + options.local_reach_margin_m);
  };
  // Where a traversal keeps its queue, its pairs, its coherent directions and its counts: the
  // object's own, or one worker's (SetThreads).
  struct Traversal {
    std::vector<QueueEntry>& queue;
    std::vector<HullPairContact>& results;
    std::vector<CoherentPair>& current;
    std::vector<FrontPair>& current_far;
    std::vector<FrontPair>& front;
    ProximityQueryStats& st;
  };
  Traversal main_traversal{queue_, results_, current_, current_far_, next_front_, st};
  // A node pair where the traversal stops joins this call's front (when it fits; a front that
  // does not fit is not used by the next call).
  std::atomic<bool> front_overflow{false};
  const bool track_front = coherent_next && !a_single && !b_single && !(budget_us < kInf) &&
                           options.max_node_pair_tests <= 0;
  auto stop_at = [&](Traversal& t, int node_A, int node_B, const glm::dvec3& axis_A) {
    if (!track_front) return;
    if (t.front.size() < t.front.capacity()) {
      t.front.push_back({node_A, node_B, axis_A});
    } else {
      front_overflow.store(true, std::memory_order_relaxed);
    }
  };
  auto push = [](Traversal& t, double key, int node_A, int node_B, const glm::dvec3& guess_A,
                 double box_gap_m) {
    t.queue.push_back({key, node_A, node_B, guess_A, box_gap_m});  // grows only during warm-up
    std::push_heap(t.queue.begin(), t.queue.end(), HeapAfter);
  };
  auto emit = [&](Traversal& t, const HullPairContact& c) {
    if (t.results.size() < max_pairs) {
      t.results.push_back(c);
      return;
    }
    ++t.st.pairs_dropped;
    if (t.results.empty()) return;
    // Full: keep the deeper of the new pair and the shallowest kept one.
    auto worst = std::max_element(t.results.begin(), t.results.end(),
                                  [](const HullPairContact& x, const HullPairContact& y) {
                                    return x.signed_distance_m < y.signed_distance_m;
                                  });
    if (c.signed_distance_m < worst->signed_distance_m) *worst = c;
  };

  const bool unlimited = !(budget_us < kInf) && options.max_node_pair_tests <= 0;
  const bool near_exit = !options.exact_internal_distances && unlimited;
  // With workers (SetThreads) and no budget, the traversal moves to them once this many node
  // pairs are queued (a budget needs the one best-first order).
  const std::size_t split_at =
      arena_ != nullptr && unlimited && !a_single && !b_single ? 16 * workers_.size() : 0;
  // One node pair of a traversal: leaf pairs are tested and emitted, internal pairs split into
  // their children (queued unless culled). Reads only what the call's set-up fixed (models,
  // poses, cache entries, the previous call's coherent directions), so that workers may run it
  // at once on their own traversals.
  // A node pair's lower bound from the overlap of its hulls' support intervals along the centre
  // line (−overlap ≤ every descendant pair's signed distance), or lb where that is larger.
  const auto centre_line_bound = [](const PosedHull& cA, const PosedHull& cB, double lb) {
    const glm::dvec3 d = cA.center_W - cB.center_W;
    const double d_len = glm::length(d);
    return d_len > 0.0 ? std::max(lb, -Overlap(cA, cB, d / d_len)) : lb;
  };
  auto process = [&](Traversal& t, const QueueEntry& e) {
    const PosedHull hA = posed(A, *entry_A, X_WA, nullptr, nullptr, glm::dvec3(0.0), e.node_A);
    const PosedHull hB = posed(B, *entry_B, X_WB, &R_AB, &R_BA, p_AB, e.node_B);
    const bool leaf_A = is_leaf(A, e.node_A);
    const bool leaf_B = is_leaf(B, e.node_B);
    ++t.st.node_pairs_tested;
    const double eps_e = pair_eps(e.node_A, e.node_B);

    if (leaf_A && leaf_B) {
      ++t.st.leaf_pairs_tested;
      stop_at(t, e.node_A, e.node_B, glm::dvec3(0.0));
      const CoherentPair* prev = nullptr;
      const FrontPair* prev_far = nullptr;
      if (coherent) {
        prev = FindPair(previous_, e.node_A, e.node_B);
        if (prev == nullptr) prev_far = FindPair(previous_far_, e.node_A, e.node_B);
      }
      // A pair farther than its tolerance: remembered with the direction (A's frame) that
      // showed it, for the next call.
      auto remember_far = [&](const glm::dvec3& v_A) {
        if (t.current_far.size() < t.current_far.capacity()) {
          t.current_far.push_back({e.node_A, e.node_B, v_A});
        }
      };
      if (prev_far != nullptr) {
        // The previous call's separating direction v: the hulls' support intervals along it
        // are at least −Overlap/|v| apart, a lower bound of their distance. Still beyond the
        // tolerance: dropped, as GJK would have (it reports only pairs within it).
        const glm::dvec3& v_A = prev_far->axis_A;
        if (-Overlap(hA, hB, v_A) > eps_e * glm::length(v_A)) {
          ++t.st.coherent_culls;
          remember_far(v_A);
          return;
        }
      }
      // Leaf pairs in W with the quaternion arithmetic (QuaternionPath): their contacts are the
      // remote step's output, and downstream a window moved by a last bit can flip a cell that
      // lies exactly on a triangle's edge (the striped blocks of fig76 are axis-aligned), so they
      // keep the bits they had before the query moved to A's frame. First guess: this pair's
      // direction in the previous query, else the centre line.
      const PosedHull wA = hA.QuaternionPath(), wB = hB.QuaternionPath();
      const GjkResult g =
          GjkDistance(wA, wB, prev != nullptr ? prev->direction_W : glm::dvec3(0.0), eps_e);
      if (g.status == GjkStatus::kFar) {
        if (coherent_next) remember_far(R_AW * g.v);
        return;
      }
      HullPairContact c;
      if (g.status == GjkStatus::kSeparated) {
        if (g.distance_m > eps_e) {
          if (coherent_next) remember_far(R_AW * g.v);
          return;
        }
        c.signed_distance_m = g.distance_m;
        c.normal_W = g.v / g.distance_m;
        c.point_A_W = g.p_A;
        c.point_B_W = g.p_B;
      } else {
        c = PenetrationContact(wA, wB, prev != nullptr ? &prev->direction_W : nullptr);
        // Touching within GJK's tolerance counts as within ε even when the support intervals
        // leave a gap of a few 1e-13 m.
        if (c.signed_distance_m > eps_e + kTouch_m) return;
      }
      c.node_A = e.node_A;
      c.node_B = e.node_B;
      if (!IsFiniteContact(c)) {
        ++t.st.numerical_faults;
        return;
      }
      if (prev != nullptr) ++t.st.coherent_hits;
      emit(t, c);
      if (t.current.size() < t.current.capacity()) {
        t.current.push_back({c.node_A, c.node_B, c.normal_W});
      }
      return;
    }

    // Internal pair: GJK, stopping as soon as the hulls are known to be farther than ε; skipped
    // for big hulls, whose support functions cost more than descending (the children's sphere,
    // box and centre-line tests then do the culling).
    GjkResult g;
    g.status = GjkStatus::kTouching;
    // Without a budget GJK is here only to cull: it stops as soon as the hulls are certainly
    // within ε (kNear), since then the pair descends whatever their exact distance; and it is
    // skipped where the pair's boxes overlap along all their face normals, where it hardly ever
    // culls (on the file and CAD part at ε = 1 mm, skipping those calls took the query from 148
    // to 124 µs).
    // With a budget the exact distance keeps the best-first order sharp.
    const bool small =
        hA.vertex_count + hB.vertex_count <= static_cast<std::size_t>(kInternalGjkMaxVertices);
    if (small && !(near_exit && e.box_gap_m < 0.0)) {
      g = GjkDistance(hA, hB, e.guess_A, eps_e, near_exit ? eps_e : -1.0);
    }
    if (g.status == GjkStatus::kFar ||
        (g.status == GjkStatus::kSeparated && g.distance_m > eps_e)) {
      stop_at(t, e.node_A, e.node_B, g.v);
      return;
    }
    double key = e.key_m;
    if (g.status == GjkStatus::kSeparated || g.status == GjkStatus::kNear) {
      key = std::max(key, g.distance_m);
    } else if (!near_exit) {
      // Overlapping: any direction's overlap bounds the penetration depth of every descendant
      // pair from above (descendant hulls lie inside these), so −overlap is a lower bound. (Keys
      // order the queue, which only a budget makes matter.)
      glm::dvec3 n = hA.center_W - hB.center_W;
      const double len = glm::length(n);
      if (len > 0.0) key = std::max(key, -Overlap(hA, hB, n / len));
    }
    // Without a budget, descend into both nodes where both are internal: each pair tested then
    // rules on four pairs below it, and on the seed scenes that cuts the internal pairs tested by
    // a third (file and CAD part at ε = 1 mm: 470 node pairs and 190 µs descending the larger
    // node alone, 300 and 125 µs both). With a budget, into the larger node (by bounding
    // radius) only, which keeps the best-first order's keys sharp. Leaves are never split.
    const bool split_A = !leaf_A && (leaf_B || unlimited || hA.radius_m >= hB.radius_m);
    const bool split_B = !leaf_B && (leaf_A || unlimited || !split_A);
    const auto children = [&](const HapticModel& m, int node, bool split, const int& self) {
      return split ? std::span<const int>(
                         m.hull_hierarchy.nodes[static_cast<std::size_t>(node)].children)
                   : std::span<const int>(&self, 1);
    };
    const std::span<const int> next_A = children(A, e.node_A, split_A, e.node_A);
    const std::span<const int> next_B = children(B, e.node_B, split_B, e.node_B);
    const int count_A = static_cast<int>(A.hull_hierarchy.nodes.size());
    const int count_B = static_cast<int>(B.hull_hierarchy.nodes.size());
    for (const int node_A : next_A) {
      if (split_A && (node_A < 0 || node_A >= count_A)) continue;
      const PosedHull cA =
          !split_A ? hA : posed(A, *entry_A, X_WA, nullptr, nullptr, glm::dvec3(0.0), node_A);
      for (const int node_B : next_B) {
        if (split_B && (node_B < 0 || node_B >= count_B)) continue;
        // Cheapest first: the bounding spheres, the oriented boxes, then the support intervals'
        // overlap along the centre line (−overlap ≤ every descendant pair's signed distance).
        // A culled pair joins the front.
        const double lb = sphere_bound(node_A, node_B);
        const double eps_child = pair_eps(node_A, node_B);
        if (lb > eps_child) {
          ++t.st.node_pairs_culled;
          stop_at(t, node_A, node_B, glm::dvec3(0.0));
          continue;
        }
        const double gap = box_gap(node_A, node_B, eps_child + kBoxSlack_m);
        if (gap > eps_child + kBoxSlack_m) {
          ++t.st.node_pairs_culled;
          stop_at(t, node_A, node_B, glm::dvec3(0.0));
          continue;
        }
        const PosedHull cB = !split_B ? hB : posed(B, *entry_B, X_WB, &R_AB, &R_BA, p_AB, node_B);
        const double bound = centre_line_bound(cA, cB, lb);
        if (bound > eps_child) {
          ++t.st.node_pairs_culled;
          stop_at(t, node_A, node_B, glm::dvec3(0.0));
          continue;
        }
        push(t, std::max(key, bound), node_A, node_B, g.v, gap);
      }
    }
  };

  // The cheap tests of a front pair f (front tracking), cheapest first: the bounding spheres,
  // the oriented boxes, for a pair that internal GJK culled the overlap along its separating
  // direction then (f.axis_A, nonzero), and the centre-line bound. These are the child tests of
  // `process` above, which stay written out there: calling this lambda from its child loop made
  // the query without coherence 8 % slower (hammer on torus 50.4 → 54.0 µs, file on CAD part
  // 112 → 121 µs). A pair none of them culls is queued (key: the bound; GJK's first guess:
  // f.axis_A); one that is culled joins the front again. The hulls are posed only once spheres
  // and boxes pass.
  auto retest = [&](Traversal& t, const FrontPair& f) {
    const double lb = sphere_bound(f.node_A, f.node_B);
    const double eps_pair = pair_eps(f.node_A, f.node_B);
    if (lb > eps_pair) {
      ++t.st.node_pairs_culled;
      stop_at(t, f.node_A, f.node_B, glm::dvec3(0.0));
      return;
    }
    const double gap = box_gap(f.node_A, f.node_B, eps_pair + kBoxSlack_m);
    if (gap > eps_pair + kBoxSlack_m) {
      ++t.st.node_pairs_culled;
      stop_at(t, f.node_A, f.node_B, glm::dvec3(0.0));
      return;
    }
    const PosedHull cA = posed(A, *entry_A, X_WA, nullptr, nullptr, glm::dvec3(0.0), f.node_A);
    const PosedHull cB = posed(B, *entry_B, X_WB, &R_AB, &R_BA, p_AB, f.node_B);
    if (glm::dot(f.axis_A, f.axis_A) > 0.0 &&
        -Overlap(cA, cB, f.axis_A) > eps_pair * glm::length(f.axis_A)) {
      ++t.st.node_pairs_culled;
      stop_at(t, f.node_A, f.node_B, f.axis_A);
      return;
    }
    const double bound = centre_line_bound(cA, cB, lb);
    if (bound > eps_pair) {
      ++t.st.node_pairs_culled;
      stop_at(t, f.node_A, f.node_B, glm::dvec3(0.0));
      return;
    }
    push(t, bound, f.node_A, f.node_B, f.axis_A, gap);
  };

  // Where the traversal starts: the previous call's front (front tracking), or the two roots.
  // Not from a front whose models were cached anew since (a model changed at its address: its
  // node indices may no longer exist).
  const bool use_front = track_front && coherent && front_valid_ && entry_builds_ == entry_builds &&
                         front_.size() <= 2 * front_base_ + 64;
  // With workers, each takes its share of the front (below).
  const bool front_on_workers = use_front && split_at > 0;
  if (use_front) {
    st.front_pairs = static_cast<int>(front_.size());
    if (!front_on_workers) {
      for (const FrontPair& f : front_) retest(main_traversal, f);
    }
  } else {
    const int root_A = a_single ? -1 : 0;
    const int root_B = b_single ? -1 : 0;
    const double lb = sphere_bound(root_A, root_B);
    const double eps_root = pair_eps(root_A, root_B);
    const double gap = lb > eps_root ? kInf : box_gap(root_A, root_B, eps_root + kBoxSlack_m);
    if (gap > eps_root + kBoxSlack_m) {
      ++st.node_pairs_culled;
      stop_at(main_traversal, root_A, root_B, glm::dvec3(0.0));
    } else {
      push(main_traversal, lb, root_A, root_B, glm::dvec3(0.0), gap);
    }
  }

  while (!queue_.empty()) {
    if (options.max_node_pair_tests > 0 && st.node_pairs_tested >= options.max_node_pair_tests) {
      st.budget_exhausted = true;
      break;
    }
    if (budget_us < kInf &&
        std::chrono::duration<double, std::micro>(Clock::now() - t0).count() >= budget_us) {
      st.budget_exhausted = true;
      break;
    }
    std::pop_heap(queue_.begin(), queue_.end(), HeapAfter);
    const QueueEntry e = queue_.back();
    queue_.pop_back();
    process(main_traversal, e);
    if (split_at > 0 && queue_.size() >= split_at) break;
  }
  if (split_at > 0 && (!queue_.empty() || front_on_workers)) {
    // The rest of the traversal on the workers: each queued node pair's subtree is one task
    // (oneTBB balances them), descended on the queue of the thread that runs it; or, starting
    // from the previous front, blocks of its pairs are the tasks. Without a budget every pair
    // that is not culled is tested whatever the order, so the pairs found are the serial
    // traversal's; sorted below.
    for (Worker& w : workers_) {
      w.queue.clear();
      w.results.clear();
      w.current.clear();
      w.current_far.clear();
      w.front.clear();
      w.st = ProximityQueryStats{};
    }
    const auto drain = [&](Worker& w) {
      Traversal t{w.queue, w.results, w.current, w.current_far, w.front, w.st};
      while (!w.queue.empty()) {
        std::pop_heap(w.queue.begin(), w.queue.end(), HeapAfter);
        const QueueEntry e = w.queue.back();
        w.queue.pop_back();
        process(t, e);
      }
    };
    constexpr int kDone = -2;  // a subtree's entry once a task has descended it
    const auto descend = [&](Worker& w, QueueEntry& entry) {
      w.queue.push_back(entry);
      entry.node_A = kDone;
      drain(w);
    };
    const auto descend_front = [&](Worker& w, FrontPair& f) {
      Traversal t{w.queue, w.results, w.current, w.current_far, w.front, w.st};
      retest(t, f);
      f.node_A = kDone;
      drain(w);
    };
    const std::size_t tasks = front_on_workers ? front_.size() : queue_.size();
    try {
      arena_->arena.execute([&] {
        oneapi::tbb::parallel_for(
            oneapi::tbb::blocked_range<std::size_t>(0, tasks, front_on_workers ? 16 : 1),
            [&](const oneapi::tbb::blocked_range<std::size_t>& r) {
              const int slot = oneapi::tbb::this_task_arena::current_thread_index();
              Worker& w = workers_[static_cast<std::size_t>(slot)];
              for (std::size_t k = r.begin(); k != r.end(); ++k) {
                if (front_on_workers) {
                  descend_front(w, front_[k]);
                } else {
                  descend(w, queue_[k]);
                }
              }
            });
      });
    } catch (...) {
      // Tasks could not be spawned: the subtrees not yet descended, on this thread.
    }
    for (QueueEntry& entry : queue_) {
      if (entry.node_A != kDone) descend(workers_[0], entry);
    }
    if (front_on_workers) {
      for (FrontPair& f : front_) {
        if (f.node_A != kDone) descend_front(workers_[0], f);
      }
    }
    queue_.clear();
    for (Worker& w : workers_) {
      for (const HullPairContact& c : w.results) emit(main_traversal, c);
      for (const CoherentPair& c : w.current) {
        if (current_.size() < current_.capacity()) current_.push_back(c);
      }
      for (const FrontPair& c : w.current_far) {
        if (current_far_.size() < current_far_.capacity()) current_far_.push_back(c);
      }
      for (const FrontPair& f : w.front) {
        if (next_front_.size() < next_front_.capacity()) {
          next_front_.push_back(f);
        } else {
          front_overflow.store(true, std::memory_order_relaxed);
        }
      }
      st.node_pairs_tested += w.st.node_pairs_tested;
      st.leaf_pairs_tested += w.st.leaf_pairs_tested;
      st.node_pairs_culled += w.st.node_pairs_culled;
      st.pairs_dropped += w.st.pairs_dropped;
      st.coherent_hits += w.st.coherent_hits;
      st.coherent_culls += w.st.coherent_culls;
      st.numerical_faults += w.st.numerical_faults;
    }
  }
  // Ties broken by the nodes, so that the order does not depend on the traversal's.
  std::sort(results_.begin(), results_.end(),
            [](const HullPairContact& x, const HullPairContact& y) {
              if (x.signed_distance_m != y.signed_distance_m) {
                return x.signed_distance_m < y.signed_distance_m;
              }
              return x.node_A != y.node_A ? x.node_A < y.node_A : x.node_B < y.node_B;
            });
  std::sort(current_.begin(), current_.end(), PairLess<CoherentPair>);
  previous_.swap(current_);
  std::sort(current_far_.begin(), current_far_.end(), PairLess<FrontPair>);
  previous_far_.swap(current_far_);
  front_valid_ = track_front && !st.budget_exhausted && !front_overflow.load();
  if (front_valid_ && !use_front) front_base_ = next_front_.size();
  front_.swap(next_front_);
  previous_A_ = &A;
  previous_B_ = &B;
  return finish();
}

}  // namespace ht
