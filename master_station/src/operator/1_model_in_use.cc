// Stage 1 of the operator tick (operator_tick.h): the contact model in use. A model that arrives
// is taken (newest wins), the one before kept for stage 2's blend; after a scripted workspace
// jump, models linearized nearer the old place than the tool are dropped.

#include <algorithm>
#include <array>
#include <cmath>

#include "master_station/operator_tick.h"

namespace ht {

bool OperatorTick::TakeArrivedModel(const ArrivedModel* arrived) noexcept {
  // Taken even while the device read fails (newest wins), unless it comes from before a
  // workspace jump.
  if (arrived == nullptr) return false;
  if (after_jump_) {
    // Models in flight were linearized at the old place (nearer to it than to the tool now):
    // meaningless here. The first from the new place ends the wait.
    const glm::dvec3& p0_W = arrived->model.X_WT0.translation;
    if (glm::length(p0_W - jumped_from_W_) < glm::length(p0_W - tool_.X_WT.translation)) {
      ++counters_.models_from_before_jump;
      return false;
    }
    after_jump_ = false;
  }
  previous_model_ = model_;  // blended out over the next model_blend_ticks ticks (stage 2)
  blend_tick_ = 0;
  model_ = arrived->model;
  // An offset in use goes on with the new model (an episode spans models); without one
  // BoundSwitchEnergy may give it its own at an onset.
  const double carried = depth_offset_m_;
  depth_offset_m_ = 0.0;
  SetDepthOffset(carried);
  model_stamp_ = *arrived;  // the stamp only: the model itself is in model_
  have_model_ = true;
  ++counters_.models_used;
  return true;
}

void OperatorTick::TakeArrivedFields(const OperatorTickInput& in) noexcept {
  if (in.arrived_fields.empty()) return;
  std::array<std::uint32_t, 2 * kMaxContacts> keep{};
  std::size_t n = 0;
  const ContactModel* in_use[2] = {&model_, in.arrived != nullptr ? &in.arrived->model : nullptr};
  for (const ContactModel* m : in_use) {
    if (m == nullptr) continue;
    for (int i = 0; i < std::clamp(m->num_contacts, 0, kMaxContacts); ++i) {
      const std::uint32_t id = m->contacts[static_cast<std::size_t>(i)].depth_field_id;
      if (id != 0 && n < keep.size()) keep[n++] = id;
    }
  }
  for (DepthField* f : in.arrived_fields) {
    if (f != nullptr && !fields_.Take(*f, {keep.data(), n})) ++counters_.fields_refused;
  }
}

void OperatorTick::SetDepthOffset(double offset_m) noexcept {
  const double d = offset_m - depth_offset_m_;
  if (d == 0.0) return;
  for (int i = 0; i < model_.num_contacts; ++i) {
    ContactLinearization& c = model_.contacts[static_cast<std::size_t>(i)];
    c.depth_m -= d;
    c.depth_field_shift_m -= d;
  }
  depth_offset_m_ = offset_m;
}

}  // namespace ht
