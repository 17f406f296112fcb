// Stage 2 of the operator tick (operator_tick.h): the blend from the model before to the one in
// use over model_blend_ticks ticks, the energy-bounded switch (a late model's onset rendered with
// a depth offset the observer's spare energy pays back), and the switch energy's attribution.

#include <algorithm>
#include <cmath>
#include <limits>

#include "master_station/operator_tick.h"

namespace ht {

bool OperatorTick::StepBlend(bool took_model, bool potential_changes, double U_before,
                             OperatorTickOutput& out) noexcept {
  const bool blending = blend_tick_ < config_.model_blend_ticks;
  if (blending) ++blend_tick_;
  if (config_.energy_bounded_switch && have_model_) {
    BoundSwitchEnergy(took_model, potential_changes ? U_before : 0.0, out.model_age_ms);
  }
  out.depth_offset_m = depth_offset_m_;
  AttributeSwitch(potential_changes, U_before, out.model_age_ms);  // at the weights stepped
  return blending;
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
    const ContactModelEvaluation raw = EvaluateContactModel(
        model_, tool_.X_WT, 1.0, std::numeric_limits<double>::infinity(), &fields_);
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
  double U = EvaluateContactModel(model_, X_WT, w, max_force, &fields_).potential_energy_j;
  if (w < 1.0)
    U += EvaluateContactModel(previous_model_, X_WT, 1.0 - w, max_force, &fields_)
             .potential_energy_j;
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
