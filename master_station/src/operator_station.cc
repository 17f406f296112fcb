#include "master_station/operator_station.h"

#include <pthread.h>
#include <sched.h>
#include <time.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <optional>
#include <stdexcept>
#include <thread>
#include <vector>

#include "display_worker.h"
#include "haptic_core/passivity.h"
#include "haptic_core/statistics.h"
#include "haptic_core/steady_clock.h"
#include "haptic_core/wrench_safety.h"
#include "master_station/lock_free.h"
#include "master_station/operator_tick.h"
#include "network_worker.h"
#include "trace_recorder.h"
#include "transport/messages.h"

namespace ht {
namespace {

void SleepUntilNs(std::int64_t t_ns) noexcept {
  timespec ts{static_cast<time_t>(t_ns / 1000000000), static_cast<long>(t_ns % 1000000000)};
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
  }
}

}  // namespace

using station::Counters;
using station::DisplayToolState;
using station::DisplayWorker;
using station::IncomingModel;
using station::NetworkWorker;
using station::OutgoingToolState;
using station::TraceRow;
using station::WriteTraceHeader;
using station::WriteTraceRow;

void StationConfig::Validate() const {
  if (!(max_contact_force_n >= 0.0)) {
    throw std::invalid_argument("the bound on a contact's force must be >= 0 N (0 = none)");
  }
  if (display.mode != DisplayConfig::Mode::kNone) {
    if (!(display.frame_rate_hz >= 0.1 && display.frame_rate_hz <= 120.0)) {
      throw std::invalid_argument("display frame rate must be within 0.1..120 frames/s, got " +
                                  std::to_string(display.frame_rate_hz));
    }
    if (display.width < 16 || display.width > 4096 || display.height < 16 ||
        display.height > 4096) {
      throw std::invalid_argument("display size must be within 16..4096 pixels each, got " +
                                  std::to_string(display.width) + "x" +
                                  std::to_string(display.height));
    }
    if (display.max_frames < 0) throw std::invalid_argument("display max frames must be >= 0");
    if (!(display.camera_distance_m >= 0.0 && display.camera_distance_m <= 1e4)) {
      throw std::invalid_argument("camera distance must be within 0..10000 m (0 = automatic)");
    }
  }
  if (display.mode == DisplayConfig::Mode::kHeadless && display.frames_dir.empty() &&
      out_dir.empty()) {
    throw std::invalid_argument(
        "--display headless writes PNG frames: give --frames-dir DIR (or --out DIR, whose "
        "frames/ folder is then used)");
  }
  if (display.mode == DisplayConfig::Mode::kWindow) {
    const char* x11 = std::getenv("DISPLAY");
    const char* wayland = std::getenv("WAYLAND_DISPLAY");
    if ((x11 == nullptr || *x11 == '\0') && (wayland == nullptr || *wayland == '\0')) {
      throw std::invalid_argument(
          "--display window needs a display server, but DISPLAY and WAYLAND_DISPLAY are unset "
          "(on a machine without one, use --display headless --frames-dir DIR)");
    }
  }
  if (!(loop_rate_hz >= 100.0 && loop_rate_hz <= 4000.0)) {
    throw std::invalid_argument("loop rate must be within 100..4000 Hz, got " +
                                std::to_string(loop_rate_hz));
  }
  if (!IsFiniteRigidTransform(X_WM)) throw std::invalid_argument("X_WM must be finite");
  if (!(connect_timeout_s > 0.0)) throw std::invalid_argument("connect timeout must be positive");
  if (mtu < static_cast<int>(wire::kMinMtuBytes) ||
      mtu > static_cast<int>(wire::kMaxDatagramBytes)) {
    throw std::invalid_argument("MTU must be within 548..1472 bytes, got " + std::to_string(mtu));
  }
  if (heartbeat_ms < 10 || heartbeat_ms > 10000) {
    throw std::invalid_argument("heartbeat must be within 10..10000 ms");
  }
  if (peer_timeout_ms <= heartbeat_ms || peer_timeout_ms > 60000) {
    throw std::invalid_argument("peer timeout must be above the heartbeat (" +
                                std::to_string(heartbeat_ms) + " ms) and at most 60000 ms, got " +
                                std::to_string(peer_timeout_ms));
  }
  if (model_blend_ticks < 1 || model_blend_ticks > 100) {
    throw std::invalid_argument("model blend ticks must be within 1..100");
  }
  if (reconnect_period_ms < 10) throw std::invalid_argument("reconnect period must be >= 10 ms");
  if (!(passivity_reserve_j >= 0.0 && passivity_reserve_j <= 1.0)) {
    throw std::invalid_argument("passivity reserve must be within 0..1 J, got " +
                                std::to_string(passivity_reserve_j));
  }
  if (!(passivity_refill_fraction >= 0.0 && passivity_refill_fraction < 1.0)) {
    throw std::invalid_argument("passivity refill fraction must be within [0, 1), got " +
                                std::to_string(passivity_refill_fraction));
  }
  if (!(passivity_release_ms >= 0.0 && passivity_release_ms <= 10000.0)) {
    throw std::invalid_argument("passivity release must be within 0..10000 ms, got " +
                                std::to_string(passivity_release_ms));
  }
  if (!(switch_offset_release_ms > 0.0)) {  // +∞ allowed; NaN refused
    throw std::invalid_argument("switch offset release must be > 0 ms, got " +
                                std::to_string(switch_offset_release_ms));
  }
  if (max_grid < 0 || max_grid > 65535) throw std::invalid_argument("max grid must be 0..65535");
  coupling.Validate();
  safety.Validate();
  if (!(stop_ramp_s >= 0.0 && stop_ramp_s <= 10.0)) {
    throw std::invalid_argument("stop ramp must be within 0..10 s, got " +
                                std::to_string(stop_ramp_s));
  }
  if (run_until_stopped && stop_requested == nullptr) {
    throw std::invalid_argument(
        "run_until_stopped needs stop_requested (a flag a signal handler sets), or the run "
        "would never end");
  }
  tool_state_deadband.Validate();
  if (!(tool_state_deadband.keepalive_s >= 1e-3 && tool_state_deadband.keepalive_s <= 60.0)) {
    throw std::invalid_argument("tool-state keep-alive must be within 1 ms..60 s");
  }
  if (!(model_deadband >= 0.0 && model_deadband < 1.0)) {
    throw std::invalid_argument("contact-model deadband must be in [0, 1), got " +
                                std::to_string(model_deadband));
  }
  if (!(model_keepalive_s >= 1e-3 && model_keepalive_s < safety.model_timeout_s)) {
    throw std::invalid_argument(
        "contact-model keep-alive must be at least 1 ms and below the model timeout (" +
        std::to_string(safety.model_timeout_s) +
        " s), or the force would fade between models; "
        "got " +
        std::to_string(model_keepalive_s) + " s");
  }
}

