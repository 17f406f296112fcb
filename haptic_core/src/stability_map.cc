#include "haptic_core/stability_map.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "haptic_core/contact_model.h"

namespace ht {

const char* ToolIntegratorName(ToolIntegrator integrator) noexcept {
  return integrator == ToolIntegrator::kImplicitEuler ? "implicit" : "explicit";
}

StabilityResult ProbeStability(const StabilityProbe& p, ToolIntegrator integrator) noexcept {
  StabilityResult out;
  if (!(p.mass_kg > 0.0) || !(p.rate_hz > 0.0) || !(p.duration_s > 0.0) ||
      !(p.stiffness_n_per_m >= 0.0)) {
    return out;
  }
  const double h = 1.0 / p.rate_hz;
  const double k_total = p.stiffness_n_per_m + p.coupling.k_translation_n_per_m;
  out.h_omega = h * std::sqrt(k_total / p.mass_kg);
  // The handle 10 mm inside the surface (a 10 N press through the default coupling), and one
  // contact along +z, δ(z) = δ0 − z, with δ0 = that press over k: at rest the tool sits at z = 0,
  // in contact, so the system is linear while it stays within δ0 of rest.
  RigidTransform X_WH;
  X_WH.translation.z = -0.01;
  const double press_n = p.coupling.k_translation_n_per_m * 0.01;
  ContactModel model;
  model.num_contacts = 1;
  ContactLinearization& c = model.contacts[0];
  c.depth_m = p.stiffness_n_per_m > 0.0 ? press_n / p.stiffness_n_per_m : 0.0;
  c.gradient.d_translation_W = {0.0, 0.0, -1.0};
  c.stiffness_n_per_m = p.stiffness_n_per_m;
  model.F_T_W_at_q0 = PenaltyWrench(c.depth_m, c.gradient, c.stiffness_n_per_m);
  const double z_rest = p.stiffness_n_per_m > 0.0 ? 0.0 : X_WH.translation.z;
  ToolInertia inertia;
  inertia.mass_kg = p.mass_kg;
  const double side = 0.04;
  inertia.inertia_diagonal_T = glm::dvec3(p.mass_kg * side * side / 6.0);
  // Bad coupling gains make the simulator refuse: an unstable answer, not an exception.
  try {
    p.coupling.Validate();
  } catch (const std::invalid_argument&) {
    return out;
  }
  const ToolSimulator sim(inertia, p.coupling);
  // Released at rest, 10 % of δ0 above the rest position (still in contact).
  const double offset0 = std::max(0.1 * c.depth_m, 1e-9);
  ToolState s;
  s.X_WT.translation.z = z_rest + offset0;
  const long steps = std::max(2L, std::lround(p.duration_s * p.rate_hz));
  double first_lo = std::numeric_limits<double>::infinity(), first_hi = -first_lo;
  double late_lo = first_lo, late_hi = first_hi, late_amp = 0.0;
  for (long n = 0; n < steps; ++n) {
    if (integrator == ToolIntegrator::kImplicitEuler) {
      const ToolStepResult r = sim.Step(s, X_WH, Twist{}, model, 1.0, h);
      if (!r.ok) return out;  // the simulator reset a non-finite state
    } else {
      const ContactModelEvaluation e = EvaluateContactModel(model, s.X_WT);
      const Wrench F = e.F_T_W + sim.CouplingWrench(s, X_WH, Twist{});
      s.V_WT_W.linear += h * F.force / p.mass_kg;
      s.X_WT.translation += h * s.V_WT_W.linear;
    }
    const double z = s.X_WT.translation.z;
    if (!std::isfinite(z) || std::abs(z - z_rest) > 1e3) {
      out.late_amplitude_m = std::numeric_limits<double>::infinity();
      return out;
    }
    if (n < steps / 2) {
      first_lo = std::min(first_lo, z);
      first_hi = std::max(first_hi, z);
    } else {
      late_lo = std::min(late_lo, z);
      late_hi = std::max(late_hi, z);
      late_amp = std::max(late_amp, std::abs(z - z_rest));
    }
  }
  out.late_amplitude_m = late_amp;
  // Stable: bounded, and either settled or still decaying (a growing swing or a limit cycle of
  // bounces in and out of contact is not).
  const double first_swing = first_hi - first_lo, late_swing = late_hi - late_lo;
  out.stable =
      late_amp <= 2.0 * offset0 && (late_amp < 1e-3 * offset0 || late_swing <= 0.9 * first_swing);
  return out;
}

}  // namespace ht
