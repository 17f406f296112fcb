#include "haptic_core/contact_model.h"

#include <algorithm>
#include <cmath>

namespace ht {

ContactModelEvaluation EvaluateContactModel(const ContactModel& model, const RigidTransform& X_WT,
                                            double stiffness_scale,
                                            double max_contact_force_n) noexcept {
  ContactModelEvaluation out;
  if (!IsFiniteRigidTransform(X_WT) || !IsFiniteRigidTransform(model.X_WT0)) return out;
  const double scale = std::clamp(std::isfinite(stiffness_scale) ? stiffness_scale : 0.0, 0.0, 1.0);
  const Twist dq = PoseDifference(X_WT, model.X_WT0);
  const int n = std::clamp(model.num_contacts, 0, kMaxContacts);
  for (int i = 0; i < n; ++i) {
    const ContactLinearization& c = model.contacts[i];
    const double k = c.stiffness_n_per_m * scale;
    if (!std::isfinite(c.depth_m) || !std::isfinite(k) || !(k > 0.0)) continue;
    const double depth = c.depth_m + c.gradient.Dot(dq);
    if (!(depth > 0.0)) continue;
    ++out.active_contacts;
    out.max_depth_m = std::max(out.max_depth_m, depth);
    // The bound on the contact's force: saturate δ along J (no stiffness beyond it). The depth
    // is held where the unscaled stiffness reaches the bound, so that blended models (scales β
    // and 1 − β of one contact) add up to the bound at most.
    const double force_per_m = c.stiffness_n_per_m * glm::length(c.gradient.d_translation_W);
    if (force_per_m * depth > max_contact_force_n) {
      out.F_T_W += PenaltyWrench(max_contact_force_n / force_per_m, c.gradient, k);
      ++out.saturated_contacts;
      continue;
    }
    out.F_T_W += PenaltyWrench(depth, c.gradient, k);
    Eigen::Matrix<double, 6, 1> J;
    J << c.gradient.d_translation_W.x, c.gradient.d_translation_W.y, c.gradient.d_translation_W.z,
        c.gradient.d_rotation_W.x, c.gradient.d_rotation_W.y, c.gradient.d_rotation_W.z;
    out.K.noalias() -= k * (J * J.transpose());
  }
  return out;
}

}  // namespace ht
