#pragma once
// A simulated device held by a scripted operator hand: the hand is a mass-spring-damper pulled
// along an experiment's target trajectory and pushed back by the device's wrench, so that the
// whole loop closes without hardware.

#include <memory>

#include "master_station/experiment.h"
#include "master_station/haptic_device.h"
#include "master_station/operator_hand.h"

namespace ht {

/// Simulated 6-DoF impedance device with a scripted hand. Capabilities are those of a
/// desktop 6-DoF device (10 N, 1 N·m, 3,000 N/m at 1 kHz, ±0.1 m workspace).
class SimulatedOperatorDevice final : public HapticDevice {
 public:
  /// `experiment` must outlive the device. Time zero of the experiment is the first ReadState,
  /// where the hand starts at the experiment's first target (so an experiment told the scene
  /// after Open() starts where it should).
  SimulatedOperatorDevice(const Experiment& experiment, const OperatorHandParams& hand = {});

  DeviceCapabilities capabilities() const override;
  void Open() override;
  void Close() noexcept override;
  bool ReadState(std::int64_t now_ns, DeviceState& state) noexcept override;
  bool WriteWrench(const Wrench& F_H_M, std::int64_t now_ns) noexcept override;

  /// Phase of the experiment at the last reading.
  int phase() const noexcept { return phase_; }
  /// Mechanical energy the device's wrench has put into the hand so far (J): ∫ F·v + τ·ω dt.
  double energy_to_operator_j() const noexcept { return energy_to_operator_j_; }

 private:
  /// The script's target with z replaced by the hand's own z control (HandZControl), advanced
  /// by dt (s).
  HandTarget ControlZ(const HandTarget& script, double dt) noexcept;

  const Experiment& experiment_;
  OperatorHandParams hand_;
  bool open_ = false;
  bool started_ = false;
  std::int64_t t0_ns_ = 0;
  std::int64_t last_ns_ = 0;
  DeviceState state_;
  Wrench F_H_M_;
  int phase_ = 0;
  double energy_to_operator_j_ = 0.0;
  // The hand's own z target when it departs from the script's (press, lift, and the return to the
  // script's z afterwards); z_free_ = true when it is the script's.
  double z_hand_ = 0.0;
  bool z_free_ = true;
  HandZControl z_mode_ = HandZControl::kPosition;
  double lift_start_z_ = 0.0;
  // Where a lift left the part sideways (along the felt force; z unused), and the workspace
  // shift it was made at (HandTarget::workspace_shift_M).
  glm::dvec3 release_offset_M_{0.0};
  glm::dvec3 release_shift_M_{0.0};
};

}  // namespace ht
