// Stage 4 of the operator tick (operator_tick.h): the time-domain passivity controller (Ryu, Kwon
// & Hannaford 2004) on the hand–device port: its damping before the safety stage (Apply), and
// after it its guard, the release of what it cut, and the observer's record of what the device
// really gets (Guard, Commit).

#include <algorithm>
#include <cmath>

#include "master_station/operator_tick.h"

namespace ht {

Wrench OperatorTick::ApplyPassivity(const Wrench& F_H_W, const Twist& V_WH_W,
                                    OperatorTickOutput& out, double& f_after_apply) noexcept {
  if (!config_.passivity) return F_H_W;
  const Wrench F = passivity_.Apply(F_H_W, V_WH_W, config_.h_s);
  out.passivity_removed_n += glm::length(F_H_W.force - F.force);
  f_after_apply = glm::length(F.force);
  return F;
}

Wrench OperatorTick::GuardPassivity(const Wrench& F_in_W, const Twist& V_WH_W, bool device_ok,
                                    double f_after_apply, OperatorTickOutput& out) noexcept {
  const double h = config_.h_s;
  Wrench F_H_W = F_in_W;
  // The safety stage's rate limit can hold back a drop passivity asked for: the guard cuts what
  // is left along the hand's motion so that the observed energy never goes negative.
  if (config_.passivity) {
    const glm::dvec3 before = F_H_W.force;
    F_H_W = passivity_.Guard(F_H_W, V_WH_W, h);
    // The release: a force the stage cut comes back over passivity_release_ticks ticks.
    // The fraction kept is the passivity stage's own (Apply's, then Guard's), not the safety
    // stage's clamps or ramps.
    if (config_.passivity_release_ticks > 0 && device_ok) {
      const auto ratio = [](double a, double b) { return b > 1e-9 ? std::min(1.0, a / b) : 1.0; };
      double kept = ratio(f_after_apply, glm::length(out.step.F_coupling_T_W.force)) *
                    ratio(glm::length(F_H_W.force), glm::length(before));
      if (kept > passivity_release_gain_) {
        const double s = passivity_release_gain_ / kept;
        F_H_W = {s * F_H_W.force, s * F_H_W.torque};
        kept = passivity_release_gain_;
      }
      passivity_release_gain_ = std::min(1.0, kept + 1.0 / config_.passivity_release_ticks);
    }
    out.passivity_removed_n += glm::length(before - F_H_W.force);
  }
  passivity_.Commit(F_H_W, V_WH_W, h);
  return F_H_W;
}

}  // namespace ht
