#include "master_station/operator_tick.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

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
  const double h = config_.h_s;

  // A scripted "go to" (with a working device): the workspace and the tool jump together, in
  // free space, and the contact models of the old place are dropped. Before stage 1, so that a
  // model arriving on the jump's own tick is judged against the new place like any later one.
  if (in.device_ok && in.workspace_shift_M != workspace_shift_M_) {
    const glm::dvec3 jump_W = X_WM_.rotation * (in.workspace_shift_M - workspace_shift_M_);
    jumped_from_W_ = tool_.X_WT.translation;
    after_jump_ = true;
    X_WM_.translation += jump_W;
    tool_.X_WT.translation += jump_W;
    workspace_shift_M_ = in.workspace_shift_M;
    model_ = ContactModel{};
    previous_model_ = ContactModel{};
    depth_offset_m_ = 0.0;
    blend_tick_ = config_.model_blend_ticks;
    ++counters_.workspace_jumps;
  }

  // The contact potential before a model or blend change (issue 33's attribution): evaluated
  // only on ticks that change it.
  const bool potential_changes = in.arrived != nullptr || blend_tick_ < config_.model_blend_ticks;
  bool took_model = false;  // a new model was taken this tick (stage 1)
  const double U_before = potential_changes ? LoopPotential(tool_.X_WT) : 0.0;

  // Stage 1: the contact model in use. A model that arrives is taken even while the device read
  // fails (newest wins), unless it comes from before a workspace jump.
  if (in.arrived != nullptr) {
    bool take = true;
    if (after_jump_) {
      // Models in flight were linearized at the old place (nearer to it than to the tool now):
      // meaningless here. The first from the new place ends the wait.
      const glm::dvec3& p0_W = in.arrived->model.X_WT0.translation;
      if (glm::length(p0_W - jumped_from_W_) < glm::length(p0_W - tool_.X_WT.translation)) {
        ++counters_.models_from_before_jump;
        take = false;
      } else {
        after_jump_ = false;
      }
    }
    if (take) {
      previous_model_ = model_;  // blended out over the next model_blend_ticks ticks
      blend_tick_ = 0;
      model_ = in.arrived->model;
      // An offset in use goes on with the new model (an episode spans models); without one
      // BoundSwitchEnergy may give it its own at an onset.
      const double carried = depth_offset_m_;
      depth_offset_m_ = 0.0;
      SetDepthOffset(carried);
      took_model = true;
      model_stamp_ = *in.arrived;  // the stamp only: the model itself is in model_
      have_model_ = true;
      ++counters_.models_used;
    }
  }
  if (have_model_) out.model_age_ms = (in.now_ns - model_stamp_.tool_state_sent_ns) * 1e-6;
  const double model_staleness_s =
      have_model_ ? (in.now_ns - model_stamp_.built_local_ns) * 1e-9 : -1.0;

  Wrench F_device_W;
  Twist V_WH_W;
  double f_after_apply = 0.0;  // |f| after Apply (N), for the release
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

    // Stage 2: coupling and the implicit step against the (blended) model.
    const bool blending = blend_tick_ < config_.model_blend_ticks;
    if (blending) ++blend_tick_;
    if (config_.energy_bounded_switch && have_model_) {
      BoundSwitchEnergy(took_model, potential_changes ? U_before : 0.0, out.model_age_ms);
    }
    out.depth_offset_m = depth_offset_m_;
    AttributeSwitch(potential_changes, U_before, out.model_age_ms);  // at the weights stepped
    if (blending) {
      out.step =
          simulator_.StepBlended(tool_, out.X_WH, V_WH_W, model_, previous_model_,
                                 static_cast<double>(blend_tick_) / config_.model_blend_ticks, h);
    } else {
      out.step = simulator_.Step(tool_, out.X_WH, V_WH_W, model_, 1.0, h);
    }
    if (!out.step.ok) ++counters_.nonfinite;
    if (out.step.saturated_contacts > 0) ++counters_.saturated_contact_ticks;
    F_device_W = -out.step.F_coupling_T_W;
    if (!IsFinite(F_device_W)) {
      ++counters_.nonfinite;
      F_device_W = {};
    }
    if (!IsFinite(out.step.F_contact_T_W) || !IsFiniteRigidTransform(tool_.X_WT)) {
      ++counters_.nonfinite;
    }
    // Stage 3: passivity (energy a delayed model created is dissipated).
    if (config_.passivity) {
      const glm::dvec3 before = F_device_W.force;
      F_device_W = passivity_.Apply(F_device_W, V_WH_W, h);
      out.passivity_removed_n += glm::length(before - F_device_W.force);
      f_after_apply = glm::length(F_device_W.force);
    }
  }
  // Stage 4: safety, on every tick. Then the observer records what the device really gets.
  F_device_W = safety_.Filter(F_device_W, V_WH_W, model_staleness_s, in.link_connected, h,
                              out.safety_actions);
  const double gain = std::isnan(in.output_gain) ? 0.0 : std::clamp(in.output_gain, 0.0, 1.0);
  if (gain < 1.0) F_device_W = {gain * F_device_W.force, gain * F_device_W.torque};
  // The safety stage's rate limit can hold back a drop passivity asked for: the guard cuts what
  // is left along the hand's motion so that the observed energy never goes negative.
  if (config_.passivity) {
    const glm::dvec3 before = F_device_W.force;
    F_device_W = passivity_.Guard(F_device_W, V_WH_W, h);
    // The release: a force the stage cut comes back over passivity_release_ticks ticks.
    // The fraction kept is the passivity stage's own (Apply's, then Guard's), not the safety
    // stage's clamps or ramps.
    if (config_.passivity_release_ticks > 0 && in.device_ok) {
      const auto ratio = [](double a, double b) { return b > 1e-9 ? std::min(1.0, a / b) : 1.0; };
      double kept = ratio(f_after_apply, glm::length(out.step.F_coupling_T_W.force)) *
                    ratio(glm::length(F_device_W.force), glm::length(before));
      if (kept > passivity_release_gain_) {
        const double s = passivity_release_gain_ / kept;
        F_device_W = {s * F_device_W.force, s * F_device_W.torque};
        kept = passivity_release_gain_;
      }
      passivity_release_gain_ = std::min(1.0, kept + 1.0 / config_.passivity_release_ticks);
    }
    out.passivity_removed_n += glm::length(before - F_device_W.force);
  }
  passivity_.Commit(F_device_W, V_WH_W, h);
  out.F_device_W = F_device_W;
  const glm::dquat R_MW = glm::conjugate(X_WM_.rotation);
  out.F_H_M = {R_MW * F_device_W.force, R_MW * F_device_W.torque};
  return out;
}

