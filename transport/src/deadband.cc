#include "transport/deadband.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "transport/messages.h"

namespace ht {
namespace {

void CheckFraction(double k, const char* name) {
  if (!(k >= 0.0 && k < 1.0)) {
    throw std::invalid_argument(std::string(name) + " must be in [0, 1) (a Weber fraction), got " +
                                std::to_string(k));
  }
}

void CheckPositive(double v, const char* name) {
  if (!(v > 0.0) || !std::isfinite(v)) {
    throw std::invalid_argument(std::string(name) + " must be positive and finite, got " +
                                std::to_string(v));
  }
}

double Frobenius3(const Stiffness6& K, int row, int col) noexcept {
  return K.block<3, 3>(row, col).norm();
}

}  // namespace

RigidTransform ExtrapolatePose(const RigidTransform& X_WT, const Twist& V_WT_W,
                               double dt_s) noexcept {
  if (!(dt_s > 0.0)) return X_WT;
  return Displace(X_WT, {V_WT_W.linear * dt_s, V_WT_W.angular * dt_s});
}

const char* ToString(DeadbandReason reason) noexcept {
  switch (reason) {
    case DeadbandReason::kNotSent:
      return "not_sent";
    case DeadbandReason::kOff:
      return "off";
    case DeadbandReason::kFirst:
      return "first";
    case DeadbandReason::kKeepAlive:
      return "keep_alive";
    case DeadbandReason::kPosition:
      return "position";
    case DeadbandReason::kRotation:
      return "rotation";
    case DeadbandReason::kVelocity:
      return "velocity";
    case DeadbandReason::kAngularVelocity:
      return "angular_velocity";
    case DeadbandReason::kContactCount:
      return "contact_count";
    case DeadbandReason::kForce:
      return "force";
    case DeadbandReason::kTorque:
      return "torque";
    case DeadbandReason::kStiffness:
      return "stiffness";
    case DeadbandReason::kDepth:
      return "depth";
    case DeadbandReason::kDepthField:
      return "depth_field";
  }
  return "unknown";
}

nlohmann::json ToJson(const wire::DeadbandTerms& terms) {
  return {{"tool_state_deadband", terms.tool_state_deadband},
          {"model_deadband", terms.model_deadband},
          {"tool_state_keepalive_ms", terms.tool_state_keepalive_ms},
          {"model_keepalive_ms", terms.model_keepalive_ms}};
}

nlohmann::json ToJson(const DeadbandCounts& counts) {
  nlohmann::json out = nlohmann::json::object();
  for (int i = 0; i < kDeadbandReasonCount; ++i) {
    if (counts[i] != 0) out[ToString(static_cast<DeadbandReason>(i))] = counts[i];
  }
  return out;
}

void ToolStateDeadband::NoteSent(const RigidTransform& X_WT, const Twist& V_WT_W,
                                 std::int64_t t_ns) noexcept {
  have_sent_ = true;
  X_sent_ = X_WT;
  V_sent_ = V_WT_W;
  t_sent_ns_ = t_ns;
}

void ToolStateDeadbandConfig::Validate() const {
  CheckFraction(weber_fraction, "tool-state deadband");
  CheckPositive(position_floor_scale_m, "tool-state deadband position floor scale");
  CheckPositive(rotation_floor_scale_rad, "tool-state deadband rotation floor scale");
  CheckPositive(contact_position_floor_scale_m, "tool-state deadband contact position floor scale");
  CheckPositive(contact_rotation_floor_scale_rad,
                "tool-state deadband contact rotation floor scale");
  CheckPositive(linear_velocity_floor_scale_m_per_s, "tool-state deadband velocity floor scale");
  CheckPositive(angular_velocity_floor_scale_rad_per_s,
                "tool-state deadband angular velocity floor scale");
  if (!(contact_floor_hold_s >= 0.0 && std::isfinite(contact_floor_hold_s))) {
    throw std::invalid_argument("tool-state deadband contact floor hold must be >= 0 s and finite");
  }
  if (!(contact_depth_floor_scale_m >= 0.0 && std::isfinite(contact_depth_floor_scale_m))) {
    throw std::invalid_argument(
        "tool-state deadband contact depth floor scale must be >= 0 m and finite");
  }
  CheckPositive(keepalive_s, "tool-state keep-alive");
  CheckPositive(adaptive_speed_ref_m_per_s, "tool-state deadband adaptive speed reference");
}

void ContactModelDeadbandConfig::Validate() const {
  CheckFraction(weber_fraction, "contact-model deadband");
  CheckPositive(force_floor_scale_n, "contact-model deadband force floor scale");
  CheckPositive(torque_floor_scale_nm, "contact-model deadband torque floor scale");
  CheckPositive(stiffness_floor_scale_n_per_m, "contact-model deadband stiffness floor scale");
  CheckPositive(rotational_stiffness_floor_scale_nm_per_rad,
                "contact-model deadband rotational stiffness floor scale");
  CheckPositive(keepalive_s, "contact-model keep-alive");
}

namespace {

// Whether a contact of `model` has a depth at X_WT and at X_WT_predicted that differ by more than
// max(k·δ, k·floor) (ToolStateDeadbandConfig::contact_depth_floor_scale_m; m).
bool DepthLeftPrediction(const ContactModel& model, const RigidTransform& X_WT,
                         const RigidTransform& X_WT_predicted, double k, double floor_m) noexcept {
  const int n = std::clamp(model.num_contacts, 0, kMaxContacts);
  if (n == 0) return false;
  const Twist dq = PoseDifference(X_WT, model.X_WT0);
  const Twist dq_predicted = PoseDifference(X_WT_predicted, model.X_WT0);
  for (int i = 0; i < n; ++i) {
    const double d = ContactDepthAt(model.contacts[i], dq);
    const double d_predicted = ContactDepthAt(model.contacts[i], dq_predicted);
    if (!std::isfinite(d) || !std::isfinite(d_predicted)) continue;
    if (d < -floor_m && d_predicted < -floor_m) continue;
    if (std::abs(d - d_predicted) > std::max(k * std::max(d, 0.0), k * floor_m)) return true;
  }
  return false;
}

}  // namespace

DeadbandReason ToolStateDeadband::Decide(const RigidTransform& X_WT, const Twist& V_WT_W,
                                         std::int64_t t_ns, bool near_contact,
                                         const ContactModel* held_model) noexcept {
  const ToolStateDeadbandConfig& c = config_;
  const double k = c.weber_fraction;
  DeadbandReason reason = DeadbandReason::kNotSent;
  const double dt = static_cast<double>(t_ns - t_sent_ns_) * 1e-9;
  if (near_contact) {
    have_near_contact_ = true;
    t_near_contact_ns_ = t_ns;
  } else if (have_near_contact_ &&
             static_cast<double>(t_ns - t_near_contact_ns_) * 1e-9 < c.contact_floor_hold_s) {
    near_contact = true;  // held: the tool has just left contact, or bounced off
  }
  if (k <= 0.0) {
    reason = DeadbandReason::kOff;
  } else if (!have_sent_) {
    reason = DeadbandReason::kFirst;
  } else if (dt >= c.keepalive_s) {
    reason = DeadbandReason::kKeepAlive;
  } else {
    const double a =
        c.velocity_adaptive ? 1.0 + glm::length(V_WT_W.linear) / c.adaptive_speed_ref_m_per_s : 1.0;
    const double floor_p =
        near_contact ? c.contact_position_floor_scale_m : c.position_floor_scale_m;
    const double floor_theta =
        near_contact ? c.contact_rotation_floor_scale_rad : c.rotation_floor_scale_rad;
    const RigidTransform X_WT_predicted = ExtrapolatePose(X_sent_, V_sent_, dt);
    const Twist error = PoseDifference(X_WT, X_WT_predicted);
    const Twist moved = PoseDifference(X_WT, X_sent_);
    if (glm::length(error.linear) > std::max(k * glm::length(moved.linear), k * floor_p * a)) {
      reason = DeadbandReason::kPosition;
    } else if (glm::length(error.angular) >
               std::max(k * glm::length(moved.angular), k * floor_theta * a)) {
      reason = DeadbandReason::kRotation;
    } else if (near_contact && c.contact_depth_floor_scale_m > 0.0 && held_model != nullptr &&
               DepthLeftPrediction(*held_model, X_WT, X_WT_predicted, k,
                                   c.contact_depth_floor_scale_m)) {
      reason = DeadbandReason::kDepth;
    } else if (!c.velocity_criterion) {
      // Pose only: the twist is sent with every pose, for the receiver's extrapolation.
    } else if (glm::length(V_WT_W.linear - V_sent_.linear) >
               std::max(k * glm::length(V_sent_.linear),
                        k * c.linear_velocity_floor_scale_m_per_s)) {
      reason = DeadbandReason::kVelocity;
    } else if (glm::length(V_WT_W.angular - V_sent_.angular) >
               std::max(k * glm::length(V_sent_.angular),
                        k * c.angular_velocity_floor_scale_rad_per_s)) {
      reason = DeadbandReason::kAngularVelocity;
    }
  }
  ++counts_[static_cast<int>(reason)];
  if (reason != DeadbandReason::kNotSent) {
    have_sent_ = true;
    X_sent_ = X_WT;
    V_sent_ = V_WT_W;
    t_sent_ns_ = t_ns;
  }
  return reason;
}

namespace {

/// A contact of `model` names a depth field that no contact of `held` names.
bool NamesNewDepthField(const ContactModel& model, const ContactModel& held) noexcept {
  const int n = std::clamp(model.num_contacts, 0, kMaxContacts);
  const int m = std::clamp(held.num_contacts, 0, kMaxContacts);
  for (int i = 0; i < n; ++i) {
    const std::uint32_t id = model.contacts[static_cast<std::size_t>(i)].depth_field_id;
    if (id == 0) continue;
    bool found = false;
    for (int j = 0; j < m && !found; ++j) {
      found = held.contacts[static_cast<std::size_t>(j)].depth_field_id == id;
    }
    if (!found) return true;
  }
  return false;
}

}  // namespace

DeadbandReason ContactModelDeadband::Decide(const ContactModel& model, std::int64_t t_ns,
                                            std::span<const DepthField* const> fields) noexcept {
  const ContactModelDeadbandConfig& c = config_;
  const double k = c.weber_fraction;
  DeadbandReason reason = DeadbandReason::kNotSent;
  if (k <= 0.0) {
    reason = DeadbandReason::kOff;
  } else if (!have_sent_) {
    reason = DeadbandReason::kFirst;
  } else if (static_cast<double>(t_ns - t_sent_ns_) * 1e-9 >= c.keepalive_s) {
    reason = DeadbandReason::kKeepAlive;
  } else if (model.num_contacts != held_.num_contacts) {
    reason = DeadbandReason::kContactCount;
  } else if (NamesNewDepthField(model, held_)) {
    reason = DeadbandReason::kDepthField;
  } else {
    // A contact whose field is not among `fields` (none given) is evaluated by its linearization.
    const ContactModelEvaluation held = EvaluateContactModel(held_, model.X_WT0, fields);
    const ContactModelEvaluation now = EvaluateContactModel(model, model.X_WT0, fields);
    const double stiffness_t = Frobenius3(now.K, 0, 0);
    const double stiffness_r = Frobenius3(now.K, 3, 3);
    if (glm::length(held.F_T_W.force - now.F_T_W.force) >
        std::max(k * glm::length(now.F_T_W.force), k * c.force_floor_scale_n)) {
      reason = DeadbandReason::kForce;
    } else if (glm::length(held.F_T_W.torque - now.F_T_W.torque) >
               std::max(k * glm::length(now.F_T_W.torque), k * c.torque_floor_scale_nm)) {
      reason = DeadbandReason::kTorque;
    } else if ((held.K.block<3, 3>(0, 0) - now.K.block<3, 3>(0, 0)).norm() >
                   std::max(k * stiffness_t, k * c.stiffness_floor_scale_n_per_m) ||
               (held.K.block<3, 3>(3, 3) - now.K.block<3, 3>(3, 3)).norm() >
                   std::max(k * stiffness_r, k * c.rotational_stiffness_floor_scale_nm_per_rad)) {
      reason = DeadbandReason::kStiffness;
    }
  }
  ++counts_[static_cast<int>(reason)];
  if (reason != DeadbandReason::kNotSent) {
    have_sent_ = true;
    held_ = model;
    t_sent_ns_ = t_ns;
  }
  return reason;
}

}  // namespace ht
