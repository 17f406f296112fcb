#pragma once

#include <span>
// The operator's haptic tick as one unit: the device state in, the device wrench out,
// with no thread, socket or clock of its own, so that tests run it tick by tick. Stages, in
// order (DESIGN.md §5), one file each in master_station/src/operator/, whose listing is this order:
//   1. the contact model in use: a newly arrived one is taken, the one before kept for the blend;
//      after a scripted workspace jump (ShiftWorkspace, the experiment driver's, between ticks),
//      models linearized nearer the old place than the tool are dropped;
//   2. the blend from the model before to the new one over a few ticks, and the energy-bounded
//      switch (a late model's onset rendered with a depth offset);
//   3. virtual coupling and the implicit (linearized backward-Euler) tool step against the blend;
//   4. passivity: the time-domain passivity controller (Ryu, Kwon & Hannaford 2004);
//   5. safety: non-finite → zero, fade when stale or the link is lost, brake, clamp, rate limit;
//      then the passivity guard scales what is left if the energy observed would go negative.
// Every tick's wrench passes the safety stage, a failed device read included: the device then
// gets the safety stage's ramp to zero, and a later recovery ramps back up instead of jumping.

#include <cstdint>
#include <limits>

#include "haptic_core/contact_model.h"
#include "haptic_core/passivity.h"
#include "haptic_core/tool_simulation.h"
#include "haptic_core/wrench_safety.h"
#include "master_station/haptic_device.h"

