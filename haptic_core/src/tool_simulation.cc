#include "haptic_core/tool_simulation.h"

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>
#include <glm/gtc/quaternion.hpp>
#include <glm/mat3x3.hpp>
#include <stdexcept>
#include <string>

namespace ht {
namespace {

using Vector6 = Eigen::Matrix<double, 6, 1>;

void RequireNonNegative(double v, const char* name) {
  if (!(v >= 0.0) || !std::isfinite(v)) {
    throw std::invalid_argument(std::string("virtual coupling: ") + name +
                                " must be finite and >= 0, got " + std::to_string(v));
  }
}

Vector6 ToVector(const Wrench& F) {
  Vector6 v;
  v << F.force.x, F.force.y, F.force.z, F.torque.x, F.torque.y, F.torque.z;
  return v;
}
Vector6 ToVector(const Twist& V) {
  Vector6 v;
  v << V.linear.x, V.linear.y, V.linear.z, V.angular.x, V.angular.y, V.angular.z;
  return v;
}

}  // namespace

void VirtualCoupling::Validate() const {
  RequireNonNegative(k_translation_n_per_m, "k_translation_n_per_m");
  RequireNonNegative(b_translation_ns_per_m, "b_translation_ns_per_m");
  RequireNonNegative(k_rotation_nm_per_rad, "k_rotation_nm_per_rad");
  RequireNonNegative(b_rotation_nms_per_rad, "b_rotation_nms_per_rad");
}

ToolSimulator::ToolSimulator(const ToolInertia& inertia, const VirtualCoupling& coupling)
    : inertia_(inertia), coupling_(coupling) {
  if (!(inertia.mass_kg > 0.0)) throw std::invalid_argument("tool mass must be positive");
  if (!(inertia.inertia_diagonal_T.x > 0.0 && inertia.inertia_diagonal_T.y > 0.0 &&
        inertia.inertia_diagonal_T.z > 0.0)) {
    throw std::invalid_argument("tool inertia must be positive");
  }
  coupling.Validate();
}

Wrench ToolSimulator::CouplingWrench(const ToolState& s, const RigidTransform& X_WH,
                                     const Twist& V_WH_W) const noexcept {
  const VirtualCoupling& c = coupling_;
  const Twist d = PoseDifference(X_WH, s.X_WT);
  return {c.k_translation_n_per_m * d.linear +
              c.b_translation_ns_per_m * (V_WH_W.linear - s.V_WT_W.linear),
          c.k_rotation_nm_per_rad * d.angular +
              c.b_rotation_nms_per_rad * (V_WH_W.angular - s.V_WT_W.angular)};
}

void ToolSimulator::set_contact_damping_hunt_crossley(double alpha_s_per_m) {
  if (!(alpha_s_per_m >= 0.0) || !std::isfinite(alpha_s_per_m)) {
    throw std::invalid_argument(
        "the Hunt-Crossley contact damping must be >= 0 s/m and finite, got " +
        std::to_string(alpha_s_per_m));
  }
  hunt_crossley_s_per_m_ = alpha_s_per_m;
}

void ToolSimulator::set_max_contact_force(double max_contact_force_n) {
  if (!(max_contact_force_n > 0.0)) {
    throw std::invalid_argument("the bound on a contact's force must be > 0 N (+inf = none), got " +
                                std::to_string(max_contact_force_n));
  }
  max_contact_force_n_ = max_contact_force_n;
}

ToolStepResult ToolSimulator::Step(ToolState& s, const RigidTransform& X_WH, const Twist& V_WH_W,
                                   const ContactModel& model, double stiffness_scale, double h,
                                   const DepthFieldCache* fields) const noexcept {
  ToolStepResult result;
  if (!IsFiniteRigidTransform(X_WH) || !IsFinite(V_WH_W) || !(h > 0.0) || !std::isfinite(h)) {
    result.ok = false;  // hold the tool where it is, at rest
    s.V_WT_W = {};
    return result;
  }
  if (!IsFiniteRigidTransform(s.X_WT) || !IsFinite(s.V_WT_W)) {
    s = {X_WH, V_WH_W};
    result.ok = false;
  }
  return Integrate(
      s, X_WH, V_WH_W,
      EvaluateContactModel(model, s.X_WT, stiffness_scale, max_contact_force_n_, fields), h,
      result);
}

ToolStepResult ToolSimulator::StepBlended(ToolState& s, const RigidTransform& X_WH,
                                          const Twist& V_WH_W, const ContactModel& current,
                                          const ContactModel& previous, double blend, double h,
                                          const DepthFieldCache* fields) const noexcept {
  ToolStepResult result;
  if (!IsFiniteRigidTransform(X_WH) || !IsFinite(V_WH_W) || !(h > 0.0) || !std::isfinite(h)) {
    result.ok = false;
    s.V_WT_W = {};
    return result;
  }
  if (!IsFiniteRigidTransform(s.X_WT) || !IsFinite(s.V_WT_W)) {
    s = {X_WH, V_WH_W};
    result.ok = false;
  }
  const double beta = std::isfinite(blend) ? std::clamp(blend, 0.0, 1.0) : 1.0;
  ContactModelEvaluation a =
      EvaluateContactModel(current, s.X_WT, beta, max_contact_force_n_, fields);
  const ContactModelEvaluation b =
      EvaluateContactModel(previous, s.X_WT, 1.0 - beta, max_contact_force_n_, fields);
  a.F_T_W.force += b.F_T_W.force;
  a.F_T_W.torque += b.F_T_W.torque;
  a.K += b.K;
  a.G += b.G;
  a.active_contacts = beta >= 0.5 ? a.active_contacts : b.active_contacts;
  a.saturated_contacts = beta >= 0.5 ? a.saturated_contacts : b.saturated_contacts;
  a.max_depth_m = std::max(a.max_depth_m, b.max_depth_m);
  a.field_contacts = beta >= 0.5 ? a.field_contacts : b.field_contacts;
  a.field_fallbacks = beta >= 0.5 ? a.field_fallbacks : b.field_fallbacks;
  a.field_beyond_margin = beta >= 0.5 ? a.field_beyond_margin : b.field_beyond_margin;
  return Integrate(s, X_WH, V_WH_W, a, h, result);
}

ToolStepResult ToolSimulator::Integrate(ToolState& s, const RigidTransform& X_WH,
                                        const Twist& V_WH_W, const ContactModelEvaluation& contact,
                                        double h, ToolStepResult result) const noexcept {
  result.F_contact_T_W = contact.F_T_W;
  result.active_contacts = contact.active_contacts;
  result.max_depth_m = contact.max_depth_m;
  result.field_contacts = contact.field_contacts;
  result.field_fallbacks = contact.field_fallbacks;
  result.field_beyond_margin = contact.field_beyond_margin;
  result.saturated_contacts = contact.saturated_contacts;

  const VirtualCoupling& c = coupling_;
  const Wrench F_T_W_total = contact.F_T_W + CouplingWrench(s, X_WH, V_WH_W);

  // Mass matrix in W: diag(m I, R I_T Rᵀ).
  const glm::dmat3 R = glm::mat3_cast(s.X_WT.rotation);
  Eigen::Matrix3d R_e;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) R_e(i, j) = R[j][i];  // glm is column-major: R[col][row]
  const Eigen::Vector3d I_T(inertia_.inertia_diagonal_T.x, inertia_.inertia_diagonal_T.y,
                            inertia_.inertia_diagonal_T.z);
  Stiffness6 A = Stiffness6::Zero();
  A.topLeftCorner<3, 3>().diagonal().setConstant(inertia_.mass_kg);
  A.bottomRightCorner<3, 3>() = R_e * I_T.asDiagonal() * R_e.transpose();

