#include "haptic_core/passivity.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace ht {

namespace {
// Time over which the energy reserve's shortfall is made up (s).
constexpr double kReserveRefillS = 0.1;
}  // namespace

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

void PassivityController::set_energy_reserve(double reserve_j, double refill_fraction) {
  if (!(reserve_j >= 0.0) || !std::isfinite(reserve_j) || !(refill_fraction >= 0.0) ||
      !(refill_fraction < 1.0)) {
    throw std::invalid_argument(
        "passivity controller: the energy reserve must be finite and >= 0, the refill fraction "
        "in [0, 1)");
  }
  reserve_j_ = reserve_j;
  refill_fraction_ = refill_fraction;
}

Wrench PassivityController::Apply(const Wrench& F, const Twist& V, double h) noexcept {
  const double predicted = energy_j_ - DevicePower(F, V) * h;
  const bool refill = predicted >= 0.0;  // passive this tick; only the reserve is short
  if (refill && (predicted >= reserve_j_ || refill_fraction_ <= 0.0)) return F;
  // Weighted twist: rotation counts as motion of a point angular_weight_m from the axis.
  const double L2 = angular_weight_m_ * angular_weight_m_;
  const double speed2 = glm::dot(V.linear, V.linear) + L2 * glm::dot(V.angular, V.angular);
  if (speed2 <= min_speed_ * min_speed_ || !(h > 0.0)) return F;
  // The reserve's refill: the shortfall made up over kReserveRefillS rather than one tick (α
  // grows from zero as E falls below the reserve: no step in the force), with α·|Ṽ| ≤
  // refill_fraction·|F̃| in the same weighting (zero for a zero wrench).
  double alpha_refill = 0.0;
  if (reserve_j_ > 0.0 && refill_fraction_ > 0.0) {
    const double wrench_norm =
        std::sqrt(glm::dot(F.force, F.force) + glm::dot(F.torque, F.torque) / L2);
    alpha_refill = std::min((reserve_j_ - predicted) / (speed2 * kReserveRefillS),
                            refill_fraction_ * wrench_norm / std::sqrt(speed2));
  }
  // F' = F − α (v, L² ω): F'·V = F·V − α·speed2. Below zero, α makes E_k = predicted +
  // α·speed2·h = 0, and no less than the refill's (so that the damping does not drop where E
  // crosses zero).
  double alpha = refill ? alpha_refill : std::max(-predicted / (speed2 * h), alpha_refill);
  if (max_damping_ > 0.0 && alpha > max_damping_) alpha = max_damping_;
  if (!(alpha > 0.0)) return F;
  Wrench out = F;
  out.force -= alpha * V.linear;
  out.torque -= alpha * L2 * V.angular;
  if (refill) {
    ++refill_ticks_;
    refilled_j_ += alpha * speed2 * h;
    force_refilled_ns_ += alpha * glm::length(V.linear) * h;
    return out;  // E stays ≥ 0: F'·V ≤ F·V
  }
  ++active_ticks_;
  dissipated_j_ += alpha * speed2 * h;
  force_damped_away_ns_ += alpha * glm::length(V.linear) * h;
  if (alpha > max_alpha_) max_alpha_ = alpha;
  // The capped damping was not enough: the guard cuts what is left along the motion.
  return Guard(out, V, h);
}

Wrench PassivityController::Guard(const Wrench& F, const Twist& V, double h) noexcept {
  const double p = DevicePower(F, V);
  if (!(p > 0.0) || !(h > 0.0) || !std::isfinite(p)) return F;  // no work done on the hand
  if (energy_j_ - p * h >= 0.0) return F;
  // The power to take away, Δ = p − max(E, 0)/h, is taken from the halves that do positive
  // work, in proportion to it: the force's share r_f by cutting f along v, the torque's r_τ by
  // cutting τ along ω. Each cut is at most that half's own component along its motion
  // (r ≤ its power), so neither |f| nor |τ| grows and what does no work is kept (scaling the whole
  // wrench dropped the normal force of a sliding tool for a tick whenever the hand's motion met
  // an empty energy store: docs/hard-cases.md).
  const double allowed = std::max(energy_j_, 0.0) / h;
  const double excess = p - allowed;
  const double p_f = glm::dot(F.force, V.linear), p_t = glm::dot(F.torque, V.angular);
  const double pf_pos = std::max(p_f, 0.0), pt_pos = std::max(p_t, 0.0);
  const double v2 = glm::dot(V.linear, V.linear), w2 = glm::dot(V.angular, V.angular);
  Wrench out = F;
  if (pf_pos + pt_pos > 0.0) {
    const double r_f = excess * pf_pos / (pf_pos + pt_pos);
    const double r_t = excess - r_f;
    if (r_f > 0.0 && v2 > 0.0) out.force -= (std::min(r_f, pf_pos) / v2) * V.linear;
    if (r_t > 0.0 && w2 > 0.0) out.torque -= (std::min(r_t, pt_pos) / w2) * V.angular;
  }
  // Rounding leaves the power a few ulps off what is allowed (with an empty store, ±1e-18 W):
  // that is no energy the port could feel. Past 1e-15 J over the tick, what is left is scaled.
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
  refilled_j_ = force_refilled_ns_ = 0.0;
  active_ticks_ = scaled_ticks_ = refill_ticks_ = 0;
}

}  // namespace ht
