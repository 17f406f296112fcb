#pragma once
// Stage 6 of the remote step (remote_step.h): assembly of the contact model. The linearized
// contacts whose patches overlapped on their window (finite penetration depth) go into the model
// that is sent to the operator, with the penalty wrench of all of them at the step's tool pose
// (DESIGN.md §4: F = k·δ·∇δ per contact, summed).

#include <span>

#include "haptic_core/contact_linearization.h"
#include "haptic_core/contact_model.h"

namespace ht {

/// Appends to `model` every linearization of `contacts` with a finite depth_m (a contact whose
/// patches did not overlap has depth −∞ and is left out), up to kMaxContacts in all, and adds
/// each one's PenaltyWrench to model.F_T_W_at_q0. Returns the number appended. noexcept,
/// allocation-free.
int AssembleContactModel(std::span<const ContactLinearization> contacts,
                         ContactModel& model) noexcept;

}  // namespace ht
