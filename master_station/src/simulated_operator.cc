#include "master_station/simulated_operator.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace ht {

SimulatedOperatorDevice::SimulatedOperatorDevice(const Experiment& experiment,
                                                 const OperatorHandParams& hand)
    : experiment_(experiment), hand_(hand) {
  if (!(hand.mass_kg > 0.0) || !(hand.inertia_kg_m2 > 0.0) || hand.substeps < 1) {
    throw std::invalid_argument("simulated operator: mass, inertia and substeps must be positive");
  }
}

DeviceCapabilities SimulatedOperatorDevice::capabilities() const {
  DeviceCapabilities c;
  c.name = "simulated operator (" + experiment_.name() + ")";
  c.max_force_n = 10.0;
  c.max_torque_nm = 1.0;
  c.max_stiffness_n_per_m = 3000.0;
  c.max_rotational_stiffness_nm_per_rad = 5.0;
  c.max_damping_ns_per_m = 40.0;
  c.rated_loop_rate_hz = 1000.0;
  c.workspace_half_extents_m = {0.1, 0.1, 0.1};
  c.dof_in = 6;
  c.dof_out = 6;
  c.scripted = true;
  return c;
}

HandTarget SimulatedOperatorDevice::ControlZ(const HandTarget& script, double dt) noexcept {
  HandTarget target = script;
  target.X_MH.translation -= script.workspace_shift_M;  // into the (moved) workspace
  target.floor_z_m -= script.workspace_shift_M.z;
  target.slow_below_z_m -= script.workspace_shift_M.z;
  const double script_z = target.X_MH.translation.z;
  if (script.z_control != z_mode_) {  // entering a mode: start from where the hand is
    if (script.z_control != HandZControl::kPosition) {
      const double here = state_.X_MH.translation.z;
      z_hand_ = z_free_ ? std::min(here, script_z) : z_hand_;
      lift_start_z_ = std::min(here, z_hand_);
      z_free_ = false;
    }
    z_mode_ = script.z_control;
  }
  double rate = 0.0;
  switch (script.z_control) {
    case HandZControl::kPress: {
      const double felt_up_n = F_H_M_.force.z;
      const double fast = z_hand_ > target.slow_below_z_m ? hand_.press_fast_speed_m_per_s
                                                          : hand_.press_slow_speed_m_per_s;
      // Nothing felt yet: come down at the approach speed; then regulate the force.
      rate = felt_up_n < 0.25 * script.press_force_n
                 ? -fast
                 : std::clamp(hand_.press_gain_m_per_s_per_n * (felt_up_n - script.press_force_n),
                              -fast, hand_.press_slow_speed_m_per_s);
      const double z =
          std::clamp(z_hand_ + rate * dt, std::min(target.floor_z_m, script_z), script_z);
      rate = (z - z_hand_) / dt;  // 0 once at the floor or the ceiling
      z_hand_ = z;
      break;
    }
    case HandZControl::kLift: {
      const double top = std::min(lift_start_z_ + script.lift_m, script_z);
      rate = z_hand_ < top ? hand_.press_slow_speed_m_per_s : 0.0;
      z_hand_ = std::min(z_hand_ + rate * dt, std::max(top, z_hand_));
      // Out along the contact's normal: sideways as the felt force pushes, in proportion.
      const double felt_n = glm::length(F_H_M_.force);
      if (felt_n > 1e-3) {
        const glm::dvec3 side(F_H_M_.force.x, F_H_M_.force.y, 0.0);
        release_offset_M_ += (hand_.press_slow_speed_m_per_s * dt / felt_n) * side;
        const double length = glm::length(release_offset_M_);
        if (length > hand_.release_offset_max_m) {
          release_offset_M_ *= hand_.release_offset_max_m / length;
        }
        release_shift_M_ = script.workspace_shift_M;
      }
      break;
    }
    case HandZControl::kPosition:
      if (!z_free_) {  // back to the script's z, at no more than the fast speed
        const double step = hand_.press_fast_speed_m_per_s * dt;
        if (std::abs(script_z - z_hand_) <= step) {
          z_free_ = true;
        } else {
          rate =
              script_z > z_hand_ ? hand_.press_fast_speed_m_per_s : -hand_.press_fast_speed_m_per_s;
          z_hand_ += rate * dt;
        }
      }
      break;
  }
  if (!z_free_) {
    target.X_MH.translation.z = z_hand_;
    target.V_MH_M.linear.z = rate;
  }
  // A lift's sideways offset: kept while the script holds the hand's x and y, taken back at the
  // fast speed as soon as it moves them (a transfer across, a slide), dropped at a jump.
  if (script.workspace_shift_M != release_shift_M_) release_offset_M_ = glm::dvec3(0.0);
  if (script.z_control != HandZControl::kLift &&
      (script.V_MH_M.linear.x != 0.0 || script.V_MH_M.linear.y != 0.0)) {
    const double length = glm::length(release_offset_M_);
    const double step = hand_.press_fast_speed_m_per_s * dt;
    release_offset_M_ *= length > step ? (length - step) / length : 0.0;
  }
  target.X_MH.translation.x += release_offset_M_.x;
  target.X_MH.translation.y += release_offset_M_.y;
  return target;
}

