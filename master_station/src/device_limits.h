#pragma once
// The clamp the vendor-library backends (force_dimension.cc, openhaptics.cc) apply to every
// wrench before it reaches the device. Internal to master_station.

#include <cmath>

#include "haptic_core/spatial.h"

namespace ht::detail {

/// F with its force magnitude at most `max_force_n` (N) and its torque magnitude at most
/// `max_torque_nm` (N·m), each scaled down keeping its direction; a limit <= 0 renders that part
/// zero. Sets `saturated` when either part was scaled down. Frame-free: F's frame is the result's.
inline Wrench ClampToDeviceLimits(const Wrench& F, double max_force_n, double max_torque_nm,
                                  bool& saturated) noexcept {
  const auto clamp = [&saturated](const glm::dvec3& v, double limit) noexcept {
    if (!(limit > 0.0)) return glm::dvec3(0.0);
    const double n = glm::length(v);
    if (n <= limit) return v;
    saturated = true;
    return v * (limit / n);
  };
  saturated = false;
  return {clamp(F.force, max_force_n), clamp(F.torque, max_torque_nm)};
}

}  // namespace ht::detail
