// The perceptual deadband measured without the machine's noise (issue 33): the operator's tick
// (master_station's OperatorTick, the simulated hand or a replayed trajectory), both deadbands,
// the compact encodings and the remote step (HapticTexturePipeline on the CPU backend) run in one
// process on one simulated clock, 1 ms a tick, with a fixed one-way delay. Every arm is judged
// against a reference arm with both deadbands off, made in the same run: the same input, the same
// code, so that what differs is the deadband's doing alone. On the loopback (deploy/deadband-table)
// two identical runs differ by 1.5–7 % in device force (network and scheduler timing, and on fig75
// a hand that reacts to the force), which is as large as the 5 % the issue allows; here they are
// identical to the bit.
//
// What it leaves out, against the loopback: the remote node's steps between ticks (it steps at
// up to ~3.5 kHz in contact and sends at most one model a millisecond; here it steps once a tick,
// right after the tick's tool state arrives), the threads' and the network's jitter, and the
// remote step's own time (a fixed `--step-ms`). So its errors are the deadband's, not a run's.
//
// Usage: deadband_lockstep [--replay FILE | --experiment fig75] [--arm NAME:KEY=V,...]...
//        [--delay-ms D] [--loss-pct L] [--reference-delay-ms D0] [--seeds K] [--out DIR]
// Exit status: 0 done; 2 bad arguments (one line saying which); 1 a run failed (e.g. an
// unreadable replay file).

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <deque>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "haptic_core/demo/demo_scenes.h"
#include "haptic_core/penetration_depth_backend.h"
#include "haptic_core/remote_step.h"
#include "haptic_core/statistics.h"
#include "master_station/experiment.h"
#include "master_station/operator_station.h"
#include "master_station/operator_tick.h"
#include "master_station/replay_device.h"
#include "master_station/simulated_operator.h"
#include "slave_sim/benchmark_scenes.h"
#include "slave_sim/frontier.h"
#include "slave_sim/remote_node.h"
#include "transport/auth.h"
#include "transport/deadband.h"
#include "transport/messages.h"

namespace {

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
};

/// What one arm's run gives, tick by tick and in all.
struct ArmRun {
  std::vector<glm::dvec3> device_force_W, device_torque_W, contact_force_W;
  std::vector<double> passivity_removed_n, model_age_ms;
  std::vector<int> contacts, model_arrived;
  std::vector<double> depth_offset_m;
  std::vector<glm::dvec3> p_WT, p_WH;
  std::vector<glm::dvec3> theta_WT;  ///< R_WT as a rotation vector (rad, W)
  std::int64_t tool_states = 0, tool_state_bytes = 0;
  std::int64_t models = 0, model_bytes = 0;
  ht::DeadbandCounts tool_decisions{}, model_decisions{};
  double duration_s = 0.0;
};