void SimulatedOperatorDevice::Open() {
  open_ = true;
  started_ = false;
  F_H_M_ = {};
}

void SimulatedOperatorDevice::Close() noexcept {
  F_H_M_ = {};
  open_ = false;
}

bool SimulatedOperatorDevice::ReadState(std::int64_t now_ns, DeviceState& out) noexcept {
  if (!open_) return false;
  if (!started_) {  // the hand starts at the experiment's first target
    started_ = true;
    t0_ns_ = now_ns;
    last_ns_ = now_ns;
    const HandTarget start = experiment_.Target(0.0);
    state_.X_MH = start.X_MH;
    state_.X_MH.translation -= start.workspace_shift_M;
    state_.V_MH_M = {};
    z_free_ = true;
    z_mode_ = HandZControl::kPosition;
    z_hand_ = state_.X_MH.translation.z;
    release_offset_M_ = glm::dvec3(0.0);
    release_shift_M_ = start.workspace_shift_M;
  }
  // Integrate the hand from the last reading to now (at most 50 ms at once after a stall).
  const double dt_total = std::clamp((now_ns - last_ns_) * 1e-9, 0.0, 0.05);
  const double dt = dt_total / hand_.substeps;
  const HandTarget script = experiment_.Target((now_ns - t0_ns_) * 1e-9);
  phase_ = script.phase;
  for (int i = 0; i < hand_.substeps && dt > 0.0; ++i) {
    Twist& V = state_.V_MH_M;
    RigidTransform& X = state_.X_MH;
    const HandTarget target = ControlZ(script, dt);
    const Twist err = PoseDifference(target.X_MH, X);
    const glm::dvec3 force = hand_.stiffness_n_per_m * err.linear +
                             hand_.damping_ns_per_m * (target.V_MH_M.linear - V.linear) +
                             F_H_M_.force;
    const glm::dvec3 torque =
        hand_.rotational_stiffness_nm_per_rad * err.angular +
        hand_.rotational_damping_nms_per_rad * (target.V_MH_M.angular - V.angular) + F_H_M_.torque;
    V.linear += dt * force / hand_.mass_kg;
    V.angular += dt * torque / hand_.inertia_kg_m2;
    X = Displace(X, {dt * V.linear, dt * V.angular});
    energy_to_operator_j_ +=
        dt * (glm::dot(F_H_M_.force, V.linear) + glm::dot(F_H_M_.torque, V.angular));
  }
  last_ns_ = now_ns;
  state_.timestamp_ns = now_ns;
  out = state_;
  return IsFiniteRigidTransform(out.X_MH) && IsFinite(out.V_MH_M);
}

bool SimulatedOperatorDevice::WriteWrench(const Wrench& F_H_M, std::int64_t) noexcept {
  if (!open_ || !IsFinite(F_H_M)) {
    F_H_M_ = {};
    return false;
  }
  F_H_M_ = F_H_M;
  return true;
}

}  // namespace ht
