// The operator station's run (operator_station.h, station_run.h): worker threads, the session
// wait, the haptic loop and its progress. Configuration: station_config.cc; the summary:
// station_summary.cc; the tick itself: src/operator/.
#include "master_station/operator_station.h"

#include <pthread.h>
#include <sched.h>
#include <time.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <stdexcept>
#include <thread>
#include <vector>

#include "haptic_core/steady_clock.h"
#include "station_run.h"
#include "transport/messages.h"

namespace ht {
namespace station {
namespace {

void SleepUntilNs(std::int64_t t_ns) noexcept {
  timespec ts{static_cast<time_t>(t_ns / 1000000000), static_cast<long>(t_ns % 1000000000)};
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
  }
}

// How often the loop hands the display its state (ticks).
constexpr std::int64_t kDisplayEveryTicks = 4;

}  // namespace

OperatorStationRun::OperatorStationRun(const StationConfig& config, HapticDevice& device,
                                       Experiment& experiment)
    : config_(config),
      device_(device),
      experiment_(experiment),
      caps_(device.capabilities()),
      ticks_(config.run_until_stopped ? std::numeric_limits<std::int64_t>::max()
                                      : static_cast<std::int64_t>(std::ceil(
                                            experiment.duration_s() * config.loop_rate_hz))),
      period_ns_(static_cast<std::int64_t>(std::llround(1e9 / config.loop_rate_hz))),
      display_config_(config.display),
      X_WM_(config.X_WM),
      tool_inertia_(config.tool_inertia) {
  if (!config.out_dir.empty()) {
    std::filesystem::create_directories(config.out_dir);
    const std::string path = config.out_dir + "/trace.csv";
    trace_ = std::fopen(path.c_str(), "w");
    if (!trace_) throw std::runtime_error("cannot write " + path);
    WriteTraceHeader(trace_);
  }
  try {
    network_.emplace(config, outgoing_, incoming_, counters_, received_scene_, field_handoff_);
  } catch (...) {
    if (trace_) std::fclose(trace_);
    trace_ = nullptr;
    throw;
  }
  // The display (off the loop): the loop hands it the tool, handle and model every few ticks.
  if (display_config_.mode == DisplayConfig::Mode::kHeadless && display_config_.frames_dir.empty())
    display_config_.frames_dir = config.out_dir + "/frames";
  display_on_ = display_config_.mode != DisplayConfig::Mode::kNone;
  // The device first, so that a missing one is said at once (a simulated hand takes its start
  // from the experiment at its first reading, after the scene is known).
  try {
    device_.Open();
    caps_ = device_.capabilities();
  } catch (...) {
    if (trace_) std::fclose(trace_);
    trace_ = nullptr;
    throw;
  }
  network_thread_ = std::thread([this] { network_->Run(stop_network_); });
  try {
    recorder_thread_ = std::thread([this] { RecorderThread(); });
  } catch (...) {
    StopWorkers();
    throw;
  }
}

OperatorStationRun::~OperatorStationRun() {
  try {
    StopWorkers();
  } catch (...) {
    // A device that fails to close on an error path: the error being thrown is the one to see.
  }
}

void OperatorStationRun::RecorderThread() {
  TraceRow row;
  std::int64_t written = 0;
  while (true) {
    const bool stopping = stop_recorder_.load(std::memory_order_acquire);
    bool any = false;
    while (rows_.Pop(row)) {
      any = true;
      if (!trace_) continue;
      // The trace is written as the run goes; past the size cap rows are counted only.
      if (config_.trace_max_bytes > 0 &&
          static_cast<std::uint64_t>(written) >= config_.trace_max_bytes) {
        ++rows_over_cap_;
        continue;
      }
      written += WriteTraceRow(trace_, row, experiment_.phase_names());
    }
    if (stopping && !any) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
}

void OperatorStationRun::StopWorkers() {
  if (workers_stopped_) return;
  workers_stopped_ = true;
  stop_display_.store(true, std::memory_order_release);
  if (display_thread_.joinable()) display_thread_.join();
  stop_network_.store(true, std::memory_order_release);
  stop_recorder_.store(true, std::memory_order_release);
  if (network_thread_.joinable()) network_thread_.join();
  if (recorder_thread_.joinable()) recorder_thread_.join();
  if (trace_) std::fclose(trace_);
  trace_ = nullptr;
  device_.Close();
}

bool OperatorStationRun::StopRequested() const {
  return config_.stop_requested != nullptr &&
         config_.stop_requested->load(std::memory_order_relaxed);
}

// Ctrl-C or SIGTERM while waiting for the remote node ends the wait at once (nothing has been
// rendered yet, so there is no force to ramp down).
void OperatorStationRun::ThrowIfStopped(const char* waiting_for) {
  if (!StopRequested()) return;
  StopWorkers();
  throw std::runtime_error(std::string("stopped on request while waiting for ") + waiting_for +
                           " from the remote node at " + config_.remote_address.ToString());
}

void OperatorStationRun::WaitForSession() {
  connect_deadline_ns_ = SteadyNowNs() + static_cast<std::int64_t>(config_.connect_timeout_s * 1e9);
  while (!counters_.connected.load() && !counters_.rejected.load() && !StopRequested() &&
         SteadyNowNs() < connect_deadline_ns_) {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  ThrowIfStopped("the session");
  if (counters_.connected.load()) {
    const wire::SceneLayout layout = network_->layout();
    if (config_.workspace_from_remote) {
      X_WM_ = layout.X_WT_home;
      if (config_.workspace_origin_W) X_WM_.translation = *config_.workspace_origin_W;
    }
    if (layout.tool_mass_kg > 0.0) {
      tool_inertia_ = {layout.tool_mass_kg, layout.tool_inertia_diagonal_T};
    }
    scene_M_ = ExperimentSceneInM(layout, X_WM_);
  }
  X_WM_start_ = X_WM_;
  experiment_.SetScene(scene_M_);
  // Said once the remote node answered (without a session the run ends with an error below, and
  // the home pose would be a default, not the node's), and not with --quiet.
  if (counters_.connected.load() && config_.progress_period_s > 0.0) {
    std::printf("[master] workspace centre in W %.4f,%.4f,%.4f (%s); %zu object(s) described\n",
                X_WM_.translation.x, X_WM_.translation.y, X_WM_.translation.z,
                !config_.workspace_from_remote ? "as configured"
                : config_.workspace_origin_W   ? "--workspace-origin"
                                               : "the remote node's home pose",
                scene_M_.targets.size());
    std::fflush(stdout);
  }
  // The tool starts where the experiment's first target puts the handle.
  tool_start_.X_WT = X_WM_ * experiment_.Target(0.0).X_MH;
  outgoing_.Write({{tool_start_.X_WT, tool_start_.V_WT_W}, SteadyNowNs(), tool_seq_});
}

void OperatorStationRun::WaitForFirstModel() {
  // The remote node answers the first tool state with a contact model, within the session's
  // deadline (connect_timeout_s covers both waits).
  while (counters_.model_accepted.load() == 0 && !counters_.rejected.load() && !StopRequested() &&
         SteadyNowNs() < connect_deadline_ns_) {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  if (counters_.model_accepted.load() != 0) return;
  ThrowIfStopped("the first contact model");
  if (counters_.model_accepted.load() != 0) return;  // came while the stop was checked
  const bool connected = counters_.connected.load();
  StopWorkers();
  if (counters_.rejected.load()) {
    throw std::runtime_error("the remote node at " + config_.remote_address.ToString() +
                             " refused the session: " + network_->reject_text());
  }
  char timeout[32];
  std::snprintf(timeout, sizeof(timeout), "%g", config_.connect_timeout_s);
  throw std::runtime_error(
      std::string("no contact model from the remote node at ") + config_.remote_address.ToString() +
      " within " + timeout + " s: " +
      (connected ? "the session opened but no model came back"
                 : "no session (is slave_sim running and listening there, do both sides "
                   "use the same --key file, and is it a release that speaks protocol v" +
                       std::to_string(wire::kProtocolVersion) +
                       "? an older remote node drops this station's Hello unanswered)") +
      "; datagrams rejected here: " + std::to_string(network_->rejected_total()));
}

void OperatorStationRun::RunHapticLoop() {
  // Said once the device is open and the first contact model came, with or without --quiet: a
  // person at the device must know how to end.
  if (config_.run_until_stopped) {
    std::printf("[master] running until Ctrl-C or SIGTERM (the force is ramped to zero first)\n");
    std::fflush(stdout);
  }
  // Bounded statistics however long the run: a uniform sample of at most 2^20 ticks.
  record_.emplace(static_cast<std::size_t>(std::min<std::int64_t>(ticks_, 1 << 20)));
  const double h = period_ns_ * 1e-9;
  tick_.emplace(OperatorTickConfigFor(config_, caps_, tool_inertia_, h), X_WM_, tool_start_);
  if (display_on_) {
    display_.emplace(display_config_, received_scene_, display_tool_,
                     X_WM_.rotation * glm::dvec3(0.0, 0.0, 1.0), config_.max_contact_force_n,
                     experiment_.phase_names());
    display_thread_ = std::thread([this] { display_->Run(stop_display_); });
  }
  std::thread loop_thread([this] { LoopThread(); });
  const std::int64_t started = SteadyNowNs();
  PrintProgressUntilDone();
  loop_thread.join();
  elapsed_s_ = (SteadyNowNs() - started) * 1e-9;
  StopWorkers();
}

void OperatorStationRun::LoopThread() {
  LoopRecord& rec = *record_;
  OperatorTick& tick = *tick_;
  sched_param sp{};
  sp.sched_priority = 80;
  if (pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp) != 0) {
    rec.realtime_note =
        "not permitted (run as root or grant CAP_SYS_NICE / rtprio); normal priority";
  }
  IncomingModel received{};
  ArrivedModel arrived{};
  std::array<DepthField*, FieldHandoff::kFields> arrived_fields{};
  std::uint32_t field_epoch = 0;
  // Missing fields told to the network worker: id and tick (ticks of the loop, −∞: none).
  std::array<std::pair<std::uint32_t, std::int64_t>, 8> missing_told{};
  missing_told.fill({0, std::numeric_limits<std::int64_t>::min() / 2});
  DisplayToolState display_state{};
  std::int64_t experiment_t0 = -1;
  std::int64_t stop_ramp_start = -1;
  // The last tick's phase, time and contact force, for the phases that should end free.
  int last_phase = -1;
  double last_t_s = 0.0, last_force_n = 0.0;
  const double stop_ramp_ticks = std::max(1.0, config_.stop_ramp_s * config_.loop_rate_hz);
  std::int64_t next = SteadyNowNs() + period_ns_;
  std::int64_t previous = next - period_ns_;
  const std::int64_t t0 = next;
  for (std::int64_t k = 0; k < ticks_; ++k) {
    SleepUntilNs(next);
    const std::int64_t now = SteadyNowNs();
    rec.period_us.Add((now - previous) * 1e-3);
    previous = now;
    TraceRow row;
    row.t_s = (now - t0) * 1e-9;

    OperatorTickInput in;
    in.now_ns = now;
    in.device_ok = device_.ReadState(now, in.device);
    in.link_connected = counters_.connected.load(std::memory_order_relaxed);
    if (in.device_ok && caps_.scripted) {
      // A scripted "go to" (HandTarget::workspace_shift_M), on the device's own clock (time 0
      // at its first reading, this tick's `now`).
      if (experiment_t0 < 0) experiment_t0 = now;
      tick.ShiftWorkspace(experiment_.Target((now - experiment_t0) * 1e-9).workspace_shift_M);
    }
    if (incoming_.Read(received)) {
      arrived.model = received.message.model;
      arrived.tool_state_sent_ns = received.message.tool_state_send_time_ns;
      arrived.built_local_ns = received.built_local_ns;
      arrived.collision_us = received.message.collision_us;
      arrived.texture_us = received.message.texture_us;
      arrived.step_us = received.message.step_us;
      in.arrived = &arrived;
      if (display_on_) {
        display_state.model = arrived.model;
        display_state.have_model = true;
      }
    }
    // The depth fields that came (before or with the model just read: the worker hands a field
    // on before the model that names it), given back to the worker after the tick.
    // A field or model of a newer session: the fields held name another session's surfaces.
    if (in.arrived != nullptr && received.field_epoch > field_epoch) {
      tick.ForgetDepthFields();
      field_epoch = received.field_epoch;
    }
    std::size_t fields_in = 0;
    FieldHandoff::Handed handed;
    while (fields_in < arrived_fields.size() && field_handoff_.ready.Pop(handed)) {
      if (handed.epoch < field_epoch) {  // an older session's field, decoded late
        field_handoff_.free.Push(handed.field);
        continue;
      }
      if (handed.epoch > field_epoch) {
        tick.ForgetDepthFields();
        field_epoch = handed.epoch;
      }
      arrived_fields[fields_in++] = handed.field;
    }
    in.arrived_fields = {arrived_fields.data(), fields_in};
    // Asked to stop (Ctrl-C, SIGTERM): ramp the device's wrench to zero (in the tick, before
    // the passivity observer records it), then end the run.
    if (stop_ramp_start < 0 && StopRequested()) stop_ramp_start = k;
    if (stop_ramp_start >= 0) {
      in.output_gain =
          std::max(0.0, 1.0 - static_cast<double>(k - stop_ramp_start + 1) / stop_ramp_ticks);
    }
    OperatorTickOutput out = tick.Step(in);
    for (std::size_t i = 0; i < fields_in; ++i) field_handoff_.free.Push(arrived_fields[i]);
    // The fields the model in use names and the tick lacks, told to the network worker at most
    // every 100 ms each (it asks the remote node for them again).
    for (int c = 0; c < std::min(tick.model().num_contacts, kMaxContacts); ++c) {
      const std::uint32_t id = tick.model().contacts[static_cast<std::size_t>(c)].depth_field_id;
      if (id == 0 || tick.HasDepthField(id)) continue;
      auto slot =
          std::ranges::find(missing_told, id, &std::pair<std::uint32_t, std::int64_t>::first);
      if (slot == missing_told.end()) {
        slot = std::ranges::min_element(missing_told, {},
                                        &std::pair<std::uint32_t, std::int64_t>::second);
      } else if (k - slot->second < 100) {
        continue;
      }
      if (field_handoff_.missing.Push(id)) *slot = {id, k};
    }
    if (!device_.WriteWrench(out.F_H_M, now)) ++rec.device_write_faults;
    if (in.device_ok) {
      ++tool_seq_;
      outgoing_.Write(
          {{tick.tool().X_WT, tick.tool().V_WT_W}, now, tool_seq_, tick.model().num_contacts > 0});
      const ToolStepResult& step = out.step;
      row.X_WT = tick.tool().X_WT;
      row.F_contact_T_W = step.F_contact_T_W;
      row.contacts = step.active_contacts;
      row.depth_m = step.max_depth_m;
      row.p_WH = out.X_WH.translation;
      row.F_H_W = out.F_H_W;
      row.f_H_M = out.F_H_M.force;
      row.passivity_removed_n = out.passivity_removed_n;
      row.model_age_ms = out.model_age_ms;
      row.remote_collision_us = tick.model_stamp().collision_us;
      row.remote_texture_us = tick.model_stamp().texture_us;
      row.remote_step_us = tick.model_stamp().step_us;
      rec.contacts_max = std::max(rec.contacts_max, step.active_contacts);
      rec.contact_force_max_n =
          std::max(rec.contact_force_max_n, glm::length(step.F_contact_T_W.force));
    }
    // The phase the simulated hand was following, when the device is scripted.
    row.phase = experiment_.Target(row.t_s).phase;
    if (caps_.scripted && row.phase != last_phase) {
      if (last_phase >= 0 && experiment_.EndsFree(last_phase)) {
        ++rec.free_ends_seen;
        if (last_force_n > LoopRecord::kWedgedForceN) {
          if (rec.wedged_count < static_cast<std::int64_t>(LoopRecord::kWedgedKept)) {
            rec.wedged[static_cast<std::size_t>(rec.wedged_count)] = {last_phase, last_t_s,
                                                                      last_force_n};
          }
          ++rec.wedged_count;
        }
      }
      last_phase = row.phase;
    }
    last_t_s = row.t_s;
    last_force_n = glm::length(row.F_contact_T_W.force);
    if (display_on_ && k % kDisplayEveryTicks == 0) {
      display_state.t_s = row.t_s;
      display_state.X_WT = tick.tool().X_WT;
      display_state.X_WH = out.X_WH;
      display_state.phase = caps_.scripted ? row.phase : -1;
      display_state.force_n = glm::length(row.F_contact_T_W.force);
      display_state.contacts = row.contacts;
      display_tool_.Write(display_state);
    }
    if (row.model_age_ms >= 0.0) rec.model_age_ms.Add(row.model_age_ms);
    const std::int64_t end = SteadyNowNs();
    row.tick_compute_us = static_cast<float>((end - now) * 1e-3);
    rec.compute_us.Add((end - now) * 1e-3);
    if (!rows_.Push(row)) rows_dropped_.fetch_add(1, std::memory_order_relaxed);
    rec.contacts.store(row.contacts, std::memory_order_relaxed);
    rec.phase.store(row.phase, std::memory_order_relaxed);
    rec.force_n.store(glm::length(row.F_contact_T_W.force), std::memory_order_relaxed);
    rec.age_ms.store(row.model_age_ms, std::memory_order_relaxed);
    rec.ticks_done.store(k + 1, std::memory_order_release);
    if (stop_ramp_start >= 0 && k - stop_ramp_start + 1 >= stop_ramp_ticks) {
      rec.stopped_by_request = true;
      break;
    }
    next += period_ns_;
    if (end > next + period_ns_) {  // fell more than a period behind: do not burst to catch up
      ++rec.overruns;
      next = end + period_ns_;
    }
  }
  device_.WriteWrench({}, SteadyNowNs());
  rec.done.store(true, std::memory_order_release);
}

void OperatorStationRun::PrintProgressUntilDone() {
  const LoopRecord& rec = *record_;
  std::int64_t last_print = SteadyNowNs();
  std::int64_t last_ticks = 0;
  std::uint64_t last_models = counters_.model_accepted.load();
  while (!rec.done.load(std::memory_order_acquire)) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    const std::int64_t now = SteadyNowNs();
    if (config_.progress_period_s > 0.0 && (now - last_print) * 1e-9 >= config_.progress_period_s) {
      const std::int64_t done = rec.ticks_done.load();
      const std::uint64_t models = counters_.model_accepted.load();
      const double dt = (now - last_print) * 1e-9;
      const int phase = rec.phase.load();
      std::printf(
          "[master] t=%5.2f/%.2f s  phase=%-8s  loop %6.0f Hz  models %6.0f Hz  contacts %d  "
          "|F|=%6.3f N  model age %5.2f ms\n",
          done / config_.loop_rate_hz, experiment_.duration_s(),
          phase < static_cast<int>(experiment_.phase_names().size())
              ? experiment_.phase_names()[phase].c_str()
              : "?",
          (done - last_ticks) / dt, (models - last_models) / dt, rec.contacts.load(),
          rec.force_n.load(), rec.age_ms.load());
      std::fflush(stdout);
      last_print = now;
      last_ticks = done;
      last_models = models;
    }
  }
}

}  // namespace station

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

nlohmann::json RunOperatorStation(const StationConfig& config, HapticDevice& device,
                                  Experiment& experiment) {
  config.Validate();
  const auto write_summary = [&](const nlohmann::json& s) {
    if (config.out_dir.empty()) return;
    const std::string path = config.out_dir + "/summary.json";
    std::ofstream out(path);
    out << s.dump(2) << "\n";
    if (!out) throw std::runtime_error("cannot write " + path);
  };
  station::OperatorStationRun run(config, device, experiment);
  try {
    run.WaitForSession();
    run.WaitForFirstModel();
  } catch (const std::runtime_error& e) {
    // No session or no model: the summary says why (the trace has its header only). What goes
    // wrong while it is written is a warning: the error thrown is the one that says why.
    try {
      write_summary(run.FailureSummary(e.what()));
    } catch (const std::exception& summary_error) {
      std::fprintf(stderr, "[master] warning: no summary.json of this run: %s\n",
                   summary_error.what());
    }
    throw;
  }
  run.RunHapticLoop();
  nlohmann::json s = run.Summary();
  write_summary(s);
  return s;
}

}  // namespace ht