  Stiffness6 K = contact.K;
  K.topLeftCorner<3, 3>().diagonal().array() -= c.k_translation_n_per_m;
  K.bottomRightCorner<3, 3>().diagonal().array() -= c.k_rotation_nm_per_rad;
  // D = −diag(b_t, b_r): A = M − h D − h² K.
  A.topLeftCorner<3, 3>().diagonal().array() += h * c.b_translation_ns_per_m;
  A.bottomRightCorner<3, 3>().diagonal().array() += h * c.b_rotation_nms_per_rad;
  A.noalias() -= (h * h) * K;
  // Hunt–Crossley contact damping D_c = −α·G (set_contact_damping_hunt_crossley): A −= h·D_c,
  // and D_c·V_n joins the force.
  const double alpha = hunt_crossley_s_per_m_;
  if (alpha > 0.0) A.noalias() += (h * alpha) * contact.G;

  const Vector6 V = ToVector(s.V_WT_W);
  Vector6 rhs = h * (ToVector(F_T_W_total) + h * (K * V));
  if (alpha > 0.0) rhs.noalias() -= (h * alpha) * (contact.G * V);
  const Eigen::LDLT<Stiffness6> ldlt(A);
  const Vector6 dV = ldlt.solve(rhs);
  const Vector6 V_next = V + dV;

  ToolState next;
  next.V_WT_W.linear = {V_next(0), V_next(1), V_next(2)};
  next.V_WT_W.angular = {V_next(3), V_next(4), V_next(5)};
  next.X_WT = Displace(s.X_WT, {h * next.V_WT_W.linear, h * next.V_WT_W.angular});
  if (ldlt.info() != Eigen::Success || !IsFiniteRigidTransform(next.X_WT) ||
      !IsFinite(next.V_WT_W)) {
    next = {X_WH, V_WH_W};
    result.ok = false;
  }
  s = next;
  result.F_coupling_T_W = CouplingWrench(s, X_WH, V_WH_W);
  return result;
}

}  // namespace ht