namespace ht {

/// What the tick is built with (validated by the station before).
struct OperatorTickConfig {
  ToolInertia inertia;
  VirtualCoupling coupling;
  /// The device's and the configuration's limits, already combined.
  SafetyLimits safety;
  /// Ticks over which a newly arrived contact model is blended in (≥ 1).
  int model_blend_ticks = 4;
  /// Run the passivity controller (else the observer only watches).
  bool passivity = true;
  /// Cap on the damping the passivity controller adds (N·s/m; 0 = none).
  double passivity_max_damping_ns_per_m = 0.0;
  /// The passivity controller's energy reserve (J; 0 = none) and the most its refill may change
  /// the wrench, a fraction of it (PassivityController::set_energy_reserve).
  double passivity_reserve_j = 0.0;
  double passivity_refill_fraction = 0.0;
  /// Release of the passivity stage's cuts (ticks; 0 = off): after a tick where the passivity
  /// stage kept only a fraction r of the coupling force (Apply's damping and Guard's cut
  /// together, |f_out|/|f_in|), the next tick's device wrench is held to at most
  /// min(1, r + 1/release_ticks) of that tick's coupling force, so a cut force comes back over
  /// up to release_ticks ticks instead of in one. Without it a hand that keeps stopping while
  /// the observed energy is short gets the whole force back on each tick it stands still (its
  /// power is zero there) and none while it moves: a train of one-tick pulses of the full force
  /// (measured: docs/measurements.md). Scaling a wrench down keeps the observed energy non-negative
  /// (its power scales with it), so passivity holds.
  int passivity_release_ticks = 0;
  /// Energy-bounded onsets (false = off): a contact model that arrives while the loop renders no
  /// contact at the tool and has one there (an onset: the tool already inside the surface of a
  /// model that came late) may raise the contact potential U at the tool's pose by no more than
  /// the energy the passivity observer holds spare, switch_energy_spend_fraction ×
  /// max(0, E − reserve); beyond that it is rendered with a depth offset o ≥ 0 (every δ_i less
  /// o: the surface moved out of the tool), the smallest that keeps the bound. The offset goes on
  /// with the models that follow and is given back every tick, as far as the same budget pays
  /// for (the operator's own work pressing in, the observer's store) and at least over
  /// switch_offset_release_ms, instead of the tool being pushed out by the stored energy at once
  /// and the guard cutting the device's force until the hand has paid (the pulse train of
  /// passivity_release_ticks). A passive model update in the sense of model-mediated
  /// teleoperation (Mitra & Niemeyer, DSCC 2008; Song, Ding, Shang & Liang, IJARS 2018, who
  /// restrain the force step of a model update).
  bool energy_bounded_switch = false;
  /// The share of the observer's spare energy a tick may spend on a switch or on giving the
  /// offset back ((0, 1]).
  double switch_energy_spend_fraction = 1.0;
  /// The longest an offset is held (ms, > 0; +∞ = as long as the budget says): whatever the
  /// budget, the offset shrinks each tick by at least its value at the onset over this time, so
  /// that a surface whose return the budget cannot pay for (a hand resting on it) comes back
  /// anyway and the passivity stage takes the rest.
  double switch_offset_release_ms = std::numeric_limits<double>::infinity();
  /// The bound applies to models at least this old (ms, the tick's model_age_ms, ≥ 0): a model
  /// answering a pose under 10 ms old stores little the hand has not already paid for, and the
  /// passivity stage's reserve handles it. Bounding every switch holds offsets on undelayed ticks
  /// and makes the simulated tool's contact force step (measured: docs/measurements.md).
  double switch_bound_min_age_ms = 10.0;
  /// Tick length h (s).
  double h_s = 1e-3;
  /// Bound on each contact's force on the simulated tool (N; +∞ = none): DESIGN.md §5's bounded
  /// delivered stiffness (ToolSimulator::set_max_contact_force).
  double max_contact_force_n = std::numeric_limits<double>::infinity();
  /// Hunt–Crossley contact damping α (s/m; ToolSimulator::set_contact_damping_hunt_crossley).
  double hunt_crossley_s_per_m = 0.0;
};

/// When a contact model was made and what its remote step cost.
struct ModelStamp {
  /// Local steady-clock times (ns): when the tool state it answers was sent, and when the remote
  /// node sent the model (mapped onto the local clock).
  std::int64_t tool_state_sent_ns = 0;
  std::int64_t built_local_ns = 0;
  /// The remote step's split (µs), for the trace.
  float collision_us = 0.0f, texture_us = 0.0f, step_us = 0.0f;
};

/// A contact model the network delivered since the last tick, with its stamp.
struct ArrivedModel : ModelStamp {
  ContactModel model;
};

/// One tick's inputs.
struct OperatorTickInput {
  std::int64_t now_ns = 0;  ///< steady clock (ns)
  /// False when the device read failed: the tool is held and the device gets the safety stage's
  /// ramp to zero.
  bool device_ok = true;
  DeviceState device;                     ///< X_MH, V_MH_M when device_ok
  const ArrivedModel* arrived = nullptr;  ///< a new model, or null
  /// The depth fields that came with `arrived` (prepared: DepthField::Prepare), taken into the
  /// tick's cache before the model (their buffers are swapped with the cache's, never copied:
  /// each pointer leaves holding an evicted field's buffers, to be reused by the caller).
  std::span<DepthField* const> arrived_fields;
  bool link_connected = true;
  /// Scales the device's wrench after the safety stage and before the passivity observer
  /// records it, clamped to [0, 1] (NaN = 0): the ramp to zero when a stop is requested. The
  /// observer then accounts the wrench the device really gets.
  double output_gain = 1.0;
};

/// One tick's outputs.
struct OperatorTickOutput {
  Wrench F_H_M;                ///< To command to the device: on the handle, in M (N, N·m).
  Wrench F_H_W;                ///< The same in W.
  ToolStepResult step;         ///< The tool step (default when the device read failed).
  RigidTransform X_WH;         ///< Handle pose in W this tick (the last good one after a fault).
  double model_age_ms = -1.0;  ///< Age of the tool pose the model in use answers; −1 = none.
  /// The depth offset the model in use is rendered with this tick (m, ≥ 0;
  /// OperatorTickConfig::energy_bounded_switch).
  double depth_offset_m = 0.0;
  std::uint32_t safety_actions = 0;
  /// What the passivity stage took off the device's force this tick (N, ≥ 0): |ΔF| of Apply's
  /// damping (and its refill) plus |ΔF| of Guard's cut; 0 with passivity off. Its sum over a run
  /// times the tick is about the summary's force_damped_away_Ns + force_refilled_Ns +
  /// force_scaled_away_Ns; per tick it says where in a run they were taken (trace.csv's
  /// passivity_removed_n).
  double passivity_removed_n = 0.0;
};

/// Counters of the tick's faults and events.
struct OperatorTickCounters {
  std::int64_t device_faults = 0;  ///< failed device reads
  std::int64_t nonfinite = 0;      ///< non-finite steps, wrenches or tool poses
  std::int64_t workspace_jumps = 0;
  std::int64_t models_from_before_jump = 0;
  std::int64_t models_used = 0;
  std::int64_t saturated_contact_ticks = 0;  ///< ticks with a contact force held at the bound
  /// Where the local loop's energy comes from (its attribution). Within one contact model
  /// the loop is conservative (ContactModelEvaluation::potential_energy_j); a new model, each
  /// blend step towards it, and a model dropped mid-blend change the contact potential U at the
  /// tool's pose q without moving it: ΔU = U_after(q) − U_before(q) on each such tick (the
  /// blended pair's U, weights as the step uses them). Positive ΔU is energy a switch put into
  /// the loop, which the passivity stage may later have to remove; negative, energy it took out.
  double switch_energy_created_j = 0.0;
  double switch_energy_absorbed_j = 0.0;   ///< Σ of the negative ΔU (≤ 0)
  std::int64_t switch_ticks = 0;           ///< ticks with a model or blend change
  std::int64_t switch_ticks_creating = 0;  ///< of those, ticks with ΔU > 0
  /// The created energy by the age of the model taken (ms at its arrival, the tick's
  /// model_age_ms): below 50 ms, 50–150 ms, above 150 ms.
  double switch_energy_created_by_age_j[3] = {0.0, 0.0, 0.0};
  /// Ticks rendered with a depth offset (energy_bounded_switch), and the largest offset (m).
  std::int64_t switch_offset_ticks = 0;
  double switch_offset_max_m = 0.0;
  /// Ticks whose tool step rendered a contact from its depth field (of which with the tool past a
  /// field's travel margin), and ticks on which a contact with a field fell back to its
  /// linearization (the field missing); fields the cache refused.
  std::int64_t field_ticks = 0;
  std::int64_t field_beyond_margin_ticks = 0;
  std::int64_t field_fallback_ticks = 0;
  std::int64_t fields_refused = 0;
};

/// The operator's tick. Construction may allocate; Step never allocates, locks, blocks or throws.
class OperatorTick {
 public:
  /// The workspace starts at X_WM and the tool at `tool_start`. Throws std::invalid_argument for
  /// bad inertia, coupling or safety limits, model_blend_ticks < 1, passivity_release_ticks < 0,
  /// switch_energy_spend_fraction outside (0, 1], switch_offset_release_ms not > 0 or
  /// switch_bound_min_age_ms not ≥ 0.
  OperatorTick(const OperatorTickConfig& config, const RigidTransform& X_WM,
               const ToolState& tool_start);

