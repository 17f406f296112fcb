#pragma once
// What each message's values must satisfy (internal to the wire format's files): Check(message),
// run on decode once a body's fields were read, in the order the checks apply.

#include "wire_fields.h"

namespace ht::wire::detail {

inline bool Finite3(const glm::dvec3& v) {
  return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}

inline DecodeStatus CheckPose(const RigidTransform& X) {
  const glm::dquat& q = X.rotation;
  if (!Finite3(X.translation) || !std::isfinite(q.w) || !std::isfinite(q.x) ||
      !std::isfinite(q.y) || !std::isfinite(q.z)) {
    return DecodeStatus::kNonFinite;
  }
  return IsFiniteRigidTransform(X) ? DecodeStatus::kOk : DecodeStatus::kBadValue;
}

inline bool FinitePositive(float v) { return std::isfinite(v) && v >= 0.0f; }

// Checks of the values, in the order they apply, run once a body's fields were read.

inline DecodeStatus Check(const EmptyBody&) { return DecodeStatus::kOk; }

inline DecodeStatus Check(const ToolStateMessage& m) {
  if (const DecodeStatus s = CheckPose(m.X_WT); s != DecodeStatus::kOk) return s;
  if (!IsFinite(m.V_WT_W)) return DecodeStatus::kNonFinite;
  return DecodeStatus::kOk;
}

inline DecodeStatus Check(const ContactModelMessage& m) {
  for (int i = 0; i < m.model.num_contacts; ++i) {
    const ContactLinearization& c = m.model.contacts[i];
    if (!std::isfinite(c.depth_m) || !Finite3(c.gradient.d_translation_W) ||
        !Finite3(c.gradient.d_rotation_W) || !std::isfinite(c.stiffness_n_per_m) ||
        !Finite3(c.point_W) || !Finite3(c.normal_W)) {
      return DecodeStatus::kNonFinite;
    }
    if (c.stiffness_n_per_m < 0.0) return DecodeStatus::kBadValue;
  }
  if (const DecodeStatus s = CheckPose(m.model.X_WT0); s != DecodeStatus::kOk) return s;
  if (!IsFinite(m.model.F_T_W_at_q0) || !std::isfinite(m.collision_us) ||
      !std::isfinite(m.texture_us) || !std::isfinite(m.step_us)) {
    return DecodeStatus::kNonFinite;
  }
  return DecodeStatus::kOk;
}

inline DecodeStatus Check(const DeadbandTerms& d) {
  if (!std::isfinite(d.tool_state_deadband) || !std::isfinite(d.model_deadband)) {
    return DecodeStatus::kNonFinite;
  }
  if (!(d.tool_state_deadband >= 0.0f && d.tool_state_deadband < 1.0f) ||
      !(d.model_deadband >= 0.0f && d.model_deadband < 1.0f) || d.tool_state_keepalive_ms == 0 ||
      d.model_keepalive_ms == 0) {
    return DecodeStatus::kBadValue;
  }
  return DecodeStatus::kOk;
}

inline DecodeStatus Check(const HelloMessage& m) {
  if (!std::isfinite(m.tool_state_rate_hz) || !std::isfinite(m.max_model_rate_hz)) {
    return DecodeStatus::kNonFinite;
  }
  if (const DecodeStatus s = Check(m.deadband); s != DecodeStatus::kOk) return s;
  if (m.min_version > m.max_version || !(m.tool_state_rate_hz > 0.0f) ||
      !FinitePositive(m.max_model_rate_hz) || m.mtu < kMinMtuBytes || m.mtu > kMaxDatagramBytes ||
      m.heartbeat_ms == 0 || m.peer_timeout_ms <= m.heartbeat_ms) {
    return DecodeStatus::kBadValue;
  }
  return DecodeStatus::kOk;
}

inline DecodeStatus Check(const WelcomeMessage& m) {
  if (const DecodeStatus s = Check(m.deadband); s != DecodeStatus::kOk) return s;
  const SceneLayout& l = m.layout;
  for (int i = 0; i < l.num_targets; ++i) {
    const WelcomeTarget& t = l.targets[i];
    if (!Finite3(t.box_min_W) || !Finite3(t.box_max_W) || !Finite3(t.top_W) ||
        !std::isfinite(t.approach_m)) {
      return DecodeStatus::kNonFinite;
    }
    if (t.box_min_W.x > t.box_max_W.x || t.box_min_W.y > t.box_max_W.y ||
        t.box_min_W.z > t.box_max_W.z || t.approach_m < 0.0) {
      return DecodeStatus::kBadValue;
    }
  }
  if (const DecodeStatus s = CheckPose(l.X_WT_home); s != DecodeStatus::kOk) return s;
  if (!std::isfinite(l.tool_mass_kg) || !Finite3(l.tool_inertia_diagonal_T) ||
      !std::isfinite(l.tool_extent_down_m)) {
    return DecodeStatus::kNonFinite;
  }
  if (l.tool_mass_kg < 0.0 || l.tool_extent_down_m < 0.0 ||
      (l.tool_mass_kg > 0.0 &&
       !(l.tool_inertia_diagonal_T.x > 0.0 && l.tool_inertia_diagonal_T.y > 0.0 &&
         l.tool_inertia_diagonal_T.z > 0.0))) {
    return DecodeStatus::kBadValue;
  }
  if (!std::isfinite(m.tool_state_rate_hz) || !std::isfinite(m.model_rate_hz) ||
      !std::isfinite(m.window_m)) {
    return DecodeStatus::kNonFinite;
  }
  if (m.scene_name_length > kSceneNameBytes || !(m.tool_state_rate_hz > 0.0f) ||
      !FinitePositive(m.model_rate_hz) || !(m.window_m > 0.0f) || m.grid < 2 ||
      m.mtu < kMinMtuBytes || m.mtu > kMaxDatagramBytes || m.heartbeat_ms == 0 ||
      m.peer_timeout_ms <= m.heartbeat_ms) {
    return DecodeStatus::kBadValue;
  }
  return DecodeStatus::kOk;
}

inline DecodeStatus Check(const RejectMessage& m) {
  const auto reason = static_cast<std::uint8_t>(m.reason);
  return reason < 1 || reason > 3 ? DecodeStatus::kBadValue : DecodeStatus::kOk;
}

inline DecodeStatus Check(const PingMessage&) { return DecodeStatus::kOk; }

inline DecodeStatus Check(const PongMessage& m) {
  return m.ping_sequence == 0 ? DecodeStatus::kBadValue : DecodeStatus::kOk;
}

inline DecodeStatus Check(const SceneFragmentMessage& m) {
  if (m.object_bytes == 0 || m.object_bytes > kMaxSceneObjectBytes || m.fragment_count == 0 ||
      m.fragment_index >= m.fragment_count || m.payload.size() > m.object_bytes) {
    return DecodeStatus::kBadValue;
  }
  return DecodeStatus::kOk;
}

inline DecodeStatus Check(const SceneManifestMessage& m) {
  if (static_cast<std::size_t>(m.first_index) + m.count > m.total_objects) {
    return DecodeStatus::kBadValue;
  }
  for (int i = 0; i < m.count; ++i) {
    const ManifestEntry& e = m.entries[static_cast<std::size_t>(i)];
    const auto kind = static_cast<int>(e.kind);
    if (kind < 1 || kind > kMaxSceneObjectKind || e.object_bytes == 0 ||
        e.object_bytes > kMaxSceneObjectBytes || e.fragment_count == 0) {
      return DecodeStatus::kBadValue;
    }
  }
  return DecodeStatus::kOk;
}

inline DecodeStatus Check(const SceneNackMessage&) { return DecodeStatus::kOk; }

/// Squared norm of a NodePose rotation, in double (an f32 sum of squares could underflow).
inline double Norm2(const glm::quat& q) {
  return static_cast<double>(q.w) * q.w + static_cast<double>(q.x) * q.x +
         static_cast<double>(q.y) * q.y + static_cast<double>(q.z) * q.z;
}

inline DecodeStatus Check(const NodePosesMessage& m) {
  if (!std::isfinite(m.scene_time_s)) return DecodeStatus::kNonFinite;
  for (int i = 0; i < m.count; ++i) {
    const NodePose& p = m.poses[static_cast<std::size_t>(i)];
    const glm::quat& q = p.rotation;
    if (!std::isfinite(p.translation.x) || !std::isfinite(p.translation.y) ||
        !std::isfinite(p.translation.z) || !std::isfinite(q.w) || !std::isfinite(q.x) ||
        !std::isfinite(q.y) || !std::isfinite(q.z) || !std::isfinite(p.scale.x) ||
        !std::isfinite(p.scale.y) || !std::isfinite(p.scale.z)) {
      return DecodeStatus::kNonFinite;
    }
    if (!(Norm2(q) >= kMinNodePoseQuaternionNorm * kMinNodePoseQuaternionNorm)) {
      return DecodeStatus::kBadValue;
    }
  }
  return DecodeStatus::kOk;
}

/// Header, body and MAC: the one encoder of every message type; `version` goes in the header

}  // namespace ht::wire::detail
