// Stage 5b: the penetration depth refined to the finest texture level (issue 32); see
// depth_refinement.h for the method.

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "haptic_core/depth_refinement.h"

namespace ht {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr float kInf32 = std::numeric_limits<float>::infinity();
// Barycentric tolerance of a point on a triangle's edge (the render's kEdgeTolerance).
constexpr double kEdgeTolerance = -1e-9;
// Spacing of a seed's sub-grid, in level-0 texels (the pattern search refines from its best).
constexpr double kSubsampleTexels = 4.0;
// The base's seeds: the deepest cells of the base and of the four in-plane translations (one
// cell either way: where a peak the filter spread over two cells lies). The rotated samples'
// cells lie where a rotation by h_θ = 2/N rad brings the depth, mostly at the window's edges.
constexpr int kBaseSeedSamples = 5;

using Projected = DepthRefiner::Projected;

// The barycentric coordinates of (s, t) on a projected triangle (outside it too).
void Barycentric(const Projected& P, double s, double t, double& b0, double& b1,
                 double& b2) noexcept {
  b0 = ((P.x[1] - s) * (P.y[2] - t) - (P.x[2] - s) * (P.y[1] - t)) * P.inv_area;
  b1 = ((P.x[2] - s) * (P.y[0] - t) - (P.x[0] - s) * (P.y[2] - t)) * P.inv_area;
  b2 = 1.0 - b0 - b1;
}

// The least length of the normalized interpolation's denominator |Σλ·n_c| over the triangle:
// |Σλ·n_c|² = (1 − c)Σλ² + c with c the smallest corner cosine is at least (1 + 2c)/3 (floored
// at 1e-12 where c < −0.5). Dividing by it can grow a normal component by at most its inverse.
double MinNormalInterpolationLength(const Projected& P) noexcept {
  const double c = std::min({P.cos01, P.cos02, P.cos12});
  return std::sqrt(std::max((1.0 + 2.0 * c) / 3.0, 1e-12));
}

// Triangle f of `m` posed at X on window w, when it faces the side's way (as the render tests
// it) and its projection is not edge-on.
bool ProjectTriangle(const HapticModel& m, const RigidTransform& X, const ContactWindow& w, int f,
                     PatchSide side, Projected& out, bool parallax = false) noexcept {
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
CornerBlend Blend(const Projected& P, double b0, double b1, double b2) noexcept {
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

double ParallaxValue(const Projected& P, const HeightField& texture, double s, double t,
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

double ValueAt(const Projected& P, const HeightField& texture, double s, double t, int level,
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
double HeightOver(std::span<const Projected> list, const HeightField& texture, bool keep_max,
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

// Where parallax carries the render's value at (s, t) (DepthRefinementOptions::
// parallax_offset_seeds): the envelope's triangle at (s, t) in the render's form at level 0 (the
// largest value for the environment, the smallest for the tool, within the box ±range) reads the
// surface point h·N of its coarse point under (s, t), which lies at (s, t) + h·N⊥ on the window
// plane. Writes that offset (m along u and v); false where no triangle covers (s, t) or the
// envelope's triangle has no parallax (N ∥ n, untextured).
bool ParallaxOffset(std::span<const Projected> list, const HeightField& texture, bool keep_max,
                    double range, double s, double t, double& ds, double& dt) noexcept {
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
void CellCoordinates(const ContactWindow& w, int index, double& s, double& t) noexcept {
  const int n = w.resolution;
  const int i = index % n, j = index / n;
  s = ((i + 0.5) / n - 0.5) * w.extent_m;
  t = ((j + 0.5) / n - 0.5) * w.extent_m;
}

int CellAt(const ContactWindow& w, double s, double t) noexcept {
  const int n = w.resolution;
  const int i = std::clamp(static_cast<int>(std::floor((s / w.extent_m + 0.5) * n)), 0, n - 1);
  const int j = std::clamp(static_cast<int>(std::floor((t / w.extent_m + 0.5) * n)), 0, n - 1);
  return j * n + i;
}

// Whether a projected triangle's box on the window plane meets [s0, s1] × [t0, t1] (m).
bool Overlaps(const Projected& P, double s0, double s1, double t0, double t1) noexcept {
  return !(P.x1 < s0 || P.x0 > s1 || P.y1 < t0 || P.y0 > t1);
}

// Bounds of ValueAt's normal factor N·n over the triangle (N the normalized interpolation of the
// corner normals): the numerator Σλ·nn_c lies between the corners' nn, and |Σλ·n_c|² =
// (1 − c)Σλ² + c with c the smallest corner cosine is at least (1 + 2c)/3, so dividing by it
// can only move the numerator away from 0 by 1/√((1 + 2c)/3). [−1, 1] where c < −0.5.
void NormalFactorRange(const Projected& P, double& lo, double& hi) noexcept {
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

}  // namespace

double PatchHeightAt(const HapticModel& model, const RigidTransform& X_WO,
                     std::span<const int> triangles, const ContactWindow& window, PatchSide side,
                     double s_m, double t_m, int level, bool parallax) noexcept {
  Envelope envelope(side == PatchSide::kEnvironment, window.depth_range_m());
  ParallaxEdge edge{};
  Projected P;
  for (const int f : triangles) {
    if (f < 0 || static_cast<std::size_t>(f) >= model.triangles.size()) continue;
    if (!ProjectTriangle(model, X_WO, window, f, side, P, parallax && level == 0)) continue;
    envelope.Add(ValueAt(P, model.texture, s_m, t_m, level, window.cell_size_m(),
                         DepthRefinementOptions{}.parallax_iterations, &edge));
    envelope.AddEdge(edge);
  }
  return envelope.Finish();
}

void DepthRefinementOptions::Validate() const {
  if (!(gradient_step_texels > 0.0) || !std::isfinite(gradient_step_texels)) {
    throw std::invalid_argument("depth refinement: gradient_step_texels must be > 0, got " +
                                std::to_string(gradient_step_texels));
  }
  if (max_subsamples < 1 || max_subsamples > 16) {
    throw std::invalid_argument("depth refinement: max_subsamples must be in [1, 16], got " +
                                std::to_string(max_subsamples));
  }
  if (!(translation_patch_floor_texels >= 0.0) || !std::isfinite(translation_patch_floor_texels)) {
    throw std::invalid_argument(
        "depth refinement: translation_patch_floor_texels must be >= 0, got " +
        std::to_string(translation_patch_floor_texels));
  }
  if (!(translation_patch_step_texels >= 0.0) || !std::isfinite(translation_patch_step_texels)) {
    throw std::invalid_argument(
        "depth refinement: translation_patch_step_texels must be >= 0, got " +
        std::to_string(translation_patch_step_texels));
  }
  if (translation_patch_spacing_cells < 1 ||
      translation_patch_spacing_cells > kMaxTranslationPatchSpacing) {
    throw std::invalid_argument(
        "depth refinement: translation_patch_spacing_cells must be in [1, " +
        std::to_string(kMaxTranslationPatchSpacing) + "], got " +
        std::to_string(translation_patch_spacing_cells));
  }
  if (!(search_floor_texels > 0.0) || !std::isfinite(search_floor_texels)) {
    throw std::invalid_argument("depth refinement: search_floor_texels must be > 0, got " +
                                std::to_string(search_floor_texels));
  }
  if (!(secant_at_kinks_m >= 0.0) || !std::isfinite(secant_at_kinks_m)) {
    throw std::invalid_argument("depth refinement: secant_at_kinks_m must be >= 0, got " +
                                std::to_string(secant_at_kinks_m));
  }
  if (!(translation_kink_tolerance_m >= 0.0) || !std::isfinite(translation_kink_tolerance_m)) {
    throw std::invalid_argument(
        "depth refinement: translation_kink_tolerance_m must be >= 0, got " +
        std::to_string(translation_kink_tolerance_m));
  }
  if (!(screen_tolerance_m >= 0.0) || !std::isfinite(screen_tolerance_m)) {
    throw std::invalid_argument("depth refinement: screen_tolerance_m must be >= 0, got " +
                                std::to_string(screen_tolerance_m));
  }
  if (!std::isfinite(screen_floor_m)) {
    throw std::invalid_argument("depth refinement: screen_floor_m must be finite, got " +
                                std::to_string(screen_floor_m));
  }
  if (parallax && conservative_screen) {
    throw std::invalid_argument(
        "depth refinement: parallax and conservative_screen cannot be on together (the screen's "
        "bounds are the render's form)");
  }
  if (parallax_iterations < 1 || parallax_iterations > 64) {
    throw std::invalid_argument("depth refinement: parallax_iterations must be in [1, 64], got " +
                                std::to_string(parallax_iterations));
  }
  if (max_screen_leaves < 1) {
    throw std::invalid_argument("depth refinement: max_screen_leaves must be >= 1, got " +
                                std::to_string(max_screen_leaves));
  }
}

DepthRefiner::DepthRefiner(const DepthRefinementOptions& options, std::size_t max_triangles,
                           int max_resolution)
    : options_(options) {
  options_.Validate();
  if (max_resolution < 1) {
    throw std::invalid_argument("depth refinement: max_resolution must be >= 1, got " +
                                std::to_string(max_resolution));
  }
  env_list_.reserve(max_triangles);
  tool_list_.reserve(max_triangles);
  vertex_scratch_.reserve(max_triangles);
  env_local_.reserve(max_triangles);
  tool_local_.reserve(max_triangles);
  tool_moved_.reserve(max_triangles);
  env_all_.reserve(max_triangles);
  tool_all_.reserve(max_triangles);
  tool_pose_all_.reserve(max_triangles);
  if (max_triangles > 0) {  // also with the patch off: SetTranslationPatch may turn it on
    const auto n = static_cast<std::size_t>(max_resolution);
    const std::size_t side = n + 2 * kTranslationPatchRadius * kMaxTranslationPatchSpacing;
    patch_env_heights_.reserve(n * n);
    patch_tool_heights_.reserve(side * side);
  }
  if (options_.conservative_screen) {
    for (auto& v : env_screen_) v.reserve(max_triangles);
    for (auto& v : tool_screen_) v.reserve(max_triangles);
  }
}

void DepthRefiner::BeginStep() noexcept {
  last_ = next_;
  num_last_ = num_next_;
  num_next_ = 0;
}

void DepthRefiner::ProjectAll(const HapticModel& model, const RigidTransform& X, PatchSide side,
                              std::span<const int> list, std::vector<Projected>& out) noexcept {
  out.clear();
  Projected P;
  for (const int f : list) {
    if (!ProjectTriangle(model, X, window_, f, side, P, options_.parallax)) continue;
    P.face = f;
    out.push_back(P);
  }
}

void DepthRefiner::GatherEnvironment(double s0, double s1, double t0, double t1) noexcept {
  env_local_.clear();
  for (const Projected& P : env_all_) {
    if (P.x1 < s0 || P.x0 > s1 || P.y1 < t0 || P.y0 > t1) continue;
    env_local_.push_back(P);
  }
}

void DepthRefiner::GatherTool(std::span<const Projected> from, double s0, double s1, double t0,
                              double t1) noexcept {
  tool_local_.clear();
  for (const Projected& P : from) {
    if (P.x1 < s0 || P.x0 > s1 || P.y1 < t0 || P.y0 > t1) continue;
    tool_local_.push_back(P);
  }
}

void DepthRefiner::MoveTool(const RigidTransform& X_WT) noexcept {
  tool_moved_.clear();
  Projected P;
  for (const Projected& L : tool_local_) {
    if (!ProjectTriangle(*tool_, X_WT, window_, L.face, PatchSide::kTool, P, options_.parallax)) {
      continue;
    }
    P.face = L.face;
    tool_moved_.push_back(P);
  }
}

double DepthRefiner::Difference(std::span<const Projected> tool, double s, double t, double shift_s,
                                double shift_t) noexcept {
  ++evaluations_;
  const double range = window_.depth_range_m();
  const int it = options_.parallax_iterations;
  const double b = HeightOver(env_local_, env_->texture, true, range, s, t, 0, 0.0, it);
  if (!(b > -kInf)) return -kInf;
  const double a =
      HeightOver(tool, tool_->texture, false, range, s - shift_s, t - shift_t, 0, 0.0, it);
  if (!(a < kInf)) return -kInf;
  return b - a;
}

DepthRefiner::Seed DepthRefiner::Search(std::span<const Projected> tool, const Box& box, double s,
                                        double t, double half_side, int subsamples, double step,
                                        double floor_m, double shift_s, double shift_t) noexcept {
  Seed best{-kInf, s, t};
  const auto inside = [&](double ss, double tt) {
    return ss >= box.s0 && ss <= box.s1 && tt >= box.t0 && tt <= box.t1;
  };
  const auto consider = [&](double ss, double tt) {
    if (!inside(ss, tt)) return false;
    const double d = Difference(tool, ss, tt, shift_s, shift_t);
    if (d > best.depth_m) {
      best = {d, ss, tt};
      return true;
    }
    return false;
  };
  // The four neighbours along u and v.
  static constexpr std::array<std::array<int, 2>, 4> kDirections{
      {{1, 0}, {-1, 0}, {0, 1}, {0, -1}}};
  if (subsamples <= 1) {
    // A start just off the surface (a rendered cell's centre a few micrometres past the edge of
    // a face whose displaced surface, with parallax, ends inside it) reads nothing: its four
    // neighbours at the pattern's steps are tried, nearest first, until one reads a depth.
    if (!consider(s, t)) {
      for (double probe = std::max(floor_m, step / 64.0);
           probe > 0.0 && probe <= step && !(best.depth_m > -kInf); probe *= 2.0) {
        for (const auto& d : kDirections) {
          consider(s + d[0] * probe, t + d[1] * probe);
        }
      }
    }
  } else {
    const double spacing = 2.0 * half_side / subsamples;
    for (int j = 0; j < subsamples; ++j) {
      for (int i = 0; i < subsamples; ++i) {
        consider(s - half_side + (i + 0.5) * spacing, t - half_side + (j + 0.5) * spacing);
      }
    }
  }
  if (!(best.depth_m > -kInf)) return best;
  // Pattern search over the four neighbours along u and v at `step`, halved when none is
  // better.
  // First improvement: the direction that last improved is tried first, and the search moves
  // as soon as a neighbour is better.
  int moves = 0, last = 0;
  while (step >= floor_m && moves < 64) {
    const Seed from = best;
    bool moved = false;
    for (int k = 0; k < 4 && !moved; ++k) {
      const int d = (last + k) % 4;
      if (consider(from.s + kDirections[d][0] * step, from.t + kDirections[d][1] * step)) {
        moved = true;
        last = d;
      }
    }
    if (moved) {
      ++moves;
    } else {
      step *= 0.5;
    }
  }
  return best;
}

double DepthRefiner::ClimbBoth(std::span<const Projected> tool, const Box& box, double s, double t,
                               double moved_s, double moved_t, double step, double floor_m,
                               double shift_s, double shift_t) noexcept {
  const Seed at_point = Search(tool, box, s, t, 0.0, 1, step, floor_m, shift_s, shift_t);
  const Seed at_moved =
      Search(tool, box, moved_s, moved_t, 0.0, 1, step, floor_m, shift_s, shift_t);
  return std::max(at_point.depth_m, at_moved.depth_m);
}

double DepthRefiner::ScreenThreshold(double best_m) const noexcept {
  return std::max(best_m, options_.screen_floor_m) + options_.screen_tolerance_m;
}

double DepthRefiner::SideBound(std::span<const Projected> all, std::span<const int> list,
                               const HeightField& texture, bool environment,
                               const Box& square) const noexcept {
  const double range = window_.depth_range_m();
  double bound = environment ? -kInf : kInf;
  for (const int i : list) {
    const Projected& P = all[static_cast<std::size_t>(i)];
    // The part of the square the triangle's box covers (ValueAt's 1e-12 margin).
    const double s0 = std::max(square.s0, P.x0 - 1e-12), s1 = std::min(square.s1, P.x1 + 1e-12);
    const double t0 = std::max(square.t0, P.y0 - 1e-12), t1 = std::min(square.t1, P.y1 + 1e-12);
    if (s0 > s1 || t0 > t1) continue;
    // The coarse height and the texture coordinates are linear on the triangle: over its part
    // inside the rectangle (the triangle clipped by the rectangle's four sides, at most seven
    // corners) their extremes are at that polygon's corners.
    std::array<double, 2 * 9> poly{}, next{};
    int count = 3;
    for (int c = 0; c < 3; ++c) {
      poly[static_cast<std::size_t>(2 * c)] = P.x[c];
      poly[static_cast<std::size_t>(2 * c + 1)] = P.y[c];
    }
    // Keep the side of axis `axis` (0: s, 1: t) where sign·(coordinate − limit) ≤ 0.
    const auto clip = [&](int axis, double limit, double sign) {
      int out = 0;
      for (int k = 0; k < count; ++k) {
        const double* a = &poly[static_cast<std::size_t>(2 * k)];
        const double* b = &poly[static_cast<std::size_t>(2 * ((k + 1) % count))];
        const double fa = sign * (a[axis] - limit), fb = sign * (b[axis] - limit);
        if (fa <= 0.0) {
          next[static_cast<std::size_t>(2 * out)] = a[0];
          next[static_cast<std::size_t>(2 * out + 1)] = a[1];
          ++out;
        }
        if ((fa < 0.0 && fb > 0.0) || (fa > 0.0 && fb < 0.0)) {
          const double r = fa / (fa - fb);
          next[static_cast<std::size_t>(2 * out)] = a[0] + r * (b[0] - a[0]);
          next[static_cast<std::size_t>(2 * out + 1)] = a[1] + r * (b[1] - a[1]);
          // The crossing lies on the limit exactly (not a rounding away from it).
          next[static_cast<std::size_t>(2 * out + axis)] = limit;
          ++out;
        }
      }
      count = out;
      poly = next;
    };
    clip(0, s1, 1.0);
    if (count > 0) clip(0, s0, -1.0);
    if (count > 0) clip(1, t1, 1.0);
    if (count > 0) clip(1, t0, -1.0);
    if (count == 0) continue;
    double d_lo = kInf, d_hi = -kInf, u_lo = kInf, u_hi = -kInf, v_lo = kInf, v_hi = -kInf;
    for (int c = 0; c < count; ++c) {
      double b0, b1, b2;
      Barycentric(P, poly[static_cast<std::size_t>(2 * c)],
                  poly[static_cast<std::size_t>(2 * c + 1)], b0, b1, b2);
      const double d = b0 * P.d[0] + b1 * P.d[1] + b2 * P.d[2];
      d_lo = std::min(d_lo, d);
      d_hi = std::max(d_hi, d);
      if (P.textured) {
        const double u = b0 * P.tu[0] + b1 * P.tu[1] + b2 * P.tu[2];
        const double v = b0 * P.tv[0] + b1 * P.tv[1] + b2 * P.tv[2];
        u_lo = std::min(u_lo, u);
        u_hi = std::max(u_hi, u);
        v_lo = std::min(v_lo, v);
        v_hi = std::max(v_hi, v);
      }
    }
    // Rounding of the clipped corners: a relative allowance on the heights.
    const double slack = 1e-9 * (std::abs(d_lo) + std::abs(d_hi)) + 1e-12;
    d_lo -= slack;
    d_hi += slack;
    double lo = d_lo, hi = d_hi;
    if (P.textured) {
      // Inside the triangle the coordinates stay within its corners' box.
      u_lo = std::max(u_lo, static_cast<double>(std::min({P.tu[0], P.tu[1], P.tu[2]})));
      u_hi = std::min(u_hi, static_cast<double>(std::max({P.tu[0], P.tu[1], P.tu[2]})));
      v_lo = std::max(v_lo, static_cast<double>(std::min({P.tv[0], P.tv[1], P.tv[2]})));
      v_hi = std::min(v_hi, static_cast<double>(std::max({P.tv[0], P.tv[1], P.tv[2]})));
      float h_lo = 0.0f, h_hi = 0.0f;
      texture.RangeOver(static_cast<float>(std::min(u_lo, u_hi)),
                        static_cast<float>(std::min(v_lo, v_hi)),
                        static_cast<float>(std::max(u_lo, u_hi)),
                        static_cast<float>(std::max(v_lo, v_hi)), h_lo, h_hi);
      double f_lo, f_hi;
      NormalFactorRange(P, f_lo, f_hi);
      const double products[4] = {h_lo * f_lo, h_lo * f_hi, h_hi * f_lo, h_hi * f_hi};
      lo += *std::min_element(products, products + 4);
      hi += *std::max_element(products, products + 4);
    }
    // Values outside the window's box are ignored (HeightOver).
    if (hi < -range || lo > range) continue;
    bound =
        environment ? std::max(bound, std::min(hi, range)) : std::min(bound, std::max(lo, -range));
  }
  return bound;
}

void DepthRefiner::ScreenSquare(const Box& square, int depth, Seed& best, int& leaves) noexcept {
  const std::vector<int>& env = env_screen_[static_cast<std::size_t>(depth)];
  const std::vector<int>& tool = tool_screen_[static_cast<std::size_t>(depth)];
  const double side = square.s1 - square.s0;
  // The finer level-0 texel over the square's triangles (TexelOfGathered's rule).
  double texel = kInf;
  for (const auto& [all, list] : {std::pair{&env_all_, &env}, std::pair{&tool_all_, &tool}}) {
    for (const int i : *list) {
      const Projected& P = (*all)[static_cast<std::size_t>(i)];
      if (P.textured && P.texel_m > 0.0) texel = std::min(texel, P.texel_m);
    }
  }
  if (!std::isfinite(texel)) texel = 0.25 * window_.cell_size_m();
  if (side <= 2.0 * texel || depth == kMaxScreenDepth) {
    // A leaf: the local search from a 2×2 sub-grid of the square, free to climb half a square
    // beyond it.
    if (leaves >= options_.max_screen_leaves) {
      truncated_ = true;
      return;
    }
    ++leaves;
    const double half = 0.5 * side;
    const Box box{square.s0 - half, square.s1 + half, square.t0 - half, square.t1 + half};
    const auto gather = [&](const std::vector<Projected>& all, const std::vector<int>& list,
                            std::vector<Projected>& out) {
      out.clear();
      for (const int i : list) {
        const Projected& P = all[static_cast<std::size_t>(i)];
        if (Overlaps(P, box.s0, box.s1, box.t0, box.t1)) out.push_back(P);
      }
    };
    gather(env_all_, env, env_local_);
    gather(tool_all_, tool, tool_local_);
    const Seed found =
        Search(tool_local_, box, 0.5 * (square.s0 + square.s1), 0.5 * (square.t0 + square.t1), half,
               2, 0.25 * side, options_.search_floor_texels * texel, 0.0, 0.0);
    if (found.depth_m > best.depth_m) best = found;
    return;
  }
  // Four children, the most promising first.
  const double sm = 0.5 * (square.s0 + square.s1), tm = 0.5 * (square.t0 + square.t1);
  std::array<Box, 4> child{Box{square.s0, sm, square.t0, tm}, Box{sm, square.s1, square.t0, tm},
                           Box{square.s0, sm, tm, square.t1}, Box{sm, square.s1, tm, square.t1}};
  std::array<double, 4> bound{};
  std::array<int, 4> order{0, 1, 2, 3};
  for (int c = 0; c < 4; ++c) {
    ++squares_;
    bound[static_cast<std::size_t>(c)] =
        SideBound(env_all_, env, env_->texture, true, child[static_cast<std::size_t>(c)]) -
        SideBound(tool_all_, tool, tool_->texture, false, child[static_cast<std::size_t>(c)]);
  }
  std::sort(order.begin(), order.end(), [&](int a, int b) {
    return bound[static_cast<std::size_t>(a)] > bound[static_cast<std::size_t>(b)];
  });
  for (const int c : order) {
    // NaN and −∞ (a side missing) never pass.
    if (!(bound[static_cast<std::size_t>(c)] > ScreenThreshold(best.depth_m))) continue;
    const Box& b = child[static_cast<std::size_t>(c)];
    const auto keep = [&](const std::vector<Projected>& all, const std::vector<int>& list,
                          std::vector<int>& out) {
      out.clear();
      for (const int i : list) {
        if (Overlaps(all[static_cast<std::size_t>(i)], b.s0, b.s1, b.t0, b.t1)) out.push_back(i);
      }
    };
    keep(env_all_, env, env_screen_[static_cast<std::size_t>(depth + 1)]);
    keep(tool_all_, tool, tool_screen_[static_cast<std::size_t>(depth + 1)]);
    ScreenSquare(b, depth + 1, best, leaves);
    if (truncated_) return;
  }
}

void DepthRefiner::Screen(Seed& best) noexcept {
  squares_ = 0;
  truncated_ = false;
  const double half = 0.5 * window_.extent_m;
  const Box root{-half, half, -half, half};
  std::vector<int>& env = env_screen_[0];
  std::vector<int>& tool = tool_screen_[0];
  env.clear();
  tool.clear();
  for (std::size_t i = 0; i < env_all_.size(); ++i) env.push_back(static_cast<int>(i));
  for (std::size_t i = 0; i < tool_all_.size(); ++i) tool.push_back(static_cast<int>(i));
  ++squares_;
  const double bound = SideBound(env_all_, env, env_->texture, true, root) -
                       SideBound(tool_all_, tool, tool_->texture, false, root);
  int leaves = 0;
  if (bound > ScreenThreshold(best.depth_m)) ScreenSquare(root, 0, best, leaves);
  counters_.screen_squares += squares_;
  counters_.screen_leaves += static_cast<std::uint64_t>(leaves);
  if (truncated_) counters_.screen_truncated += 1;
}

int DepthRefiner::SeedsNear(std::span<const Seed> base, int num_seeds, const Seed& deepest,
                            double reach, std::span<int> order) noexcept {
  const int n = std::min(num_seeds, static_cast<int>(order.size()));
  for (int k = 0; k < n; ++k) order[static_cast<std::size_t>(k)] = k;
  std::sort(order.begin(), order.begin() + n, [&](int a, int b) {
    return base[static_cast<std::size_t>(a)].depth_m > base[static_cast<std::size_t>(b)].depth_m;
  });
  int num_near = 0;
  while (num_near < std::min(n, 4) &&
         base[static_cast<std::size_t>(order[static_cast<std::size_t>(num_near)])].depth_m >=
             deepest.depth_m - 4.0 * reach) {
    ++num_near;
  }
  return num_near;
}

PenetrationGradient DepthRefiner::TexelScaleGradient(const RigidTransform& X_WT,
                                                     std::span<const Seed> base, int num_seeds,
                                                     const Seed& deepest,
                                                     const glm::dvec3& point_W) noexcept {
  const ContactWindow& w = window_;
  const double cell = w.cell_size_m();
  const glm::dvec3& u = w.axis_u_W;
  const glm::dvec3& v = w.axis_v_W;
  const glm::dvec3& n = w.normal_W;
  GatherEnvironment(deepest.s - cell, deepest.s + cell, deepest.t - cell, deepest.t + cell);
  GatherTool(tool_all_, deepest.s - cell, deepest.s + cell, deepest.t - cell, deepest.t + cell);
  const double texel = TexelOfGathered(tool_local_);
  const double h_x = options_.gradient_step_texels * texel;
  const double h_theta = h_x / (0.5 * w.gradient_lever_extent_m());
  const double reach = h_x + h_theta * glm::length(point_W - X_WT.translation);
  const double floor_m = options_.search_floor_texels * texel;
  // The base seeds within reach of the deepest (a small step cannot bring a far, lower peak
  // above it), deepest first, at most four.
  std::array<int, kBaseSeedSamples> order{};
  const int num_near = SeedsNear(base, num_seeds, deepest, reach, order);
  const auto poses = GradientSamplePoses(X_WT, w, {h_x, h_theta});
  std::array<double, 10> displaced{};
  displaced.fill(-kInf);
  for (int m = 0; m < num_near; ++m) {
    const Seed& sd = base[static_cast<std::size_t>(order[static_cast<std::size_t>(m)])];
    const double margin = reach + 4.0 * texel;
    const Box box{sd.s - margin, sd.s + margin, sd.t - margin, sd.t + margin};
    GatherEnvironment(box.s0, box.s1, box.t0, box.t1);
    GatherTool(tool_all_, box.s0 - reach, box.s1 + reach, box.t0 - reach, box.t1 + reach);
    // Sample k + 1 of the table: ±u, ±v, ±θu, ±θv, ±θn (the translations alone where the rotation
    // part is the secant's: DepthRefinementOptions::texel_scale_rotation).
    const int displacements = options_.texel_scale_rotation ? 10 : 4;
    for (int k = 0; k < displacements; ++k) {
      const int axis = k / 2;
      const double sign = (k % 2 == 0) ? 1.0 : -1.0;
      double shift_s = 0.0, shift_t = 0.0;
      std::span<const Projected> tool_tris = tool_local_;
      // The maximum may stay with the environment's feature (the seed's point) or move with the
      // tool's (the seed's point carried by the displacement: where a tool edge bounds it, the
      // seed's own point may have left the tool's support): both starts are climbed.
      double moved_s = sd.s, moved_t = sd.t;
      if (axis == 0) {
        shift_s = sign * h_x;
        moved_s += shift_s;
      } else if (axis == 1) {
        shift_t = sign * h_x;
        moved_t += shift_t;
      } else {
        const RigidTransform& X = poses[static_cast<std::size_t>(k + 1)];
        MoveTool(X);
        tool_tris = tool_moved_;
        const glm::dvec3 p_W = w.center_W + sd.s * u + sd.t * v;
        const glm::dvec3 moved_W = X * (X_WT.Inverse() * p_W) - w.center_W;
        moved_s = glm::dot(moved_W, u);
        moved_t = glm::dot(moved_W, v);
      }
      double& d = displaced[static_cast<std::size_t>(k)];
      d = std::max(d, ClimbBoth(tool_tris, box, sd.s, sd.t, moved_s, moved_t, texel, floor_m,
                                shift_s, shift_t));
    }
  }
  // Central differences, one-sided where a displaced pose found no overlap.
  const auto central = [&](int axis, double step) {
    const double plus = displaced[static_cast<std::size_t>(2 * axis)];
    const double minus = displaced[static_cast<std::size_t>(2 * axis + 1)];
    if (plus > -kInf && minus > -kInf) return (plus - minus) / (2.0 * step);
    if (plus > -kInf) return (plus - deepest.depth_m) / step;
    if (minus > -kInf) return (deepest.depth_m - minus) / step;
    return 0.0;
  };
  PenetrationGradient g;
  g.d_translation_W = central(0, h_x) * u + central(1, h_x) * v - n;
  g.d_rotation_W = central(2, h_theta) * u + central(3, h_theta) * v + central(4, h_theta) * n;
  return g;
}

int DepthRefiner::TranslationKinkPlanes(std::span<const Seed> found, const Seed& deepest,
                                        double h_x, ContactLinearization& lin) noexcept {
  const ContactWindow& w = window_;
  const glm::dvec3 axes[2] = {w.axis_u_W, w.axis_v_W};
  int added = 0;
  for (int a = 0; a < 2; ++a) {
    const double slope = glm::dot(lin.gradient.d_translation_W, axes[a]);
    for (int side = 0; side < 2 && lin.num_kink_planes < kMaxKinkPlanes; ++side) {
      const Seed& f = found[static_cast<std::size_t>(2 * a + side)];
      const double sign = side == 0 ? 1.0 : -1.0;
      if (!(f.depth_m > -kInf)) continue;
      const double above = f.depth_m - (deepest.depth_m + sign * slope * h_x);
      if (!(above > options_.translation_kink_tolerance_m)) continue;
      // The arm's slope: the refined maximum's central difference at ±h_x ± h_t, climbed from the
      // sample's refined point and from that point carried by the extra shift.
      const double shift = sign * h_x;
      GatherEnvironment(f.s - h_x, f.s + h_x, f.t - h_x, f.t + h_x);
      GatherTool(tool_all_, f.s - 2.0 * h_x, f.s + 2.0 * h_x, f.t - 2.0 * h_x, f.t + 2.0 * h_x);
      const double texel = TexelOfGathered(tool_local_);
      const double h_t = options_.gradient_step_texels * texel;
      const double margin = h_t + 4.0 * texel;
      const Box box{f.s - margin, f.s + margin, f.t - margin, f.t + margin};
      GatherEnvironment(box.s0, box.s1, box.t0, box.t1);
      const double reach = std::abs(shift) + h_t;
      GatherTool(tool_all_, box.s0 - reach, box.s1 + reach, box.t0 - reach, box.t1 + reach);
      const double floor_m = options_.search_floor_texels * texel;
      double at[2] = {-kInf, -kInf};  // at shift + h_t, shift − h_t
      for (int e = 0; e < 2; ++e) {
        const double extra = e == 0 ? h_t : -h_t;
        const double shift_s = a == 0 ? shift + extra : 0.0;
        const double shift_t = a == 1 ? shift + extra : 0.0;
        const double moved_s = f.s + (a == 0 ? extra : 0.0);
        const double moved_t = f.t + (a == 1 ? extra : 0.0);
        const Seed at_point =
            Search(tool_local_, box, f.s, f.t, 0.0, 1, texel, floor_m, shift_s, shift_t);
        const Seed at_moved =
            Search(tool_local_, box, moved_s, moved_t, 0.0, 1, texel, floor_m, shift_s, shift_t);
        at[e] = std::max(at_point.depth_m, at_moved.depth_m);
      }
      double arm = 0.0;
      if (at[0] > -kInf && at[1] > -kInf) {
        arm = (at[0] - at[1]) / (2.0 * h_t);
      } else if (at[0] > -kInf) {
        arm = (at[0] - f.depth_m) / h_t;
      } else if (at[1] > -kInf) {
        arm = (f.depth_m - at[1]) / h_t;
      } else {
        continue;
      }
      // Convex across the cell: the arm on the + side rises faster than the contact's plane, the
      // arm on the − side falls faster (seen going +a).
      if (!(sign * (arm - slope) > 0.0) || !std::isfinite(arm)) continue;
      KinkPlane p;
      p.depth_m = std::min(f.depth_m - shift * arm, lin.depth_m);
      p.d_rotation_W = lin.gradient.d_rotation_W;
      p.d_translation_offset_W = (arm - slope) * axes[a];
      if (!std::isfinite(p.depth_m)) continue;
      lin.kink_planes[static_cast<std::size_t>(lin.num_kink_planes++)] = p;
      ++added;
    }
  }
  counters_.translation_kink_planes += static_cast<std::uint64_t>(added);
  return added;
}

void DepthRefiner::FillTranslationPatch(const RigidTransform& X_WT, const Seed& deepest,
                                        std::span<const Seed> found, double cell_step,
                                        ContactLinearization& lin) noexcept {
  constexpr int R = kTranslationPatchRadius;
  constexpr int S = kTranslationPatchSide;
  const int m = options_.translation_patch_spacing_cells;
  const double h = m * cell_step;  // the nodes' spacing
  const int grow = R * m;          // cells the tool's render is grown by
  const ContactWindow& w = window_;
  TranslationPatch& patch = lin.patch;
  patch = TranslationPatch{};
  patch.step_m = h;
  patch.axis_u_W = w.axis_u_W;
  patch.axis_v_W = w.axis_v_W;
  const double slope_u = glm::dot(lin.gradient.d_translation_W, w.axis_u_W);
  const double slope_v = glm::dot(lin.gradient.d_translation_W, w.axis_v_W);
  // The window's grid at the base pose, the tool's grown by R·m cells: node (i, j), the tool moved
  // by (i·m, j·m) cells, is the tool's render read (−i·m, −j·m) cells over (as the four rendered
  // translation samples are), so each node's deepest cell is found over the whole window.
  const int n = w.resolution, nt = n + 2 * grow;
  patch_env_heights_.assign(static_cast<std::size_t>(n) * n, -kInf32);
  patch_tool_heights_.assign(static_cast<std::size_t>(nt) * nt, kInf32);
  RenderPatchHeightsFast(*env_, X_WO_, env_list_, w, PatchSide::kEnvironment, 0,
                         patch_env_heights_);
  RenderPatchHeightsFast(*tool_, X_WT, tool_list_, w, PatchSide::kTool, grow, patch_tool_heights_);
  std::array<Seed, static_cast<std::size_t>(S * S)> at{};
  at.fill(Seed{-kInf, 0.0, 0.0});
  const auto index = [](int i, int j) { return static_cast<std::size_t>((j + R) * S + (i + R)); };
  at[index(0, 0)] = deepest;
  // The rendered samples one cell away (1: +u, 2: −u, 3: +v, 4: −v), already refined: the nodes
  // one step away when the spacing is one cell.
  const std::array<std::array<int, 2>, 4> rendered{{{1, 0}, {-1, 0}, {0, 1}, {0, -1}}};
  if (m == 1) {
    for (std::size_t k = 0; k < rendered.size() && k < found.size(); ++k) {
      at[index(rendered[k][0], rendered[k][1])] = found[k];
    }
  }
  const double cell = w.cell_size_m();
  // Ring by ring, so that each node's neighbour towards q0 is done first.
  for (int ring = 1; ring <= R; ++ring) {
    for (int j = -ring; j <= ring; ++j) {
      for (int i = -ring; i <= ring; ++i) {
        if (std::max(std::abs(i), std::abs(j)) != ring) continue;
        Seed& node = at[index(i, j)];
        if (node.depth_m > -kInf) continue;  // a refined rendered sample
        const double shift_s = i * h, shift_t = j * h;
        // A pattern search from (s, t) over a square of half side `half` (sub-sampled on the
        // grid's cell when `subgrid`).
        const auto climb = [&](double s, double t, double half, bool subgrid) {
          const Box box{s - half - cell, s + half + cell, t - half - cell, t + half + cell};
          GatherEnvironment(box.s0, box.s1, box.t0, box.t1);
          GatherTool(tool_all_, box.s0 - shift_s, box.s1 - shift_s, box.t0 - shift_t,
                     box.t1 - shift_t);
          if (env_local_.empty() || tool_local_.empty()) return;
          const double texel = TexelOfGathered(tool_local_);
          const double floor_m = (options_.translation_patch_floor_texels > 0.0
                                      ? options_.translation_patch_floor_texels
                                      : options_.search_floor_texels) *
                                 texel;
          const int g =
              subgrid
                  ? std::clamp(static_cast<int>(std::ceil(2.0 * half / (kSubsampleTexels * texel))),
                               1, options_.max_subsamples)
                  : 1;
          const Seed r = Search(tool_local_, box, s, t, half, g, 0.5 * (2.0 * half / g), floor_m,
                                shift_s, shift_t);
          if (r.depth_m > node.depth_m) node = r;
        };
        const DepthSample grid = DirectionalPenetrationDepthShifted(
            patch_env_heights_, n, patch_tool_heights_, grow, -i * m, -j * m);
        if (grid.cell >= 0) {
          double s = 0.0, t = 0.0;
          CellCoordinates(w, grid.cell, s, t);
          climb(s, t, 0.75 * cell, options_.subgrid_translations);
        }
        // The neighbour one step nearer q0: its maximum carried by that step (a tool feature).
        const int ni = i - (i > 0) + (i < 0), nj = j - (j > 0) + (j < 0);
        const Seed& near = at[index(ni, nj)];
        if (options_.translation_patch_neighbour_climbs && near.depth_m > -kInf) {
          climb(near.s + (i - ni) * h, near.t + (j - nj) * h, 0.25 * h, false);
          climb(near.s, near.t, 0.25 * h, false);
        }
      }
    }
  }
  for (int j = -R; j <= R; ++j) {
    for (int i = -R; i <= R; ++i) {
      const Seed& node = at[index(i, j)];
      const double value = (node.depth_m > -kInf && std::isfinite(node.depth_m))
                               ? node.depth_m - deepest.depth_m
                               : (slope_u * i + slope_v * j) * h;
      patch.depth_m[index(i, j)] = static_cast<float>(value);
    }
  }
  patch.depth_m[index(0, 0)] = 0.0f;
  if (options_.translation_patch_follows_rotation) {
    patch.lever_W = w.center_W + deepest.s * w.axis_u_W + deepest.t * w.axis_v_W - X_WT.translation;
  }
}

void DepthRefiner::FillTexelTranslationPatch(std::span<const Seed> base, int num_seeds,
                                             std::span<const Seed> found, const Seed& deepest,
                                             ContactLinearization& lin) noexcept {
  constexpr int R = kTranslationPatchRadius;
  constexpr int S = kTranslationPatchSide;
  const ContactWindow& w = window_;
  const double cell = w.cell_size_m();
  GatherEnvironment(deepest.s - cell, deepest.s + cell, deepest.t - cell, deepest.t + cell);
  GatherTool(tool_all_, deepest.s - cell, deepest.s + cell, deepest.t - cell, deepest.t + cell);
  const double texel = TexelOfGathered(tool_local_);
  const double h = options_.translation_patch_step_texels * texel;
  const double reach = R * h;
  const double floor_m = options_.search_floor_texels * texel;
  TranslationPatch& patch = lin.patch;
  patch = TranslationPatch{};
  patch.step_m = h;
  patch.axis_u_W = w.axis_u_W;
  patch.axis_v_W = w.axis_v_W;
  // The base seeds within reach of the deepest, deepest first, at most four (as
  // TexelScaleGradient).
  std::array<int, kBaseSeedSamples> order{};
  const int num_near = SeedsNear(base, num_seeds, deepest, reach, order);
  std::array<double, static_cast<std::size_t>(S * S)> node{};
  node.fill(-kInf);
  const auto index = [](int i, int j) { return static_cast<std::size_t>((j + R) * S + (i + R)); };
  // Every node climbed from a start `f` (ClimbBoth: from its point and from its point carried by
  // the node's shift).
  const auto climb_from = [&](const Seed& f) {
    if (!(f.depth_m > -kInf)) return;
    const double margin = reach + 4.0 * texel;
    const Box box{f.s - margin, f.s + margin, f.t - margin, f.t + margin};
    GatherEnvironment(box.s0, box.s1, box.t0, box.t1);
    GatherTool(tool_all_, box.s0 - reach, box.s1 + reach, box.t0 - reach, box.t1 + reach);
    for (int j = -R; j <= R; ++j) {
      for (int i = -R; i <= R; ++i) {
        if (i == 0 && j == 0) continue;
        const double shift_s = i * h, shift_t = j * h;
        double& d = node[index(i, j)];
        d = std::max(d, ClimbBoth(tool_local_, box, f.s, f.t, f.s + shift_s, f.t + shift_t, texel,
                                  floor_m, shift_s, shift_t));
      }
    }
  };
  // The starts: the base seeds within reach, and, since a peak that a shift brings above the
  // deepest one (the other flank across a trough, whose V the patch is for) need not be among
  // them (their cells lie next to the deepest's or on it), the neighbouring peaks
  // (neighbour_peak_seeds) and the refined rendered translation samples' maxima (±1 cell along u
  // and v).
  for (int m = 0; m < num_near; ++m) {
    climb_from(base[static_cast<std::size_t>(order[static_cast<std::size_t>(m)])]);
  }
  for (int k = 0; k < num_neighbour_peaks_; ++k) {
    climb_from(neighbour_peaks_[static_cast<std::size_t>(k)]);
  }
  for (const Seed& f : found) climb_from(f);
  const double slope_u = glm::dot(lin.gradient.d_translation_W, w.axis_u_W);
  const double slope_v = glm::dot(lin.gradient.d_translation_W, w.axis_v_W);
  for (int j = -R; j <= R; ++j) {
    for (int i = -R; i <= R; ++i) {
      const double d = node[index(i, j)];
      const double value =
          (d > -kInf && std::isfinite(d)) ? d - deepest.depth_m : (slope_u * i + slope_v * j) * h;
      patch.depth_m[index(i, j)] = static_cast<float>(value);
    }
  }
  patch.depth_m[index(0, 0)] = 0.0f;
}

double DepthRefiner::TexelOfGathered(std::span<const Projected> tool_tris) const noexcept {
  double texel = kInf;
  for (const Projected& P : env_local_) {
    if (P.textured && P.texel_m > 0.0) texel = std::min(texel, P.texel_m);
  }
  for (const Projected& P : tool_tris) {
    if (P.textured && P.texel_m > 0.0) texel = std::min(texel, P.texel_m);
  }
  return std::isfinite(texel) ? texel : 0.25 * window_.cell_size_m();
}

bool DepthRefiner::Refine(const HapticModel& tool, const RigidTransform& X_WT,
                          const ContactQuery& query, std::span<DepthSample> samples,
                          ContactLinearization& lin) noexcept {
  if (samples.size() < static_cast<std::size_t>(kGradientSamples) || samples[0].cell < 0 ||
      query.environment == nullptr) {
    return false;
  }
  env_ = query.environment;
  tool_ = &tool;
  X_WO_ = query.X_WO;
  window_ = query.window;
  const ContactWindow& w = window_;
  const double cell = w.cell_size_m();
  const GradientSteps big = GradientSteps::For(w);
  evaluations_ = 0;
  SelectPatchTrianglesIn(query.environment_triangles, *env_, X_WO_, w, PatchSide::kEnvironment,
                         cell, env_list_, 0.0, &vertex_scratch_, trees_.For(*env_));
  SelectPatchTrianglesIn(query.tool_triangles, tool, X_WT, w, PatchSide::kTool, 2.0 * big.h_x,
                         tool_list_, big.h_theta + 1e-9, &vertex_scratch_, trees_.For(tool),
                         big.h_theta);
  ProjectAll(*env_, X_WO_, PatchSide::kEnvironment, env_list_, env_all_);
  ProjectAll(tool, X_WT, PatchSide::kTool, tool_list_, tool_all_);

  // A search from the window point (s, t) (m) within the 1.75-cell square around it, the tool at
  // X (shifted in-plane by (shift_s, shift_t) where X is the base pose): a sub-grid over its
  // 1.5-cell square first with `subgrid`, else a pattern search from the point alone.
  const auto refine_at = [&](double s, double t, std::span<const Projected> tool_at, double shift_s,
                             double shift_t, bool subgrid) -> Seed {
    const double half = 0.75 * cell;
    const Box box{s - half - cell, s + half + cell, t - half - cell, t + half + cell};
    GatherEnvironment(box.s0, box.s1, box.t0, box.t1);
    GatherTool(tool_at, box.s0 - shift_s, box.s1 - shift_s, box.t0 - shift_t, box.t1 - shift_t);
    const double texel = TexelOfGathered(tool_local_);
    const double floor_m = options_.search_floor_texels * texel;
    if (!subgrid)
      return Search(tool_local_, box, s, t, half, 1, 0.5 * half, floor_m, shift_s, shift_t);
    const int g = std::clamp(static_cast<int>(std::ceil(2.0 * half / (kSubsampleTexels * texel))),
                             1, options_.max_subsamples);
    return Search(tool_local_, box, s, t, half, g, 0.5 * (2.0 * half / g), floor_m, shift_s,
                  shift_t);
  };
  // One rendered sample's deepest cell refined at a pose.
  const auto refine_cell = [&](int cell_index, std::span<const Projected> tool_at, double shift_s,
                               double shift_t, bool subgrid) -> Seed {
    double s = 0.0, t = 0.0;
    CellCoordinates(w, cell_index, s, t);
    return refine_at(s, t, tool_at, shift_s, shift_t, subgrid);
  };

  // The base: every distinct deepest cell of the samples is a seed.
  std::array<int, kBaseSeedSamples> seed_cells{};
  int num_seeds = 0;
  for (int k = 0; k < kBaseSeedSamples; ++k) {
    const int c = samples[static_cast<std::size_t>(k)].cell;
    if (c < 0 || c >= w.resolution * w.resolution) continue;
    // A cell next to a seed is mostly within that seed's square (1.5 cells) and its climb.
    const int n = w.resolution;
    if (std::any_of(seed_cells.begin(), seed_cells.begin() + num_seeds, [&](int o) {
          return std::abs(o % n - c % n) <= 1 && std::abs(o / n - c / n) <= 1;
        })) {
      continue;
    }
    seed_cells[static_cast<std::size_t>(num_seeds++)] = c;
  }
  std::array<Seed, kBaseSeedSamples> base{};
  int best = -1;
  for (int k = 0; k < num_seeds; ++k) {
    base[static_cast<std::size_t>(k)] = refine_cell(seed_cells[k], tool_all_, 0.0, 0.0, true);
    if (best < 0 || base[k].depth_m > base[static_cast<std::size_t>(best)].depth_m) best = k;
  }
  Seed deepest = best >= 0 ? base[static_cast<std::size_t>(best)] : Seed{-kInf, 0.0, 0.0};
  // A deeper point found away from the grid's seeds (the screen, the last step) becomes deepest
  // and one of the base seeds (TexelScaleGradient's), and the displaced samples are searched
  // from it too. Returns how much deeper (µm, rounded; 0 when the seeds found nothing).
  bool deeper_away_from_seeds = false;
  const auto take_deeper = [&](const Seed& found) -> std::uint64_t {
    const std::uint64_t raised =
        deepest.depth_m > -kInf
            ? static_cast<std::uint64_t>(std::llround((found.depth_m - deepest.depth_m) * 1e6))
            : 0;
    deepest = found;
    deeper_away_from_seeds = true;
    if (num_seeds < kBaseSeedSamples) {
      base[static_cast<std::size_t>(num_seeds++)] = deepest;
    } else {
      base[static_cast<std::size_t>(best)] = deepest;
    }
    return raised;
  };
  // The grid's seeds carried by parallax (parallax_offset_seeds): where each side's envelope
  // reads its surface point, more than half a cell away.
  if (options_.parallax && options_.parallax_offset_seeds) {
    const double half_extent = 0.5 * w.extent_m, range = w.depth_range_m();
    const int grid_seeds = num_seeds;
    for (int k = 0; k < grid_seeds; ++k) {
      double s = 0.0, t = 0.0;
      CellCoordinates(w, seed_cells[static_cast<std::size_t>(k)], s, t);
      for (const bool environment : {true, false}) {
        double ds = 0.0, dt = 0.0;
        if (!ParallaxOffset(environment ? std::span<const Projected>(env_all_)
                                        : std::span<const Projected>(tool_all_),
                            environment ? env_->texture : tool.texture, environment, range, s, t,
                            ds, dt)) {
          continue;
        }
        if (ds * ds + dt * dt < 0.25 * cell * cell) continue;
        const double cs = std::clamp(s + ds, -half_extent, half_extent),
                     ct = std::clamp(t + dt, -half_extent, half_extent);
        ++counters_.parallax_offset_seeds;
        const Seed found = refine_at(cs, ct, tool_all_, 0.0, 0.0, true);
        if (!(found.depth_m > deepest.depth_m)) continue;
        ++counters_.parallax_offset_found;
        counters_.parallax_offset_raised_um += take_deeper(found);
      }
    }
  }
  // The conservative screen: wherever b − a can still beat the seeds' best.
  if (options_.conservative_screen) {
    Seed screened = deepest;
    Screen(screened);
    if (screened.depth_m > deepest.depth_m) {
      counters_.screen_found += 1;
      counters_.screen_raised_um += take_deeper(screened);
    }
  }
  // The last step's deepest points within this window (seed_from_last_step), each searched by a
  // pattern search from the point (it was a refined maximum one step ago: no sub-grid).
  if (options_.seed_from_last_step) {
    const double half_extent = 0.5 * w.extent_m;
    for (int k = 0; k < num_last_; ++k) {
      const LastStepPoint& last = last_[static_cast<std::size_t>(k)];
      if (last.environment != env_) continue;
      const glm::dvec3 r = X_WT * last.p_T - w.center_W;
      const double s = glm::dot(r, w.axis_u_W), t = glm::dot(r, w.axis_v_W);
      if (!(std::abs(s) <= half_extent && std::abs(t) <= half_extent)) continue;
      ++counters_.last_step_seeds;
      const Seed found = refine_at(s, t, tool_all_, 0.0, 0.0, false);
      if (!(found.depth_m > deepest.depth_m)) continue;
      ++counters_.last_step_found;
      counters_.last_step_raised_um += take_deeper(found);
    }
  }
  // The neighbouring peaks (neighbour_peak_seeds): climbs from half a cell and a cell from the
  // deepest along ±u and ±v, where the other flank across a trough lies (its cell is next to
  // the deepest's, and so never a seed of its own).
  num_neighbour_peaks_ = 0;
  if (options_.neighbour_peak_seeds && deepest.depth_m > -kInf) {
    const double half_extent = 0.5 * w.extent_m;
    const Seed from = deepest;
    static constexpr std::array<std::array<int, 2>, 4> kAxes{{{1, 0}, {-1, 0}, {0, 1}, {0, -1}}};
    for (const auto& a : kAxes) {
      for (const double along : {0.5 * cell, cell}) {
        const double s = std::clamp(from.s + a[0] * along, -half_extent, half_extent);
        const double t = std::clamp(from.t + a[1] * along, -half_extent, half_extent);
        const Box box{s - cell, s + cell, t - cell, t + cell};
        GatherEnvironment(box.s0, box.s1, box.t0, box.t1);
        GatherTool(tool_all_, box.s0, box.s1, box.t0, box.t1);
        const double texel = TexelOfGathered(tool_local_);
        const Seed found = Search(tool_local_, box, s, t, 0.0, 1, 2.0 * texel,
                                  options_.search_floor_texels * texel, 0.0, 0.0);
        ++counters_.neighbour_peak_seeds;
        if (!(found.depth_m > -kInf)) continue;
        // Distinct from the deepest and from the peaks kept (two texels apart).
        const auto near = [&](const Seed& o) {
          return std::hypot(o.s - found.s, o.t - found.t) < 2.0 * texel;
        };
        bool seen = near(from);
        for (int k = 0; k < num_neighbour_peaks_ && !seen; ++k) {
          seen = near(neighbour_peaks_[static_cast<std::size_t>(k)]);
        }
        if (seen) continue;
        if (num_neighbour_peaks_ < kMaxNeighbourPeaks) {
          neighbour_peaks_[static_cast<std::size_t>(num_neighbour_peaks_++)] = found;
        }
        if (found.depth_m > deepest.depth_m) {
          ++counters_.neighbour_peak_found;
          counters_.neighbour_peak_raised_um += take_deeper(found);
        }
      }
    }
  }
  if (!(deepest.depth_m > -kInf)) {
    counters_.evaluations += evaluations_;
    return false;
  }

  const glm::dvec3 point_W = w.center_W + deepest.s * w.axis_u_W + deepest.t * w.axis_v_W;
  if (options_.texel_scale_gradient) {
    lin.gradient = TexelScaleGradient(X_WT, base, num_seeds, deepest, point_W);
  }

  // The rendered displaced samples, each from its own deepest cell at its own pose.
  std::array<Seed, 4> translation_found{};
  translation_found.fill(Seed{-kInf, 0.0, 0.0});
  if (options_.refine_rendered_samples || !options_.texel_scale_gradient ||
      !options_.texel_scale_rotation) {
    const auto poses = GradientSamplePoses(X_WT, w);
    for (int k = 1; k < kGradientSamples; ++k) {
      DepthSample& sample = samples[static_cast<std::size_t>(k)];
      if (sample.cell < 0) continue;
      if (k > 4) {
        ProjectAll(tool, poses[static_cast<std::size_t>(k)], PatchSide::kTool, tool_list_,
                   tool_pose_all_);
      }
      // The sample refined from one cell: ±h_x along u (1, 2) and v (3, 4) are the base pose
      // shifted, the rotations (5…10) the tool at their pose.
      const auto refine_from = [&](int cell_index) {
        if (k > 4) {
          return refine_cell(cell_index, tool_pose_all_, 0.0, 0.0, options_.subgrid_rotations);
        }
        const double sign = (k % 2 == 1) ? 1.0 : -1.0;
        return refine_cell(cell_index, tool_all_, k <= 2 ? sign * big.h_x : 0.0,
                           k <= 2 ? 0.0 : sign * big.h_x, options_.subgrid_translations);
      };
      Seed found = refine_from(sample.cell);
      if (deeper_away_from_seeds) {
        // The screen or the last step found the maximum away from the seeds: the displaced
        // sample is searched from there too (its own deepest cell may hold the seeds' lower
        // peak).
        const Seed also = refine_from(CellAt(w, deepest.s, deepest.t));
        if (also.depth_m > found.depth_m) found = also;
      }
      if (found.depth_m > -kInf) sample.depth_m = found.depth_m;
      if (k <= 4) translation_found[static_cast<std::size_t>(k - 1)] = found;
    }
  }

  counters_.contacts += 1;
  counters_.seeds += static_cast<std::uint64_t>(num_seeds);
  counters_.evaluations += evaluations_;
  const double raised = deepest.depth_m - samples[0].depth_m;
  if (raised > 0.0) counters_.raised_um += static_cast<std::uint64_t>(std::llround(raised * 1e6));
  samples[0] = {deepest.depth_m, CellAt(w, deepest.s, deepest.t)};
  lin.depth_m = deepest.depth_m;
  lin.point_W = point_W;
  if (options_.seed_from_last_step && num_next_ < kMaxLastStepSeeds) {
    // p_T = R_WTᵀ (p_W − p_WT): the point in the tool's frame.
    next_[static_cast<std::size_t>(num_next_++)] = {
        env_, glm::conjugate(X_WT.rotation) * (point_W - X_WT.translation)};
  }
  if (options_.texel_scale_gradient && options_.refine_rendered_samples &&
      options_.secant_at_kinks_m > 0.0) {
    // Per axis, the tangent against the refined samples one cell away: a kink within the cell
    // takes the secant (DepthRefinementOptions::secant_at_kinks_m).
    const glm::dvec3 axes[3] = {w.axis_u_W, w.axis_v_W, w.normal_W};
    const auto across = [&](int first_sample, double step, const glm::dvec3& axis,
                            glm::dvec3& derivative) {
      const double plus = samples[static_cast<std::size_t>(first_sample)].depth_m;
      const double minus = samples[static_cast<std::size_t>(first_sample + 1)].depth_m;
      if (samples[static_cast<std::size_t>(first_sample)].cell < 0 ||
          samples[static_cast<std::size_t>(first_sample + 1)].cell < 0 || !(plus > -kInf) ||
          !(minus > -kInf)) {
        return;
      }
      const double slope = glm::dot(derivative, axis);
      const double above = std::max(plus - (deepest.depth_m + slope * step),
                                    minus - (deepest.depth_m - slope * step));
      if (above > options_.secant_at_kinks_m) {
        derivative += ((plus - minus) / (2.0 * step) - slope) * axis;
      }
    };
    across(1, big.h_x, axes[0], lin.gradient.d_translation_W);
    across(3, big.h_x, axes[1], lin.gradient.d_translation_W);
    for (int a = 0; a < 3; ++a) {
      across(5 + 2 * a, big.h_theta, axes[a], lin.gradient.d_rotation_W);
    }
  }
  const bool texel_rotation = options_.texel_scale_gradient && options_.texel_scale_rotation;
  if (!texel_rotation) {
    // The refined rendered samples' one-cell secants: the whole gradient, or (texel-scale
    // translation only) its rotation part.
    LinearizationFaults faults;
    const PenetrationGradient secant =
        AssembleLinearization(w, samples, lin.stiffness_n_per_m, faults).gradient;
    if (options_.texel_scale_gradient) {
      lin.gradient.d_rotation_W = secant.d_rotation_W;
    } else {
      lin.gradient = secant;
    }
    // Without rotated samples (RotationGradient::kContactLever: only the base pose is drawn) the
    // rotation part stays the lever's, now at the refined deepest point: (r × ∂δ/∂x).
    bool rotations_drawn = true;
    for (int k = 5; k < kGradientSamples; ++k) {
      rotations_drawn &= samples[static_cast<std::size_t>(k)].cell >= 0;
    }
    if (!rotations_drawn) {
      lin.gradient.d_rotation_W =
          glm::cross(point_W - X_WT.translation, lin.gradient.d_translation_W);
    }
  }
  lin.num_kink_planes = 0;
  if (options_.texel_scale_gradient && options_.refine_rendered_samples &&
      options_.translation_kink_planes) {
    TranslationKinkPlanes(translation_found, deepest, big.h_x, lin);
  }
  lin.patch = TranslationPatch{};
  if (options_.translation_patch) {
    const std::uint64_t before = evaluations_;
    if (options_.translation_patch_step_texels > 0.0) {
      FillTexelTranslationPatch(base, num_seeds, translation_found, deepest, lin);
    } else {
      FillTranslationPatch(X_WT, deepest, translation_found, big.h_x, lin);
    }
    counters_.translation_patches += 1;
    counters_.evaluations += evaluations_ - before;
  }
  return true;
}

}  // namespace ht