  /// Runs the stages above once.
  OperatorTickOutput Step(const OperatorTickInput& in) noexcept;

  /// A scripted "go to" (HandTarget::workspace_shift_M, m in M), for the experiment driver to
  /// call between ticks while the device works: when `workspace_shift_M` differs from the last
  /// one, the workspace and the tool jump together by the difference, in free space, the models
  /// in use are dropped, and stage 1 drops those of the old place still in flight. Returns
  /// whether it jumped.
  bool ShiftWorkspace(const glm::dvec3& workspace_shift_M) noexcept;

  const ToolState& tool() const noexcept { return tool_; }
  const RigidTransform& X_WM() const noexcept { return X_WM_; }
  /// The scripted workspace shift in effect (m, in M at the start).
  const glm::dvec3& workspace_shift_M() const noexcept { return workspace_shift_M_; }
  const OperatorTickCounters& counters() const noexcept { return counters_; }
  const PassivityController& passivity() const noexcept { return passivity_; }
  const WrenchSafetyFilter& safety() const noexcept { return safety_; }
  /// The stamp of the model in use (its times and its remote step's split).
  const ModelStamp& model_stamp() const noexcept { return model_stamp_; }
  /// The contact model in use (the newest taken; empty before the first).
  const ContactModel& model() const noexcept { return model_; }
  /// Fields whose evaluation passed kDepthFieldMaxNodes: their contacts rendered from their
  /// linearizations (DepthFieldCache::over_budget).
  std::int64_t depth_fields_over_budget() const noexcept { return fields_.over_budget(); }
  /// Whether the tick holds depth field `id` (DepthFieldCache::Find). noexcept.
  bool HasDepthField(std::uint32_t id) const noexcept { return fields_.Find(id) != nullptr; }
  /// Forgets every depth field held (the remote node's ids of a new session name other fields).
  /// noexcept, no allocation.
  void ForgetDepthFields() noexcept { fields_.Clear(); }