ExperimentScene ExperimentSceneInM(const wire::SceneLayout& layout, const RigidTransform& X_WM) {
  ExperimentScene scene_M;
  scene_M.tool_extent_down_m = layout.tool_extent_down_m;
  const RigidTransform X_MW = X_WM.Inverse();
  const int n =
      std::min(static_cast<int>(layout.num_targets), static_cast<int>(layout.targets.size()));
  for (int i = 0; i < n; ++i) {
    const wire::WelcomeTarget& t = layout.targets[static_cast<std::size_t>(i)];
    ExperimentTarget e;
    e.box_min_M = glm::dvec3(std::numeric_limits<double>::infinity());
    e.box_max_M = -e.box_min_M;
    for (int c = 0; c < 8; ++c) {  // the box's corners in M, and their bounds
      const glm::dvec3 corner_W{(c & 1) ? t.box_max_W.x : t.box_min_W.x,
                                (c & 2) ? t.box_max_W.y : t.box_min_W.y,
                                (c & 4) ? t.box_max_W.z : t.box_min_W.z};
      const glm::dvec3 corner_M = X_MW * corner_W;
      e.box_min_M = glm::min(e.box_min_M, corner_M);
      e.box_max_M = glm::max(e.box_max_M, corner_M);
    }
    e.top_M = X_MW * t.top_W;
    e.approach_z_M = e.top_M.z + t.approach_m;
    scene_M.targets.push_back(e);
  }
  return scene_M;
}

