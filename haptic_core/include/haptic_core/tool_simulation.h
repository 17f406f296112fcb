#pragma once

#include <limits>
// Simulated tool driven by the haptic device through a virtual coupling, integrated with one
// linearized backward-Euler step per tick against the local contact model (DESIGN.md §5;
// Otaduy & Lin 2005, "Stable and responsive six-degree-of-freedom haptic manipulation using
// implicit integration").

#include <cstdint>

#include "haptic_core/contact_model.h"
#include "haptic_core/spatial.h"

namespace ht {

/// Spring-damper between the device handle H and the simulated tool T.
struct VirtualCoupling {
  double k_translation_n_per_m = 1000.0;
  double b_translation_ns_per_m = 5.0;
  double k_rotation_nm_per_rad = 1.0;
  double b_rotation_nms_per_rad = 0.005;

  /// Throws std::invalid_argument naming the first gain that is negative or not finite.
  void Validate() const;
};

/// Mass properties of the tool about its centre of mass (frame T).
struct ToolInertia {
  double mass_kg = 0.1;
  glm::dvec3 inertia_diagonal_T{1e-5, 1e-5, 1e-5};  ///< Principal moments along T's axes (kg·m²).
};

/// State of the simulated tool: pose of T (at the centre of mass) in W and its twist in W.
struct ToolState {
  RigidTransform X_WT;
  Twist V_WT_W;
};

/// What one tick of the tool simulation produced.
struct ToolStepResult {
  /// Coupling wrench on the tool at its centre of mass, in W, after the step (N, N·m). The device
  /// is commanded with its negation.
  Wrench F_coupling_T_W;
  /// Contact wrench Φ on the tool at its centre of mass, in W, at the pose before the step.
  Wrench F_contact_T_W;
  int active_contacts = 0;
  double max_depth_m = 0.0;
  /// Active contacts whose force was held at the simulator's bound this step.
  int saturated_contacts = 0;
  /// Contacts rendered from their depth field (of which beyond its travel margin), and contacts
  /// whose field fell back to their linearization (ContactModelEvaluation).
  int field_contacts = 0;
  int field_beyond_margin = 0;
  int field_fallbacks = 0;
  /// False when the step produced a non-finite state; the tool was then reset onto the handle.
  bool ok = true;
};

/// Integrates the tool with (M − h·D − h²·K)·ΔV = h·(Φ(q_n, V_n) + h·K·V_n), a 6×6 symmetric
/// positive-definite system solved with Eigen's fixed-size LDLT (no allocation) [L: OL05].
class ToolSimulator {
 public:
  /// Throws std::invalid_argument for a non-positive mass or inertia, or bad coupling gains.
  ToolSimulator(const ToolInertia& inertia, const VirtualCoupling& coupling);

  /// One step of length `h_s` (s): handle pose X_WH and twist V_WH_W (world), contact model
  /// evaluated with its stiffness scaled by `stiffness_scale` ∈ [0, 1]. Updates `state`.
  /// noexcept and allocation-free. Non-finite inputs or results reset the tool onto the handle
  /// (or hold it when the handle pose itself is not finite) and return ok = false.
  /// `fields`: the depth fields the model's contacts refer to (EvaluateContactModel), or null.
  ToolStepResult Step(ToolState& state, const RigidTransform& X_WH, const Twist& V_WH_W,
                      const ContactModel& model, double stiffness_scale, double h_s,
                      const DepthFieldCache* fields = nullptr) const noexcept;

  /// Like Step, with a newly received contact model blended in: contact wrench and stiffness are
  /// blend·(current) + (1 − blend)·(previous), blend ∈ [0, 1] (clamped; NaN counts as 1). Ramping
  /// blend over a few ticks after each arrival replaces a jump of the force by steps of at most
  /// |ΔΦ|/ticks (DESIGN.md §5).
  ToolStepResult StepBlended(ToolState& state, const RigidTransform& X_WH, const Twist& V_WH_W,
                             const ContactModel& current, const ContactModel& previous,
                             double blend, double h_s,
                             const DepthFieldCache* fields = nullptr) const noexcept;
  /// Coupling wrench on the tool at its centre of mass, in W: k (p_H − p_T) + b (v_H − v_T) and
  /// k_r·rotvec(R_H R_Tᵀ) + b_r (ω_H − ω_T).
  Wrench CouplingWrench(const ToolState& state, const RigidTransform& X_WH,
                        const Twist& V_WH_W) const noexcept;

  const VirtualCoupling& coupling() const noexcept { return coupling_; }
  const ToolInertia& inertia() const noexcept { return inertia_; }
  /// The bound on each contact's force (N; +∞ = none, the default), passed to
  /// EvaluateContactModel by Step and StepBlended. Throws std::invalid_argument unless > 0.
  void set_max_contact_force(double max_contact_force_n);
  double max_contact_force_n() const noexcept { return max_contact_force_n_; }
  /// Hunt–Crossley contact damping (Hunt & Crossley 1975): each active contact's force becomes
  /// −k_i δ_i (1 + α·dδ_i/dt) ∇δ_i, dδ_i/dt = J_i·V, i.e. the damping D = −α·G
  /// (ContactModelEvaluation::G), integrated implicitly with the coupling's damping
  /// (A = M − h(D_coupling + D) − h²K; D·V_n joins the force). The damping grows with the depth
  /// and vanishes at first touch: a linear damper β·K attracts a tool that leaves faster than δ/β,
  /// this one only above 1/α whatever the depth. At depth δ it damps as β = α·δ would: a contact of
  /// stiffness k on the tool's mass m gets the damping ratio ζ = α·δ·√(k/m)/2. α in s/m; 0 (the
  /// default here): none; the operator station's default is
  /// OperatorStationConfig::hunt_crossley_s_per_m. Throws std::invalid_argument unless α ≥ 0 and
  /// finite.
  void set_contact_damping_hunt_crossley(double alpha_s_per_m);
  double contact_damping_hunt_crossley_s_per_m() const noexcept { return hunt_crossley_s_per_m_; }

 private:
  ToolStepResult Integrate(ToolState& state, const RigidTransform& X_WH, const Twist& V_WH_W,
                           const ContactModelEvaluation& contact, double h,
                           ToolStepResult result) const noexcept;
  ToolInertia inertia_;
  VirtualCoupling coupling_;
  double max_contact_force_n_ = std::numeric_limits<double>::infinity();
  double hunt_crossley_s_per_m_ = 0.0;
};

}  // namespace ht
