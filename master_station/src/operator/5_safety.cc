// Stage 5 of the operator tick (operator_tick.h): the safety filter on every tick, a failed device
// read included (non-finite → zero, fade when stale or the link is lost, brake, clamp, rate
// limit), then the stop ramp's gain.

#include <algorithm>
#include <cmath>

#include "master_station/operator_tick.h"

namespace ht {

Wrench OperatorTick::LimitWrench(const Wrench& F_H_W, const Twist& V_WH_W, double model_staleness_s,
                                 const OperatorTickInput& in, OperatorTickOutput& out) noexcept {
  Wrench F = safety_.Filter(F_H_W, V_WH_W, model_staleness_s, in.link_connected, config_.h_s,
                            out.safety_actions);
  const double gain = std::isnan(in.output_gain) ? 0.0 : std::clamp(in.output_gain, 0.0, 1.0);
  if (gain < 1.0) F = {gain * F.force, gain * F.torque};
  return F;
}

}  // namespace ht
