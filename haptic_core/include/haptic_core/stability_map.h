#pragma once
// Stability of the operator's tool integration against a stiff contact (DESIGN.md §5 and §8): the
// linearized backward-Euler step of ToolSimulator beside an explicit (semi-implicit, symplectic)
// Euler step of the same forces, over contact stiffness × tool mass × loop rate. Theory [L: OL05]:
// the explicit step of an undamped spring of stiffness k_total on mass m is stable only while
// h·ω < 2, ω = √(k_total/m); the backward-Euler step is stable for every h on a passive linear
// system.

#include <string>
#include <vector>

#include "haptic_core/tool_simulation.h"

namespace ht {

/// How the tool's state is advanced.
enum class ToolIntegrator {
  kImplicitEuler,  ///< ToolSimulator::Step (linearized backward Euler, the product's).
  kExplicitEuler,  ///< v ← v + h·F(x, v)/m; x ← x + h·v (semi-implicit Euler, the usual explicit
                   ///< choice).
};

/// "implicit" or "explicit".
const char* ToolIntegratorName(ToolIntegrator integrator) noexcept;

/// One point of the map.
struct StabilityProbe {
  double stiffness_n_per_m = 8000.0;  ///< k of the contact (one contact along +z).
  double mass_kg = 0.1;               ///< Tool mass; inertia that of a 4 cm cube of that mass.
  double rate_hz = 1000.0;            ///< Loop rate: h = 1/rate.
  double duration_s = 1.0;            ///< Simulated time.
  VirtualCoupling coupling;           ///< The operator loop's coupling (default gains).
};

/// What a probe gave.
struct StabilityResult {
  /// The tool's position stayed finite and within 2× its initial offset from rest over the last
  /// half of the run, and it either settled (within 0.1 % of that offset) or its last-half
  /// peak-to-peak swing was at most 0.9× the first half's (a growing swing, or a limit cycle of
  /// bounces in and out of contact, is unstable).
  bool stable = false;
  /// Largest |z − z_rest| (m) over the last half of the run (∞ when non-finite).
  double late_amplitude_m = 0.0;
  /// h·ω with ω = √((k + k_coupling)/m): the explicit step's theoretical limit is 2.
  double h_omega = 0.0;
};

/// Simulates the tool pressed by the coupling (handle 10 mm below, 10 N) onto one contact of
/// stiffness k along +z (J = −ẑ; at rest the tool is in contact at δ0 = 10 N / k), released at
/// rest 0.1·δ0 above its rest position, with `integrator`; linear while the tool stays in
/// contact. Never throws: a non-positive mass, rate or duration, a negative stiffness or bad
/// coupling gains give stable = false.
StabilityResult ProbeStability(const StabilityProbe& probe, ToolIntegrator integrator) noexcept;

}  // namespace ht
