#pragma once
// Scripted operator motions (experiments) expressed in the device frame M, relative to the
// workspace centre (which the station maps onto the tool's home pose in W).

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "haptic_core/spatial.h"

namespace ht {

/// How the simulated hand moves along M's z (the scene's up).
enum class HandZControl : std::uint8_t {
  /// Follow X_MH's z (coming back to it at no more than the hand's fast speed after a press).
  kPosition,
  /// Press: what a person does when told to press on a surface whose height they do not know.
  /// The hand comes down from X_MH's z (its ceiling) until it feels `press_force_n` pushing up
  /// from the device, then holds that force; fast above `slow_below_z_m`, slowly below it, never
  /// below `floor_z_m`.
  kPress,
  /// Lift off: rise by `lift_m` from where the hand was when the lift began (never above X_MH's z).
  kLift,
};

/// A target pose of the operator's hand at one time, with the name of the experiment phase.
struct HandTarget {
  RigidTransform X_MH;  ///< Target handle pose in M (m, rad).
  Twist V_MH_M;         ///< Its time derivative (m/s, rad/s).
  int phase = 0;        ///< Index into Experiment::phase_names().
  HandZControl z_control = HandZControl::kPosition;
  double press_force_n = 0.0;   ///< kPress: upward force to hold (N).
  double floor_z_m = 0.0;       ///< kPress: lowest hand z in M (m).
  double slow_below_z_m = 0.0;  ///< kPress: below this z, the slow approach speed (m).
  double lift_m = 0.0;          ///< kLift: rise (m).
  /// "Go to" for scenes larger than the device's workspace: how far the workspace centre has been
  /// moved from where it started, in M at the start (m). Piecewise constant, and changed by a
  /// script only while the tool is in free space, by the same amount as X_MH, so that the handle
  /// stays where it is in the device while the workspace and the tool jump together. X_MH is in
  /// the starting workspace's coordinates: the device's handle target is X_MH shifted by
  /// −workspace_shift_M.
  glm::dvec3 workspace_shift_M{0.0};
};

/// One touchable object of the remote scene as an experiment sees it, in the device frame M (m;
/// M's +z is the scene's up): its bounds at the session's start and its highest point.
struct ExperimentTarget {
  glm::dvec3 box_min_M{0.0};
  glm::dvec3 box_max_M{0.0};
  glm::dvec3 top_M{0.0};
  /// Hand height in M (m) over top_M where the tool is clear of every object (checked by the
  /// remote node).
  double approach_z_M = 0.0;
};

/// What an experiment is told of the remote scene when the session opens.
struct ExperimentScene {
  std::vector<ExperimentTarget> targets;  ///< Largest first; may be empty.
  /// How far the tool reaches below the hand along −z (m): the hand is this high above the point
  /// of contact when the tool touches a surface below it.
  double tool_extent_down_m = 0.0;
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
  /// Called once when the session opens, before the first Target(), with where the remote
  /// scene's touchable objects are. Scripts that move along fixed axes ignore it. Throws
  /// std::bad_alloc only.
  virtual void SetScene(const ExperimentScene& scene) { (void)scene; }
  /// Whether the tool should touch nothing at the end of `phase` (explore: a release, a
  /// transfer): the operator station reports a contact still loaded then as a wedged tool
  /// (summary.json "wedged"). Default: no such phase.
  virtual bool EndsFree(int phase) const noexcept {
    (void)phase;
    return false;
  }
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

/// Seed Fig. 76 (roughness under rotation), for the striped-blocks scene: the upper block is
/// pressed into the lower one (phase approach, the first 10 % or 1 s at most), then rotated back
/// and forth about n (the device's z, the scene's up) while the hand keeps pressing: θ(t) =
/// amplitude·sin(2π t/period) (phase rotate). Seed: 6,000 frames, about 12 s.
struct Fig76Params {
  double duration_s = 12.0;
  double press_depth_m = 2e-3;   ///< Hand target below the contact (m).
  double start_height_m = 2e-3;  ///< Hand height above the contact at t = 0 (m).
  double amplitude_rad = 0.05;   ///< Rotation amplitude about n (rad, about 2.9°).
  double period_s = 2.0;         ///< Period of the oscillation (s).
};

/// Builds the Fig. 76 experiment. Throws std::invalid_argument for a non-positive duration,
/// period or amplitude.
std::unique_ptr<Experiment> MakeFig76Experiment(const Fig76Params& params = {});

/// Seed Fig. 77 (performance with complex contact), for the file-on-cad-part and hammer-on-torus
/// scenes: the tool is pressed onto the object (phase approach, the first 10 % or 1 s at most),
/// then scraped `stroke_m` along +x (eased), swaying ±`sway_m` in y twice and yawing
/// ±`yaw_rad` three times (phase scrape), as benchmarks/fig77_scrape does offline.
struct Fig77Params {
  double duration_s = 10.0;
  double press_depth_m = 2e-3;
  double start_height_m = 1e-3;
  double stroke_m = 0.06;
  double sway_m = 0.01;
  double yaw_rad = 0.0873;  ///< 5°
};

/// Builds the Fig. 77 experiment. Throws std::invalid_argument for a non-positive duration or
/// stroke.
std::unique_ptr<Experiment> MakeFig77Experiment(const Fig77Params& params = {});

/// `explore`: lets any scene be felt without a script. The simulated operator visits the remote
/// scene's touchable objects in turn (largest first, then round again at other spots of each):
/// it lifts the tool above the scene, moves over the object, lowers it and presses with
/// `press_force_n` under force control (the surface height below a spot is unknown), slides it
/// along x and then y while pressing, releases, presses again, and moves on, until the duration
/// is over. Phases: transfer, press, slide_x, slide_y, release, each suffixed with "@k" for the
/// k-th target (from 1). A spot more than `jump_beyond_m` away is reached by a "go to" jump of the
/// workspace (HandTarget::workspace_shift_M) at the travel height, where the tool is in free
/// space: large scenes need no hand motion beyond the device's workspace.
struct ExploreParams {
  double duration_s = 20.0;
  double press_force_n = 1.5;        ///< Force the hand presses with (N).
  double travel_height_m = 5e-3;     ///< Height above the home pose for moves between spots (m).
  double transfer_speed_m_s = 0.25;  ///< Mean speed of moves between spots (m/s).
  double stroke_m = 15e-3;           ///< Slide amplitude, at most 40 % of the object's half width.
  double press_s = 0.5;              ///< Time to come down and settle on a spot (s).
  double slide_s = 0.8;              ///< Duration of each slide (along x, along y) (s).
  double release_s = 0.4;            ///< Time lifted off between the two presses of a visit (s).
  double release_lift_m = 5e-3;      ///< Hand lift when releasing (m).
  double jump_beyond_m = 0.05;       ///< Spots farther than this are reached by a jump (m).
};

/// Builds the explore experiment. Throws std::invalid_argument for a non-positive duration,
/// force, speed or phase time.
std::unique_ptr<Experiment> MakeExploreExperiment(const ExploreParams& params = {});

/// Builds an experiment by name ("fig75", "fig76", "fig77", "explore"). Throws
/// std::invalid_argument listing the known names.
std::unique_ptr<Experiment> MakeExperiment(const std::string& name, double duration_s);

}  // namespace ht
