// The deadband lockstep's arm parsing and one arm's run (deadband_lockstep_arm.h).

#include "deadband_lockstep_arm.h"

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
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
#include <unordered_set>
#include <vector>

#include "codecs/depth_field_codec.h"
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

namespace lockstep {
namespace {

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
/// the remote step's options), depth_fields, field_min_margin_mm, field_smooth_max_um,
/// field_subdivision, field_speed_mm_s (the contact model as depth fields), remote_period_ms
/// (the remote node's extrapolated steps at most this often). Defaults:
/// master_station's and slave_sim's, deadband 10 %.

/// A depth field's datagrams: each carries up to this many of its bytes (a 1,400-byte datagram
/// less its header, MAC and a fragment's ids), and costs this many besides.
constexpr std::int64_t kFieldFragmentPayload = 1350;
constexpr std::int64_t kFieldDatagramOverhead = 50;

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

}  // namespace

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
    } else if (key == "depth_fields") {  // the contact model as depth fields (0 / 1)
      arm.depth_fields = v != 0.0;
    } else if (key == "field_min_margin_mm") {
      arm.depth_field_min_margin_m = NonNegative(key, v) * 1e-3;
    } else if (key == "field_subdivision") {
      arm.depth_field_subdivision = static_cast<int>(v);
    } else if (key == "field_speed_mm_s") {
      arm.depth_field_speed_m_per_s = NonNegative(key, v) * 1e-3;
    } else if (key == "remote_period_ms") {
      arm.remote_step_period_s = NonNegative(key, v) * 1e-3;
    } else if (key == "field_smooth_max_um") {
      if (!(v > 0.0)) throw std::invalid_argument("--arm: field_smooth_max_um must be > 0");
      arm.depth_field_smooth_max_m = v * 1e-6;
    } else if (key == "pressure") {  // 0 / 1: slave_sim --force-law seed / pressure
      arm.force_law = v != 0.0 ? ht::ForceLaw::kPressure : ht::ForceLaw::kSeed;
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

ArmRun RunArm(const Setup& setup, const Arm& arm) {
  using namespace ht;
  const wire::SceneLayout layout = MakeSceneLayout(*setup.scene);
  const RigidTransform X_WM = layout.X_WT_home;
  std::unique_ptr<Experiment> experiment = MakeExperiment(setup.experiment, setup.duration_s);
  experiment->SetScene(ExperimentSceneInM(layout, X_WM));  // as RunOperatorStation does
  std::unique_ptr<HapticDevice> device;
  double duration_s = setup.duration_s;
  if (!setup.replay_samples.empty()) {
    auto replay = std::make_unique<ReplayDevice>(setup.replay_samples, "the reference's hand");
    duration_s = replay->duration_s();
    device = std::move(replay);
  } else if (!setup.replay_file.empty()) {
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
  if (arm.depth_fields) {
    options.depth_fields = true;
    options.depth_field_margin_m =
        std::max(arm.depth_field_min_margin_m, arm.depth_field_speed_m_per_s * rtt_ms * 1e-3);
    if (arm.depth_field_smooth_max_m > 0.0) {
      options.depth_field_smooth_max_m = arm.depth_field_smooth_max_m;
    }
    options.depth_field_subdivision = arm.depth_field_subdivision;
    options.force_law = arm.force_law;
    options.Validate();
  }
  // The CPU backend with the setting's texture path and rotation gradient (as the frontier makes
  // it; with the default setting, what slave_sim --pd-backend cpu makes).
  HapticTexturePipeline pipeline(
      *setup.scene, options,
      std::make_unique<CpuPenetrationDepthBackend>(std::max(2, options.max_window_resolution()),
                                                   setting.texture_path, options.texture_threads));
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
  // The depth fields each model in flight carries (in to_operator's order).
  std::deque<std::vector<DepthField>> fields_to_operator;
  std::vector<DepthField> arrived_fields;
  std::vector<DepthField*> arrived_field_ptrs;
  DecodedDepthMap decoded_map;
  std::unordered_set<std::uint64_t> nodes_sent;        // (lattice, map, i, j) the operator has had
  std::unordered_set<std::uint32_t> fields_delivered;  // ids sent with a model that arrives
  SentToolState remote;              // the newest tool state the remote node holds
  std::int64_t remote_recv_ns = -1;  // when it arrived (< 0: none yet)
  // The remote node's last step (remote clock, ns) and its period for extrapolated steps.
  std::int64_t last_remote_step_ns = std::numeric_limits<std::int64_t>::min() / 2;
  const auto remote_period_ns = static_cast<std::int64_t>(arm.remote_step_period_s * 1e9);
  ContactModel held_model{};  // the newest model the operator received (its deadband's)
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
    arrived_field_ptrs.clear();
    arrived_fields.clear();
    while (!to_operator.empty() && to_operator.front().arrive_ns <= now) {
      arrived = to_operator.front().value;
      to_operator.pop_front();
      // Every field that came, also with a model the newer one in this tick replaces.
      for (DepthField& f : fields_to_operator.front()) arrived_fields.push_back(std::move(f));
      fields_to_operator.pop_front();
      have_arrived = true;
    }
    if (have_arrived) {
      in.arrived = &arrived;
      held_model = arrived.model;
      for (DepthField& f : arrived_fields) arrived_field_ptrs.push_back(&f);
      in.arrived_fields = arrived_field_ptrs;
    }
    const auto tick_start = std::chrono::steady_clock::now();
    const OperatorTickOutput out = tick.Step(in);
    run.tick_us.push_back(
        std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - tick_start)
            .count());
    device->WriteWrench(out.F_H_M, now);
    run.device_force_W.push_back(out.F_H_W.force);
    run.device_torque_W.push_back(out.F_H_W.torque);
    run.contact_force_W.push_back(out.step.F_contact_T_W.force);
    run.passivity_removed_n.push_back(out.passivity_removed_n);
    run.model_age_ms.push_back(out.model_age_ms);
    run.contacts.push_back(out.step.active_contacts);
    run.field_contacts.push_back(out.step.field_contacts);
    run.field_fallbacks.push_back(out.step.field_fallbacks);
    run.field_beyond_margin.push_back(out.step.field_beyond_margin);
    run.depth_offset_m.push_back(out.depth_offset_m);
    run.model_arrived.push_back(have_arrived ? 1 : 0);
    run.p_WT.push_back(tick.tool().X_WT.translation);
    run.theta_WT.push_back(RotationVectorFromQuaternion(tick.tool().X_WT.rotation));
    run.p_WH.push_back(out.X_WH.translation);
    run.R_WH.push_back(out.X_WH.rotation);
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
    bool fresh_state = false;
    while (!to_remote.empty() && to_remote.front().arrive_ns <= t_r) {
      remote = to_remote.front().value;
      remote_recv_ns = to_remote.front().arrive_ns;
      to_remote.pop_front();
      fresh_state = true;
    }
    if (remote_recv_ns < 0) continue;
    if (!fresh_state && t_r - last_remote_step_ns < remote_period_ns) continue;
    last_remote_step_ns = t_r;
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
    const DeadbandReason model_why =
        model_deadband.Decide(message.model, sent_ns, pipeline.kept_depth_fields());
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
    // The depth fields travel beside the model here (the model names them by id; on the wire
    // they are DepthFieldFragments, transport/depth_field_stream.h). A field goes with the first
    // model that refers to it and arrives (a repaired stream's delivery at the model's latency); a
    // field kept from an earlier step is referred to by its id alone. It goes through the
    // depth-field codec (codecs/depth_field_codec.h: the operator evaluates the decoded field), and
    // its bytes are counted twice: in datagrams, and the surface a receiver that caches it by
    // lattice node would still lack (the nodes of each lattice it has not had yet, at this
    // field's map bytes per node).
    const bool lost = uniform(loss_to_operator) < setup.loss;
    if (options.depth_fields) {
      for (int c = 0; c < message.model.num_contacts; ++c) {
        const ContactLinearization& lin = message.model.contacts[static_cast<std::size_t>(c)];
        ++run.contacts_sent;
        if (std::isfinite(lin.depth_m) && lin.depth_field_id == 0)
          ++run.contacts_sent_without_field;
      }
    }
    std::vector<DepthField> fields;
    for (const DepthField* f : pipeline.last_depth_fields()) {
      if (!lost && fields_delivered.insert(f->id).second) fields.push_back(*f);
    }
    for (DepthField& f : fields) {
      const std::vector<std::uint8_t> encoded = EncodeDepthField(f);
      std::int64_t present = 0, fresh = 0;
      for (const bool tool_map : {false, true}) {
        const std::vector<float>& map = tool_map ? f.tool_height_m : f.env_height_m;
        const std::int32_t i0 = tool_map ? f.tool_lattice_i0 : f.lattice_i0;
        const std::int32_t j0 = tool_map ? f.tool_lattice_j0 : f.lattice_j0;
        for (int j = 0; j < f.ny; ++j) {
          for (int i = 0; i < f.nx; ++i) {
            if (std::isnan(map[static_cast<std::size_t>(j) * f.nx + i])) continue;
            ++present;
            const std::uint64_t node =
                (static_cast<std::uint64_t>(f.lattice_id) << 41) |
                (static_cast<std::uint64_t>(tool_map) << 40) |
                (static_cast<std::uint64_t>(static_cast<std::uint32_t>(i0 + i) & 0xFFFFFu) << 20) |
                (static_cast<std::uint64_t>(static_cast<std::uint32_t>(j0 + j) & 0xFFFFFu));
            if (nodes_sent.insert(node).second) ++fresh;
          }
        }
      }
      std::string error;
      if (!DecodeDepthField(encoded, f, decoded_map, error)) {
        throw std::runtime_error("a depth field did not decode: " + error);
      }
      const auto size = static_cast<std::int64_t>(encoded.size());
      const std::int64_t datagrams = (size + kFieldFragmentPayload - 1) / kFieldFragmentPayload;
      run.field_bytes += size + datagrams * kFieldDatagramOverhead;
      const auto maps = size - static_cast<std::int64_t>(kDepthFieldFixedBytes);
      run.field_cached_bytes += present > 0 ? maps * fresh / present : std::int64_t{0};
      ++run.fields_sent;
    }
    a.tool_state_sent_ns = decoded.tool_state_send_time_ns;
    a.built_local_ns = sent_ns;
    a.collision_us = static_cast<float>(timings.collision_us);
    a.texture_us = static_cast<float>(timings.texture_us);
    a.step_us = static_cast<float>(timings.total_us);
    if (!lost) {
      to_operator.push_back({arrive_ns, a});
      fields_to_operator.push_back(std::move(fields));
    }
  }
  device->Close();
  return run;
}

}  // namespace lockstep
