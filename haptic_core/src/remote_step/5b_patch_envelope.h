#pragma once
// Stage 5b's evaluation of a patch's envelope at a point of a window (internal to the
// 5b_*.cc files): a coarse triangle projected on the window (ProjectTriangle), its corners'
// blend, the textured height at (s, t) with parallax (ParallaxValue, ValueAt), the envelope of
// the triangles that hold a point (Envelope, HeightOver) and the cells of a window.

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <span>

#include "haptic_core/depth_refinement.h"

namespace ht::patch_envelope {

inline constexpr double kInf = std::numeric_limits<double>::infinity();
inline constexpr float kInf32 = std::numeric_limits<float>::infinity();
// Barycentric tolerance of a point on a triangle's edge (the render's kEdgeTolerance).
inline constexpr double kEdgeTolerance = -1e-9;
// Spacing of a seed's sub-grid, in level-0 texels (the pattern search refines from its best).
inline constexpr double kSubsampleTexels = 4.0;
// The base's seeds: the deepest cells of the base and of the four in-plane translations (one
// cell either way: where a peak the filter spread over two cells lies). The rotated samples'
// cells lie where a rotation by h_θ = 2/N rad brings the depth, mostly at the window's edges.
inline constexpr int kBaseSeedSamples = 5;

using Projected = DepthRefiner::Projected;

// The barycentric coordinates of (s, t) on a projected triangle (outside it too).
inline void Barycentric(const Projected& P, double s, double t, double& b0, double& b1,
                        double& b2) noexcept {
  b0 = ((P.x[1] - s) * (P.y[2] - t) - (P.x[2] - s) * (P.y[1] - t)) * P.inv_area;
  b1 = ((P.x[2] - s) * (P.y[0] - t) - (P.x[0] - s) * (P.y[2] - t)) * P.inv_area;
  b2 = 1.0 - b0 - b1;
}

// The least length of the normalized interpolation's denominator |Σλ·n_c| over the triangle:
// |Σλ·n_c|² = (1 − c)Σλ² + c with c the smallest corner cosine is at least (1 + 2c)/3 (floored
// at 1e-12 where c < −0.5). Dividing by it can grow a normal component by at most its inverse.
inline double MinNormalInterpolationLength(const Projected& P) noexcept {
  const double c = std::min({P.cos01, P.cos02, P.cos12});
  return std::sqrt(std::max((1.0 + 2.0 * c) / 3.0, 1e-12));
}

// Triangle f of `m` posed at X on window w, when it faces the side's way (as the render tests
// it) and its projection is not edge-on.
inline bool ProjectTriangle(const HapticModel& m, const RigidTransform& X, const ContactWindow& w,
                            int f, PatchSide side, Projected& out, bool parallax = false) noexcept {
  const glm::ivec3 tri = m.triangles[static_cast<std::size_t>(f)];
  glm::dvec3 p[3];
  for (int c = 0; c < 3; ++c) {
    p[c] = X * m.vertices_O[static_cast<std::size_t>(tri[c])] - w.center_W;
    out.x[c] = glm::dot(p[c], w.axis_u_W);
    out.y[c] = glm::dot(p[c], w.axis_v_W);
    out.d[c] = glm::dot(p[c], w.normal_W);
    out.nn[c] =
        glm::dot(X.rotation * m.corner_normals_O[3 * static_cast<std::size_t>(f) + c], w.normal_W);
  }
  const glm::dvec3 cr = glm::cross(p[1] - p[0], p[2] - p[0]);
  const double cr_len = glm::length(cr);
  if (!(cr_len > 0.0)) return false;
  const double facing = glm::dot(cr, w.normal_W) / cr_len;
  if (side == PatchSide::kEnvironment ? facing <= kPatchFacingThreshold
                                      : facing >= -kPatchFacingThreshold) {
    return false;
  }
  const double area =
      (out.x[1] - out.x[0]) * (out.y[2] - out.y[0]) - (out.x[2] - out.x[0]) * (out.y[1] - out.y[0]);
  if (!(std::abs(area) > 0.0)) return false;
  out.inv_area = 1.0 / area;
  const std::size_t k = 3 * static_cast<std::size_t>(f);
  for (int c = 0; c < 3; ++c) {
    out.tu[c] = m.corner_uvs[k + c].x;
    out.tv[c] = m.corner_uvs[k + c].y;
  }
  const glm::dvec3& n0 = m.corner_normals_O[k];
  const glm::dvec3& n1 = m.corner_normals_O[k + 1];
  const glm::dvec3& n2 = m.corner_normals_O[k + 2];
  out.cos01 = glm::dot(n0, n1);
  out.cos02 = glm::dot(n0, n2);
  out.cos12 = glm::dot(n1, n2);
  out.x0 = std::min({out.x[0], out.x[1], out.x[2]});
  out.x1 = std::max({out.x[0], out.x[1], out.x[2]});
  out.y0 = std::min({out.y[0], out.y[1], out.y[2]});
  out.y1 = std::max({out.y[0], out.y[1], out.y[2]});
  out.textured = m.textured[static_cast<std::size_t>(f)] != 0 && !m.texture.empty();
  out.texel_m = m.texel_size_m[static_cast<std::size_t>(f)];
  out.parallax = parallax && out.textured;
  out.reach = 0.0;
  if (out.parallax) {
    for (int c = 0; c < 3; ++c) {
      const glm::dvec3 N_W = X.rotation * m.corner_normals_O[k + c];
      out.nu[c] = glm::dot(N_W, w.axis_u_W);
      out.nv[c] = glm::dot(N_W, w.axis_v_W);
    }
    // The displaced surface lies within |h|·|N⊥| of the coarse triangle's projection. The
    // normalized interpolation's |N⊥| is at most the corners' largest over the interpolation's
    // least length, √((1 + 2c)/3) with c the smallest corner cosine (NormalFactorRange).
    double lateral = 0.0;
    for (int c = 0; c < 3; ++c) {
      lateral = std::max(lateral, std::sqrt(out.nu[c] * out.nu[c] + out.nv[c] * out.nv[c]));
    }
    if (!(lateral > 1e-12)) {
      out.parallax = false;  // N ∥ n at every corner: the render's form is exact
      return true;
    }
    lateral = std::min(1.0, lateral / MinNormalInterpolationLength(out));
    double max_abs_h = static_cast<double>(m.texture.MaxAbsOver(
        0, std::min({out.tu[0], out.tu[1], out.tu[2]}), std::min({out.tv[0], out.tv[1], out.tv[2]}),
        std::max({out.tu[0], out.tu[1], out.tu[2]}), std::max({out.tv[0], out.tv[1], out.tv[2]})));
    if (!std::isfinite(max_abs_h)) max_abs_h = 0.0;
    out.reach = lateral * max_abs_h;
    // Each edge's altitude over the opposite corner (m): barycentric b_c · altitude_c is the
    // signed distance from edge c (the one opposite corner c) on the window plane.
    for (int c = 0; c < 3; ++c) {
      const int e0 = (c + 1) % 3, e1 = (c + 2) % 3;
      const double dx = out.x[e1] - out.x[e0], dy = out.y[e1] - out.y[e0];
      const double len = std::sqrt(dx * dx + dy * dy);
      out.altitude[c] = len > 0.0 ? std::abs(area) / len : 0.0;
    }
    out.x0 -= out.reach;
    out.x1 += out.reach;
    out.y0 -= out.reach;
    out.y1 += out.reach;
  }
  return true;
}

// The corner data interpolated at barycentrics (b0, b1, b2) of a projected triangle: len2 the
// squared length |Σλ·n_c|² of the corner normals' blend (from the corner cosines; divide the
// blended components by its root to normalize), and the texture coordinates (u, v).
struct CornerBlend {
  double len2;
  float u, v;
};
inline CornerBlend Blend(const Projected& P, double b0, double b1, double b2) noexcept {
  return {b0 * b0 + b1 * b1 + b2 * b2 +
              2.0 * (b0 * b1 * P.cos01 + b0 * b2 * P.cos02 + b1 * b2 * P.cos12),
          static_cast<float>(b0 * P.tu[0] + b1 * P.tu[1] + b2 * P.tu[2]),
          static_cast<float>(b0 * P.tv[0] + b1 * P.tv[1] + b2 * P.tv[2])};
}

// The parallax value of one projected triangle at (s, t) (DepthRefinementOptions::parallax): the
// height along n of the displaced surface r(q) = q + h(q)·N(q) where it crosses the line through
// (s, t) along n, q on the triangle. Damped fixed-point steps q ← q + ω((s, t) − h(q)·N⊥(q) − q)
// from q = (s, t), q kept on the triangle (barycentrics clamped), ω from the last two steps (a
// secant along the step); settled when the step is under a hundredth of a level-0 texel (the
// height's error is that times the surface's slope). NaN where it does not settle within
// `iterations`, or where q is clamped onto the triangle and the step leads out again (the line
// meets the displaced surface beyond this triangle's edge): then `edge`, when given, gets the
// clamped point's height and the lateral miss g = (s, t) − (q + h·N⊥) (m), which the envelope uses
// to bridge a crack (Envelope). Level 0, bilinear.
// No default member initializers: an Envelope holds eight of these per evaluation of a height
// and reads only those it filled, so they are left uninitialized there (zeroing them took a tenth
// of stage 5b's instructions); a lone edge is value-initialized where it is declared
// (`ParallaxEdge e{}`).
struct ParallaxEdge {
  double value, gs, gt;
  double qs, qt;  // the clamped coarse point on the window plane (m)
  double limit;   // the widest crack it may bridge: 2·|h| there (m)
  double texel;   // its triangle's level-0 texel (m)
  bool valid;
};

inline double ParallaxValue(const Projected& P, const HeightField& texture, double s, double t,
                            int iterations, ParallaxEdge* edge) noexcept {
  constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
  if (edge != nullptr) edge->valid = false;
  if (s < P.x0 - 1e-12 || s > P.x1 + 1e-12 || t < P.y0 - 1e-12 || t > P.y1 + 1e-12) return kNaN;
  // (s, t)'s barycentrics: the reach test's and the first step's (q starts at (s, t)).
  double s_b0, s_b1, s_b2;
  Barycentric(P, s, t, s_b0, s_b1, s_b2);
  // Farther than the reach from the triangle's projection: no foot q on it.
  if (s_b0 * P.altitude[0] < -P.reach || s_b1 * P.altitude[1] < -P.reach ||
      s_b2 * P.altitude[2] < -P.reach) {
    return kNaN;
  }
  const HeightFieldLevel& L = texture.level(0);
  const double tol = std::max(0.01 * P.texel_m, 1e-9);
  double qs = s, qt = t, omega = 1.0, previous = kInf, gs_last = 0.0, gt_last = 0.0;
  for (int k = 0; k < iterations; ++k) {
    double b0 = s_b0, b1 = s_b1, b2 = s_b2;
    if (k > 0) Barycentric(P, qs, qt, b0, b1, b2);
    bool clamped = false;
    if (b0 < 0.0 || b1 < 0.0 || b2 < 0.0) {
      clamped = true;
      b0 = std::max(b0, 0.0);
      b1 = std::max(b1, 0.0);
      b2 = std::max(b2, 0.0);
      const double sum = b0 + b1 + b2;
      if (!(sum > 0.0)) return kNaN;
      b0 /= sum;
      b1 /= sum;
      b2 /= sum;
      qs = b0 * P.x[0] + b1 * P.x[1] + b2 * P.x[2];
      qt = b0 * P.y[0] + b1 * P.y[1] + b2 * P.y[2];
    }
    const CornerBlend blend = Blend(P, b0, b1, b2);
    if (!(blend.len2 > 1e-12)) return kNaN;
    const double inv_len = 1.0 / std::sqrt(blend.len2);
    const double Nn = (b0 * P.nn[0] + b1 * P.nn[1] + b2 * P.nn[2]) * inv_len;
    const double Nu = (b0 * P.nu[0] + b1 * P.nu[1] + b2 * P.nu[2]) * inv_len;
    const double Nv = (b0 * P.nv[0] + b1 * P.nv[1] + b2 * P.nv[2]) * inv_len;
    const double h = static_cast<double>(texture.SampleAt(0, L, blend.u, blend.v));
    const double value = b0 * P.d[0] + b1 * P.d[1] + b2 * P.d[2] + h * Nn;
    const double gs = s - h * Nu - qs, gt = t - h * Nv - qt;
    const double g2 = gs * gs + gt * gt;
    if (g2 <= tol * tol) return value;
    if (k > 0) {
      // The step's ratio to the last one along it estimates the damped map's contraction
      // ρ = 1 − ω(1 − λ); ω/(1 − ρ) = 1/(1 − λ) is the step that would land on the fixed point
      // were the map linear (a secant). ρ ≥ 1 (growing): halve.
      const double rho = (gs * gs_last + gt * gt_last) / previous;
      omega = rho < 0.95 ? std::clamp(omega / (1.0 - rho), 0.05, 1.5) : 0.5 * omega;
    }
    previous = g2;
    gs_last = gs;
    gt_last = gt;
    if (clamped) {
      // Clamped here and the next point outside too: the line meets the displaced surface
      // beyond this edge (the next step would clamp again).
      double c0, c1, c2;
      Barycentric(P, qs + omega * gs, qt + omega * gt, c0, c1, c2);
      if (c0 < 0.0 || c1 < 0.0 || c2 < 0.0) {
        if (edge != nullptr) *edge = {value, gs, gt, qs, qt, 2.0 * std::abs(h), P.texel_m, true};
        return kNaN;
      }
    }
    qs += omega * gs;
    qt += omega * gt;
  }
  return kNaN;
}

// The envelope of one side at one point over triangles (largest for the environment, smallest for
// the tool, within the box ±range). With parallax, where no displaced surface crosses the line
// (a crack: at a crease the corner normals of two triangles differ, and their displaced surfaces
// part by |h|·|N_A − N_B|), the crack is bridged: of the triangles whose line met their surface
// beyond an edge, two stopped at one point of a shared edge (within kCreaseTexels texels), on
// opposite sides (misses g_A·g_B < 0) and no farther apart than the widest gap that height can
// open (|g_A| + |g_B| ≤ 2|h|), the nearest such pair, give the height interpolated linearly
// across the gap between their edges: a skirt joining the two surfaces. Fixed storage: never
// allocates.
class Envelope {
 public:
  Envelope(bool keep_max, double range) noexcept
      : keep_max_(keep_max), range_(range), best_(keep_max ? -kInf : kInf) {}
  void Add(double value) noexcept {
    if (!(std::abs(value) <= range_)) return;  // NaN (not covered) or outside the box
    best_ = keep_max_ ? std::max(best_, value) : std::min(best_, value);
  }
  void AddEdge(const ParallaxEdge& e) noexcept {
    // Only a point no displaced surface crosses needs a bridge: once one has, edges are moot.
    if (!e.valid || !std::isinf(best_) || !(std::abs(e.value) <= range_)) return;
    const double g = std::sqrt(e.gs * e.gs + e.gt * e.gt);
    if (!(g <= e.limit)) return;
    if (count_ < kEdges) {
      edges_[count_] = e;
      miss_[count_++] = g;
      return;
    }
    // Keep the nearest kEdges: replace the farthest.
    int far = 0;
    for (int i = 1; i < kEdges; ++i) {
      if (miss_[i] > miss_[far]) far = i;
    }
    if (g < miss_[far]) {
      edges_[far] = e;
      miss_[far] = g;
    }
  }
  double Finish() const noexcept {
    if (!std::isinf(best_) || count_ < 2) return best_;
    double best = best_, best_gap = kInf;
    for (int i = 0; i < count_; ++i) {
      for (int j = i + 1; j < count_; ++j) {
        const ParallaxEdge& A = edges_[i];
        const ParallaxEdge& B = edges_[j];
        if (!(A.gs * B.gs + A.gt * B.gt < 0.0)) continue;  // not on opposite sides
        // One crease: both lines were stopped at one point of a shared edge.
        if (!(std::hypot(A.qs - B.qs, A.qt - B.qt) <= kCreaseTexels * std::max(A.texel, B.texel))) {
          continue;
        }
        const double ga = miss_[i], gb = miss_[j];
        if (!(ga + gb <= std::max(A.limit, B.limit)) || ga + gb > best_gap) continue;
        best_gap = ga + gb;
        best = (A.value * gb + B.value * ga) / (ga + gb);
      }
    }
    return best;
  }

