#include "haptic_core/passivity.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace ht {

double DevicePower(const Wrench& F, const Twist& V) noexcept {
  return glm::dot(F.force, V.linear) + glm::dot(F.torque, V.angular);
}

PassivityController::PassivityController(double min_speed, double max_damping_ns_per_m,
                                         double angular_weight_m)
    : min_speed_(min_speed),
      max_damping_(max_damping_ns_per_m),
      angular_weight_m_(angular_weight_m) {
  if (!(min_speed >= 0.0) || !std::isfinite(min_speed) || !(max_damping_ns_per_m >= 0.0) ||
      !std::isfinite(max_damping_ns_per_m) || !(angular_weight_m > 0.0) ||
      !std::isfinite(angular_weight_m)) {
    throw std::invalid_argument(
        "passivity controller: min speed and max damping must be finite and >= 0, angular weight "
        "finite and > 0");
  }
}

Wrench PassivityController::Apply(const Wrench& F, const Twist& V, double h) noexcept {
  const double predicted = energy_j_ - DevicePower(F, V) * h;
  if (predicted >= 0.0) return F;
  // Weighted twist: rotation counts as motion of a point angular_weight_m from the axis.
  const double L2 = angular_weight_m_ * angular_weight_m_;
  const double speed2 = glm::dot(V.linear, V.linear) + L2 * glm::dot(V.angular, V.angular);
  if (speed2 <= min_speed_ * min_speed_ || !(h > 0.0)) return F;
  // F' = F − α (v, L² ω): F'·V = F·V − α·speed2, and E_k = predicted + α·speed2·h = 0.
  double alpha = -predicted / (speed2 * h);
  if (max_damping_ > 0.0 && alpha > max_damping_) alpha = max_damping_;
  Wrench out = F;
  out.force -= alpha * V.linear;
  out.torque -= alpha * L2 * V.angular;
  ++active_ticks_;
  dissipated_j_ += alpha * speed2 * h;
  force_damped_away_ns_ += alpha * glm::length(V.linear) * h;
  if (alpha > max_alpha_) max_alpha_ = alpha;
  // The capped damping was not enough: scale the wrench itself down to what keeps E_k ≥ 0.
  return Guard(out, V, h);
}

Wrench PassivityController::Guard(const Wrench& F, const Twist& V, double h) noexcept {
  const double p = DevicePower(F, V);
  if (!(p > 0.0) || !(h > 0.0) || !std::isfinite(p)) return F;  // no work done on the hand
  if (energy_j_ - p * h >= 0.0) return F;
  // The least change of F (in the weighted metric) whose power keeps E ≥ 0: only the part of F
  // along the hand's weighted twist does work, so only that part is cut, by β·(v, L²ω) with
  //   p' = p − β·speed2 = max(E, 0)/h.
  // The cut is at most F's component along the motion (β·|Ṽ| ≤ p/|Ṽ|); the rest of F, which
  // does no work, is kept (scaling the whole wrench dropped the normal force of a sliding tool
  // for a tick whenever the hand's motion met an empty energy store: docs/hard-cases.md).
  const double L2 = angular_weight_m_ * angular_weight_m_;
  const double speed2 = glm::dot(V.linear, V.linear) + L2 * glm::dot(V.angular, V.angular);
  const double allowed = std::max(energy_j_, 0.0) / h;
  Wrench out = F;
  if (speed2 > 0.0 && std::isfinite(speed2)) {
    const double beta = (p - allowed) / speed2;
    out.force -= beta * V.linear;
    out.torque -= beta * L2 * V.angular;
  }
  // Rounding leaves the power a few ulps off what is allowed (with an empty store, ±1e-18 W):
  // that is no energy the port could feel. Past 1e-15 J over the tick (a twist too small to
  // carry the cut), what is left is scaled.
  const double p_out = DevicePower(out, V);
  if (!((p_out - allowed) * h <= 1e-15) || !std::isfinite(p_out)) {
    const double s =
        p_out > 0.0 && std::isfinite(p_out) ? std::clamp(allowed / p_out, 0.0, 1.0) : 0.0;
    out = {s * out.force, s * out.torque};
  }
  ++scaled_ticks_;
  force_scaled_away_ns_ += glm::length(F.force - out.force) * h;
  scaled_away_j_ += (p - DevicePower(out, V)) * h;
  return out;
}

void PassivityController::Commit(const Wrench& F, const Twist& V, double h) noexcept {
  const double p = DevicePower(F, V);
  if (!std::isfinite(p) || !(h > 0.0)) return;
  energy_j_ -= p * h;
  if (p > 0.0) {
    energy_out_j_ += p * h;
  } else {
    energy_in_j_ -= p * h;
  }
}

void PassivityController::Reset() noexcept {
  energy_j_ = energy_in_j_ = energy_out_j_ = dissipated_j_ = max_alpha_ = 0.0;
  force_scaled_away_ns_ = force_damped_away_ns_ = scaled_away_j_ = 0.0;
  active_ticks_ = scaled_ticks_ = 0;
}

}  // namespace ht
