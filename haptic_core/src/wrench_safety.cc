#include "haptic_core/wrench_safety.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace ht {
namespace {

bool ClampLength(glm::dvec3& v, double limit) noexcept {
  const double len = glm::length(v);
  if (len <= limit) return false;
  v *= limit / len;
  return true;
}

/// Moves `from` toward `to` by at most `step` (vector distance).
bool StepToward(glm::dvec3& to, const glm::dvec3& from, double step) noexcept {
  const glm::dvec3 d = to - from;
  const double len = glm::length(d);
  if (len <= step) return false;
  to = from + d * (step / len);
  return true;
}

}  // namespace

void SafetyLimits::Validate() const {
  const auto positive = [](double v, const char* name) {
    if (!(v > 0.0) || !std::isfinite(v)) {
      throw std::invalid_argument(std::string("safety limit ") + name +
                                  " must be positive and finite, got " + std::to_string(v));
    }
  };
  positive(max_force_n, "max_force_n");
  positive(max_torque_nm, "max_torque_nm");
  positive(max_force_rate_n_per_s, "max_force_rate_n_per_s");
  positive(max_torque_rate_nm_per_s, "max_torque_rate_nm_per_s");
  positive(brake_speed_m_per_s, "brake_speed_m_per_s");
  positive(brake_angular_speed_rad_per_s, "brake_angular_speed_rad_per_s");
  positive(model_timeout_s, "model_timeout_s");
  positive(fade_out_s, "fade_out_s");
  positive(fade_in_s, "fade_in_s");
  if (!(brake_damping_ns_per_m >= 0.0) || !(brake_damping_nms_per_rad >= 0.0)) {
    throw std::invalid_argument("safety limit: brake damping must be >= 0");
  }
}

WrenchSafetyFilter::WrenchSafetyFilter(const SafetyLimits& limits) : limits_(limits) {
  limits_.Validate();
}

Wrench WrenchSafetyFilter::Filter(const Wrench& F_desired_W, const Twist& V_WH_W,
                                  double model_staleness_s, bool link_up, double h,
                                  std::uint32_t& actions) noexcept {
  actions = kSafetyNone;
  if (!(h > 0.0) || !std::isfinite(h)) h = 1e-3;
  Wrench F = F_desired_W;  // in W throughout
  if (!IsFinite(F)) {
    F = {};
    actions |= kSafetyNonFinite;
    ++counters_.nonfinite;
  }
  // Fade: to zero over fade_out_s when stale or the link is lost; back over fade_in_s.
  const bool stale =
      !link_up || (model_staleness_s >= 0.0 && model_staleness_s > limits_.model_timeout_s);
  gain_ = stale ? std::max(0.0, gain_ - h / limits_.fade_out_s)
                : std::min(1.0, gain_ + h / limits_.fade_in_s);
  if (gain_ < 1.0) {
    F.force *= gain_;
    F.torque *= gain_;
    actions |= kSafetyFading;
    ++counters_.fading;
  }
  // Brake: above the speed limit the device only dissipates.
  if (IsFinite(V_WH_W) && (glm::length(V_WH_W.linear) > limits_.brake_speed_m_per_s ||
                           glm::length(V_WH_W.angular) > limits_.brake_angular_speed_rad_per_s)) {
    F.force = -limits_.brake_damping_ns_per_m * V_WH_W.linear;
    F.torque = -limits_.brake_damping_nms_per_rad * V_WH_W.angular;
    actions |= kSafetyBraking;
    ++counters_.braking;
  }
  bool clamped = ClampLength(F.force, limits_.max_force_n);
  clamped |= ClampLength(F.torque, limits_.max_torque_nm);
  // Rate limit (the brake and a fade to zero are rate-limited too: no step in force).
  bool limited = StepToward(F.force, previous_.force, limits_.max_force_rate_n_per_s * h);
  limited |= StepToward(F.torque, previous_.torque, limits_.max_torque_rate_nm_per_s * h);
  if (clamped) {
    actions |= kSafetyClamped;
    ++counters_.clamped;
  }
  if (limited) {
    actions |= kSafetyRateLimited;
    ++counters_.rate_limited;
  }
  previous_ = F;
  return F;
}

}  // namespace ht
