// Stage 3 of the operator tick (operator_tick.h): the virtual coupling between the handle and the
// simulated tool, and the implicit (linearized backward-Euler) tool step against the contact
// model in use, blended with the one before while stage 2 blends (ToolSimulator::StepBlended).

#include <algorithm>
#include <cmath>

#include "master_station/operator_tick.h"

namespace ht {

Wrench OperatorTick::StepTool(const RigidTransform& X_WH, const Twist& V_WH_W, bool blending,
                              OperatorTickOutput& out) noexcept {
  const double h = config_.h_s;
  if (blending) {
    out.step = simulator_.StepBlended(tool_, X_WH, V_WH_W, model_, previous_model_,
                                      static_cast<double>(blend_tick_) / config_.model_blend_ticks,
                                      h, &fields_);
  } else {
    out.step = simulator_.Step(tool_, X_WH, V_WH_W, model_, 1.0, h, &fields_);
  }
  if (!out.step.ok) ++counters_.nonfinite;
  if (out.step.field_contacts > 0) ++counters_.field_ticks;
  if (out.step.field_fallbacks > 0) ++counters_.field_fallback_ticks;
  if (out.step.field_beyond_margin > 0) ++counters_.field_beyond_margin_ticks;
  if (out.step.saturated_contacts > 0) ++counters_.saturated_contact_ticks;
  Wrench F_H_W = -out.step.F_coupling_T_W;
  if (!IsFinite(F_H_W)) {
    ++counters_.nonfinite;
    F_H_W = {};
  }
  if (!IsFinite(out.step.F_contact_T_W) || !IsFiniteRigidTransform(tool_.X_WT)) {
    ++counters_.nonfinite;
  }
  return F_H_W;
}

}  // namespace ht
