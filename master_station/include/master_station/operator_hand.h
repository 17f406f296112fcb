#pragma once
// The simulated operator's hand (SimulatedOperatorDevice, simulated_operator.h), in a header of
// its own so that the experiments (experiment.cc) can read its speeds without the device.

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
  /// Force control along z (HandZControl::kPress): while the felt upward force is below a quarter
  /// of the wanted one, the hand's z target comes down at the fast speed (above the target's
  /// slow_below_z_m) or the slow speed (below it); then it moves at gain·(felt − wanted), within
  /// the same bound downwards and the slow speed upwards. kLift rises at the slow speed and, while
  /// the felt force has a sideways part (a tool wedged against a side), also moves sideways along
  /// it at the slow speed times its share of the force: it leaves the part along the contact's
  /// normal. That sideways offset (at most release_offset_max_m) is kept until the script moves
  /// the hand sideways, which takes it back at the fast speed, or jumps the workspace.
  double press_gain_m_per_s_per_n = 0.02;
  double press_fast_speed_m_per_s = 0.25;
  double press_slow_speed_m_per_s = 0.05;
  double release_offset_max_m = 0.01;
};

}  // namespace ht
