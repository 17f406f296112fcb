#pragma once
// Time-domain passivity on the port between the operator's hand and the haptic device (Ryu,
// Kwon & Hannaford, "Stable teleoperation with time-domain passivity control", IEEE TRA 20(2),
// 2004; Hannaford & Ryu, "Time-domain passivity control of haptic interfaces", IEEE TRA 18(1),
// 2002). The observer integrates the energy the operator puts into the rest of the system (the
// device, the virtual coupling, the tool and the network-delayed contact model); the controller
// adds the damping needed to keep that energy non-negative, and otherwise nothing, unless an
// energy reserve is set (set_energy_reserve): then a gentle damping also refills the store while
// the energy is below the reserve.

#include <cstdint>

#include "haptic_core/spatial.h"

namespace ht {

/// Passivity observer and controller for one impedance-type port (velocity in, wrench out).
/// Sign convention: F_H_W is the wrench the device applies to the hand (N, N·m, in W, at the
/// handle), V_WH_W the hand's twist (m/s, rad/s, in W). The device does work on the hand at the
/// rate F·V; the hand does work on the system at −F·V. The observed energy
///   E_k = Σ_{i≤k} −(F_i · V_i) h   (J)
/// is what the operator has put in minus what the system has given back; the port is passive
/// while E_k ≥ 0 [L: RKH04, eq. 5].
class PassivityController {
 public:
  /// `min_speed`: below this hand speed (m/s, with rad/s weighted by `angular_weight_m`), no
  /// damping is added (it would be unbounded); `max_damping`: cap on the added damping (N·s/m;
  /// N·m·s/rad = max_damping·angular_weight_m²), 0 = none. Throws std::invalid_argument for
  /// negative or non-finite values.
  PassivityController(double min_speed = 1e-4, double max_damping_ns_per_m = 0.0,
                      double angular_weight_m = 0.05);

  /// An energy reserve (off by default): while the observed energy would fall below
  /// `reserve_j` (J, ≥ 0) but stay ≥ 0, Apply adds damping that makes up the shortfall over
  /// 0.1 s (so that it grows from zero as E falls below the reserve), changing the wrench by at
  /// most `refill_fraction` of itself (weighted as the twist; in [0, 1))
  /// and never above max_damping: nothing where the wrench is zero, at most that fraction of the
  /// small coupling force in free space, and below a force's just-noticeable difference in
  /// contact. A later tick whose hand moves too slowly for the damping to act (a
  /// turn's reversal, where taking a small power away over a speed near zero is a large cut of
  /// the force) then draws on the store instead of the guard. E ≥ 0 is kept exactly as without
  /// it: below zero the capped damping and the guard act as before. Throws
  /// std::invalid_argument for values out of range or not finite.
  void set_energy_reserve(double reserve_j, double refill_fraction);
  /// The reserve (J) and the refill's largest change of the wrench, a fraction of it.
  double energy_reserve_j() const noexcept { return reserve_j_; }
  double refill_fraction() const noexcept { return refill_fraction_; }
  /// Ticks where only the reserve's refill damped, the energy it dissipated (J) and the force it
  /// took, Σ α·|v|·h (N·s). Not in active_ticks, dissipated_j or force_damped_away_ns, which
  /// count the damping that kept E ≥ 0.
  std::int64_t refill_ticks() const noexcept { return refill_ticks_; }
  double refilled_j() const noexcept { return refilled_j_; }
  double force_refilled_ns() const noexcept { return force_refilled_ns_; }

  /// Given the wrench about to be commanded and the hand's twist over the tick of length `h_s`,
  /// returns the wrench with passivity damping added when the step would make E negative:
  /// F' = F − α·Ṽ with α ≥ 0 chosen so that E_k = 0 exactly (Ṽ weights rotation by
  /// angular_weight_m), and with a reserve set no less than the refill's α. When α is capped
  /// (max_damping) and that is not enough, Guard() takes the rest along the same twist, so that
  /// E_k never goes negative. With a reserve set, while E_k would stay ≥ 0 but fall below it,
  /// the refill's damping alone (set_energy_reserve; counted apart: refill_ticks). Does not
  /// update E (call Commit with what was really sent).
  Wrench Apply(const Wrench& F_H_W, const Twist& V_WH_W, double h_s) noexcept;
  /// The last word before the device: when commanding F over the tick would make E negative
  /// (F·V > 0 and E − F·V·h < 0), returns F with its power brought down to max(E, 0)/h by
  /// cutting the halves that do positive work, in proportion to that work: f by a multiple of v
  /// and τ by a multiple of ω, each cut at most that half's own component along its motion, so
  /// that neither |f| nor |τ| grows and a force or torque that does no work (⟂ to its motion) is
  /// kept. F unchanged otherwise. For a wrench a later stage (the safety stage's rate limit)
  /// changed after Apply, and for Apply's capped damping when that is not enough. Counted in
  /// scaled_ticks, force_scaled_away_ns (|Δf|·h) and scaled_away_j.
  Wrench Guard(const Wrench& F_H_W, const Twist& V_WH_W, double h_s) noexcept;
  /// Records the wrench actually commanded (after any later safety stage) over the tick.
  void Commit(const Wrench& F_H_W, const Twist& V_WH_W, double h_s) noexcept;

  /// E_k (J): operator's input minus output so far (≥ 0 while passive).
  double observed_energy_j() const noexcept { return energy_j_; }
  /// Energy the operator put into the system, Σ max(−F·V, 0) h (J).
  double energy_in_j() const noexcept { return energy_in_j_; }
  /// Energy the system gave to the operator, Σ max(F·V, 0) h (J).
  double energy_out_j() const noexcept { return energy_out_j_; }
  /// Energy the controller dissipated (J), and ticks where it acted.
  double dissipated_j() const noexcept { return dissipated_j_; }
  std::int64_t active_ticks() const noexcept { return active_ticks_; }
  /// Largest damping coefficient it applied (N·s/m).
  double max_alpha() const noexcept { return max_alpha_; }
  /// Ticks where Guard cut the wrench (capped damping not enough, or after the safety stage),
  /// and the force taken away that way, Σ |f − f'|·h (N·s): what the guard cost in force.
  std::int64_t scaled_ticks() const noexcept { return scaled_ticks_; }
  double force_scaled_away_ns() const noexcept { return force_scaled_away_ns_; }
  /// The force Apply's damping took away, Σ α·|v|·h (N·s): with force_scaled_away_ns(), all the
  /// force the passivity stage removed.
  double force_damped_away_ns() const noexcept { return force_damped_away_ns_; }
  /// The energy the guard kept from the hand, Σ (F − F')·V·h (J): with dissipated_j(), what the
  /// controller removed from the port.
  double scaled_away_j() const noexcept { return scaled_away_j_; }
  void Reset() noexcept;

 private:
  double min_speed_, max_damping_, angular_weight_m_;
  double reserve_j_ = 0.0, refill_fraction_ = 0.0;
  double refilled_j_ = 0.0, force_refilled_ns_ = 0.0;
  std::int64_t refill_ticks_ = 0;
  double energy_j_ = 0.0, energy_in_j_ = 0.0, energy_out_j_ = 0.0, dissipated_j_ = 0.0;
  double max_alpha_ = 0.0;
  double force_scaled_away_ns_ = 0.0, force_damped_away_ns_ = 0.0, scaled_away_j_ = 0.0;
  std::int64_t active_ticks_ = 0, scaled_ticks_ = 0;
};

/// Power the device delivers to the hand, F·V = f·v + τ·ω (W).
double DevicePower(const Wrench& F_H_W, const Twist& V_WH_W) noexcept;

}  // namespace ht
