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

/// The wrench on the tool at its centre of mass, in W (N, N·m), of `model`'s contacts
/// [0, num_contacts) at the model's own linearization point q0: Σ PenaltyWrench(δ_i, J_i, k_i)
/// with δ_i, J_i from ContactDepthAt at zero displacement, as the operator's loop evaluates a
/// contact there and as AssembleContactModel sums model.F_T_W_at_q0. A compact contact model
/// (protocol version 11) does not carry that wrench: its receiver restores it with this. A
/// contact with a non-finite field gives a non-finite wrench. noexcept, allocation-free.
Wrench ContactModelWrenchAtQ0(const ContactModel& model) noexcept;

}  // namespace ht