void OperatorTick::SetDepthOffset(double offset_m) noexcept {
  const double d = offset_m - depth_offset_m_;
  if (d == 0.0) return;
  for (int i = 0; i < model_.num_contacts; ++i) {
    ContactLinearization& c = model_.contacts[static_cast<std::size_t>(i)];
    c.depth_m -= d;
    for (int m = 0; m < c.num_kink_planes; ++m)
      c.kink_planes[static_cast<std::size_t>(m)].depth_m -= d;
  }
  depth_offset_m_ = offset_m;
}

void OperatorTick::BoundSwitchEnergy(bool took_model, double U_before,
                                     double model_age_ms) noexcept {
  const double spare = std::max(0.0, passivity_.observed_energy_j() -
                                         (config_.passivity ? passivity_.energy_reserve_j() : 0.0));
  const double budget = config_.switch_energy_spend_fraction * spare;
  // The smallest offset in [0, o_hi] whose loop potential at the tool is within `limit`, or
  // o_hi when none is (U at the tool falls as the offset grows).
  const auto smallest_within = [&](double o_hi, double limit) {
    SetDepthOffset(0.0);
    if (!std::isfinite(o_hi) || o_hi <= 0.0 || LoopPotential(tool_.X_WT) <= limit) return 0.0;
    double lo = 0.0, hi = o_hi;
    for (int k = 0; k < 16; ++k) {
      const double mid = 0.5 * (lo + hi);
      SetDepthOffset(mid);
      if (LoopPotential(tool_.X_WT) <= limit) {
        hi = mid;
      } else {
        lo = mid;
      }
    }
    return hi;
  };
  if (took_model && depth_offset_m_ == 0.0) {
    // An onset: the loop rendered no contact at the tool and this model has one, whose whole
    // stored energy would go in at once; it may add at most the budget (old models only).
    if (!(U_before <= 0.0) || !(model_age_ms >= config_.switch_bound_min_age_ms)) return;
    const ContactModelEvaluation raw = EvaluateContactModel(model_, tool_.X_WT);
    if (raw.active_contacts == 0) return;
    const double o = smallest_within(raw.max_depth_m, U_before + budget);
    SetDepthOffset(o);
    depth_offset_peak_m_ = o;
    if (o > 0.0) {
      ++counters_.switch_offset_ticks;
      counters_.switch_offset_max_m = std::max(counters_.switch_offset_max_m, o);
    }
    return;
  }
  const double o = depth_offset_m_;
  if (o == 0.0) return;
  // Giving the offset back: at least at the release rate (from the onset's offset), and further
  // as far as the budget pays for.
  double o_hi = o;
  if (std::isfinite(config_.switch_offset_release_ms)) {
    o_hi = std::max(
        0.0, o - depth_offset_peak_m_ * config_.h_s * 1e3 / config_.switch_offset_release_ms);
  }
  const double limit = LoopPotential(tool_.X_WT) + budget;  // U at the offset in use
  const double o_new = smallest_within(o_hi, limit);
  SetDepthOffset(o_new);
  if (o_new > 0.0) ++counters_.switch_offset_ticks;
}

double OperatorTick::LoopPotential(const RigidTransform& X_WT) const noexcept {
  const double w = std::min(1.0, static_cast<double>(blend_tick_) / config_.model_blend_ticks);
  const double max_force = simulator_.max_contact_force_n();
  double U = EvaluateContactModel(model_, X_WT, w, max_force).potential_energy_j;
  if (w < 1.0)
    U += EvaluateContactModel(previous_model_, X_WT, 1.0 - w, max_force).potential_energy_j;
  return U;
}

void OperatorTick::AttributeSwitch(bool potential_changes, double U_before,
                                   double model_age_ms) noexcept {
  if (!potential_changes) return;
  const double dU = LoopPotential(tool_.X_WT) - U_before;
  if (!std::isfinite(dU)) return;
  ++counters_.switch_ticks;
  if (dU > 0.0) {
    ++counters_.switch_ticks_creating;
    counters_.switch_energy_created_j += dU;
    const int bin = model_age_ms < 50.0 ? 0 : (model_age_ms <= 150.0 ? 1 : 2);
    counters_.switch_energy_created_by_age_j[bin] += dU;
  } else {
    counters_.switch_energy_absorbed_j += dU;
  }
}

}  // namespace ht
