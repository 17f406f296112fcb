#pragma once
// The last stage before a wrench reaches the device: reject non-finite values, fade to zero when
// the contact model is stale or the link is lost (and back in smoothly), brake (damping only)
// above a speed limit, clamp to the device's limits keeping direction, and limit the rate of
// change. Runs in the 1 kHz loop: noexcept, no allocation.

#include <cstdint>

#include "haptic_core/spatial.h"

namespace ht {

/// Limits of the safety stage. Frames: wrenches and twists in the same frame (the station uses W).
struct SafetyLimits {
  double max_force_n = 10.0;                ///< |f| cap (N), direction kept
  double max_torque_nm = 0.5;               ///< |τ| cap (N·m), direction kept
  double max_force_rate_n_per_s = 5000.0;   ///< |Δf|/h cap (N/s): the impulse limit
  double max_torque_rate_nm_per_s = 250.0;  ///< |Δτ|/h cap (N·m/s)
  double brake_speed_m_per_s = 1.0;         ///< above this hand speed: damping only
  double brake_angular_speed_rad_per_s = 10.0;
  double brake_damping_ns_per_m = 5.0;      ///< the brake's damping (N·s/m)
  double brake_damping_nms_per_rad = 0.02;  ///< (N·m·s/rad)
  double model_timeout_s = 0.25;            ///< a model with a longer staleness counts as stale
  double fade_out_s = 0.1;  ///< ramp from full to zero wrench when stale or link lost
  double fade_in_s = 0.2;   ///< ramp back once fresh
  /// Throws std::invalid_argument naming the first value that is negative, zero where it must be
  /// positive, or not finite.
  void Validate() const;
};

/// What the stage did on one tick (bits may combine).
enum SafetyAction : std::uint32_t {
  kSafetyNone = 0,
  kSafetyNonFinite = 1u << 0,    ///< the input was NaN/inf: replaced by zero
  kSafetyFading = 1u << 1,       ///< stale model or link lost: gain below 1
  kSafetyBraking = 1u << 2,      ///< over the speed limit: damping only
  kSafetyClamped = 1u << 3,      ///< magnitude limited
  kSafetyRateLimited = 1u << 4,  ///< change per tick limited
};

/// Counters of SafetyAction over a run (ticks on which each acted).
struct SafetyCounters {
  std::int64_t nonfinite = 0, fading = 0, braking = 0, clamped = 0, rate_limited = 0;
};

/// The safety stage. One instance per device; state: the previous output and the fade gain.
class WrenchSafetyFilter {
 public:
  /// Throws std::invalid_argument when `limits` is invalid.
  explicit WrenchSafetyFilter(const SafetyLimits& limits);

  /// Filters the desired device wrench F_desired_W (on the hand, in W: N, N·m) for a tick of `h_s`
  /// seconds. `V_WH_W` is the hand's twist in W (m/s, rad/s);
  /// `model_staleness_s` the seconds since the remote node sent the contact model in use (its
  /// send time on the local clock; negative = no model yet, which counts as fresh: free motion
  /// has no model). Not the "model age" of traces and summaries, which is the age of the tool
  /// pose the model answers (one round trip more); `link_up` false when the remote node is lost.
  /// Returns the wrench to command, in W; `actions` gets the SafetyAction bits of this tick.
  Wrench Filter(const Wrench& F_desired_W, const Twist& V_WH_W, double model_staleness_s,
                bool link_up, double h_s, std::uint32_t& actions) noexcept;

  /// Current fade gain in [0, 1].
  double gain() const noexcept { return gain_; }
  const SafetyCounters& counters() const noexcept { return counters_; }
  const SafetyLimits& limits() const noexcept { return limits_; }

 private:
  SafetyLimits limits_;
  Wrench previous_;
  double gain_ = 1.0;
  SafetyCounters counters_;
};

}  // namespace ht
