// The deadband lockstep's arms and runs (deadband_lockstep.cc): an arm's settings parsed from
// NAME:KEY=V,..., the run's set-up, and one arm run on the one simulated clock; the figures a run
// is judged by (deadband_lockstep_metrics.cc).
#pragma once

#include <cstdint>
#include <glm/vec3.hpp>
#include <string>
#include <vector>

#include "haptic_core/haptic_scene.h"
#include "haptic_core/remote_step.h"
#include "master_station/operator_station.h"
#include "master_station/replay_device.h"
#include "slave_sim/remote_node_config.h"
#include "transport/deadband.h"

namespace lockstep {

/// One arm: both deadbands' settings (the master_station / slave_sim options they stand for).
struct Arm {
  std::string name;
  ht::ToolStateDeadbandConfig tool;
  ht::ContactModelDeadbandConfig model;
  /// The operator station's settings (master_station's defaults unless the arm says otherwise:
  /// the passivity release and the energy-bounded onsets), and the one tick option the station
  /// does not set.
  ht::StationConfig station;
  double switch_energy_spend_fraction = ht::OperatorTickConfig{}.switch_energy_spend_fraction;
  /// The remote step's setting, by its frontier name (speed_error_frontier --list-settings):
  /// its PipelineOptions and CPU backend choices. Empty: the run's own (--reference-setting).
  std::string setting;
  /// The remote step's speculative lead (s; < 0: the setting's, PipelineOptions::
  /// speculative_lead_s), as slave_sim --speculative-lead-ms.
  double speculative_lead_s = -1.0;
  /// Its largest margin (m; < 0: PipelineOptions::max_speculative_margin_m).
  double speculative_margin_m = -1.0;
  /// Its floor (m; < 0: the remote node's by the round trip, speculative_speed_m_per_s).
  double speculative_floor_m = -1.0;
  /// The remote node's RemoteNodeConfig::speculative_speed_m_per_s (m/s), whose floor follows
  /// the run's round trip (2 × delay + step time).
  double speculative_speed_m_per_s = ht::RemoteNodeConfig{}.speculative_speed_m_per_s;
  /// The contact model as depth fields (PipelineOptions::depth_fields), evaluated by the
  /// operator's tick at its tool pose; their travel margin is depth_field_speed_m_per_s times the
  /// run's round trip, at least depth_field_min_margin_m.
  bool depth_fields = false;
  double depth_field_min_margin_m = 2e-3;
  double depth_field_speed_m_per_s = 0.05;
  int depth_field_subdivision = ht::PipelineOptions{}.depth_field_subdivision;
  /// The fields' smooth-maximum width (m; < 0: PipelineOptions' default).
  double depth_field_smooth_max_m = -1.0;
  /// The fields' force law (PipelineOptions::force_law, slave_sim --force-law).
  ht::ForceLaw force_law = ht::ForceLaw::kSeed;
  /// The remote node steps when a tool state has arrived, and otherwise (on the pose extrapolated
  /// under the tool-state deadband) at most this often (s; 0: every tick).
  double remote_step_period_s = 0.0;
};

/// What one arm's run gives, tick by tick and in all.
struct ArmRun {
  std::vector<glm::dvec3> device_force_W, device_torque_W, contact_force_W;
  std::vector<double> passivity_removed_n, model_age_ms;
  std::vector<int> contacts, model_arrived;
  /// Per tick: contacts the tool step rendered from a depth field, and those that fell back.
  std::vector<int> field_contacts, field_fallbacks, field_beyond_margin;
  /// Per tick: the operator tick's own time (µs, this machine's clock; the tick only).
  std::vector<double> tick_us;
  std::vector<double> depth_offset_m;
  std::vector<glm::dvec3> p_WT, p_WH;
  std::vector<glm::dquat> R_WH;      ///< the hand's rotation, per tick
  std::vector<glm::dvec3> theta_WT;  ///< R_WT as a rotation vector (rad, W)
  std::int64_t tool_states = 0, tool_state_bytes = 0;
  std::int64_t models = 0, model_bytes = 0;
  /// Depth fields sent, their bytes (codecs/depth_field_codec.h, in datagrams), and the bytes of
  /// the surface a receiver caching it by lattice node would lack (the maps' share only).
  std::int64_t fields_sent = 0, field_bytes = 0, field_cached_bytes = 0;
  /// Contacts in the models sent, and those with a finite depth but no field (their
  /// linearization alone).
  std::int64_t contacts_sent = 0, contacts_sent_without_field = 0;
  ht::DeadbandCounts tool_decisions{}, model_decisions{};
  double duration_s = 0.0;
};

/// Parses "NAME:KEY=V,..." into an arm; throws std::invalid_argument naming a bad key or value.
Arm ParseArm(const std::string& text);

struct Setup {
  const ht::HapticScene* scene = nullptr;
  /// The remote step's setting when an arm names none (a frontier setting's name).
  std::string setting = "default";
  std::string replay_file;
  /// A handle trajectory to replay (in M), taking the place of replay_file and the simulated
  /// hand when not empty (--hand-from-reference).
  std::vector<ht::ReplaySample> replay_samples;
  std::string experiment = "fig75";
  double duration_s = 5.0;
  double delay_ms = 0.1;
  double reference_delay_ms = -1.0;  ///< the reference arm's delay (< 0: delay_ms)
  double step_ms = 0.3;
  /// The tool's start shifted along `seed_axis` of W (m): a seed (--seed-step-um apart).
  double start_offset_m = 0.0;
  int seed_axis = 0;  ///< 0, 1, 2: W's x, y, z
  /// Each datagram's delay is delay_ms plus a draw from [0, jitter_ms] (ms; 0: none), from a
  /// generator seeded with `seed` (datagrams keep their order: a later one never overtakes).
  double jitter_ms = 0.0;
  int seed = 0;
  /// Share of datagrams lost on each stream ([0, 1)), drawn from a generator seeded alike in
  /// every run (the same datagram numbers are lost in every arm).
  double loss = 0.0;
};

/// One seed's shift of the tool's start (m): far below anything the method resolves, enough to
/// change which ridge crest the rocking tool meets first.
constexpr double kSeedOffsetM = 1e-6;  // the default --seed-step-um

/// Runs `arm` on `setup`: the operator's ticks, both deadbands and the remote step, one clock.
ArmRun RunArm(const Setup& setup, const Arm& arm);

/// 100 · √(Σ|b − a|² / Σ|a|²) over the ticks (the runs are tick for tick on one clock).
double RmsErrorPct(const std::vector<glm::dvec3>& ref, const std::vector<glm::dvec3>& run);
/// The largest change of `v` from one tick to the next.
double LargestStep(const std::vector<glm::dvec3>& v);
/// One row per tick of `r` (trace.csv's columns); throws std::runtime_error when it cannot write.
void WriteTrace(const std::string& path, const ArmRun& r);
/// Ticks whose change of `v` exceeds `n`.
int StepsAbove(const std::vector<glm::dvec3>& v, double n);
/// The q-quantile of the changes of `v` from tick to tick.
double StepQuantile(const std::vector<glm::dvec3>& v, double q);
/// The RMS (×1000: mN for a force in N) of `v` less its 51-tick moving mean: the ripple.
double HighPassRmsMilli(const std::vector<glm::dvec3>& v);
/// The q-quantile of `v` (0 when empty).
double Quantile(std::vector<double> v, double q);
/// Share of ticks (%) whose count in `per_tick` is above zero.
double FieldTickShare(const std::vector<int>& per_tick);
/// What the passivity controller removed over the device force's impulse, Σ removed / Σ|F| (%).
double PassivityShare(const ArmRun& r);

}  // namespace lockstep