 private:
  static constexpr int kEdges = 8;
  static constexpr double kCreaseTexels = 2.0;
  bool keep_max_;
  double range_;
  double best_;
  // Entries [0, count_) are filled (AddEdge); the rest are never read.
  std::array<ParallaxEdge, kEdges> edges_;
  std::array<double, kEdges> miss_;  // |g| of each edge (m)
  int count_ = 0;
};

inline double ValueAt(const Projected& P, const HeightField& texture, double s, double t, int level,
                      double cell_m, int parallax_iterations, ParallaxEdge* edge) noexcept {
  if (edge != nullptr) edge->valid = false;
  if (P.parallax && level == 0) return ParallaxValue(P, texture, s, t, parallax_iterations, edge);
  if (s < P.x0 - 1e-12 || s > P.x1 + 1e-12 || t < P.y0 - 1e-12 || t > P.y1 + 1e-12) {
    return std::numeric_limits<double>::quiet_NaN();
  }
  double b0, b1, b2;
  Barycentric(P, s, t, b0, b1, b2);
  if (b0 < kEdgeTolerance || b1 < kEdgeTolerance || b2 < kEdgeTolerance) {
    return std::numeric_limits<double>::quiet_NaN();
  }
  double value = b0 * P.d[0] + b1 * P.d[1] + b2 * P.d[2];
  if (P.textured) {
    const CornerBlend blend = Blend(P, b0, b1, b2);
    const float u = blend.u, v = blend.v;
    const double ndotn = blend.len2 > 1e-12
                             ? (b0 * P.nn[0] + b1 * P.nn[1] + b2 * P.nn[2]) / std::sqrt(blend.len2)
                             : 0.0;
    if (level == 0) {
      value += static_cast<double>(texture.SampleAt(0, texture.level(0), u, v)) * ndotn;
    } else {
      const int lv = level > 0 ? level : texture.LevelForFootprint(P.texel_m, cell_m);
      value += static_cast<double>(texture.Sample(lv, u, v)) * ndotn;
    }
  }
  return value;
}

// The envelope of `list` at (s, t): the largest value for the environment, the smallest for the
// tool, within the box ±range.
inline double HeightOver(std::span<const Projected> list, const HeightField& texture, bool keep_max,
                         double range, double s, double t, int level, double cell_m,
                         int parallax_iterations) noexcept {
  Envelope envelope(keep_max, range);
  ParallaxEdge edge{};
  for (const Projected& P : list) {
    envelope.Add(ValueAt(P, texture, s, t, level, cell_m, parallax_iterations, &edge));
    envelope.AddEdge(edge);
  }
  return envelope.Finish();
}

// Where parallax carries the render's value at (s, t) (stage 5b's seeds carried by parallax):
// the envelope's triangle at (s, t) in the render's form at level 0 (the
// largest value for the environment, the smallest for the tool, within the box ±range) reads the
// surface point h·N of its coarse point under (s, t), which lies at (s, t) + h·N⊥ on the window
// plane. Writes that offset (m along u and v); false where no triangle covers (s, t) or the
// envelope's triangle has no parallax (N ∥ n, untextured).
inline bool ParallaxOffset(std::span<const Projected> list, const HeightField& texture,
                           bool keep_max, double range, double s, double t, double& ds,
                           double& dt) noexcept {
  double best = keep_max ? -kInf : kInf;
  bool found = false, parallax = false;
  const HeightFieldLevel& L = texture.level(0);
  for (const Projected& P : list) {
    double b0, b1, b2;
    Barycentric(P, s, t, b0, b1, b2);
    if (b0 < kEdgeTolerance || b1 < kEdgeTolerance || b2 < kEdgeTolerance) continue;
    double value = b0 * P.d[0] + b1 * P.d[1] + b2 * P.d[2];
    double h = 0.0, Nu = 0.0, Nv = 0.0;
    if (P.textured) {
      const CornerBlend blend = Blend(P, b0, b1, b2);
      if (!(blend.len2 > 1e-12)) continue;
      const double inv_len = 1.0 / std::sqrt(blend.len2);
      h = static_cast<double>(texture.SampleAt(0, L, blend.u, blend.v));
      value += h * (b0 * P.nn[0] + b1 * P.nn[1] + b2 * P.nn[2]) * inv_len;
      if (P.parallax) {
        Nu = (b0 * P.nu[0] + b1 * P.nu[1] + b2 * P.nu[2]) * inv_len;
        Nv = (b0 * P.nv[0] + b1 * P.nv[1] + b2 * P.nv[2]) * inv_len;
      }
    }
    if (!(std::abs(value) <= range)) continue;
    if (keep_max ? value > best : value < best) {
      best = value;
      found = true;
      parallax = P.parallax;
      ds = h * Nu;
      dt = h * Nv;
    }
  }
  return found && parallax;
}

// Window coordinates (m) of cell `index`'s centre.
inline void CellCoordinates(const ContactWindow& w, int index, double& s, double& t) noexcept {
  const int n = w.resolution;
  const int i = index % n, j = index / n;
  s = ((i + 0.5) / n - 0.5) * w.extent_m;
  t = ((j + 0.5) / n - 0.5) * w.extent_m;
}

inline int CellAt(const ContactWindow& w, double s, double t) noexcept {
  const int n = w.resolution;
  const int i = std::clamp(static_cast<int>(std::floor((s / w.extent_m + 0.5) * n)), 0, n - 1);
  const int j = std::clamp(static_cast<int>(std::floor((t / w.extent_m + 0.5) * n)), 0, n - 1);
  return j * n + i;
}

// Whether a projected triangle's box on the window plane meets [s0, s1] × [t0, t1] (m).
inline bool Overlaps(const Projected& P, double s0, double s1, double t0, double t1) noexcept {
  return !(P.x1 < s0 || P.x0 > s1 || P.y1 < t0 || P.y0 > t1);
}

// Bounds of ValueAt's normal factor N·n over the triangle (N the normalized interpolation of the
// corner normals): the numerator Σλ·nn_c lies between the corners' nn, and |Σλ·n_c|² =
// (1 − c)Σλ² + c with c the smallest corner cosine is at least (1 + 2c)/3, so dividing by it
// can only move the numerator away from 0 by 1/√((1 + 2c)/3). [−1, 1] where c < −0.5.
inline void NormalFactorRange(const Projected& P, double& lo, double& hi) noexcept {
  const double c = std::min({P.cos01, P.cos02, P.cos12});
  const double nn_lo = std::min({P.nn[0], P.nn[1], P.nn[2]});
  const double nn_hi = std::max({P.nn[0], P.nn[1], P.nn[2]});
  if (!(c >= -0.5)) {
    lo = -1.0;
    hi = 1.0;
    return;
  }
  const double inv_len = 1.0 / MinNormalInterpolationLength(P);
  lo = std::max(-1.0, nn_lo >= 0.0 ? nn_lo : nn_lo * inv_len);
  hi = std::min(1.0, nn_hi >= 0.0 ? nn_hi * inv_len : nn_hi);
}

}  // namespace ht::patch_envelope
