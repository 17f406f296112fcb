#pragma once
// The operator-side device interface, in the manner of the known haptics frameworks (CHAI3D's
// cGenericHapticDevice, libnifalcon, hidapi-based 6-DoF mice): open/close, read the handle's state
// with a timestamp, write a wrench, and a capabilities struct that says what the device can render.

#include <cstdint>
#include <string>

#include "haptic_core/spatial.h"

namespace ht {

/// What a device can sense and render. Frames: M is the device base, H its handle.
struct DeviceCapabilities {
  std::string name;
  double max_force_n = 0.0;    ///< Largest force magnitude it renders (N); 0 = no force output.
  double max_torque_nm = 0.0;  ///< Largest torque magnitude it renders (N·m); 0 = none.
  /// Largest coupling stiffness it renders stably at `rated_loop_rate_hz` (N/m, N·m/rad).
  double max_stiffness_n_per_m = 0.0;
  double max_rotational_stiffness_nm_per_rad = 0.0;
  double max_damping_ns_per_m = 0.0;  ///< Largest stable damping (N·s/m).
  double rated_loop_rate_hz = 1000.0;
  /// Half sizes of the reachable box of the handle in M (m).
  glm::dvec3 workspace_half_extents_m{0.0};
  int dof_in = 6;   ///< Sensed degrees of freedom.
  int dof_out = 6;  ///< Actuated degrees of freedom.
  /// The handle is moved by the experiment's script (a simulated operator): the station then
  /// applies the script's workspace jumps (HandTarget::workspace_shift_M) too.
  bool scripted = false;
};

/// Handle state read from a device: pose X_MH, twist V_MH_M, buttons, device timestamp.
struct DeviceState {
  RigidTransform X_MH;
  Twist V_MH_M;
  std::uint32_t buttons = 0;
  std::int64_t timestamp_ns = 0;  ///< steady clock of the reading (ns).
};

/// A haptic device. Open/Close run outside the haptic loop and may throw; ReadState and
/// WriteWrench run inside it and are noexcept, allocation-free, and report faults by returning
/// false (the caller counts them and commands zero wrench).
class HapticDevice {
 public:
  virtual ~HapticDevice() = default;
  /// What this device can do. Valid before Open, except for devices that learn their figures
  /// from the device at Open (Force Dimension, OpenHaptics): those give their name and no force
  /// before Open and the device's own figures after it. The station reads them after Open.
  virtual DeviceCapabilities capabilities() const = 0;
  /// Opens the device. Throws std::runtime_error saying what is missing and what to do.
  virtual void Open() = 0;
  /// Releases the device, commanding zero wrench first where it has output.
  virtual void Close() noexcept = 0;
  /// Reads the handle's state at steady-clock time `now_ns`. False when no valid reading exists.
  virtual bool ReadState(std::int64_t now_ns, DeviceState& state) noexcept = 0;
  /// Commands the wrench F_H_M (on the handle, at its origin, expressed in M) to be rendered from
  /// `now_ns` on. The caller has already clamped it to capabilities(). False on a device fault.
  virtual bool WriteWrench(const Wrench& F_H_M, std::int64_t now_ns) noexcept = 0;
};

}  // namespace ht
