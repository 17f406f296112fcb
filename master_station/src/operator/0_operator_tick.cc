// The operator tick (operator_tick.h), stage by stage: this folder's listing is their order.
// This file: the tick's constructor, the tick as the list of its stages, and the scripted
// workspace jump (not a stage: the experiment driver's, between ticks).

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "master_station/operator_tick.h"

namespace ht {

OperatorTick::OperatorTick(const OperatorTickConfig& config, const RigidTransform& X_WM,
                           const ToolState& tool_start)
    : config_(config),
      simulator_(config.inertia, config.coupling),
      passivity_(1e-4, config.passivity_max_damping_ns_per_m),
      safety_(config.safety),
      X_WM_(X_WM),
      tool_(tool_start),
      X_WH_last_(tool_start.X_WT),
      fields_(4 * kMaxContacts + 4),
      blend_tick_(config.model_blend_ticks) {
  if (config.model_blend_ticks < 1) {
    throw std::invalid_argument("model blend ticks must be >= 1, got " +
                                std::to_string(config.model_blend_ticks));
  }
  if (!(config.h_s > 0.0)) throw std::invalid_argument("tick length must be positive");
  if (config.passivity_release_ticks < 0) {
    throw std::invalid_argument("passivity release ticks must be >= 0, got " +
                                std::to_string(config.passivity_release_ticks));
  }
  if (!(config.switch_energy_spend_fraction > 0.0 && config.switch_energy_spend_fraction <= 1.0)) {
    throw std::invalid_argument("switch energy spend fraction must be in (0, 1], got " +
                                std::to_string(config.switch_energy_spend_fraction));
  }
  if (!(config.switch_bound_min_age_ms >= 0.0)) {
    throw std::invalid_argument("switch bound min age must be >= 0 ms, got " +
                                std::to_string(config.switch_bound_min_age_ms));
  }
  if (!(config.switch_offset_release_ms > 0.0)) {
    throw std::invalid_argument("switch offset release must be > 0 ms, got " +
                                std::to_string(config.switch_offset_release_ms));
  }
  passivity_.set_energy_reserve(config.passivity_reserve_j, config.passivity_refill_fraction);
  simulator_.set_max_contact_force(config.max_contact_force_n);
  simulator_.set_contact_damping_hunt_crossley(config.hunt_crossley_s_per_m);
}

OperatorTickOutput OperatorTick::Step(const OperatorTickInput& in) noexcept {
  OperatorTickOutput out;
  // The contact potential before a model or blend change (issue 33's attribution): evaluated
  // only on ticks that change it.
  const bool potential_changes = in.arrived != nullptr || blend_tick_ < config_.model_blend_ticks;
  const double U_before = potential_changes ? LoopPotential(tool_.X_WT) : 0.0;

  // Stage 1: the contact model in use, with its depth fields.
  TakeArrivedFields(in);
  const bool took_model = TakeArrivedModel(in.arrived);
  if (have_model_) out.model_age_ms = (in.now_ns - model_stamp_.tool_state_sent_ns) * 1e-6;
  const double model_staleness_s =
      have_model_ ? (in.now_ns - model_stamp_.built_local_ns) * 1e-9 : -1.0;

  Wrench F_H_W;
  Twist V_WH_W;
  double f_after_apply = 0.0;  // |f| after passivity's Apply (N), for its release
  if (!in.device_ok) {
    // The device read failed: hold the tool, observe no motion, and let the safety stage ramp
    // the last force down (and back up once the device answers again).
    ++counters_.device_faults;
    out.X_WH = X_WH_last_;
    AttributeSwitch(potential_changes, U_before, out.model_age_ms);
  } else {
    out.X_WH = X_WM_ * in.device.X_MH;
    X_WH_last_ = out.X_WH;
    V_WH_W = {X_WM_.rotation * in.device.V_MH_M.linear, X_WM_.rotation * in.device.V_MH_M.angular};
    // Stage 2: the blend from the model before to the one in use, its switch energy bounded.
    const bool blending = StepBlend(took_model, potential_changes, U_before, out);
    // Stage 3: virtual coupling and the implicit tool step against the (blended) model.
    F_H_W = StepTool(out.X_WH, V_WH_W, blending, out);
    // Stage 4: passivity (energy a delayed model created is dissipated).
    F_H_W = ApplyPassivity(F_H_W, V_WH_W, out, f_after_apply);
  }
  // Stage 5: safety, on every tick, then the stop ramp's gain; then stage 4's guard and release,
  // and the observer records what the device really gets.
  F_H_W = LimitWrench(F_H_W, V_WH_W, model_staleness_s, in, out);
  F_H_W = GuardPassivity(F_H_W, V_WH_W, in.device_ok, f_after_apply, out);
  out.F_H_W = F_H_W;
  const glm::dquat R_MW = glm::conjugate(X_WM_.rotation);
  out.F_H_M = {R_MW * F_H_W.force, R_MW * F_H_W.torque};
  return out;
}

bool OperatorTick::ShiftWorkspace(const glm::dvec3& workspace_shift_M) noexcept {
  if (workspace_shift_M == workspace_shift_M_) return false;
  // The workspace and the tool jump together, in free space, and the contact models of the old
  // place are dropped (stage 1 drops those still in flight).
  const glm::dvec3 jump_W = X_WM_.rotation * (workspace_shift_M - workspace_shift_M_);
  jumped_from_W_ = tool_.X_WT.translation;
  after_jump_ = true;
  X_WM_.translation += jump_W;
  tool_.X_WT.translation += jump_W;
  workspace_shift_M_ = workspace_shift_M;
  model_ = ContactModel{};
  previous_model_ = ContactModel{};
  depth_offset_m_ = 0.0;
  blend_tick_ = config_.model_blend_ticks;
  ++counters_.workspace_jumps;
  return true;
}

}  // namespace ht
