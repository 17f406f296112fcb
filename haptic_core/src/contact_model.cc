#include "haptic_core/contact_model.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

namespace ht {

// Declared in contact_linearization.h; defined here, beside the loop's evaluation that uses it, so
// that a receiver of contact models (transport's decoder, its fuzz target) links without the
// remote step's texture stage.
Wrench PenaltyWrench(double depth_m, const PenetrationGradient& J,
                     double stiffness_n_per_m) noexcept {
  if (!(depth_m > 0.0) || !std::isfinite(depth_m)) return {};
  const double s = -stiffness_n_per_m * depth_m;
  return {s * J.d_translation_W, s * J.d_rotation_W};
}

double ContactDepthAt(const ContactLinearization& c, const Twist& dq,
                      PenetrationGradient* gradient) noexcept {
  if (gradient != nullptr) *gradient = c.gradient;
  return c.depth_m + c.gradient.Dot(dq);
}

namespace {

/// EvaluateContactModel with `field_at(id, X_WT)` giving a contact's field evaluation (valid
/// false where there is none) when `has_fields`.
template <typename FieldAt>
ContactModelEvaluation EvaluateWithFields(const ContactModel& model, const RigidTransform& X_WT,
                                          double stiffness_scale, double max_contact_force_n,
                                          bool has_fields, const FieldAt& field_at) noexcept {
  ContactModelEvaluation out;
  if (!IsFiniteRigidTransform(X_WT) || !IsFiniteRigidTransform(model.X_WT0)) return out;
  const double scale = std::clamp(std::isfinite(stiffness_scale) ? stiffness_scale : 0.0, 0.0, 1.0);
  const Twist dq = PoseDifference(X_WT, model.X_WT0);
  const int n = std::clamp(model.num_contacts, 0, kMaxContacts);
  Stiffness6 curvature = Stiffness6::Zero();
  for (int i = 0; i < n; ++i) {
    const ContactLinearization& c = model.contacts[i];
    const double k = c.stiffness_n_per_m * scale;
    if (!std::isfinite(c.depth_m) || !std::isfinite(k) || !(k > 0.0)) continue;
    PenetrationGradient J_active;
    bool curved = false, pressure = false;
    double depth;
    DepthFieldEvaluation fe;
    if (has_fields && c.depth_field_id != 0) fe = field_at(c.depth_field_id, X_WT);
    if (fe.valid) {
      ++out.field_contacts;
      if (!fe.within_margin) ++out.field_beyond_margin;
      depth = fe.depth_m + c.depth_field_shift_m;
      J_active = fe.gradient;
      curvature = fe.curvature;
      curved = true;
      pressure = fe.force_law == ForceLaw::kPressure;
    } else {
      if (has_fields && c.depth_field_id != 0) ++out.field_fallbacks;
      depth = ContactDepthAt(c, dq, &J_active);
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
    if (pressure) {
      out.G.noalias() += k * fe.pressure_damping;
    } else {
      out.G.noalias() += (k * depth) * (J * J.transpose());
    }
    if (curved) out.K.noalias() -= (k * depth) * curvature;
  }
  return out;
}

}  // namespace

ContactModelEvaluation EvaluateContactModel(const ContactModel& model, const RigidTransform& X_WT,
                                            double stiffness_scale, double max_contact_force_n,
                                            const DepthFieldCache* fields) noexcept {
  return EvaluateWithFields(model, X_WT, stiffness_scale, max_contact_force_n, fields != nullptr,
                            [fields](std::uint32_t id, const RigidTransform& X) noexcept {
                              return fields->Evaluate(id, X);
                            });
}

ContactModelEvaluation EvaluateContactModel(const ContactModel& model, const RigidTransform& X_WT,
                                            std::span<const DepthField* const> fields) noexcept {
  return EvaluateWithFields(model, X_WT, 1.0, std::numeric_limits<double>::infinity(), true,
                            [fields](std::uint32_t id, const RigidTransform& X) noexcept {
                              for (const DepthField* f : fields) {
                                if (f != nullptr && f->prepared && f->id == id)
                                  return DepthFieldDepthAt(*f, X);
                              }
                              return DepthFieldEvaluation{};
                            });
}

}  // namespace ht
