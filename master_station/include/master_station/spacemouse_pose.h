#pragma once
// 3Dconnexion SpaceMouse, shaping and mapping: the settings of the SpaceMouse backend, dead zone
// and hold-then-decay of stale axes, and the mapping of cap deflection to the handle pose X_MH
// (rate control or position control). Stage 4 of the SpaceMouse pipeline (spacemouse.h).

#include <array>
#include <cstdint>
#include <glm/vec3.hpp>
#include <string>

#include "master_station/haptic_device.h"
#include "master_station/spacemouse_report.h"

namespace ht {

// ------------------------------------------------------------------------------------------------
// 4. Shaping and mapping
// ------------------------------------------------------------------------------------------------

/// How deflection moves the handle.
enum class SpaceMouseControlMode {
  kRate,      ///< Deflection → twist, integrated (the usual SpaceMouse use).
  kPosition,  ///< Deflection → offset from the workspace centre (springs back when released).
};

/// Settings of SpaceMouseDevice and SpaceMousePoseMapper. ValidateSpaceMouseConfig says which
/// value is wrong.
struct SpaceMouseConfig {
  /// hidapi path (e.g. /dev/hidraw3) to open; empty = the first 6-DoF model of the table found.
  std::string path;
  /// Dead zone as a fraction of full deflection, [0, 1): |d| below it reads 0, and the rest is
  /// rescaled so that the output still reaches 1 and is continuous at the edge.
  double dead_zone = 0.05;
  /// An axis not refreshed by a report for `hold_s` then ramps linearly to 0 over `decay_s`.
  /// 3Dconnexion firmwares send an all-zero report when the cap is released (observed:
  /// `01 00 00 00 00 00 00`) and keep reporting while it is deflected (the sensor noise changes
  /// the value), so the hold covers short quiet spells; the decay stops a runaway under rate
  /// control when reports stop for good (unplug, wireless drop-out, a firmware that goes quiet
  /// while deflected). Buttons are sent on change only and are kept.
  double hold_s = 0.5;
  double decay_s = 0.2;
  SpaceMouseControlMode mode = SpaceMouseControlMode::kRate;
  double v_max_m_per_s = 0.1;    ///< Rate control: linear speed at full deflection (m/s).
  double w_max_rad_per_s = 1.0;  ///< Rate control: angular speed at full deflection (rad/s).
  /// Largest rotation of H from the initial orientation (rad), (0, pi]: the clamp under rate
  /// control, the rotation at full deflection under position control.
  double max_rotation_rad = 0.5;
  /// Half sizes of the box the handle origin stays in, centred on M's origin (m). Under position
  /// control, full deflection reaches its faces.
  glm::dvec3 workspace_half_extents_m{0.1, 0.1, 0.1};
  /// Longest integration step (s): a longer gap between ReadState calls (a stall) integrates only
  /// this much, so that the handle does not jump.
  double max_step_s = 0.05;
  SpaceMouseAxisMap axis_map;
  int read_timeout_ms = 20;  ///< Reader thread's hid_read_timeout (ms), (0, 1000].
};

/// Throws std::invalid_argument naming the first bad value of `config`.
void ValidateSpaceMouseConfig(const SpaceMouseConfig& config);

/// Dead zone on one normalized value: 0 inside ±dead_zone, else sign(v)(|v| - dz)/(1 - dz).
double ApplySpaceMouseDeadZone(double v, double dead_zone) noexcept;

/// Factor on an axis whose last report is `age_s` old: 1 up to hold_s, then linear to 0 at
/// hold_s + decay_s (a step at hold_s when decay_s is 0).
double SpaceMouseStalenessGain(double age_s, double hold_s, double decay_s) noexcept;

/// The deflections to use at `now_ns`: staleness gain times dead-zoned axes (frame M, order
/// SpaceMouseAxis, each in [-1, 1]). Axes never set read 0.
std::array<double, 6> ShapeSpaceMouseAxes(const SpaceMouseSample& sample, std::int64_t now_ns,
                                          const SpaceMouseConfig& config) noexcept;

/// Turns shaped deflections into the handle pose X_MH and twist V_MH_M.
/// Rate control: v = v_max (d_tx, d_ty, d_tz) m/s and w = w_max (d_rx, d_ry, d_rz) rad/s in M,
/// integrated over the real time since the previous Step (at most max_step_s): p_MH += v dt, then
/// clamped per axis to ±workspace_half_extents_m; R_MH ← exp(w dt) R_MH, then its rotation
/// vector clamped to max_rotation_rad. Position control: p_MH = d_t ∘ half extents,
/// R_MH = exp(max_rotation_rad d_r) with |d_r| limited to 1. In both, V_MH_M is the pose change
/// over dt (after the clamps), 0 on the first Step.
class SpaceMousePoseMapper {
 public:
  /// Throws std::invalid_argument from ValidateSpaceMouseConfig.
  explicit SpaceMousePoseMapper(const SpaceMouseConfig& config);
  /// Back to X_MH = identity, time restarts at the next Step.
  void Reset() noexcept;
  /// Advances to `now_ns` (steady clock) with `sample`; writes X_MH, V_MH_M, buttons, timestamp.
  /// A time earlier than the previous Step counts as dt = 0.
  void Step(const SpaceMouseSample& sample, std::int64_t now_ns, DeviceState& state) noexcept;
  const RigidTransform& X_MH() const noexcept { return X_MH_; }

 private:
  SpaceMouseConfig config_;
  RigidTransform X_MH_;
  bool started_ = false;
  std::int64_t last_ns_ = 0;
};

}  // namespace ht