double ParseNumber(const std::string& key, const std::string& text) {
  std::size_t used = 0;
  double v = 0.0;
  try {
    v = std::stod(text, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used != text.size() || !std::isfinite(v)) {
    throw std::invalid_argument("--arm: " + key + "=" + text + " is not a finite number");
  }
  return v;
}

/// `v` when it is ≥ 0; throws std::invalid_argument naming --arm's `key` otherwise.
double NonNegative(const std::string& key, double v) {
  if (!(v >= 0.0)) throw std::invalid_argument("--arm: " + key + " must be >= 0");
  return v;
}

/// "NAME:KEY=V,KEY=V": keys deadband (both streams, %), tool_deadband, model_deadband (%),
/// keepalive_ms (both), contact_floor_mm, contact_floor_mrad, contact_depth_floor_um,
/// contact_hold_ms (tool states), force_floor, torque_floor, stiffness_floor,
/// rotational_stiffness_floor (the contact-model floor scales, as slave_sim's
/// --model-deadband-*-floor), release_ticks, energy_bounded_switch, switch_spend,
/// offset_release_ms (the operator tick's passivity options), setting (a frontier setting's name:
/// the remote step's options). Defaults: master_station's and slave_sim's, deadband 10 %.
Arm ParseArm(const std::string& text) {
  Arm arm;  // the floors and hold: ToolStateDeadbandConfig's defaults, master_station's too
  arm.tool.weber_fraction = 0.1;
  arm.model.weber_fraction = 0.1;
  const std::size_t colon = text.find(':');
  arm.name = text.substr(0, colon);
  if (arm.name.empty()) throw std::invalid_argument("--arm " + text + ": no name before ':'");
  if (colon == std::string::npos) return arm;
  std::stringstream items(text.substr(colon + 1));
  std::string item;
  while (std::getline(items, item, ',')) {
    if (item.empty()) continue;
    const std::size_t eq = item.find('=');
    if (eq == std::string::npos) {
      throw std::invalid_argument("--arm " + text + ": '" + item + "' is not KEY=VALUE");
    }
    const std::string key = item.substr(0, eq);
    if (key == "setting") {  // the one key that takes a name
      arm.setting = item.substr(eq + 1);
      ht::FrontierSettingNamed(arm.setting);  // throws naming it when there is none
      continue;
    }
    const double v = ParseNumber(key, item.substr(eq + 1));
    if (key == "deadband") {
      arm.tool.weber_fraction = arm.model.weber_fraction = v / 100.0;
    } else if (key == "tool_deadband") {
      arm.tool.weber_fraction = v / 100.0;
    } else if (key == "model_deadband") {
      arm.model.weber_fraction = v / 100.0;
    } else if (key == "keepalive_ms") {
      arm.tool.keepalive_s = arm.model.keepalive_s = v * 1e-3;
    } else if (key == "contact_floor_mm") {
      arm.tool.contact_position_floor_scale_m = v * 1e-3;
    } else if (key == "contact_floor_mrad") {
      arm.tool.contact_rotation_floor_scale_rad = v * 1e-3;
    } else if (key == "contact_depth_floor_um") {
      arm.tool.contact_depth_floor_scale_m = v * 1e-6;
    } else if (key == "velocity_criterion") {  // master_station --deadband-velocity
      arm.tool.velocity_criterion = v != 0.0;
    } else if (key == "contact_hold_ms") {
      arm.tool.contact_floor_hold_s = v * 1e-3;
    } else if (key == "release_ticks") {  // ticks of 1 ms
      arm.station.passivity_release_ms = v;
    } else if (key == "energy_bounded_switch") {
      arm.station.energy_bounded_switch = v != 0.0;
    } else if (key == "switch_spend") {
      arm.switch_energy_spend_fraction = v;
    } else if (key == "offset_release_ms") {  // 0 = as long as the budget says
      arm.station.switch_offset_release_ms = v > 0.0 ? v : std::numeric_limits<double>::infinity();
    } else if (key == "contact_damping_hc") {  // s/m, master_station --contact-damping-hc
      arm.station.hunt_crossley_s_per_m = v;
    } else if (key == "speculative_lead_ms") {  // slave_sim --speculative-lead-ms
      arm.speculative_lead_s = NonNegative(key, v) * 1e-3;
    } else if (key == "speculative_margin_mm") {  // PipelineOptions::max_speculative_margin_m
      arm.speculative_margin_m = NonNegative(key, v) * 1e-3;
    } else if (key == "speculative_speed_mm_s") {  // slave_sim --speculative-speed-mm-s
      arm.speculative_speed_m_per_s = NonNegative(key, v) * 1e-3;
    } else if (key == "speculative_floor_mm") {  // a fixed PipelineOptions::speculative_floor_m
      arm.speculative_floor_m = NonNegative(key, v) * 1e-3;
    } else if (key == "force_floor") {
      arm.model.force_floor_scale_n = v;
    } else if (key == "torque_floor") {
      arm.model.torque_floor_scale_nm = v;
    } else if (key == "stiffness_floor") {
      arm.model.stiffness_floor_scale_n_per_m = v;
    } else if (key == "rotational_stiffness_floor") {
      arm.model.rotational_stiffness_floor_scale_nm_per_rad = v;
    } else {
      throw std::invalid_argument("--arm " + text + ": unknown key '" + key + "'");
    }
  }
  arm.tool.Validate();
  arm.model.Validate();
  arm.station.Validate();
  return arm;
}

/// A message in flight: it arrives at `arrive_ns`.
template <typename T>
struct InFlight {
  std::int64_t arrive_ns = 0;
  T value;
};

/// A tool state as the remote node holds it: as decoded, its sequence number and the
/// operator's send time (ns, the one clock).
struct SentToolState {
  ht::wire::ToolStateMessage message;
  std::uint64_t seq = 0;
  std::int64_t sent_ns = 0;
};

struct Setup {
  const ht::HapticScene* scene = nullptr;
  /// The remote step's setting when an arm names none (a frontier setting's name).
  std::string setting = "default";
  /// With --translation-patch: every model carries its patch, whatever the round trip.
  bool translation_patch = false;
  std::string replay_file;
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

ArmRun RunArm(const Setup& setup, const Arm& arm) {
  using namespace ht;
  const wire::SceneLayout layout = MakeSceneLayout(*setup.scene);
  const RigidTransform X_WM = layout.X_WT_home;
  std::unique_ptr<Experiment> experiment = MakeExperiment(setup.experiment, setup.duration_s);
  experiment->SetScene(ExperimentSceneInM(layout, X_WM));  // as RunOperatorStation does
  std::unique_ptr<HapticDevice> device;
  double duration_s = setup.duration_s;
  if (!setup.replay_file.empty()) {
    auto replay = std::make_unique<ReplayDevice>(
        LoadReplayTrace(setup.replay_file, X_WM.translation), setup.replay_file);
    duration_s = replay->duration_s();
    device = std::move(replay);
  } else {
    device = std::make_unique<SimulatedOperatorDevice>(*experiment);
  }
  device->Open();
  const DeviceCapabilities caps = device->capabilities();

  const ToolInertia inertia = layout.tool_mass_kg > 0.0
                                  ? ToolInertia{layout.tool_mass_kg, layout.tool_inertia_diagonal_T}
                                  : arm.station.tool_inertia;
  OperatorTickConfig tc = OperatorTickConfigFor(arm.station, caps, inertia, 1e-3);
  tc.switch_energy_spend_fraction = arm.switch_energy_spend_fraction;
  ToolState tool;
  tool.X_WT = X_WM * experiment->Target(0.0).X_MH;
  tool.X_WT.translation[setup.seed_axis] += setup.start_offset_m;
  OperatorTick tick(tc, X_WM, tool);

  // The translation patches by the round trip, as the remote node's default
  // (RemoteNodeConfig::translation_patch_rtt_ms, 10 ms): here on from the first step.
  const FrontierSetting setting =
      FrontierSettingNamed(arm.setting.empty() ? setup.setting : arm.setting);
  PipelineOptions options = PipelineOptionsFor(setting);
  options.texture_threads = 1;
  if (arm.speculative_lead_s >= 0.0) options.speculative_lead_s = arm.speculative_lead_s;
  if (arm.speculative_margin_m >= 0.0) options.max_speculative_margin_m = arm.speculative_margin_m;
  // The round trip the operator would report, from which the remote node sets the floor and the
  // patches.
  const double rtt_ms = 2.0 * setup.delay_ms + setup.step_ms;
  if (arm.speculative_floor_m >= 0.0) {
    options.speculative_floor_m = arm.speculative_floor_m;
  } else {
    RemoteNodeConfig node;
    node.speculative_speed_m_per_s = arm.speculative_speed_m_per_s;
    options.speculative_floor_m =
        SpeculativeFloorForRoundTrip(node, static_cast<std::int64_t>(std::llround(rtt_ms * 1e6)));
  }
  if (setup.translation_patch || rtt_ms >= RemoteNodeConfig{}.translation_patch_rtt_ms) {
    options.depth_refinement.translation_patch = true;
  }
  // The CPU backend with the setting's texture path and rotation gradient (as the frontier makes
  // it; with the default setting, what slave_sim --pd-backend cpu makes).
  HapticTexturePipeline pipeline(
      *setup.scene, options,
      std::make_unique<CpuPenetrationDepthBackend>(std::max(2, options.max_window_resolution()),
                                                   setting.texture_path, options.texture_threads,
                                                   setting.rotation_gradient));
  ToolStateDeadband tool_deadband(arm.tool);
  ContactModelDeadband model_deadband(arm.model);
  const MacKey key{};  // the MAC is computed as on the wire; its key does not matter here

  const std::int64_t kTickNs = 1'000'000;
  const auto delay_ns = static_cast<std::int64_t>(std::llround(setup.delay_ms * 1e6));
  const auto step_ns = static_cast<std::int64_t>(std::llround(setup.step_ms * 1e6));
  const std::int64_t t0 = 1'000'000'000;  // the clocks start at 1 s (the echo is a time)
  const std::int64_t keepalive_ns = static_cast<std::int64_t>(arm.tool.keepalive_s * 1e9);
  const auto ticks = static_cast<std::int64_t>(std::llround(duration_s * 1e3));

  std::deque<InFlight<SentToolState>> to_remote;
  std::deque<InFlight<ArrivedModel>> to_operator;
  SentToolState remote;              // the newest tool state the remote node holds
  std::int64_t remote_recv_ns = -1;  // when it arrived (< 0: none yet)
  ContactModel held_model{};         // the newest model the operator received (its deadband's)
  std::uint64_t tool_seq = 0, model_seq = 0;
  ArmRun run;
  run.duration_s = static_cast<double>(ticks) * 1e-3;
  ArrivedModel arrived;
  std::mt19937_64 loss_to_remote(7), loss_to_operator(11);
  std::mt19937_64 jitter_rng(1000 + static_cast<std::uint64_t>(setup.seed));
  const auto jitter_ns = static_cast<std::int64_t>(std::llround(setup.jitter_ms * 1e6));
  std::uniform_int_distribution<std::int64_t> jitter(0, jitter_ns);
  std::int64_t last_to_remote_ns = 0, last_to_operator_ns = 0;  // arrivals keep their order
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  for (std::int64_t k = 0; k < ticks; ++k) {
    const std::int64_t now = t0 + k * kTickNs;
    // The operator: the newest model that has arrived, then the tick.
    OperatorTickInput in;
    in.now_ns = now;
    in.device_ok = device->ReadState(now, in.device);
    bool have_arrived = false;
    while (!to_operator.empty() && to_operator.front().arrive_ns <= now) {
      arrived = to_operator.front().value;
      to_operator.pop_front();
      have_arrived = true;
    }
    if (have_arrived) {
      in.arrived = &arrived;
      held_model = arrived.model;
    }
    const OperatorTickOutput out = tick.Step(in);
    device->WriteWrench(out.F_H_M, now);
    run.device_force_W.push_back(out.F_device_W.force);
    run.device_torque_W.push_back(out.F_device_W.torque);
    run.contact_force_W.push_back(out.step.F_contact_T_W.force);
    run.passivity_removed_n.push_back(out.passivity_removed_n);
    run.model_age_ms.push_back(out.model_age_ms);
    run.contacts.push_back(out.step.active_contacts);
    run.depth_offset_m.push_back(out.depth_offset_m);
    run.model_arrived.push_back(have_arrived ? 1 : 0);
    run.p_WT.push_back(tick.tool().X_WT.translation);
    run.theta_WT.push_back(RotationVectorFromQuaternion(tick.tool().X_WT.rotation));
    run.p_WH.push_back(out.X_WH.translation);
    // Its tool state, through the operator's deadband (on what the remote node will decode).
    ++tool_seq;
    const wire::ToolStateMessage state{tick.tool().X_WT, tick.tool().V_WT_W};
    const wire::ToolStateMessage received = wire::CompactToolStateAsReceived(state);
    const DeadbandReason why = tool_deadband.Decide(received.X_WT, received.V_WT_W, now,
                                                    tick.model().num_contacts > 0, &held_model);
    ++run.tool_decisions[static_cast<std::size_t>(why)];
    if (why != DeadbandReason::kNotSent) {
      wire::Header h;
      h.session_id = 1;
      h.sequence = tool_seq;
      h.send_time_ns = now;
      run.tool_state_bytes +=
          static_cast<std::int64_t>(wire::EncodeCompactToolState(h, state, key).size);
      ++run.tool_states;
      if (uniform(loss_to_remote) >= setup.loss) {
        const std::int64_t arrive =
            std::max(last_to_remote_ns, now + delay_ns + (jitter_ns > 0 ? jitter(jitter_rng) : 0));
        last_to_remote_ns = arrive;
        to_remote.push_back({arrive, {received, tool_seq, now}});
      }
    }
    // The remote node, right after this tick's tool state has arrived: one step at the newest
    // state, extrapolated under a tool-state deadband as RemoteSession::ToolPoseForStep does.
    const std::int64_t t_r = now + delay_ns;
    while (!to_remote.empty() && to_remote.front().arrive_ns <= t_r) {
      remote = to_remote.front().value;
      remote_recv_ns = to_remote.front().arrive_ns;
      to_remote.pop_front();
    }
    if (remote_recv_ns < 0) continue;
    const std::int64_t extrapolation_ns =
        arm.tool.weber_fraction > 0.0
            ? std::clamp<std::int64_t>(t_r - remote_recv_ns, 0, keepalive_ns)
            : 0;
    const RigidTransform X_WT = ExtrapolatePose(remote.message.X_WT, remote.message.V_WT_W,
                                                static_cast<double>(extrapolation_ns) * 1e-9);
    StepTimings timings;
    wire::ContactModelMessage message;
    message.model = pipeline.Step(X_WT, remote.seq, timings, remote.message.V_WT_W);
    const std::int64_t sent_ns = t_r + step_ns;
    const DeadbandReason model_why = model_deadband.Decide(message.model, sent_ns);
    ++run.model_decisions[static_cast<std::size_t>(model_why)];
    if (model_why == DeadbandReason::kNotSent) continue;
    message.tool_state_send_time_ns = remote.sent_ns + extrapolation_ns;
    message.hold_ns = sent_ns - (remote_recv_ns + extrapolation_ns);
    message.remote_step_count = static_cast<std::uint64_t>(k + 1);
    wire::Header h;
    h.type = wire::MessageType::kCompactContactModel;
    h.session_id = 1;
    h.sequence = ++model_seq;
    h.send_time_ns = sent_ns;
    const wire::Datagram d = wire::EncodeCompactContactModel(h, message, key);
    run.model_bytes += static_cast<std::int64_t>(d.size);
    ++run.models;
    // What the operator decodes (the compact encoding's quantization included).
    wire::Header opened;
    std::span<const std::uint8_t> body;
    wire::ContactModelMessage decoded;
    const std::int64_t arrive_ns = std::max(
        last_to_operator_ns, sent_ns + delay_ns + (jitter_ns > 0 ? jitter(jitter_rng) : 0));
    last_to_operator_ns = arrive_ns;
    if (wire::OpenDatagram(d.view(), key, opened, body) != wire::DecodeStatus::kOk ||
        wire::DecodeCompactContactModel(body, decoded, arrive_ns) != wire::DecodeStatus::kOk) {
      throw std::runtime_error("a contact model did not decode (tick " + std::to_string(k) + ")");
    }
    ArrivedModel a;
    a.model = decoded.model;
    a.tool_state_sent_ns = decoded.tool_state_send_time_ns;
    a.built_local_ns = sent_ns;
    a.collision_us = static_cast<float>(timings.collision_us);
    a.texture_us = static_cast<float>(timings.texture_us);
    a.step_us = static_cast<float>(timings.total_us);
    if (uniform(loss_to_operator) >= setup.loss) to_operator.push_back({arrive_ns, a});
  }
  device->Close();
  return run;
}

/// 100 · √(Σ|b − a|² / Σ|a|²) over the ticks (the runs are tick for tick on one clock).
double RmsErrorPct(const std::vector<glm::dvec3>& ref, const std::vector<glm::dvec3>& run) {
  double num = 0.0, den = 0.0;
  const std::size_t n = std::min(ref.size(), run.size());
  for (std::size_t i = 0; i < n; ++i) {
    const glm::dvec3 d = run[i] - ref[i];
    num += glm::dot(d, d);
    den += glm::dot(ref[i], ref[i]);
  }
  return den > 0.0 ? 100.0 * std::sqrt(num / den) : 0.0;
}

double LargestStep(const std::vector<glm::dvec3>& v) {
  double m = 0.0;
  for (std::size_t i = 1; i < v.size(); ++i) m = std::max(m, glm::length(v[i] - v[i - 1]));
  return m;
}

/// One row per tick: what the operator felt and why; tool_x..tool_z and tool_rx..tool_rz are X_WT
/// as master_station's trace.csv has it (speed_error_frontier --trace reads it).
void WriteTrace(const std::string& path, const ArmRun& r) {
  std::ofstream f(path);
  if (!f) throw std::runtime_error("cannot write " + path);
  f << "t_s,device_fx,device_fy,device_fz,device_tx,device_ty,device_tz,contact_fx,contact_fy,"
       "contact_fz,passivity_removed_n,model_age_ms,contacts,model_arrived,tool_x,tool_y,tool_z,"
       "hand_x,hand_y,hand_z,depth_offset_um,tool_rx,tool_ry,tool_rz\n";
  for (std::size_t i = 0; i < r.device_force_W.size(); ++i) {
    const auto v = [&](const glm::dvec3& a) { f << ',' << a.x << ',' << a.y << ',' << a.z; };
    f << static_cast<double>(i) * 1e-3;
    v(r.device_force_W[i]);
    v(r.device_torque_W[i]);
    v(r.contact_force_W[i]);
    f << ',' << r.passivity_removed_n[i] << ',' << r.model_age_ms[i] << ',' << r.contacts[i] << ','
      << r.model_arrived[i];
    v(r.p_WT[i]);
    v(r.p_WH[i]);
    f << ',' << r.depth_offset_m[i] * 1e6;
    v(r.theta_WT[i]);
    f << '\n';
  }
}

int StepsAbove(const std::vector<glm::dvec3>& v, double n) {
  int c = 0;
  for (std::size_t i = 1; i < v.size(); ++i) c += glm::length(v[i] - v[i - 1]) > n ? 1 : 0;
  return c;
}

/// The q-quantile of the one-tick change |v[i] − v[i−1]| (nearest rank, Percentile; 0 for fewer
/// than two).
double StepQuantile(const std::vector<glm::dvec3>& v, double q) {
  std::vector<double> d;
  for (std::size_t i = 1; i < v.size(); ++i) d.push_back(glm::length(v[i] - v[i - 1]));
  return ht::Percentile(std::move(d), q);
}

/// What a hand feels as ripple (mN): the RMS of v less its centred 50-tick moving mean (a
/// high-pass at about 20 Hz; the eleventh stop's stick_ripple measure on one clock).
double HighPassRmsMilli(const std::vector<glm::dvec3>& v) {
  constexpr std::size_t kHalf = 25;
  if (v.size() <= 2 * kHalf) return 0.0;
  std::vector<glm::dvec3> prefix(v.size() + 1, glm::dvec3(0.0));
  for (std::size_t i = 0; i < v.size(); ++i) prefix[i + 1] = prefix[i] + v[i];
  double sum = 0.0;
  std::size_t n = 0;
  for (std::size_t i = kHalf; i + kHalf < v.size(); ++i) {
    const glm::dvec3 mean =
        (prefix[i + kHalf + 1] - prefix[i - kHalf]) / static_cast<double>(2 * kHalf + 1);
    const glm::dvec3 d = v[i] - mean;
    sum += glm::dot(d, d);
    ++n;
  }
  return 1e3 * std::sqrt(sum / static_cast<double>(n));
}

double PassivityShare(const ArmRun& r) {
  double removed = 0.0, impulse = 0.0;
  for (std::size_t i = 0; i < r.device_force_W.size(); ++i) {
    removed += r.passivity_removed_n[i];
    impulse += glm::length(r.device_force_W[i]);
  }
  return impulse > 0.0 ? 100.0 * removed / impulse : 0.0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "The perceptual deadband on one simulated clock: the operator's tick, both deadbands, the\n"
      "compact encodings and the remote step in one process, 1 ms a tick, a fixed one-way delay.\n"
      "Each --arm is judged tick for tick against a reference with both deadbands off, made in\n"
      "the same run (the loopback's run-to-run noise, 1.5-7 % in device force, is not in it).\n"
      "CPU penetration depth."};
  Setup setup;
  std::vector<std::string> arm_texts;
  std::string out_dir, scene_name = "block-on-gear";
  int seeds = 3;
  app.add_option("--replay", setup.replay_file,
                 "a handle trajectory CSV (master_station --device replay; e.g. from\n"
                 "deploy/kinesthetic-replay); default: the simulated hand of --experiment");
  app.add_option("--scene", scene_name,
                 "built-in scene, as slave_sim --scene: block-on-gear (seed Fig. 75), stiff-wall\n"
                 "(the same block on a flat wall five times stiffer), striped-blocks (seed\n"
                 "Fig. 76), file-on-cad-part (Fig. 77), hammer-on-torus; the benchmark scenes'\n"
                 "models are built or read from --cache-dir as slave_sim does")
      ->check(CLI::IsMember(
          {"block-on-gear", "stiff-wall", "striped-blocks", "file-on-cad-part", "hammer-on-torus"}))
      ->capture_default_str();
  std::string cache_dir = ht::HapticModelCache::DefaultDir();
  app.add_option("--cache-dir", cache_dir, "model cache folder (the benchmark scenes)")
      ->capture_default_str();
  std::string experiment;
  app.add_option("--experiment", experiment,
                 "the simulated hand's script (default: fig76 on striped-blocks, else fig75)")
      ->check(CLI::IsMember({"fig75", "fig76", "explore"}));
  app.add_option("--reference-setting", setup.setting,
                 "the remote step's setting of the reference and of every arm that names none\n"
                 "(a frontier setting's name: speed_error_frontier --list-settings)")
      ->capture_default_str();
  app.add_option("--duration", setup.duration_s, "seconds, with the simulated hand")
      ->check(CLI::Range(0.1, 600.0))
      ->capture_default_str();
  app.add_option("--delay-ms", setup.delay_ms, "one-way delay of both streams (ms)")
      ->check(CLI::Range(0.0, 1000.0))
      ->capture_default_str();
  double loss_pct = 0.0;
  app.add_option("--loss-pct", loss_pct,
                 "datagrams lost on each stream (%; the same datagram numbers in every arm; the\n"
                 "reference has none)")
      ->check(CLI::Range(0.0, 90.0))
      ->capture_default_str();
  app.add_option("--reference-delay-ms", setup.reference_delay_ms,
                 "the reference arm's one-way delay (ms; default --delay-ms): e.g. 0 to judge\n"
                 "the arms under --delay-ms 150 against the undelayed run")
      ->check(CLI::Range(0.0, 1000.0));
  app.add_option("--step-ms", setup.step_ms,
                 "the remote step's time, fixed (ms): a model goes out this long after its tool\n"
                 "state arrived")
      ->check(CLI::Range(0.0, 100.0))
      ->capture_default_str();
  app.add_option(
         "--seeds", seeds,
         "runs per arm, the tool's start --seed-step-um apart along --seed-axis (seed k:\n"
         "k steps); each arm is judged against the reference's seed 0, and the reference's\n"
         "other seeds show how far such a start moves by itself")
      ->check(CLI::Range(1, 100))
      ->capture_default_str();
  app.add_option(
         "--jitter-ms", setup.jitter_ms,
         "each datagram's delay varies by a draw from [0, this] (ms; seed k draws from its\n"
         "own generator; the reference too, unless --seeds 1): the loopback's timing noise,\n"
         "which on fig76 decides the block's course where a start offset does not")
      ->check(CLI::Range(0.0, 100.0))
      ->capture_default_str();
  double seed_step_um = kSeedOffsetM * 1e6;
  app.add_option("--seed-step-um", seed_step_um,
                 "how far apart the seeds' starts are (um; on fig76 a 1 um step along x changes\n"
                 "nothing, and the block can settle in either of two places)")
      ->check(CLI::Range(0.0, 1000.0))
      ->capture_default_str();
  std::string seed_axis = "x";
  app.add_option("--seed-axis", seed_axis, "W's axis the seeds' starts are shifted along")
      ->check(CLI::IsMember({"x", "y", "z"}))
      ->capture_default_str();
  app.add_option(
      "--arm", arm_texts,
      "NAME:KEY=V,...: an arm (repeatable; default one arm 'default' at 10 %).\n"
      "Keys: deadband, tool_deadband, model_deadband (%), keepalive_ms,\n"
      "contact_floor_mm, contact_floor_mrad, contact_depth_floor_um, contact_hold_ms,\n"
      "velocity_criterion (0/1)\n"
      "(the tool-state deadband, as master_station's --deadband-*), force_floor,\n"
      "torque_floor, stiffness_floor, rotational_stiffness_floor (the contact-model\n"
      "floor scales, as slave_sim's --model-deadband-*-floor); release_ticks,\n"
      "energy_bounded_switch (0/1), switch_spend, offset_release_ms, contact_damping_hc\n"
      "(the operator tick's passivity options, OperatorTickConfig; master_station's\n"
      "defaults, as in the reference, unless given); speculative_lead_ms (slave_sim\n"
      "--speculative-lead-ms), speculative_margin_mm, speculative_speed_mm_s (slave_sim\n"
      "--speculative-speed-mm-s: the floor by the round trip) or a fixed\n"
      "speculative_floor_mm; setting=NAME, the remote step's setting by its frontier\n"
      "name (speed_error_frontier --list-settings; default --reference-setting)");
  app.add_flag("--translation-patch", setup.translation_patch,
               "every contact model carries its translation patch (slave_sim --translation-patch;\n"
               "by default the remote node sends patches from a 10 ms round trip)");
  app.add_option("--out", out_dir,
                 "folder for summary.json and one trace per arm, ARM.csv (created); default:\n"
                 "the table on stdout only");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int rc = app.exit(e);
    return rc == 0 ? 0 : 2;
  }
  const double seed_step_m = seed_step_um * 1e-6;
  std::vector<Arm> arms;
  const Arm reference = ParseArm("reference:deadband=0");
  try {
    ht::FrontierSettingNamed(setup.setting);
    setup.seed_axis = seed_axis == "x" ? 0 : seed_axis == "y" ? 1 : 2;
    setup.experiment = !experiment.empty()              ? experiment
                       : scene_name == "striped-blocks" ? "fig76"
                                                        : "fig75";
    if (arm_texts.empty()) arm_texts.push_back("default");
    for (const std::string& t : arm_texts) arms.push_back(ParseArm(t));
  } catch (const std::invalid_argument& e) {
    std::fprintf(stderr, "deadband_lockstep: %s\n", e.what());
    return 2;
  }
  try {
    std::fprintf(stderr, "deadband_lockstep: building %s...\n", scene_name.c_str());
    ht::HapticScene scene;
    if (scene_name == "stiff-wall") {
      scene = ht::MakeStiffWallScene();
    } else if (scene_name == "block-on-gear") {
      scene = ht::MakeBlockOnGearScene();
    } else {  // as slave_sim --scene builds it
      const std::string name = ht::BenchmarkSceneOfBuiltin(scene_name);
      scene = ht::MakeBenchmarkScene(name, ht::ProductModelSettings(name),
                                     ht::HapticModelCache(cache_dir))
                  .haptic;
      scene.name = scene_name;
    }
    setup.scene = &scene;
    std::fprintf(stderr, "deadband_lockstep: reference (both deadbands off)...\n");
    setup.loss = loss_pct / 100.0;
    Setup reference_setup = setup;
    reference_setup.loss = 0.0;
    if (setup.reference_delay_ms >= 0.0) reference_setup.delay_ms = setup.reference_delay_ms;
    const ArmRun ref = RunArm(reference_setup, reference);
    nlohmann::json summary;
    summary["input"] = setup.replay_file.empty() ? setup.experiment : setup.replay_file;
    summary["scene"] = scene_name;
    summary["reference_setting"] = setup.setting;
    summary["duration_s"] = ref.duration_s;
    summary["delay_ms"] = setup.delay_ms;
    summary["step_ms"] = setup.step_ms;
    summary["reference_delay_ms"] = reference_setup.delay_ms;
    summary["loss_pct"] = loss_pct;
    summary["jitter_ms"] = setup.jitter_ms;
    summary["seed_step_um"] = seed_step_um;
    summary["seed_axis"] = seed_axis;
    std::printf(
        "| arm | tool states /s | kbit/s | reduction %% | models /s | kbit/s | reduction %% | "
        "device F err %% | device tau err %% | contact F err %% | largest device dF (N) | "
        "passivity share %% | device dF > 0.5 N | device dF > 0.2 N | contact dF > 0.2 N | "
        "contact dF p99 (N) | device ripple (mN) |\n"
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
    // One arm over its seeds: every figure's mean, and min–max where the seeds differ.
    // `arm`: null for the reference's seeds against its first.
    const auto report = [&](const std::string& name, const Arm* arm,
                            const std::vector<ArmRun>& runs, bool skip_first) {
      std::map<std::string, std::vector<double>> v;
      nlohmann::json per_seed = nlohmann::json::array();
      for (std::size_t k = skip_first ? 1 : 0; k < runs.size(); ++k) {
        const ArmRun& r = runs[k];
        const double d = r.duration_s;
        const nlohmann::json j = {
            {"seed", k},
            {"tool_states_per_s", static_cast<double>(r.tool_states) / d},
            {"tool_state_kbit_s", static_cast<double>(r.tool_state_bytes) * 8e-3 / d},
            {"tool_state_reduction_pct",
             100.0 * (1.0 - static_cast<double>(r.tool_states) /
                                static_cast<double>(std::max<std::int64_t>(1, ref.tool_states)))},
            {"models_per_s", static_cast<double>(r.models) / d},
            {"model_kbit_s", static_cast<double>(r.model_bytes) * 8e-3 / d},
            {"model_reduction_pct",
             100.0 * (1.0 - static_cast<double>(r.models) /
                                static_cast<double>(std::max<std::int64_t>(1, ref.models)))},
            {"device_force_error_pct", RmsErrorPct(ref.device_force_W, r.device_force_W)},
            {"device_torque_error_pct", RmsErrorPct(ref.device_torque_W, r.device_torque_W)},
            {"contact_force_error_pct", RmsErrorPct(ref.contact_force_W, r.contact_force_W)},
            {"largest_device_force_step_n", LargestStep(r.device_force_W)},
            {"passivity_share_pct", PassivityShare(r)},
            {"device_force_steps_above_0_5n", StepsAbove(r.device_force_W, 0.5)},
            {"device_force_steps_above_0_2n", StepsAbove(r.device_force_W, 0.2)},
            {"contact_force_steps_above_0_2n", StepsAbove(r.contact_force_W, 0.2)},
            {"contact_force_step_p99_n", StepQuantile(r.contact_force_W, 0.99)},
            {"device_force_ripple_mn", HighPassRmsMilli(r.device_force_W)},
            {"tool_state_decisions", ht::ToJson(r.tool_decisions)},
            {"model_decisions", ht::ToJson(r.model_decisions)}};
        for (const auto& [key, value] : j.items()) {
          if (value.is_number() && key != "seed") v[key].push_back(value.get<double>());
        }
        per_seed.push_back(j);
      }
      const auto cell = [&](const char* key, const char* format) {
        const std::vector<double>& x = v[key];
        double sum = 0.0, lo = x.empty() ? 0.0 : x[0], hi = lo;
        for (double e : x) {
          sum += e;
          lo = std::min(lo, e);
          hi = std::max(hi, e);
        }
        const double mean = x.empty() ? 0.0 : sum / static_cast<double>(x.size());
        char text[128];
        char a[32], b[32], c[32];
        std::snprintf(a, sizeof(a), format, mean);
        std::snprintf(b, sizeof(b), format, lo);
        std::snprintf(c, sizeof(c), format, hi);
        if (std::string(b) == c) {
          std::snprintf(text, sizeof(text), "%s", a);
        } else {
          std::snprintf(text, sizeof(text), "%s (%s–%s)", a, b, c);
        }
        return std::string(text);
      };
      std::printf(
          "| %s | %s | %s | %s | %s | %s | %s | %s | %s | %s | %s | %s | %s | %s | %s | %s | %s "
          "|\n",
          name.c_str(), cell("tool_states_per_s", "%.0f").c_str(),
          cell("tool_state_kbit_s", "%.1f").c_str(),
          cell("tool_state_reduction_pct", "%.1f").c_str(), cell("models_per_s", "%.0f").c_str(),
          cell("model_kbit_s", "%.1f").c_str(), cell("model_reduction_pct", "%.1f").c_str(),
          cell("device_force_error_pct", "%.2f").c_str(),
          cell("device_torque_error_pct", "%.2f").c_str(),
          cell("contact_force_error_pct", "%.2f").c_str(),
          cell("largest_device_force_step_n", "%.3f").c_str(),
          cell("passivity_share_pct", "%.2f").c_str(),
          cell("device_force_steps_above_0_5n", "%.0f").c_str(),
          cell("device_force_steps_above_0_2n", "%.0f").c_str(),
          cell("contact_force_steps_above_0_2n", "%.0f").c_str(),
          cell("contact_force_step_p99_n", "%.3f").c_str(),
          cell("device_force_ripple_mn", "%.1f").c_str());
      std::fflush(stdout);
      summary["arms"].push_back({{"arm", name}, {"seeds", per_seed}});
      if (arm != nullptr) {
        summary["arms"].back()["setting"] = arm->setting.empty() ? setup.setting : arm->setting;
      }
      if (!out_dir.empty()) {
        std::filesystem::create_directories(out_dir);
        if (!skip_first) WriteTrace(out_dir + "/" + name + ".csv", runs[0]);  // seed 0
      }
    };
    // The reference's other seeds against its first: how far a start 1 µm away goes by itself
    // (the rocking tool and the hand's reaction amplify any difference).
    if (!out_dir.empty()) {
      std::filesystem::create_directories(out_dir);
      WriteTrace(out_dir + "/reference.csv", ref);
    }
    std::vector<ArmRun> reference_runs{ref};
    for (int k = 1; k < seeds; ++k) {
      Setup s2 = reference_setup;
      s2.start_offset_m = k * seed_step_m;
      s2.seed = k;
      reference_runs.push_back(RunArm(s2, reference));
    }
    if (seeds > 1) report("reference (seeds 1.. against 0)", nullptr, reference_runs, true);
    for (const Arm& arm : arms) {
      std::fprintf(stderr, "deadband_lockstep: arm %s...\n", arm.name.c_str());
      std::vector<ArmRun> runs;
      for (int k = 0; k < seeds; ++k) {
        Setup s2 = setup;
        s2.start_offset_m = k * seed_step_m;
        s2.seed = k;
        runs.push_back(RunArm(s2, arm));
      }
      report(arm.name, &arm, runs, false);
    }
    if (!out_dir.empty()) {
      std::filesystem::create_directories(out_dir);
      std::ofstream(out_dir + "/summary.json") << summary.dump(1) << '\n';
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "deadband_lockstep: %s\n", e.what());
    return 1;
  }
  return 0;
}
