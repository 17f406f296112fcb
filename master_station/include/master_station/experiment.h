#pragma once
// Scripted operator motions (experiments) expressed in the device frame M, relative to the
// workspace centre (which the station maps onto the tool's home pose in W).

#include <memory>
#include <string>
#include <vector>

#include "haptic_core/spatial.h"

namespace ht {

/// A target pose of the operator's hand at one time, with the name of the experiment phase.
struct HandTarget {
  RigidTransform X_MH;  ///< Target handle pose in M (m, rad).
  Twist V_MH_M;         ///< Its time derivative (m/s, rad/s).
  int phase = 0;        ///< Index into Experiment::phase_names().
};

/// A scripted motion of duration `duration_s`. Target() is noexcept and allocation-free.
class Experiment {
 public:
  virtual ~Experiment() = default;
  virtual const std::string& name() const noexcept = 0;
  virtual double duration_s() const noexcept = 0;
  virtual const std::vector<std::string>& phase_names() const noexcept = 0;
  /// Target at time t_s (s from the start); holds the last target after the end.
  virtual HandTarget Target(double t_s) const noexcept = 0;
};

/// Seed Fig. 75 (roughness under translation): the block is brought down onto the gear, then
/// translated along x (parallel to the ridges), then along y (across them), then pressed and
/// lifted along z. Phases: approach, x, y, z. The default 5 s at 1 kHz gives 5,000 frames
/// (seed: 1,500 frames at ~500 Hz).
struct Fig75Params {
  double duration_s = 5.0;
  double press_depth_m = 2e-3;   ///< Hand target below the contact (m): presses with k_hand·depth.
  double start_height_m = 2e-3;  ///< Hand height above the contact at t = 0 (m).
  double x_amplitude_m = 8e-3;
  double y_amplitude_m = 6e-3;
  double lift_height_m = 3e-3;  ///< Hand height above the contact at the top of the z phase (m).
};

/// Builds the Fig. 75 experiment. Throws std::invalid_argument for a non-positive duration.
std::unique_ptr<Experiment> MakeFig75Experiment(const Fig75Params& params = {});

/// Builds an experiment by name ("fig75"). Throws std::invalid_argument listing the known names.
std::unique_ptr<Experiment> MakeExperiment(const std::string& name, double duration_s);

}  // namespace ht
