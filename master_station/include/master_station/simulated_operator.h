#pragma once
// A simulated device held by a scripted operator hand: the hand is a mass-spring-damper pulled
// along an experiment's target trajectory and pushed back by the device's wrench, so that the
// whole loop closes without hardware.

#include <memory>

#include "master_station/experiment.h"
#include "master_station/haptic_device.h"

namespace ht {

/// Impedance of the simulated hand (translational and rotational).
struct OperatorHandParams {
  double mass_kg = 0.5;
  double stiffness_n_per_m = 800.0;
  double damping_ns_per_m = 25.0;
  double inertia_kg_m2 = 5e-4;
  double rotational_stiffness_nm_per_rad = 2.0;
  double rotational_damping_nms_per_rad = 0.04;
  int substeps = 10;  ///< Semi-implicit Euler substeps per ReadState interval.
};

/// Simulated 6-DoF impedance device with a scripted hand. Capabilities are those of a
/// desktop 6-DoF device (10 N, 1 N·m, 3,000 N/m at 1 kHz, ±0.1 m workspace).
class SimulatedOperatorDevice final : public HapticDevice {
 public:
  /// `experiment` must outlive the device. Time zero of the experiment is the first ReadState.
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
};

}  // namespace ht