OperatorTickConfig OperatorTickConfigFor(const StationConfig& config,
                                         const DeviceCapabilities& caps, const ToolInertia& inertia,
                                         double h_s) {
  OperatorTickConfig tick_config;
  tick_config.inertia = inertia;
  tick_config.coupling = config.coupling;
  // The device's own limits bound the configured ones (a device without force output gets a
  // vanishing limit: it renders nothing).
  tick_config.safety = config.safety;
  tick_config.safety.max_force_n =
      std::max(1e-9, std::min(config.safety.max_force_n, caps.max_force_n));
  tick_config.safety.max_torque_nm =
      std::max(1e-9, std::min(config.safety.max_torque_nm, caps.max_torque_nm));
  tick_config.model_blend_ticks = config.model_blend_ticks;
  tick_config.passivity = config.passivity;
  // The added damping is capped (4 x the device's rated damping: the controller acts for single
  // ticks, well inside what a 1 kHz device renders); energy it cannot dissipate in one tick stays
  // in the observer (E < 0) and is dissipated on the next ones.
  tick_config.passivity_max_damping_ns_per_m = 4.0 * caps.max_damping_ns_per_m;
  tick_config.passivity_reserve_j = config.passivity_reserve_j;
  tick_config.passivity_refill_fraction = config.passivity_refill_fraction;
  tick_config.passivity_release_ticks =
      static_cast<int>(std::lround(config.passivity_release_ms * 1e-3 / h_s));
  tick_config.energy_bounded_switch = config.energy_bounded_switch;
  tick_config.switch_offset_release_ms = config.switch_offset_release_ms;
  tick_config.h_s = h_s;
  tick_config.max_contact_force_n = config.max_contact_force_n > 0.0
                                        ? config.max_contact_force_n
                                        : std::numeric_limits<double>::infinity();
  tick_config.hunt_crossley_s_per_m = config.hunt_crossley_s_per_m;
  return tick_config;
}

