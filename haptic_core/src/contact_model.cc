#include "haptic_core/contact_model.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

namespace ht {
namespace {}  // namespace

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
  if (gradient != nullptr) *gradient = {t_top + blend_t, r_top + blend_r};
  return depth + lift - lift0;
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
    bool curved = c.num_kink_planes > 0;
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
