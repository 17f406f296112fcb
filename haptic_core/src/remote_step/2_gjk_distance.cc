// GJK distance (Gilbert, Johnson & Keerthi 1988) on the Minkowski difference A − B, with the
// closest point of each simplex found by Voronoi-region tests (Ericson, Real-Time Collision
// Detection §5.1.5, §5.1.6) and the barycentric coordinates kept for the witness points.
#include <algorithm>
#include <cmath>
#include <glm/geometric.hpp>

#include "2_posed_hull.h"

namespace ht::hull_geometry {
namespace {

// GJK stops when the gap between its upper (|v|) and lower (v·w/|v|) distance bounds is below
// kGjkAbsTol_m + kGjkRelTol·|v|.
constexpr double kGjkAbsTol_m = 1e-12;
constexpr double kGjkRelTol = 1e-10;
constexpr int kGjkMaxIterations = 64;

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

}  // namespace

GjkResult GjkDistance(const PosedHull& A, const PosedHull& B, glm::dvec3 guess, double far_m,
                      double near_m) noexcept {
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

}  // namespace ht::hull_geometry