nlohmann::json RunOperatorStation(const StationConfig& config, HapticDevice& device,
                                  Experiment& experiment) {
  config.Validate();
  const DeviceCapabilities caps = device.capabilities();
  const auto ticks =
      config.run_until_stopped
          ? std::numeric_limits<std::int64_t>::max()
          : static_cast<std::int64_t>(std::ceil(experiment.duration_s() * config.loop_rate_hz));
  const std::int64_t period_ns = static_cast<std::int64_t>(std::llround(1e9 / config.loop_rate_hz));
  const double h = period_ns * 1e-9;

  std::FILE* trace = nullptr;
  if (!config.out_dir.empty()) {
    std::filesystem::create_directories(config.out_dir);
    const std::string path = config.out_dir + "/trace.csv";
    trace = std::fopen(path.c_str(), "w");
    if (!trace) throw std::runtime_error("cannot write " + path);
    WriteTraceHeader(trace);
  }

  TripleBuffer<OutgoingToolState> outgoing;
  TripleBuffer<IncomingModel> incoming;
  SpscRing<TraceRow> rows(16384);
  Counters counters;
  ReceivedScene received_scene;
  NetworkWorker network(config, outgoing, incoming, counters, received_scene);
  // The display (off the loop): the loop hands it the tool, handle and model every few ticks.
  DisplayConfig display_config = config.display;
  if (display_config.mode == DisplayConfig::Mode::kHeadless && display_config.frames_dir.empty())
    display_config.frames_dir = config.out_dir + "/frames";
  const bool display_on = display_config.mode != DisplayConfig::Mode::kNone;
  TripleBuffer<DisplayToolState> display_tool;
  std::optional<DisplayWorker> display;
  std::atomic<bool> stop_display{false};
  std::thread display_thread;

  // The device first, so that a missing one is said at once (a simulated hand takes its start
  // from the experiment at its first reading, after the scene is known).
  device.Open();
  std::atomic<bool> stop_network{false}, stop_recorder{false};
  std::thread network_thread([&] { network.Run(stop_network); });
  std::atomic<std::uint64_t> rows_dropped{0};
  std::uint64_t rows_over_cap = 0;
  std::thread recorder_thread([&] {
    TraceRow row;
    std::int64_t written = 0;
    while (true) {
      const bool stopping = stop_recorder.load(std::memory_order_acquire);
      bool any = false;
      while (rows.Pop(row)) {
        any = true;
        if (!trace) continue;
        // The trace is written as the run goes; past the size cap rows are counted only.
        if (config.trace_max_bytes > 0 &&
            static_cast<std::uint64_t>(written) >= config.trace_max_bytes) {
          ++rows_over_cap;
          continue;
        }
        written += WriteTraceRow(trace, row, experiment.phase_names());
      }
      if (stopping && !any) break;
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
  });
  const auto stop_threads = [&] {
    stop_display.store(true, std::memory_order_release);
    if (display_thread.joinable()) display_thread.join();
    stop_network.store(true, std::memory_order_release);
    stop_recorder.store(true, std::memory_order_release);
    network_thread.join();
    recorder_thread.join();
    if (trace) std::fclose(trace);
    trace = nullptr;
    device.Close();
  };

  // Ctrl-C or SIGTERM while waiting for the remote node ends the wait at once (nothing has been
  // rendered yet, so there is no force to ramp down).
  const auto stop_requested = [&] {
    return config.stop_requested != nullptr &&
           config.stop_requested->load(std::memory_order_relaxed);
  };
  const auto throw_if_stopped = [&](const char* waiting_for) {
    if (!stop_requested()) return;
    stop_threads();
    throw std::runtime_error(std::string("stopped on request while waiting for ") + waiting_for +
                             " from the remote node at " + config.remote_address.ToString());
  };

  // The session first: its Welcome says where the workspace goes (the tool's home pose), the
  // tool's inertia and where the touchable objects are.
  const std::int64_t connect_deadline =
      SteadyNowNs() + static_cast<std::int64_t>(config.connect_timeout_s * 1e9);
  while (!counters.connected.load() && !counters.rejected.load() && !stop_requested() &&
         SteadyNowNs() < connect_deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  throw_if_stopped("the session");
  RigidTransform X_WM = config.X_WM;
  ToolInertia tool_inertia = config.tool_inertia;
  ExperimentScene scene_M;
  const std::vector<ExperimentTarget>& targets_M = scene_M.targets;
  if (counters.connected.load()) {
    const wire::SceneLayout layout = network.layout();
    if (config.workspace_from_remote) {
      X_WM = layout.X_WT_home;
      if (config.workspace_origin_W) X_WM.translation = *config.workspace_origin_W;
    }
    if (layout.tool_mass_kg > 0.0) {
      tool_inertia = {layout.tool_mass_kg, layout.tool_inertia_diagonal_T};
    }
    scene_M = ExperimentSceneInM(layout, X_WM);
  }
  const RigidTransform X_WM_start = X_WM;
  experiment.SetScene(scene_M);
  // Said once the remote node answered (without a session the run ends with an error below, and
  // the home pose would be a default, not the node's), and not with --quiet.
  if (counters.connected.load() && config.progress_period_s > 0.0) {
    std::printf("[master] workspace centre in W %.4f,%.4f,%.4f (%s); %zu object(s) described\n",
                X_WM.translation.x, X_WM.translation.y, X_WM.translation.z,
                !config.workspace_from_remote ? "as configured"
                : config.workspace_origin_W   ? "--workspace-origin"
                                              : "the remote node's home pose",
                targets_M.size());
    std::fflush(stdout);
  }
  // The tool starts where the experiment's first target puts the handle.
  ToolState tool;
  tool.X_WT = X_WM * experiment.Target(0.0).X_MH;
  std::uint64_t tool_seq = 1;
  outgoing.Write({{tool.X_WT, tool.V_WT_W}, SteadyNowNs(), tool_seq});

  // Then the remote node's first contact model (it answers our first tool state).
  while (counters.model_accepted.load() == 0 && !counters.rejected.load() && !stop_requested() &&
         SteadyNowNs() < connect_deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  if (counters.model_accepted.load() == 0) throw_if_stopped("the first contact model");
  if (counters.model_accepted.load() == 0) {
    const bool connected = counters.connected.load();
    stop_threads();
    if (counters.rejected.load()) {
      throw std::runtime_error("the remote node at " + config.remote_address.ToString() +
                               " refused the session: " + network.reject_text());
    }
    char timeout[32];
    std::snprintf(timeout, sizeof(timeout), "%g", config.connect_timeout_s);
    throw std::runtime_error(
        std::string("no contact model from the remote node at ") +
        config.remote_address.ToString() + " within " + timeout + " s: " +
        (connected ? "the session opened but no model came back"
                   : "no session (is slave_sim running and listening there, do both sides "
                     "use the same --key file, and is it a release that speaks protocol v" +
                         std::to_string(wire::kProtocolVersion) +
                         "? an older remote node drops this station's Hello unanswered)") +
        "; datagrams rejected here: " + std::to_string(network.rejected_total()));
  }

  // Said once the device is open and the first contact model came (issue 35: it used to come before
  // the device had even opened), with or without --quiet: a person at the device must know how to
  // end.
  if (config.run_until_stopped) {
    std::printf("[master] running until Ctrl-C or SIGTERM (the force is ramped to zero first)\n");
    std::fflush(stdout);
  }
  // The haptic loop, on its own thread with real-time priority when permitted.
  // Bounded statistics however long the run: a uniform sample of at most 2^20 ticks.
  const auto sample_capacity = static_cast<std::size_t>(std::min<std::int64_t>(ticks, 1 << 20));
  ReservoirSamples compute_us(sample_capacity), period_us(sample_capacity);
  ReservoirSamples model_age_samples(sample_capacity);
  std::atomic<std::int64_t> ticks_done{0};
  std::atomic<bool> loop_done{false};
  bool stopped_by_request = false;
  std::atomic<int> progress_contacts{0}, progress_phase{0};
  std::atomic<double> progress_force{0.0}, progress_age_ms{-1.0};
  std::int64_t overruns = 0, device_write_faults = 0;
  const OperatorTickConfig tick_config = OperatorTickConfigFor(config, caps, tool_inertia, h);
  const SafetyLimits& safety_limits = tick_config.safety;
  OperatorTick tick(tick_config, X_WM, tool);
  const PassivityController& passivity = tick.passivity();
  const WrenchSafetyFilter& safety = tick.safety();
  int contacts_max = 0;
  double force_max = 0.0;
  std::string realtime_note = "SCHED_FIFO priority 80";

  if (display_on) {
    display.emplace(display_config, received_scene, display_tool,
                    X_WM.rotation * glm::dvec3(0.0, 0.0, 1.0), config.max_contact_force_n,
                    experiment.phase_names());
    display_thread = std::thread([&] { display->Run(stop_display); });
  }

  std::thread loop_thread([&] {
    sched_param sp{};
    sp.sched_priority = 80;
    if (pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp) != 0) {
      realtime_note = "not permitted (run as root or grant CAP_SYS_NICE / rtprio); normal priority";
    }
    IncomingModel received{};
    ArrivedModel arrived{};
    DisplayToolState display_state{};
    constexpr std::int64_t kDisplayEveryTicks = 4;
    std::int64_t experiment_t0 = -1;
    std::int64_t stop_ramp_start = -1;
    const double stop_ramp_ticks = std::max(1.0, config.stop_ramp_s * config.loop_rate_hz);
    std::int64_t next = SteadyNowNs() + period_ns;
    std::int64_t previous = next - period_ns;
    const std::int64_t t0 = next;
    for (std::int64_t k = 0; k < ticks; ++k) {
      SleepUntilNs(next);
      const std::int64_t now = SteadyNowNs();
      period_us.Add((now - previous) * 1e-3);
      previous = now;
      TraceRow row;
      row.t_s = (now - t0) * 1e-9;

      OperatorTickInput in;
      in.now_ns = now;
      in.device_ok = device.ReadState(now, in.device);
      in.link_connected = counters.connected.load(std::memory_order_relaxed);
      if (in.device_ok && caps.scripted) {
        // A scripted "go to" (HandTarget::workspace_shift_M), on the device's own clock (time 0
        // at its first reading, this tick's `now`).
        if (experiment_t0 < 0) experiment_t0 = now;
        tick.ShiftWorkspace(experiment.Target((now - experiment_t0) * 1e-9).workspace_shift_M);
      }
      if (incoming.Read(received)) {
        arrived.model = received.message.model;
        arrived.tool_state_sent_ns = received.message.tool_state_send_time_ns;
        arrived.built_local_ns = received.built_local_ns;
        arrived.collision_us = received.message.collision_us;
        arrived.texture_us = received.message.texture_us;
        arrived.step_us = received.message.step_us;
        in.arrived = &arrived;
        if (display_on) {
          display_state.model = arrived.model;
          display_state.have_model = true;
        }
      }
      // Asked to stop (Ctrl-C, SIGTERM): ramp the device's wrench to zero (in the tick, before
      // the passivity observer records it), then end the run.
      if (stop_ramp_start < 0 && config.stop_requested != nullptr &&
          config.stop_requested->load(std::memory_order_relaxed)) {
        stop_ramp_start = k;
      }
      if (stop_ramp_start >= 0) {
        in.output_gain =
            std::max(0.0, 1.0 - static_cast<double>(k - stop_ramp_start + 1) / stop_ramp_ticks);
      }
      OperatorTickOutput out = tick.Step(in);
      if (!device.WriteWrench(out.F_H_M, now)) ++device_write_faults;
      if (in.device_ok) {
        ++tool_seq;
        outgoing.Write(
            {{tick.tool().X_WT, tick.tool().V_WT_W}, now, tool_seq, tick.model().num_contacts > 0});
        const ToolStepResult& step = out.step;
        row.X_WT = tick.tool().X_WT;
        row.F_contact_T_W = step.F_contact_T_W;
        row.contacts = step.active_contacts;
        row.depth_m = step.max_depth_m;
        row.p_WH = out.X_WH.translation;
        row.F_device_W = out.F_device_W;
        row.passivity_removed_n = out.passivity_removed_n;
        row.model_age_ms = out.model_age_ms;
        row.remote_collision_us = tick.model_stamp().collision_us;
        row.remote_texture_us = tick.model_stamp().texture_us;
        row.remote_step_us = tick.model_stamp().step_us;
        contacts_max = std::max(contacts_max, step.active_contacts);
        force_max = std::max(force_max, glm::length(step.F_contact_T_W.force));
      }
      // The phase the simulated hand was following, when the device is scripted.
      row.phase = experiment.Target(row.t_s).phase;
      if (display_on && k % kDisplayEveryTicks == 0) {
        display_state.t_s = row.t_s;
        display_state.X_WT = tick.tool().X_WT;
        display_state.X_WH = out.X_WH;
        display_state.phase = caps.scripted ? row.phase : -1;
        display_state.force_n = glm::length(row.F_contact_T_W.force);
        display_state.contacts = row.contacts;
        display_tool.Write(display_state);
      }
      if (row.model_age_ms >= 0.0) model_age_samples.Add(row.model_age_ms);
      const std::int64_t end = SteadyNowNs();
      row.tick_compute_us = static_cast<float>((end - now) * 1e-3);
      compute_us.Add((end - now) * 1e-3);
      if (!rows.Push(row)) rows_dropped.fetch_add(1, std::memory_order_relaxed);
      progress_contacts.store(row.contacts, std::memory_order_relaxed);
      progress_phase.store(row.phase, std::memory_order_relaxed);
      progress_force.store(glm::length(row.F_contact_T_W.force), std::memory_order_relaxed);
      progress_age_ms.store(row.model_age_ms, std::memory_order_relaxed);
      ticks_done.store(k + 1, std::memory_order_release);
      if (stop_ramp_start >= 0 && k - stop_ramp_start + 1 >= stop_ramp_ticks) {
        stopped_by_request = true;
        break;
      }
      next += period_ns;
      if (end > next + period_ns) {  // fell more than a period behind: do not burst to catch up
        ++overruns;
        next = end + period_ns;
      }
    }
    device.WriteWrench({}, SteadyNowNs());
    loop_done.store(true, std::memory_order_release);
  });

  // Progress while the loop runs.
  const std::int64_t started = SteadyNowNs();
  std::int64_t last_print = started;
  std::int64_t last_ticks = 0;
  std::uint64_t last_models = counters.model_accepted.load();
  while (!loop_done.load(std::memory_order_acquire)) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    const std::int64_t now = SteadyNowNs();
    if (config.progress_period_s > 0.0 && (now - last_print) * 1e-9 >= config.progress_period_s) {
      const std::int64_t done = ticks_done.load();
      const std::uint64_t models = counters.model_accepted.load();
      const double dt = (now - last_print) * 1e-9;
      const int phase = progress_phase.load();
      std::printf(
          "[master] t=%5.2f/%.2f s  phase=%-8s  loop %6.0f Hz  models %6.0f Hz  contacts %d  "
          "|F|=%6.3f N  model age %5.2f ms\n",
          done / config.loop_rate_hz, experiment.duration_s(),
          phase < static_cast<int>(experiment.phase_names().size())
              ? experiment.phase_names()[phase].c_str()
              : "?",
          (done - last_ticks) / dt, (models - last_models) / dt, progress_contacts.load(),
          progress_force.load(), progress_age_ms.load());
      std::fflush(stdout);
      last_print = now;
      last_ticks = done;
      last_models = models;
    }
  }
  loop_thread.join();
  const double elapsed_s = (SteadyNowNs() - started) * 1e-9;
  stop_threads();

  const std::vector<double>& ages = model_age_samples.values();
  const std::int64_t ticks_run = ticks_done.load();
  nlohmann::json s;
  s["experiment"] = experiment.name();
  s["workspace"] = {
      {"origin_W_at_start",
       {X_WM_start.translation.x, X_WM_start.translation.y, X_WM_start.translation.z}},
      {"rotation_WM_wxyz",
       {X_WM_start.rotation.w, X_WM_start.rotation.x, X_WM_start.rotation.y,
        X_WM_start.rotation.z}},
      {"from_remote", config.workspace_from_remote},
      {"targets", targets_M.size()},
      {"jumps", tick.counters().workspace_jumps},
      {"models_dropped_from_before_a_jump", tick.counters().models_from_before_jump},
      {"targets_M",
       [&] {
         nlohmann::json list = nlohmann::json::array();
         for (const ExperimentTarget& t : targets_M) {
           list.push_back({{"box_min", {t.box_min_M.x, t.box_min_M.y, t.box_min_M.z}},
                           {"box_max", {t.box_max_M.x, t.box_max_M.y, t.box_max_M.z}},
                           {"top", {t.top_M.x, t.top_M.y, t.top_M.z}}});
         }
         return list;
       }()},
      {"shift_M",
       {tick.workspace_shift_M().x, tick.workspace_shift_M().y, tick.workspace_shift_M().z}}};
  if (display) {
    s["display"] = display->Summary();
  } else {
    s["display"] = {{"mode", "none"}};
  }
  s["contact_force_bound_n"] = config.max_contact_force_n;
  s["contact_damping_hunt_crossley_s_per_m"] = config.hunt_crossley_s_per_m;
  s["saturated_contact_ticks"] = tick.counters().saturated_contact_ticks;
  s["tool_mass_kg"] = tool_inertia.mass_kg;
  s["device"] = caps.name;
  s["duration_s"] =
      config.run_until_stopped || stopped_by_request ? elapsed_s : experiment.duration_s();
  s["run_until_stopped"] = config.run_until_stopped;
  s["stopped_by_request"] = stopped_by_request;
  s["ticks"] = ticks_run;
  s["operator_rate_hz"] = ticks_run / std::max(elapsed_s, 1e-9);
  // Percentiles over a uniform sample of at most 2^20 ticks (all of them in runs up to 17 min).
  s["tick_statistics_sampled"] = compute_us.count() > compute_us.values().size();
  s["operator_period_p50_us"] = Percentile(period_us.values(), 0.5);
  s["operator_period_p99_us"] = Percentile(period_us.values(), 0.99);
  s["operator_period_max_us"] = Percentile(period_us.values(), 1.0);
  s["operator_tick_p50_us"] = Percentile(compute_us.values(), 0.5);
  s["operator_tick_p99_us"] = Percentile(compute_us.values(), 0.99);
  s["operator_tick_max_us"] = Percentile(compute_us.values(), 1.0);
  s["operator_overruns"] = overruns;
  s["realtime_priority"] = realtime_note;
  s["remote_rate_hz"] = network.RemoteRateHz();
  s["remote_step_p50_us"] = Percentile(network.remote_step_us(), 0.5);
  s["remote_step_p99_us"] = Percentile(network.remote_step_us(), 0.99);
  s["remote_step_in_contact_p50_us"] = Percentile(network.contact_step_us(), 0.5);
  s["remote_step_in_contact_p99_us"] = Percentile(network.contact_step_us(), 0.99);
  s["remote_collision_p50_us"] = Percentile(network.collision_us(), 0.5);
  s["remote_texture_p50_us"] = Percentile(network.texture_us(), 0.5);
  s["rtt_ms_p50"] = Percentile(network.rtt_ms(), 0.5);
  s["rtt_ms_p99"] = Percentile(network.rtt_ms(), 0.99);
  s["model_age_ms_p50"] = Percentile(ages, 0.5);
  s["model_age_ms_p99"] = Percentile(ages, 0.99);
  s["contacts_max"] = contacts_max;
  s["contact_force_max_n"] = force_max;
  s["device_max_force_n"] = caps.max_force_n;
  s["device_max_torque_nm"] = caps.max_torque_nm;
  const SafetyCounters& sc = safety.counters();
  s["force_clamped_ticks"] = sc.clamped;
  s["operator_energy_in_J"] = passivity.energy_in_j();
  s["operator_energy_out_J"] = passivity.energy_out_j();
  s["passivity"] = {
      {"enabled", config.passivity},
      {"observed_energy_J", passivity.observed_energy_j()},
      {"dissipated_J", passivity.dissipated_j()},
      {"active_ticks", passivity.active_ticks()},
      {"max_damping_ns_per_m", passivity.max_alpha()},
      {"scaled_ticks", passivity.scaled_ticks()},
      {"force_scaled_away_Ns", passivity.force_scaled_away_ns()},
      {"force_damped_away_Ns", passivity.force_damped_away_ns()},
      {"scaled_away_J", passivity.scaled_away_j()},
      {"reserve_J", config.passivity_reserve_j},
      {"refill_fraction", config.passivity_refill_fraction},
      {"release_ms", config.passivity_release_ms},
      {"energy_bounded_switch", config.energy_bounded_switch},
      {"switch_offset_release_ms", std::isfinite(config.switch_offset_release_ms)
                                       ? nlohmann::json(config.switch_offset_release_ms)
                                       : nlohmann::json(nullptr)},
      {"switch_offset_ticks", tick.counters().switch_offset_ticks},
      {"switch_offset_max_um", tick.counters().switch_offset_max_m * 1e6},
      {"refill_ticks", passivity.refill_ticks()},
      {"refilled_J", passivity.refilled_j()},
      {"force_refilled_Ns", passivity.force_refilled_ns()}};
  {
    // Issue 33: where the loop's energy comes from. Within one contact model the loop is
    // conservative; the switches (a new model, each blend step, a model dropped mid-blend)
    // change the contact potential at the tool's pose: what they created is what the
    // controller (dissipated_J + scaled_away_J) may have to remove.
    const OperatorTickCounters& tc = tick.counters();
    const double removed = passivity.dissipated_j() + passivity.scaled_away_j();
    s["passivity"]["attribution"] = {
        {"switch_energy_created_J", tc.switch_energy_created_j},
        {"switch_energy_absorbed_J", tc.switch_energy_absorbed_j},
        {"switch_ticks", tc.switch_ticks},
        {"switch_ticks_creating", tc.switch_ticks_creating},
        {"switch_energy_created_by_model_age_J",
         {{"below_50ms", tc.switch_energy_created_by_age_j[0]},
          {"50_to_150ms", tc.switch_energy_created_by_age_j[1]},
          {"above_150ms", tc.switch_energy_created_by_age_j[2]}}},
        {"controller_removed_J", removed},
        {"created_over_removed", removed > 0.0 ? tc.switch_energy_created_j / removed : 0.0}};
  }
  s["safety"] = {{"nonfinite_ticks", sc.nonfinite},
                 {"fading_ticks", sc.fading},
                 {"braking_ticks", sc.braking},
                 {"clamped_ticks", sc.clamped},
                 {"rate_limited_ticks", sc.rate_limited},
                 {"max_force_n", safety_limits.max_force_n},
                 {"max_torque_nm", safety_limits.max_torque_nm},
                 {"model_timeout_s", safety_limits.model_timeout_s}};
  s["nonfinite_count"] = tick.counters().nonfinite;
  s["device_faults"] = tick.counters().device_faults + device_write_faults;
  s["device_read_faults"] = tick.counters().device_faults;
  s["device_write_faults"] = device_write_faults;
  s["trace_rows_dropped"] = rows_dropped.load();
  s["trace_rows_over_cap"] = rows_over_cap;
  s["transport"] = network.Summary();
  // Packet and bit rates per stream: this side's datagrams (sent plus received) of the whole
  // session, handshake and scene included, over the loop's run time (payload bytes: header,
  // body and MAC; UDP and IP headers not counted). The remote node's own counts are merged under
  // each stream's "remote". (deploy/deadband-table divides the same counts by duration_s.)
  for (auto& [type, stream] : s["transport"]["streams"].items()) {
    const double packets = stream.value("sent", 0.0) + stream.value("received", 0.0);
    const double bytes = stream.value("bytes_sent", 0.0) + stream.value("bytes_received", 0.0);
    stream["packets_per_s"] = packets / std::max(elapsed_s, 1e-9);
    stream["kbit_per_s"] = bytes * 8e-3 / std::max(elapsed_s, 1e-9);
  }
  s["clock_offset_ms"] = s["transport"]["clock"]["offset_ms"];
  s["model_one_way_ms_p50"] = Percentile(network.one_way_ms(), 0.5);
  s["model_one_way_ms_p99"] = Percentile(network.one_way_ms(), 0.99);
  if (!config.out_dir.empty()) {
    const std::string path = config.out_dir + "/summary.json";
    std::ofstream out(path);
    out << s.dump(2) << "\n";
    if (!out) throw std::runtime_error("cannot write " + path);
  }
  return s;
}

}  // namespace ht