 private:
  OperatorTickConfig config_;
  ToolSimulator simulator_;
  PassivityController passivity_;
  WrenchSafetyFilter safety_;
  RigidTransform X_WM_;
  ToolState tool_;
  RigidTransform X_WH_last_;
  ContactModel model_{}, previous_model_{};
  /// The depth fields the models in use refer to, and those that came since (4·kMaxContacts + 4
  /// slots: two models' worth kept, and room for as many arriving while fields churn).
  DepthFieldCache fields_;
  /// Stage 1: takes the fields that came with `in.arrived` into fields_, keeping those the model
  /// in use and the arriving one refer to.
  void TakeArrivedFields(const OperatorTickInput& in) noexcept;
  int blend_tick_;
  bool have_model_ = false;
  ModelStamp model_stamp_{};
  glm::dvec3 workspace_shift_M_{0.0};
  glm::dvec3 jumped_from_W_{0.0};
  bool after_jump_ = false;
  OperatorTickCounters counters_;
  /// The passivity stage's release (passivity_release_ticks): the largest fraction of the
  /// coupling force the next tick may pass.
  double passivity_release_gain_ = 1.0;
  /// The depth offset applied to model_'s depths (m, ≥ 0; energy_bounded_switch).
  double depth_offset_m_ = 0.0;
  double depth_offset_peak_m_ = 0.0;  ///< the offset at the episode's onset (m)
  /// Stage 1: takes `arrived` (null: none) as the model in use, the one before kept for the
  /// blend, unless it is from before a workspace jump; returns whether it was taken.
  bool TakeArrivedModel(const ArrivedModel* arrived) noexcept;
  /// Stage 2: advances the blend, bounds the switch's energy (BoundSwitchEnergy) and attributes
  /// it (AttributeSwitch); returns whether this tick blends.
  bool StepBlend(bool took_model, bool potential_changes, double U_before,
                 OperatorTickOutput& out) noexcept;
  /// Stage 3: the coupling and the tool step against the model (blended when `blending`), from
  /// the handle at X_WH with twist V_WH_W (W); returns the device's wrench in W (zero when not
  /// finite, counted).
  Wrench StepTool(const RigidTransform& X_WH, const Twist& V_WH_W, bool blending,
                  OperatorTickOutput& out) noexcept;
  /// Stage 4 before safety: the passivity controller's damping of `F_H_W`; `f_after_apply`
  /// gets |f| after it (N) for the release.
  Wrench ApplyPassivity(const Wrench& F_H_W, const Twist& V_WH_W, OperatorTickOutput& out,
                        double& f_after_apply) noexcept;
  /// Stage 5: the safety filter and the stop ramp's gain.
  Wrench LimitWrench(const Wrench& F_H_W, const Twist& V_WH_W, double model_staleness_s,
                     const OperatorTickInput& in, OperatorTickOutput& out) noexcept;
  /// Stage 4 after safety: the guard, the release of what the stage cut, and the observer's
  /// record (Commit) of the wrench returned, which the device gets.
  Wrench GuardPassivity(const Wrench& F_H_W, const Twist& V_WH_W, bool device_ok,
                        double f_after_apply, OperatorTickOutput& out) noexcept;
  /// Sets model_'s depth offset to `offset_m` (shifts every contact's depth and its depth field's).
  void SetDepthOffset(double offset_m) noexcept;
  /// The energy-bounded onset, after stage 1 and the blend step: at an onset (`took_model`
  /// with no offset in use, no contact potential before it, `U_before`, and a model at least
  /// switch_bound_min_age_ms old) the smallest offset that keeps the potential at the tool
  /// within the budget; otherwise the offset in use (stage 1 carries it to a new model) given
  /// back, at least at the release rate and further as the budget pays for.
  void BoundSwitchEnergy(bool took_model, double U_before, double model_age_ms) noexcept;
  /// U of the blended pair at X_WT: model_ at weight blend_tick_/ticks, previous_model_ at the
  /// rest (ContactModelEvaluation::potential_energy_j; J).
  double LoopPotential(const RigidTransform& X_WT) const noexcept;
  /// Adds the tick's ΔU (LoopPotential now less `U_before`, evaluated before stage 1 when
  /// `potential_changes`) to the switch counters; model_age_ms bins the created energy.
  void AttributeSwitch(bool potential_changes, double U_before, double model_age_ms) noexcept;
};

}  // namespace ht
