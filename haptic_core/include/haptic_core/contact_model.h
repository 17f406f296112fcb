#pragma once
// The intermediate representation between the remote node and the operator loop (DESIGN.md §5):
// a set of linearized contacts at tool pose q0, evaluated every tick at the current tool pose.

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <limits>
#include <span>

#include "haptic_core/contact_linearization.h"
#include "haptic_core/depth_field.h"
#include "haptic_core/spatial.h"

namespace ht {

/// Largest number of contacts one contact model carries (seed: up to 7 after clustering); sized so
/// that a whole model fits in one UDP datagram (transport/protocol.h).
inline constexpr int kMaxContacts = 14;

/// Generalized stiffness ∂Φ/∂q (6×6, rows/cols: translation x,y,z then rotation x,y,z, world
/// axes; units N/m, N/rad, N·m/m, N·m/rad).
using Stiffness6 = Eigen::Matrix<double, 6, 6>;

/// A contact model: the linearizations of all contacts at the tool pose X_WT0 (q0).
/// Fixed capacity so that it can be copied between threads and evaluated without allocation.
struct ContactModel {
  /// Tool pose q0 (frame T at the tool's centre of mass) the linearizations were taken at.
  RigidTransform X_WT0;
  /// Sequence number of the tool state the remote node used for q0 (0 = none yet).
  std::uint64_t tool_state_seq = 0;
  /// Number of valid entries in `contacts` (0..kMaxContacts).
  int num_contacts = 0;
  std::array<ContactLinearization, kMaxContacts> contacts{};
  /// Total penalty wrench on the tool at q0, at its centre of mass, in W (N, N·m).
  Wrench F_T_W_at_q0;
};

/// δ of contact `c` at the pose change Δq = q ⊖ q0 (Δq.linear in m, Δq.angular in rad, world
/// axes): its linearization δ0 + J·Δq. `gradient` (optional) receives J.
/// noexcept, allocation-free (1 kHz loop).
double ContactDepthAt(const ContactLinearization& c, const Twist& dq,
                      PenetrationGradient* gradient = nullptr) noexcept;

/// Result of evaluating a contact model at a tool pose.
struct ContactModelEvaluation {
  /// Φ = Σ −k_i max(δ_i(q), 0) J_i: wrench on the tool at its centre of mass, in W (δ_i and
  /// J_i = ∇δ_i from ContactDepthAt).
  Wrench F_T_W;
  /// K = Σ_{δ_i>0} −k_i (J_i J_iᵀ + δ_i ∇²δ_i) (negative semi-definite; ∇²δ_i is a depth
  /// field's smooth maximum's curvature, zero for a linearization).
  Stiffness6 K = Stiffness6::Zero();
  /// Contacts with δ_i(q) > 0.
  int active_contacts = 0;
  /// Largest δ_i(q) (m), or 0 with no contact.
  double max_depth_m = 0.0;
  /// Potential energy U(q) (J) whose negative gradient Φ is along each active contact's J_i:
  /// Σ ½ k_i δ_i² (k_i times the stiffness scale), and for a saturated contact (held at δ_s)
  /// k_i (δ_s δ_i − ½ δ_s²), which grows linearly with δ as its bounded force does. Within one
  /// model the local loop is conservative in U; a new model (or a blend step) at the same pose
  /// changes U, which is the energy a model switch puts into the loop (its attribution).
  double potential_energy_j = 0.0;
  /// Active contacts whose force was saturated at the bound (see EvaluateContactModel).
  int saturated_contacts = 0;
  /// G = Σ_{δ_i>0, unsaturated} k_i δ_i J_i J_iᵀ (a field under ForceLaw::kPressure: k_i times
  /// its DepthFieldEvaluation::pressure_damping) (positive semi-definite, 6×6, rows/cols as K;
  /// N in its translation block, N·m/rad and N·m²/rad² where rotation enters): the
  /// depth-weighted stiffness, from which a Hunt–Crossley contact damping D = −α·G (α in s/m)
  /// gives each contact the force −k_i δ_i α (J_i·V) J_i, which vanishes with δ_i
  /// (ToolSimulator::set_contact_damping_hunt_crossley).
  Stiffness6 G = Stiffness6::Zero();
  /// Contacts whose δ came from their depth field (of which, with the tool beyond the field's
  /// travel margin: field_beyond_margin), and contacts with a field that fell back to their
  /// linearization (the field missing from the cache).
  int field_contacts = 0;
  int field_beyond_margin = 0;
  int field_fallbacks = 0;
};

/// Evaluates `model` at tool pose X_WT: δ_i(q) = δ0_i + J_i·(q ⊖ q0) (ContactDepthAt), per-contact
/// switching by max(δ_i, 0) (DESIGN.md §5). Contacts whose δ0 or
/// stiffness is not finite are skipped. `stiffness_scale` ∈ [0, 1] multiplies every k_i (used to
/// blend a new model in).
///
/// `max_contact_force_n` (N, > 0; +∞ = none) bounds each contact's force, DESIGN.md §5's bounded
/// delivered stiffness: where k_i·δ_i·|∂δ_i/∂x| exceeds it (k_i unscaled), δ_i is held at the
/// depth that gives the bound (the contact's force and torque saturate along J_i; times
/// `stiffness_scale`, so that two blended evaluations add up to the bound at most) and the
/// contact adds no stiffness to K (its force no longer grows with δ). A grazing contact whose δ is
/// the sideways overlap of patches that are not height fields (docs/hard-cases.md) then pushes with
/// the bound, not with thousands of newtons. noexcept and allocation-free: callable from the 1 kHz
/// loop.
///
/// With `fields`, a contact with a depth field (ContactLinearization::depth_field_id) that the
/// cache holds takes δ, ∇δ and the smooth maximum's curvature (under the pressure law, its
/// equivalents: DepthFieldEvaluation) from the field at X_WT
/// (DepthFieldCache::Evaluate, plus depth_field_shift_m) instead of its linearization, also beyond
/// the field's travel margin (counted: a linearization made a round trip ago is worse there, its
/// steps at the margin were the largest force steps on the gear at 25 ms); without the field,
/// its linearization, and the fallback is counted.
ContactModelEvaluation EvaluateContactModel(
    const ContactModel& model, const RigidTransform& X_WT, double stiffness_scale = 1.0,
    double max_contact_force_n = std::numeric_limits<double>::infinity(),
    const DepthFieldCache* fields = nullptr) noexcept;

/// The same at tool pose X_WT (W, T at the tool's centre of mass) with unit stiffness scale and
/// no force bound, the fields looked up by id among `fields` (prepared ones; null entries
/// skipped; empty: every contact by its linearization) and evaluated afresh (DepthFieldDepthAt):
/// the remote node's view of what the operator renders, from the fields it keeps. A contact
/// whose field is not found takes its linearization (counted in field_fallbacks). noexcept,
/// allocation-free.
ContactModelEvaluation EvaluateContactModel(const ContactModel& model, const RigidTransform& X_WT,
                                            std::span<const DepthField* const> fields) noexcept;

}  // namespace ht
