#include "haptic_core/contact_model.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

namespace ht {
namespace {

// Catmull–Rom weights of the nodes −1, 0, 1, 2 of a unit segment at f ∈ [0, 1], and their
// derivatives along f.
void CatmullRomWeights(double f, std::array<double, 4>& w, std::array<double, 4>& dw,
                       std::array<double, 4>& ddw) noexcept {
  const double f2 = f * f, f3 = f2 * f;
  w = {0.5 * (-f3 + 2.0 * f2 - f), 0.5 * (3.0 * f3 - 5.0 * f2 + 2.0),
       0.5 * (-3.0 * f3 + 4.0 * f2 + f), 0.5 * (f3 - f2)};
  dw = {0.5 * (-3.0 * f2 + 4.0 * f - 1.0), 0.5 * (9.0 * f2 - 10.0 * f),
        0.5 * (-9.0 * f2 + 8.0 * f + 1.0), 0.5 * (3.0 * f2 - 2.0 * f)};
  ddw = {0.5 * (-6.0 * f + 4.0), 0.5 * (18.0 * f - 10.0), 0.5 * (-18.0 * f + 8.0),
         0.5 * (6.0 * f - 2.0)};
}

// Whether ContactDepthAt gives the patch's curvature to the implicit step (a patch no wider than
// kPatchCurvatureMaxStepM between nodes).
bool PatchGivesCurvature(const TranslationPatch& p) noexcept {
  return p.step_m > 0.0 && p.step_m <= kPatchCurvatureMaxStepM;
}

// How far past a translation patch's edge its slope fades to zero (node spacings): short, so that
// little of the edge's slope is carried on, and not zero, so that the gradient stays continuous
// (docs/passivity/README.md, "Past the patch's edge": a quarter and one spacing measured).
constexpr double kPatchFadeSpacings = 0.25;

// The translation patch's residual at the in-plane displacement Δq.linear (TranslationPatch): the
// bicubic interpolant of its nodes (linear ghosts one node past each edge; the displacement
// clamped to the patch) less the contact's own linear part there, so that δ passes the nodes;
// past an edge, the interpolant's slope there fading to zero over kPatchFadeSpacings. The
// linear part subtracted is the interpolant's tangent at q0 near q0 and the contact's in-plane
// slope (`slope_W`, ∂δ/∂x) from one node on, joined by a smoothstep; the two are one where the
// nodes are one cell apart (the central difference is the contact's secant). Its gradient along
// u and v (W) is added to `d_translation`, and where `hessian` is given it receives the residual's
// second derivatives in the patch's (u, v) basis (1/m; zero past an edge). 0 for no patch or a
// non-finite one.
double PatchResidual(const TranslationPatch& p, const glm::dvec3& dx, const glm::dvec3& slope_W,
                     glm::dvec3& d_translation, Eigen::Matrix2d* hessian = nullptr) noexcept {
  if (hessian != nullptr) hessian->setZero();
  constexpr int R = kTranslationPatchRadius;
  constexpr int S = kTranslationPatchSide;
  const double h = p.step_m;
  if (!(h > 0.0) || !std::isfinite(h)) return 0.0;
  for (const float v : p.depth_m) {
    if (!std::isfinite(v)) return 0.0;
  }
  const auto node = [&](int i, int j) {
    return static_cast<double>(p.depth_m[(j + R) * S + (i + R)]);
  };
  // Nodes −R−1 … R+1: past an edge, the line through the edge's two nodes.
  const auto at = [&](int i, int j) {
    const auto row = [&](int ii) {
      if (j < -R) return 2.0 * node(ii, -R) - node(ii, -R + 1);
      if (j > R) return 2.0 * node(ii, R) - node(ii, R - 1);
      return node(ii, j);
    };
    if (i < -R) return 2.0 * row(-R) - row(-R + 1);
    if (i > R) return 2.0 * row(R) - row(R - 1);
    return row(i);
  };
  const double x_raw = glm::dot(dx, p.axis_u_W) / h;
  const double y_raw = glm::dot(dx, p.axis_v_W) / h;
  if (!std::isfinite(x_raw) || !std::isfinite(y_raw)) return 0.0;
  const double x = std::clamp(x_raw, -static_cast<double>(R), static_cast<double>(R));
  const double y = std::clamp(y_raw, -static_cast<double>(R), static_cast<double>(R));
  const int i0 = std::min(static_cast<int>(std::floor(x)), R - 1);
  const int j0 = std::min(static_cast<int>(std::floor(y)), R - 1);
  std::array<double, 4> wx, dwx, ddwx, wy, dwy, ddwy;
  CatmullRomWeights(x - i0, wx, dwx, ddwx);
  CatmullRomWeights(y - j0, wy, dwy, ddwy);
  double value = 0.0, d_x = 0.0, d_y = 0.0, d_xy = 0.0, d_xx = 0.0, d_yy = 0.0;
  for (int b = 0; b < 4; ++b) {
    for (int a = 0; a < 4; ++a) {
      const double v = at(i0 - 1 + a, j0 - 1 + b);
      const auto ua = static_cast<std::size_t>(a), ub = static_cast<std::size_t>(b);
      value += wx[ua] * wy[ub] * v;
      d_x += dwx[ua] * wy[ub] * v;
      d_y += wx[ua] * dwy[ub] * v;
      d_xy += dwx[ua] * dwy[ub] * v;
      d_xx += ddwx[ua] * wy[ub] * v;
      d_yy += wx[ua] * ddwy[ub] * v;
    }
  }
  // The linear part subtracted, per node spacing: T(x) = g·x − (g − c)·x·φ(|x|), g the
  // interpolant's tangent at q0 (its central difference), c the contact's slope, φ(a) = 3a² − 2a³
  // up to a = 1 and 1 beyond, so that T′(0) = g (∇δ(q0) is the contact's) and T(x) = c·x from one
  // node on (δ passes the nodes). T′(x) = g − (g − c)·(9a² − 8a³) up to a = 1, c beyond.
  const double g_x = 0.5 * (node(1, 0) - node(-1, 0));
  const double g_y = 0.5 * (node(0, 1) - node(0, -1));
  const double c_x = glm::dot(slope_W, p.axis_u_W) * h, c_y = glm::dot(slope_W, p.axis_v_W) * h;
  const auto linear_part = [](double s, double g, double c, double& dT) {
    const double a = std::min(std::abs(s), 1.0);
    dT = g - (g - c) * a * a * (9.0 - 8.0 * a);
    return g * s - (g - c) * s * a * a * (3.0 - 2.0 * a);
  };
  double dT_x = 0.0, dT_y = 0.0;
  const double T = linear_part(x, g_x, c_x, dT_x) + linear_part(y, g_y, c_y, dT_y);
  if (x == x_raw) d_translation += ((d_x - dT_x) / h) * p.axis_u_W;
  if (y == y_raw) d_translation += ((d_y - dT_y) / h) * p.axis_v_W;
  if (hessian != nullptr && x == x_raw && y == y_raw) {
    // T″(s) = −(g − c)·sign(s)·(18a − 24a²) up to a = 1, 0 beyond.
    const auto linear_second = [](double s, double g, double c) {
      const double a = std::min(std::abs(s), 1.0);
      return a < 1.0 ? -(g - c) * std::copysign(a * (18.0 - 24.0 * a), s) : 0.0;
    };
    *hessian << d_xx - linear_second(x, g_x, c_x), d_xy, d_xy, d_yy - linear_second(y, g_y, c_y);
    *hessian /= h * h;
  }
  // Past an edge (e = the displacement beyond it, in node spacings) nothing is known of the
  // surface: the in-plane slope fades from the interpolant's at the edge to zero over L =
  // kPatchFadeSpacings and the depth then holds (the edge's depth plus L/2 of its slope), so that δ
  // and ∇δ stay continuous and a ridge's slope is not carried on past the patch into where the next
  // ridge may be (docs/passivity/README.md, "Past the patch's edge"). Along an edge the slope at
  // the edge varies with the other coordinate: that cross term is in the gradient too, so that it
  // stays the depth's derivative (a conservative field).
  double beyond = 0.0;
  constexpr double L = kPatchFadeSpacings;
  const auto fade = [&](double e, double slope_at_edge, double linear_slope, const glm::dvec3& axis,
                        bool other_inside, const glm::dvec3& other_axis) {
    const double a = std::abs(e);
    const double held = a < L ? e - 0.5 * e * a / L : std::copysign(0.5 * L, e);
    beyond += slope_at_edge * held - linear_slope * e;
    d_translation += ((slope_at_edge * std::max(1.0 - a / L, 0.0) - linear_slope) / h) * axis;
    if (other_inside) d_translation += (d_xy * held / h) * other_axis;
  };
  if (x != x_raw) fade(x_raw - x, d_x, c_x, p.axis_u_W, y == y_raw, p.axis_v_W);
  if (y != y_raw) fade(y_raw - y, d_y, c_y, p.axis_v_W, x == x_raw, p.axis_u_W);
  return value - T + beyond;
}

}  // namespace

// Declared in contact_linearization.h; defined here, beside the loop's evaluation that uses it, so
// that a receiver of contact models (transport's decoder, its fuzz target) links without the
// remote step's texture stage.
Wrench PenaltyWrench(double depth_m, const PenetrationGradient& J,
                     double stiffness_n_per_m) noexcept {
  if (!(depth_m > 0.0) || !std::isfinite(depth_m)) return {};
  const double s = -stiffness_n_per_m * depth_m;
  return {s * J.d_translation_W, s * J.d_rotation_W};
}

double ContactDepthAt(const ContactLinearization& c, const Twist& dq, PenetrationGradient* gradient,
                      Stiffness6* curvature) noexcept {
  const int n = std::clamp(c.num_kink_planes, 0, kMaxKinkPlanes);
  // Plane values and gradients: index 0 the contact's own, 1..n its kink planes.
  std::array<double, kMaxKinkPlanes + 1> d{};
  std::array<glm::dvec3, kMaxKinkPlanes + 1> t{};  // ∂δ_i/∂x
  std::array<glm::dvec3, kMaxKinkPlanes + 1> r{};  // ∂δ_i/∂θ
  d[0] = c.depth_m + c.gradient.Dot(dq);
  t[0] = c.gradient.d_translation_W;
  r[0] = c.gradient.d_rotation_W;
  const auto finite3 = [](const glm::dvec3& a) {
    return std::isfinite(a.x) && std::isfinite(a.y) && std::isfinite(a.z);
  };
  int top = 0;
  for (int m = 0; m < n; ++m) {
    const KinkPlane& p = c.kink_planes[static_cast<std::size_t>(m)];
    const std::size_t i = static_cast<std::size_t>(m + 1);
    t[i] = c.gradient.d_translation_W + p.d_translation_offset_W;
    r[i] = p.d_rotation_W;
    d[i] = p.depth_m + (glm::dot(t[i], dq.linear) + glm::dot(r[i], dq.angular));
    if (!std::isfinite(d[i]) || !finite3(t[i]) || !finite3(r[i])) {
      d[i] = -std::numeric_limits<double>::infinity();
      continue;
    }
    if (d[i] > d[static_cast<std::size_t>(top)]) top = m + 1;
  }
  const double eps = kKinkBlendM;
  const glm::dvec3 t_top = t[static_cast<std::size_t>(top)];
  const glm::dvec3 r_top = r[static_cast<std::size_t>(top)];
  double depth = d[static_cast<std::size_t>(top)];
  glm::dvec3 blend_t(0.0), blend_r(0.0);
  double weight = 0.0;
  if (curvature != nullptr) curvature->setZero();
  for (int i = 0; i <= n; ++i) {
    const double gap = depth - d[static_cast<std::size_t>(i)];
    if (i == top || !(gap < eps)) continue;  // also skips −∞ and NaN
    const double w = (eps - gap) / (2.0 * eps);
    const glm::dvec3 diff_t = t[static_cast<std::size_t>(i)] - t_top;
    const glm::dvec3 diff_r = r[static_cast<std::size_t>(i)] - r_top;
    blend_t += w * diff_t;
    blend_r += w * diff_r;
    weight += w;
    if (curvature != nullptr) {
      Eigen::Matrix<double, 6, 1> e;
      e << diff_t.x, diff_t.y, diff_t.z, diff_r.x, diff_r.y, diff_r.z;
      curvature->noalias() += (1.0 / (2.0 * eps)) * (e * e.transpose());
    }
  }
  // The blend's lift here, less its lift at q0 (planes that tie at q0: a level face on a flat, or
  // pressed exactly at its V's vertex), so that δ(q0) = δ0 and a touching contact (δ0 = 0) pushes
  // with nothing.
  const auto lift_at = [&](const auto& value, int count) {
    int best = 0;
    for (int i = 1; i <= count; ++i) {
      if (value(i) > value(best)) best = i;
    }
    double lift = 0.0;
    for (int i = 0; i <= count; ++i) {
      const double gap = value(best) - value(i);
      if (i != best && gap < eps) lift += (eps - gap) * (eps - gap) / (4.0 * eps);
    }
    return lift;
  };
  const double lift = lift_at([&](int i) { return d[static_cast<std::size_t>(i)]; }, n);
  const double lift0 = lift_at(
      [&](int i) {
        if (i == 0) return c.depth_m;
        const KinkPlane& p = c.kink_planes[static_cast<std::size_t>(i - 1)];
        return std::isfinite(d[static_cast<std::size_t>(i)])
                   ? p.depth_m
                   : -std::numeric_limits<double>::infinity();
      },
      n);
  if (weight > 1.0) {  // three or more planes at a tie: a convex combination
    blend_t /= weight;
    blend_r /= weight;
  }
  // The patch at the contact's slide: Δx, plus Δθ × lever where the patch follows rotation
  // (∂/∂Δθ of g·(Δθ × r) is r × g).
  glm::dvec3 patch_t(0.0);
  const bool lever = c.patch.lever_W != glm::dvec3(0.0) && finite3(c.patch.lever_W);
  const glm::dvec3 slide = lever ? dq.linear + glm::cross(dq.angular, c.patch.lever_W) : dq.linear;
  const bool curved_patch = curvature != nullptr && PatchGivesCurvature(c.patch);
  Eigen::Matrix2d patch_hessian;
  const double patch = PatchResidual(c.patch, slide, c.gradient.d_translation_W, patch_t,
                                     curved_patch ? &patch_hessian : nullptr);
  if (curved_patch) {
    // The patch's curvature along the window's plane, its convex part only (a ridge's top, where
    // it is concave, is left to the planes: K stays negative semi-definite), through the slide:
    // ∂slide/∂(Δx, Δθ) = B·[I, −[r]×] with a lever, B·[I, 0] without, B = [u v] (3×2).
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eigen;
    eigen.computeDirect(patch_hessian);
    const Eigen::Vector2d l = eigen.eigenvalues().cwiseMax(0.0);
    if (l.allFinite() && l.maxCoeff() > 0.0) {
      const Eigen::Matrix2d convex =
          eigen.eigenvectors() * l.asDiagonal() * eigen.eigenvectors().transpose();
      const glm::dvec3& u = c.patch.axis_u_W;
      const glm::dvec3& v = c.patch.axis_v_W;
      Eigen::Matrix<double, 3, 2> B;
      B << u.x, v.x, u.y, v.y, u.z, v.z;
      Eigen::Matrix<double, 3, 6> A = Eigen::Matrix<double, 3, 6>::Zero();
      A.leftCols<3>().setIdentity();
      if (lever) {
        const glm::dvec3& lw = c.patch.lever_W;
        Eigen::Matrix3d rx;
        rx << 0.0, -lw.z, lw.y, lw.z, 0.0, -lw.x, -lw.y, lw.x, 0.0;
        A.rightCols<3>() = -rx;
      }
      const Eigen::Matrix<double, 2, 6> BA = B.transpose() * A;
      curvature->noalias() += BA.transpose() * convex * BA;
    }
  }
  const glm::dvec3 patch_r = lever ? glm::cross(c.patch.lever_W, patch_t) : glm::dvec3(0.0);
  if (gradient != nullptr) *gradient = {t_top + blend_t + patch_t, r_top + blend_r + patch_r};
  return depth + lift - lift0 + patch;
}

ContactModelEvaluation EvaluateContactModel(const ContactModel& model, const RigidTransform& X_WT,
                                            double stiffness_scale, double max_contact_force_n,
                                            const DepthFieldCache* fields) noexcept {
  ContactModelEvaluation out;
  if (!IsFiniteRigidTransform(X_WT) || !IsFiniteRigidTransform(model.X_WT0)) return out;
  const double scale = std::clamp(std::isfinite(stiffness_scale) ? stiffness_scale : 0.0, 0.0, 1.0);
  const Twist dq = PoseDifference(X_WT, model.X_WT0);
  const int n = std::clamp(model.num_contacts, 0, kMaxContacts);
  Stiffness6 curvature;
  for (int i = 0; i < n; ++i) {
    const ContactLinearization& c = model.contacts[i];
    const double k = c.stiffness_n_per_m * scale;
    if (!std::isfinite(c.depth_m) || !std::isfinite(k) || !(k > 0.0)) continue;
    PenetrationGradient J_active;
    bool curved = c.num_kink_planes > 0 || PatchGivesCurvature(c.patch);
    double depth;
    DepthFieldEvaluation fe;
    if (fields != nullptr && c.depth_field_id != 0) fe = fields->Evaluate(c.depth_field_id, X_WT);
    if (fe.valid) {
      ++out.field_contacts;
      if (!fe.within_margin) ++out.field_beyond_margin;
      depth = fe.depth_m + c.depth_field_shift_m;
      J_active = fe.gradient;
      curvature = fe.curvature;
      curved = true;
    } else {
      if (fields != nullptr && c.depth_field_id != 0) ++out.field_fallbacks;
      depth = ContactDepthAt(c, dq, &J_active, curved ? &curvature : nullptr);
    }
    if (!(depth > 0.0)) continue;
    ++out.active_contacts;
    out.max_depth_m = std::max(out.max_depth_m, depth);
    // The bound on the contact's force: saturate δ along J (no stiffness beyond it). The depth
    // is held where the unscaled stiffness reaches the bound, so that blended models (scales β
    // and 1 − β of one contact) add up to the bound at most.
    const double force_per_m = c.stiffness_n_per_m * glm::length(J_active.d_translation_W);
    if (force_per_m * depth > max_contact_force_n) {
      const double held = max_contact_force_n / force_per_m;
      out.F_T_W += PenaltyWrench(held, J_active, k);
      out.potential_energy_j += k * (held * depth - 0.5 * held * held);
      ++out.saturated_contacts;
      continue;
    }
    out.F_T_W += PenaltyWrench(depth, J_active, k);
    out.potential_energy_j += 0.5 * k * depth * depth;
    Eigen::Matrix<double, 6, 1> J;
    J << J_active.d_translation_W.x, J_active.d_translation_W.y, J_active.d_translation_W.z,
        J_active.d_rotation_W.x, J_active.d_rotation_W.y, J_active.d_rotation_W.z;
    out.K.noalias() -= k * (J * J.transpose());
    out.G.noalias() += (k * depth) * (J * J.transpose());
    if (curved) out.K.noalias() -= (k * depth) * curvature;
  }
  return out;
}

}  // namespace ht
