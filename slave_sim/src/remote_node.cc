// The remote node (remote_node.h, remote_node_run.h): set-up, then its loop (receive and handle
// datagrams through the session, stream the scene, step, send the contact model, pace), then the
// run summary (remote_node_summary.cc). The session protocol is in remote_session.cc, the step
// statistics in remote_step_statistics.cc, the remote step itself in haptic_core (remote_step.h).
#include "slave_sim/remote_node.h"

#include <sys/resource.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <glm/gtc/quaternion.hpp>
#include <limits>
#include <optional>
#include <stdexcept>
#include <string>
#include <thread>

#include "haptic_core/gpu_penetration_depth.h"
#include "haptic_core/remote_step.h"
#include "haptic_core/steady_clock.h"
#include "remote_node_run.h"
#include "transport/messages.h"
#include "transport/session.h"

namespace ht {
namespace remote {
namespace {

// A coarse triangle's centroid and outward unit normal (frame O), or false when it has no area.
bool TriangleFrame(const HapticModel& m, int f, glm::dvec3& centroid_O, glm::dvec3& normal_O) {
  const glm::ivec3 t = m.triangles[static_cast<std::size_t>(f)];
  const glm::dvec3 a = m.vertices_O[static_cast<std::size_t>(t[0])];
  const glm::dvec3 b = m.vertices_O[static_cast<std::size_t>(t[1])];
  const glm::dvec3 c = m.vertices_O[static_cast<std::size_t>(t[2])];
  const glm::dvec3 cr = glm::cross(b - a, c - a);
  const double len = glm::length(cr);
  if (!(len > 0.0) || !std::isfinite(len)) return false;
  centroid_O = (a + b + c) / 3.0;
  normal_O = cr / len;
  return true;
}

// The penetration-depth backend's first batches, before the first operator: the GPU backend
// compiles its GL programs at its first draws (0.2–0.5 s on llvmpipe without a shader cache),
// which at the first contact of a session stalled the remote node past the operator's 500 ms
// peer timeout (a CI run of loopback_fig75_gpu). One contact made for it, the tool's first
// triangle laid face to face on the first touchable's first triangle, in two batches: with
// windows that pick by box (the instanced draws) and with triangle lists (the per-contact draws
// of each cluster's own triangles). The results are discarded; a failure is left to the
// first real step, which falls back to the CPU. Returns the backend's missing-overlap count
// after it, so that the run's summary counts only the session's.
std::int64_t WarmUpPenetrationDepth(PenetrationDepthBackend& backend, const HapticScene& scene,
                                    const PipelineOptions& options) {
  if (!scene.tool || scene.touchables.empty()) return backend.faults().missing_overlap;
  const HapticModel& tool = *scene.tool;
  const TouchableObject& object = scene.touchables.front();
  const HapticModel& model = *object.model;
  glm::dvec3 c_O, n_O, c_T, n_T;
  int f_object = -1, f_tool = -1;
  for (int f = 0; f < static_cast<int>(model.triangles.size()) && f_object < 0; ++f) {
    if (TriangleFrame(model, f, c_O, n_O)) f_object = f;
  }
  for (int f = 0; f < static_cast<int>(tool.triangles.size()) && f_tool < 0; ++f) {
    if (TriangleFrame(tool, f, c_T, n_T)) f_tool = f;
  }
  if (f_object < 0 || f_tool < 0) return backend.faults().missing_overlap;
  const glm::dvec3 c_W = object.X_WO * c_O;
  const glm::dvec3 n_W = glm::normalize(object.X_WO.rotation * n_O);
  // The tool turned so that its triangle's outward normal is −n_W, its centroid on c_W.
  RigidTransform X_WT;
  if (glm::dot(n_T, -n_W) < -0.999999) {
    const glm::dvec3 axis = std::abs(n_T.x) < 0.9 ? glm::dvec3(1, 0, 0) : glm::dvec3(0, 1, 0);
    X_WT.rotation = glm::angleAxis(std::acos(-1.0), glm::normalize(glm::cross(n_T, axis)));
  } else {
    X_WT.rotation = glm::dquat(n_T, -n_W);
  }
  X_WT.translation = c_W - X_WT.rotation * c_T;
  const std::optional<ContactWindow> window =
      ContactWindow::TryMake(c_W, n_W, options.window_extent_m, options.grid_resolution);
  if (!window) return backend.faults().missing_overlap;
  const int object_list[1] = {f_object}, tool_list[1] = {f_tool};
  ContactQuery q{&model, object.X_WO, *window, object.stiffness_n_per_m,
                 std::numeric_limits<double>::infinity()};
  ContactLinearization out;
  backend.LinearizeBatch(tool, X_WT, {&q, 1}, {&out, 1});
  q.environment_triangles = TriangleSubset::Of(object_list);
  q.tool_triangles = TriangleSubset::Of(tool_list);
  backend.LinearizeBatch(tool, X_WT, {&q, 1}, {&out, 1});
  return backend.faults().missing_overlap;
}

// Throws std::invalid_argument naming the first option of `config` out of range.
void CheckConfig(const RemoteNodeConfig& config) {
  config.pipeline.Validate();
  if (!(config.max_deadband >= 0.0 && config.max_deadband < 1.0)) {
    throw std::invalid_argument("max deadband must be in [0, 1) (a Weber fraction), got " +
                                std::to_string(config.max_deadband));
  }
  config.model_deadband.Validate();
  if (!(config.speculative_speed_m_per_s >= 0.0) ||
      !std::isfinite(config.speculative_speed_m_per_s)) {
    throw std::invalid_argument("speculative speed must be a finite value >= 0 m/s, got " +
                                std::to_string(config.speculative_speed_m_per_s));
  }
  if (!(config.max_speculative_floor_m >= 0.0) || !std::isfinite(config.max_speculative_floor_m)) {
    throw std::invalid_argument("max speculative floor must be a finite value >= 0 m, got " +
                                std::to_string(config.max_speculative_floor_m));
  }
  if (!(config.display_rate_hz >= 1.0 && config.display_rate_hz <= 1000.0)) {
    throw std::invalid_argument("display rate must be 1..1000 Hz, got " +
                                std::to_string(config.display_rate_hz));
  }
}

}  // namespace

double ProcessCpuSeconds() noexcept {
  struct rusage usage {};
  getrusage(RUSAGE_SELF, &usage);
  return static_cast<double>(usage.ru_utime.tv_sec + usage.ru_stime.tv_sec) +
         static_cast<double>(usage.ru_utime.tv_usec + usage.ru_stime.tv_usec) * 1e-6;
}

RemoteNodeRun::RemoteNodeRun(const RemoteNodeConfig& config, const HapticScene& scene)
    : config_(config),
      statistics_(!config.step_trace_path.empty()),
      min_period_ns_(config.max_rate_hz > 0.0 ? static_cast<std::int64_t>(1e9 / config.max_rate_hz)
                                              : 0),
      current_scene_(&scene) {
  CheckConfig(config);
  std::unique_ptr<PenetrationDepthBackend> backend = MakePenetrationDepthBackend(
      config.pd_backend, config.gpu, config.pipeline.max_window_resolution(), backend_message_,
      config.pipeline.texture_threads);
  if (auto* gpu = dynamic_cast<GpuPenetrationDepthBackend*>(backend.get())) {
    // Stage 5a (the split) runs with the CPU texture stage only (HapticTexturePipeline).
    backend_message_ += "; stage 5a's split is off on the GPU backend (--pd-backend cpu has it)";
    gpu_instanced_draws_ = gpu->instanced_draws();
    gl_renderer_ = gpu->info().renderer;
    gl_version_ = gpu->info().version;
    gl_vendor_ = gpu->info().vendor;
  }
  backend->UseScene(scene);  // the GPU's uploads, once per model, before the warm-up
  warm_up_missing_overlap_ = WarmUpPenetrationDepth(*backend, scene, config.pipeline);
  // --quiet (progress_period_s 0): no start-up lines either; errors and the last line stay.
  const bool chatty = config.progress_period_s > 0.0;
  if (chatty) {
    std::printf("[slave] %s\n", backend_message_.c_str());
    std::fflush(stdout);
  }
  pipeline_ = std::make_unique<HapticTexturePipeline>(scene, config.pipeline, std::move(backend));
  backend_at_start_ = std::string(pipeline_->backend().name());
  socket_.emplace(config.listen_address);
  bound_ = socket_->local_address();
  if (!config.port_file.empty()) {
    const std::string tmp = config.port_file + ".tmp";
    {
      std::ofstream f(tmp);
      f << bound_.port() << "\n";
      if (!f) throw std::runtime_error("cannot write port file " + tmp);
    }
    std::rename(tmp.c_str(), config.port_file.c_str());
  }
  link_.emplace(*socket_, config.key, LinkRole::kRemote);
  scene_sender_.emplace(config.mtu);
  for (const StreamObject& o : config.scene_objects) {
    scene_sender_->Update(o.id, o.bytes, o.kind);
    scene_bytes_ += o.bytes.size();
  }
  caps_.grid = static_cast<std::uint16_t>(config.pipeline.grid_resolution);
  caps_.window_m = static_cast<float>(config.pipeline.window_extent_m);
  caps_.mtu = static_cast<std::uint16_t>(config.mtu);
  caps_.max_model_rate_hz = static_cast<float>(config.max_rate_hz);
  caps_.peer_timeout_ms = static_cast<std::uint16_t>(config.peer_timeout_ms);
  caps_.max_deadband = static_cast<float>(config.max_deadband);
  caps_.codecs = wire::kCodecDracoMesh | wire::kCodecCompactContactModel |
                 wire::kCodecCompactToolState |
                 (config.depth_fields ? wire::kCodecDepthFields : 0u);
  caps_.scene_objects = static_cast<std::uint16_t>(config.scene_objects.size());
  caps_.scene_name = scene.name;
  caps_.layout = MakeSceneLayout(scene);
  if (chatty) {
    std::printf(
        "[slave] scene '%s': tool '%s', %zu touchable(s), %zu scene object(s) (%zu bytes); "
        "listening on %s (authenticated)\n",
        scene.name.c_str(), scene.tool->name.c_str(), scene.touchables.size(),
        config.scene_objects.size(), scene_bytes_, bound_.ToString().c_str());
    std::fflush(stdout);
  }
  start_ns_ = SteadyNowNs();
  session_.emplace(config, *link_, *scene_sender_, caps_, start_ns_);
  last_progress_ns_ = start_ns_;
  bad_mac_said_ns_ = start_ns_ - 5'000'000'000LL;
}

bool RemoteNodeRun::Pass() {
  if (!ReceiveDatagrams()) return false;
  // The session: lost operator, rebuilt scene, scene stream.
  const std::int64_t now_loop = SteadyNowNs();
  session_->CheckPeerTimeout(now_loop);
  if (config_.take_reload) SwitchToReloadedScene();
  SayBadMacs(now_loop);
  if (!session_->open()) {
    socket_->WaitReadable(50);
    return true;
  }
  session_->StreamScene(now_loop);
  session_->MaybeSendNodePoses(now_loop);
  if (!session_->have_tool_state()) {
    socket_->WaitReadable(1);
    return true;
  }
  StepOrWait();
  return true;
}

bool RemoteNodeRun::ReceiveDatagrams() {
  // At most kDrainPerPass datagrams between steps, so that a flood delays steps, never stops
  // them.
  constexpr int kDrainPerPass = 256;
  int drained = 0;
  SocketAddress from;
  std::optional<std::size_t> n;
  bool running = true;
  while (drained++ < kDrainPerPass && (n = socket_->ReceiveFrom(buffer_, from))) {
    const std::span<const std::uint8_t> datagram(buffer_.data(), std::min(*n, buffer_.size()));
    if (!session_->OnDatagram(datagram, from, SteadyNowNs())) running = false;
  }
  return running;
}

void RemoteNodeRun::SwitchToReloadedScene() {
  reload_objects_.clear();
  const HapticScene* next = config_.take_reload(&reload_objects_);
  if (next == nullptr) return;
  const auto t0 = SteadyNowNs();
  std::unique_ptr<PenetrationDepthBackend> kept = pipeline_->ReleaseBackend();
  try {
    // The new pipeline moves the backend to the new scene (UseScene: the GPU uploads the new
    // models before the first step and frees the old ones').
    pipeline_ = std::make_unique<HapticTexturePipeline>(*next, config_.pipeline, std::move(kept));
  } catch (const std::exception& e) {
    // The GPU refused the new models: the CPU backend, as after a failed batch.
    std::printf("[slave] the %s backend failed on the rebuilt scene (%s); CPU backend\n",
                backend_at_start_.c_str(), e.what());
    pipeline_ = std::make_unique<HapticTexturePipeline>(*next, config_.pipeline, nullptr);
  }
  current_scene_ = next;
  std::size_t changed = 0, changed_bytes = 0;
  for (const StreamObject& o : reload_objects_) {
    const auto& held = scene_sender_->objects();
    const auto it = std::find_if(held.begin(), held.end(),
                                 [&](const SceneObject& h) { return h.object_id == o.id; });
    if (it != held.end() && it->kind == o.kind && it->bytes == o.bytes) continue;
    const std::uint32_t version = scene_sender_->Update(o.id, o.bytes, o.kind);
    if (o.kind == wire::SceneObjectKind::kSceneGraph) session_->SetGraphVersion(version);
    ++changed;
    changed_bytes += o.bytes.size();
  }
  session_->SceneChanged(MakeSceneLayout(*next));
  ++scene_reloads_;
  reload_bytes_ += changed_bytes;
  std::printf(
      "[slave] switched to the rebuilt scene in %.1f ms: %zu object(s) changed, "
      "%zu bytes queued for the operator\n",
      (SteadyNowNs() - t0) * 1e-6, changed, changed_bytes);
  std::fflush(stdout);
}

void RemoteNodeRun::SayBadMacs(std::int64_t now_ns) {
  // A wrong key on one side otherwise shows only as an operator that never connects.
  if (const std::uint64_t bad = link_->rejected(wire::DecodeStatus::kBadMac);
      bad > bad_mac_said_ && now_ns - bad_mac_said_ns_ >= 5'000'000'000LL) {
    std::printf(
        "[slave] note: %llu datagram(s) failed authentication (bad MAC) so far: an "
        "operator is using another --key file\n",
        static_cast<unsigned long long>(bad));
    std::fflush(stdout);
    bad_mac_said_ = bad;
    bad_mac_said_ns_ = now_ns;
  }
}

void RemoteNodeRun::StepOrWait() {
  // The remote step at the newest tool state (extrapolated under a tool-state deadband), and its
  // contact model to the operator. A step that would see nothing new (no fresh tool state, and
  // the same pose or a pose still inside the last step's free space) waits on the socket: the
  // operator keeps the model it holds, refreshed at the keep-alive.
  const std::int64_t t_step = SteadyNowNs();
  const RigidTransform X_WT = session_->ToolPoseForStep(t_step);
  const StepCause cause =
      session_->WhyStep(X_WT, static_cast<bool>(config_.animate),
                        pipeline_->ToolMotionBound(session_->last_step_pose(), X_WT), t_step);
  if (cause == StepCause::kWait) {
    session_->CountSkippedStep();
    session_->MaybeSendKeepAlive(t_step);
    // A pose that holds still (and no scene left to stream) is re-checked every 10 ms: a
    // datagram wakes the wait at once, and the keep-alives and the manifest run on timers far
    // longer than that. A pose still moving (extrapolated in free space) or a scene stream under
    // way is re-checked every millisecond.
    const bool holds_still = session_->AtLastStepPose(X_WT);
    if (const std::int64_t due_ns = session_->ModelDueInNs(t_step); due_ns > 0) {
      // A model held by the model period: stepped again at the period's end, to the µs.
      socket_->WaitReadableNs(std::min<std::int64_t>(due_ns, 1'000'000));
    } else {
      socket_->WaitReadable(holds_still && scene_sender_->queued() == 0 ? 10 : 1);
    }
    return;
  }
  if (config_.animate) config_.animate(static_cast<double>(t_step - start_ns_) * 1e-9);
  if (first_step_ns_ < 0) {  // the scene is built and a session steps: the idle measure starts
    first_step_ns_ = t_step;
    first_step_cpu_s_ = ProcessCpuSeconds();
  }
  FollowRoundTrip();
  StepTimings timings;
  wire::ContactModelMessage out;
  out.model = pipeline_->Step(X_WT, session_->latest_tool_state_seq(), timings,
                              session_->latest_tool_state().V_WT_W);
  session_->SteppedAt(X_WT, timings.free_space_clearance_m, t_step);
  session_->CountStep(cause);
  if (pipeline_->backend_failures() == 1 && !reported_fallback_) {
    reported_fallback_ = true;
    std::printf("[slave] GPU penetration depth failed (%s); continuing on the CPU backend\n",
                pipeline_->fallback_reason().c_str());
    std::fflush(stdout);
  }
  const std::int64_t step_end_ns = SteadyNowNs();
  statistics_.Record(static_cast<double>(t_step - start_ns_) * 1e-9, t_step, step_end_ns, timings,
                     out.model.num_contacts, session_->latest_tool_state_seq(),
                     static_cast<int>(cause), pipeline_->last_contact_queries());
  session_->MaybeSendContactModel(out, timings, statistics_.steps(), step_end_ns,
                                  pipeline_->last_depth_fields(), pipeline_->kept_depth_fields());
  PrintProgress(timings, out.model.num_contacts);
  // The pace (config.max_rate_hz).
  if (min_period_ns_ > 0) {
    const std::int64_t wait = t_step + min_period_ns_ - SteadyNowNs();
    if (wait > 0) std::this_thread::sleep_for(std::chrono::nanoseconds(wait));
  }
}

void RemoteNodeRun::FollowRoundTrip() {
  // Depth fields for a session whose operator takes them, their margin by its round trip.
  if (session_->depth_fields() != pipeline_->depth_fields()) {
    pipeline_->SetDepthFields(session_->depth_fields());
  }
  if (session_->depth_fields()) {
    pipeline_->SetDepthFieldMargin(std::max(config_.depth_field_min_margin_m,
                                            config_.depth_field_speed_m_per_s *
                                                static_cast<double>(session_->operator_rtt_ns()) *
                                                1e-9));
  }
  // The speculative floor by the operator's round trip (speculative_speed_m_per_s).
  if (config_.speculative_speed_m_per_s > 0.0) {
    const double floor_m = SpeculativeFloorForRoundTrip(config_, session_->operator_rtt_ns());
    pipeline_->SetSpeculativeFloor(floor_m);
    largest_speculative_floor_m_ = std::max(largest_speculative_floor_m_, floor_m);
  }
}

void RemoteNodeRun::PrintProgress(const StepTimings& timings, int num_contacts) {
  const std::int64_t now = SteadyNowNs();
  if (!(config_.progress_period_s > 0.0) ||
      (now - last_progress_ns_) * 1e-9 < config_.progress_period_s) {
    return;
  }
  const double dt = (now - last_progress_ns_) * 1e-9;
  std::printf(
      "[slave] %6.0f steps/s  step %6.0f us (collision %4.0f, texture %6.0f)  "
      "contacts %d  tool states %llu  rejected %llu\n",
      (statistics_.steps() - last_progress_steps_) / dt, timings.total_us, timings.collision_us,
      timings.texture_us, num_contacts,
      static_cast<unsigned long long>(link_->stats(wire::MessageType::kToolState).received +
                                      link_->stats(wire::MessageType::kCompactToolState).received),
      static_cast<unsigned long long>(link_->rejected_total()));
  std::fflush(stdout);
  last_progress_ns_ = now;
  last_progress_steps_ = statistics_.steps();
}

void RemoteNodeRun::Finish() {
  // Stopped: tell the operator, which reconnects at once.
  if (config_.goodbye_on_stop) session_->SayGoodbye();
  if (!config_.step_trace_path.empty()) statistics_.WriteTrace(config_.step_trace_path);
}

}  // namespace remote

double SpeculativeFloorForRoundTrip(const RemoteNodeConfig& config,
                                    std::int64_t operator_rtt_ns) noexcept {
  if (!(config.speculative_speed_m_per_s > 0.0) || operator_rtt_ns <= 0) return 0.0;
  return std::min(config.max_speculative_floor_m,
                  config.speculative_speed_m_per_s * static_cast<double>(operator_rtt_ns) * 1e-9);
}

nlohmann::json RunRemoteNode(const RemoteNodeConfig& config, const HapticScene& scene,
                             const std::atomic<bool>& stop) {
  remote::RemoteNodeRun run(config, scene);
  while (!stop.load(std::memory_order_relaxed) && run.Pass()) {
  }
  run.Finish();
  return run.Summary();
}

}  // namespace ht
