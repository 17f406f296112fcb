// The remote node: set-up, then its loop (receive and handle datagrams through the session,
// stream the scene, step, send the contact model, pace), then the run summary. The session
// protocol is in remote_session.cc, the step statistics in remote_step_statistics.cc, the remote
// step itself in haptic_core (remote_step.h).
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

#include "haptic_core/remote_step.h"
#include "haptic_core/steady_clock.h"
#include "remote_session.h"
#include "remote_step_statistics.h"
#include "transport/link.h"
#include "transport/messages.h"
#include "transport/scene_stream.h"
#include "transport/session.h"

namespace ht {

namespace {

/// The process's CPU time so far (s): user + system, every thread (getrusage).
double ProcessCpuSeconds() noexcept {
  struct rusage usage {};
  getrusage(RUSAGE_SELF, &usage);
  return static_cast<double>(usage.ru_utime.tv_sec + usage.ru_stime.tv_sec) +
         static_cast<double>(usage.ru_utime.tv_usec + usage.ru_stime.tv_usec) * 1e-6;
}

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
// windows that pick by box (the instanced draws) and with triangle lists (the per-contact draws,
// PipelineOptions::cluster_triangles). The results are discarded; a failure is left to the
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

// Whether the next step fills translation patches (RemoteNodeConfig::translation_patch_rtt_ms):
// always with the option, else from the threshold on and, once on (`on_now`), until the round
// trip the operator reported (ns; 0: none yet) falls below kTranslationPatchOffFraction of it.
bool TranslationPatchWanted(const RemoteNodeConfig& config, std::int64_t operator_rtt_ns,
                            bool on_now) noexcept {
  if (config.pipeline.depth_refinement.translation_patch) return true;
  const double threshold_ms = config.translation_patch_rtt_ms;
  if (!std::isfinite(threshold_ms) || operator_rtt_ns <= 0) return false;
  const double rtt_ms = static_cast<double>(operator_rtt_ns) * 1e-6;
  return rtt_ms >= (on_now ? kTranslationPatchOffFraction * threshold_ms : threshold_ms);
}

}  // namespace

double SpeculativeFloorForRoundTrip(const RemoteNodeConfig& config,
                                    std::int64_t operator_rtt_ns) noexcept {
  if (!(config.speculative_speed_m_per_s > 0.0) || operator_rtt_ns <= 0) return 0.0;
  return std::min(config.max_speculative_floor_m,
                  config.speculative_speed_m_per_s * static_cast<double>(operator_rtt_ns) * 1e-9);
}

nlohmann::json RunRemoteNode(const RemoteNodeConfig& config, const HapticScene& scene,
                             const std::atomic<bool>& stop) {
  config.pipeline.Validate();
  if (!(config.max_deadband >= 0.0 && config.max_deadband < 1.0)) {
    throw std::invalid_argument("max deadband must be in [0, 1) (a Weber fraction), got " +
                                std::to_string(config.max_deadband));
  }
  config.model_deadband.Validate();
  if (!(config.translation_patch_rtt_ms >= 0.0)) {
    throw std::invalid_argument(
        "translation patch round trip must be >= 0 ms (infinite: never by the round trip), got " +
        std::to_string(config.translation_patch_rtt_ms));
  }
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
  std::string backend_message;
  std::unique_ptr<PenetrationDepthBackend> backend = MakePenetrationDepthBackend(
      config.pd_backend, config.gpu, config.pipeline.max_window_resolution(), backend_message,
      config.pipeline.texture_threads, config.pipeline.rotation_gradient);
  std::string gl_renderer, gl_version, gl_vendor;
  bool gpu_instanced_draws = false;
  if (auto* gpu = dynamic_cast<GpuPenetrationDepthBackend*>(backend.get())) {
    // Stage 5a (the split) runs with the CPU texture stage only (HapticTexturePipeline).
    if (config.pipeline.split_windows_at_separated_overlap) {
      backend_message += "; stage 5a's split is off on the GPU backend (--pd-backend cpu has it)";
    }
    gpu_instanced_draws = gpu->instanced_draws();
    gl_renderer = gpu->info().renderer;
    gl_version = gpu->info().version;
    gl_vendor = gpu->info().vendor;
    gpu->Upload(*scene.tool);  // textures once per model, before the first step
    for (const TouchableObject& t : scene.touchables) gpu->Upload(*t.model);
  }
  const std::int64_t warm_up_missing_overlap =
      WarmUpPenetrationDepth(*backend, scene, config.pipeline);
  // --quiet (progress_period_s 0): no start-up lines either; errors and the last line stay.
  const bool chatty = config.progress_period_s > 0.0;
  if (chatty) {
    std::printf("[slave] %s\n", backend_message.c_str());
    std::fflush(stdout);
  }
  auto pipeline =
      std::make_unique<HapticTexturePipeline>(scene, config.pipeline, std::move(backend));
  const std::string backend_at_start(pipeline->backend().name());
  UdpSocket socket(config.listen_address);
  const SocketAddress bound = socket.local_address();
  if (!config.port_file.empty()) {
    const std::string tmp = config.port_file + ".tmp";
    {
      std::ofstream f(tmp);
      f << bound.port() << "\n";
      if (!f) throw std::runtime_error("cannot write port file " + tmp);
    }
    std::rename(tmp.c_str(), config.port_file.c_str());
  }
  SecureLink link(socket, config.key, LinkRole::kRemote);
  SceneSender scene_sender(config.mtu);
  std::size_t scene_bytes = 0;
  for (const StreamObject& o : config.scene_objects) {
    scene_sender.Update(o.id, o.bytes, o.kind);
    scene_bytes += o.bytes.size();
  }
  RemoteCapabilities caps;
  caps.grid = static_cast<std::uint16_t>(config.pipeline.grid_resolution);
  caps.window_m = static_cast<float>(config.pipeline.window_extent_m);
  caps.mtu = static_cast<std::uint16_t>(config.mtu);
  caps.max_model_rate_hz = static_cast<float>(config.max_rate_hz);
  caps.peer_timeout_ms = static_cast<std::uint16_t>(config.peer_timeout_ms);
  caps.max_deadband = static_cast<float>(config.max_deadband);
  caps.codecs =
      wire::kCodecDracoMesh | wire::kCodecCompactContactModel | wire::kCodecCompactToolState;
  caps.scene_objects = static_cast<std::uint16_t>(config.scene_objects.size());
  caps.scene_name = scene.name;
  caps.layout = MakeSceneLayout(scene);
  if (chatty) {
    std::printf(
        "[slave] scene '%s': tool '%s', %zu touchable(s), %zu scene object(s) (%zu bytes); "
        "listening on %s (authenticated)\n",
        scene.name.c_str(), scene.tool->name.c_str(), scene.touchables.size(),
        config.scene_objects.size(), scene_bytes, bound.ToString().c_str());
    std::fflush(stdout);
  }

  const std::int64_t start_ns = SteadyNowNs();
  RemoteSession session(config, link, scene_sender, caps, start_ns);
  RemoteStepStatistics statistics(!config.step_trace_path.empty());
  std::array<std::uint8_t, wire::kMaxDatagramBytes + 1> buffer{};
  const std::int64_t min_period_ns =
      config.max_rate_hz > 0.0 ? static_cast<std::int64_t>(1e9 / config.max_rate_hz) : 0;
  std::int64_t last_progress_ns = start_ns;
  std::uint64_t bad_mac_said = 0;  // bad-MAC datagrams already said (below)
  std::int64_t bad_mac_said_ns = start_ns - 5'000'000'000LL;
  std::uint64_t last_progress_steps = 0;
  bool running = true;
  bool reported_fallback = false;
  std::uint64_t steps_with_patch_on = 0, patch_switches = 0;
  double largest_speculative_floor_m = 0.0;
  std::vector<StreamObject> reload_objects;
  const HapticScene* current_scene = &scene;  // the scene the pipeline steps (a reload moves it)
  std::uint64_t scene_reloads = 0;
  std::size_t reload_bytes = 0;
  std::int64_t first_step_ns = -1;  // the first step's time, and the process's CPU time then
  double first_step_cpu_s = 0.0;

  while (running && !stop.load(std::memory_order_relaxed)) {
    // 1. Receive: at most kDrainPerPass datagrams between steps, so that a flood delays steps,
    // never stops them.
    constexpr int kDrainPerPass = 256;
    int drained = 0;
    SocketAddress from;
    std::optional<std::size_t> n;
    while (drained++ < kDrainPerPass && (n = socket.ReceiveFrom(buffer, from))) {
      const std::span<const std::uint8_t> datagram(buffer.data(), std::min(*n, buffer.size()));
      if (!session.OnDatagram(datagram, from, SteadyNowNs())) running = false;
    }
    if (!running) break;
    // 2. The session: lost operator, scene stream.
    const std::int64_t now_loop = SteadyNowNs();
    session.CheckPeerTimeout(now_loop);
    // A rebuilt scene (its file changed): switch the pipeline between two steps, and stream the
    // objects whose bytes changed as new versions.
    if (config.take_reload) {
      reload_objects.clear();
      if (const HapticScene* next = config.take_reload(&reload_objects)) {
        const auto t0 = SteadyNowNs();
        std::unique_ptr<PenetrationDepthBackend> kept = pipeline->ReleaseBackend();
        try {
          if (auto* gpu = dynamic_cast<GpuPenetrationDepthBackend*>(kept.get())) {
            // Uploads are keyed by the model's address: the old models' go (a new model may
            // reuse a freed address), the new ones are uploaded before the first step.
            gpu->ForgetModels();
            gpu->Upload(*next->tool);
            for (const TouchableObject& t : next->touchables) gpu->Upload(*t.model);
          }
          const bool patch_was_on = pipeline->translation_patch();
          pipeline =
              std::make_unique<HapticTexturePipeline>(*next, config.pipeline, std::move(kept));
          pipeline->SetTranslationPatch(patch_was_on);  // the round trip's choice goes on
        } catch (const std::exception& e) {
          // The GPU refused the new models: the CPU backend, as after a failed batch.
          std::printf("[slave] the %s backend failed on the rebuilt scene (%s); CPU backend\n",
                      backend_at_start.c_str(), e.what());
          pipeline = std::make_unique<HapticTexturePipeline>(*next, config.pipeline, nullptr);
        }
        current_scene = next;
        std::size_t changed = 0, changed_bytes = 0;
        for (const StreamObject& o : reload_objects) {
          const auto& held = scene_sender.objects();
          const auto it = std::find_if(held.begin(), held.end(),
                                       [&](const SceneObject& h) { return h.object_id == o.id; });
          if (it != held.end() && it->kind == o.kind && it->bytes == o.bytes) continue;
          const std::uint32_t version = scene_sender.Update(o.id, o.bytes, o.kind);
          if (o.kind == wire::SceneObjectKind::kSceneGraph) session.SetGraphVersion(version);
          ++changed;
          changed_bytes += o.bytes.size();
        }
        session.SceneChanged(MakeSceneLayout(*next));
        ++scene_reloads;
        reload_bytes += changed_bytes;
        std::printf(
            "[slave] switched to the rebuilt scene in %.1f ms: %zu object(s) changed, "
            "%zu bytes queued for the operator\n",
            (SteadyNowNs() - t0) * 1e-6, changed, changed_bytes);
        std::fflush(stdout);
      }
    }
    // Datagrams that fail authentication are said, even with --quiet (at most every 5 s): a
    // wrong key on one side otherwise shows only as an operator that never connects.
    if (const std::uint64_t bad = link.rejected(wire::DecodeStatus::kBadMac);
        bad > bad_mac_said && now_loop - bad_mac_said_ns >= 5'000'000'000LL) {
      std::printf(
          "[slave] note: %llu datagram(s) failed authentication (bad MAC) so far: an "
          "operator is using another --key file\n",
          static_cast<unsigned long long>(bad));
      std::fflush(stdout);
      bad_mac_said = bad;
      bad_mac_said_ns = now_loop;
    }
    if (!session.open()) {
      socket.WaitReadable(50);
      continue;
    }
    session.StreamScene(now_loop);
    session.MaybeSendNodePoses(now_loop);
    if (!session.have_tool_state()) {
      socket.WaitReadable(1);
      continue;
    }
    // 3. The remote step at the newest tool state (extrapolated under a tool-state deadband),
    // and its contact model to the operator. A step that would see nothing new (no fresh tool
    // state, and the same pose or a pose still inside the last step's free space) waits on the
    // socket: the operator keeps the model it holds, refreshed at the keep-alive.
    const std::int64_t t_step = SteadyNowNs();
    const RigidTransform X_WT = session.ToolPoseForStep(t_step);
    const StepCause cause =
        session.WhyStep(X_WT, static_cast<bool>(config.animate),
                        pipeline->ToolMotionBound(session.last_step_pose(), X_WT), t_step);
    if (cause == StepCause::kWait) {
      session.CountSkippedStep();
      session.MaybeSendKeepAlive(t_step);
      // A pose that holds still (and no scene left to stream) is re-checked every 10 ms: a
      // datagram wakes the wait at once, and the keep-alives and the manifest run on
      // timers far longer than that. A pose still moving (extrapolated in free space) or
      // a scene stream under way is re-checked every millisecond.
      const bool holds_still = session.AtLastStepPose(X_WT);
      if (const std::int64_t due_ns = session.ModelDueInNs(t_step); due_ns > 0) {
        // A model held by the model period: stepped again at the period's end, to the µs.
        socket.WaitReadableNs(std::min<std::int64_t>(due_ns, 1'000'000));
      } else {
        socket.WaitReadable(holds_still && scene_sender.queued() == 0 ? 10 : 1);
      }
      continue;
    }
    if (config.animate) config.animate(static_cast<double>(t_step - start_ns) * 1e-9);
    if (first_step_ns < 0) {  // the scene is built and a session steps: the idle measure starts
      first_step_ns = t_step;
      first_step_cpu_s = ProcessCpuSeconds();
    }
    // The translation patches by the operator's round trip. A switch sends the next model
    // whatever the deadband (it compares forces, not patches).
    if (config.pipeline.refine_depth) {
      const bool was_on = pipeline->translation_patch();
      const bool patch = TranslationPatchWanted(config, session.operator_rtt_ns(), was_on);
      if (patch != was_on) {
        pipeline->SetTranslationPatch(patch);
        session.ResendNextModel();
        ++patch_switches;
      }
      if (patch) ++steps_with_patch_on;
    }
    // The speculative floor by the operator's round trip (speculative_speed_m_per_s).
    if (config.speculative_speed_m_per_s > 0.0) {
      const double floor_m = SpeculativeFloorForRoundTrip(config, session.operator_rtt_ns());
      pipeline->SetSpeculativeFloor(floor_m);
      largest_speculative_floor_m = std::max(largest_speculative_floor_m, floor_m);
    }
    StepTimings timings;
    wire::ContactModelMessage out;
    out.model = pipeline->Step(X_WT, session.latest_tool_state_seq(), timings,
                               session.latest_tool_state().V_WT_W);
    session.SteppedAt(X_WT, timings.free_space_clearance_m);
    session.CountStep(cause);
    if (pipeline->backend_failures() == 1 && !reported_fallback) {
      reported_fallback = true;
      std::printf("[slave] GPU penetration depth failed (%s); continuing on the CPU backend\n",
                  pipeline->fallback_reason().c_str());
      std::fflush(stdout);
    }
    const std::int64_t step_end_ns = SteadyNowNs();
    statistics.Record(static_cast<double>(t_step - start_ns) * 1e-9, t_step, step_end_ns, timings,
                      out.model.num_contacts, session.latest_tool_state_seq(),
                      static_cast<int>(cause), pipeline->last_contact_queries());
    session.MaybeSendContactModel(out, timings, statistics.steps(), step_end_ns);
    // 4. Progress, and the pace (config.max_rate_hz).
    const std::int64_t now = SteadyNowNs();
    if (config.progress_period_s > 0.0 &&
        (now - last_progress_ns) * 1e-9 >= config.progress_period_s) {
      const double dt = (now - last_progress_ns) * 1e-9;
      std::printf(
          "[slave] %6.0f steps/s  step %6.0f us (collision %4.0f, texture %6.0f)  "
          "contacts %d  tool states %llu  rejected %llu\n",
          (statistics.steps() - last_progress_steps) / dt, timings.total_us, timings.collision_us,
          timings.texture_us, out.model.num_contacts,
          static_cast<unsigned long long>(
              link.stats(wire::MessageType::kToolState).received +
              link.stats(wire::MessageType::kCompactToolState).received),
          static_cast<unsigned long long>(link.rejected_total()));
      std::fflush(stdout);
      last_progress_ns = now;
      last_progress_steps = statistics.steps();
    }
    if (min_period_ns > 0) {
      const std::int64_t wait = t_step + min_period_ns - SteadyNowNs();
      if (wait > 0) std::this_thread::sleep_for(std::chrono::nanoseconds(wait));
    }
  }
  // Stopped: tell the operator, which reconnects at once.
  if (config.goodbye_on_stop) session.SayGoodbye();
  if (!config.step_trace_path.empty()) statistics.WriteTrace(config.step_trace_path);

  nlohmann::json s;
  s["scene"] = current_scene->name;
  s["listen"] = bound.ToString();
  statistics.AddTo(s);
  s["tool_state_gap_max_ms"] = session.tool_state_gap_max_ns() * 1e-6;
  // The process's CPU time over the run (user + system, every thread; getrusage), and its share
  // of one core over the node's wall time; the same from the first step on (the scene built and
  // a session stepping): what issue 33's "idle when nothing changes" is measured by.
  {
    const double cpu_s = ProcessCpuSeconds();
    const std::int64_t end_ns = SteadyNowNs();
    const double wall_s = static_cast<double>(end_ns - start_ns) * 1e-9;
    s["cpu_s"] = cpu_s;
    s["wall_s"] = wall_s;
    s["cpu_share_of_one_core"] = wall_s > 0.0 ? cpu_s / wall_s : 0.0;
    const double stepping_s =
        first_step_ns < 0 ? 0.0 : static_cast<double>(end_ns - first_step_ns) * 1e-9;
    s["cpu_s_since_first_step"] = first_step_ns < 0 ? 0.0 : cpu_s - first_step_cpu_s;
    s["wall_s_since_first_step"] = stepping_s;
    s["cpu_share_since_first_step"] =
        stepping_s > 0.0 ? (cpu_s - first_step_cpu_s) / stepping_s : 0.0;
  }
  s["grid_resolution"] = config.pipeline.grid_resolution;
  s["window_extent_m"] = config.pipeline.window_extent_m;
  s["max_window_extent_m"] = config.pipeline.max_window_extent_m;
  s["texture_threads"] = config.pipeline.texture_threads;
  s["rotation_gradient"] = ToString(config.pipeline.rotation_gradient);
  // The warm-up's count is the backend's it started with (not the CPU's it may have fallen to).
  s["linearization_missing_overlap"] =
      pipeline->faults().missing_overlap -
      (pipeline->backend_failures() == 0 ? warm_up_missing_overlap : 0);
  s["grazing_guard"] = config.pipeline.grazing_guard;
  s["kink_planes"] = config.pipeline.kink_planes;
  s["kink_hang_other_arm"] = config.pipeline.kink_hang_other_arm;
  s["parallax"] = config.pipeline.depth_refinement.parallax;
  s["refine_depth"] = config.pipeline.refine_depth;
  {
    // Stage 5b (issue 32), warm-up included: contacts refined, and per contact the seeds, the
    // evaluations of b − a and how far δ0 rose above the grid's; the conservative screen's
    // squares and leaves per contact, the contacts where it found a deeper point than the seeds
    // (and Σ µm), and those it stopped at its leaf budget; the translation arms added as kink
    // planes (DepthRefinementOptions::translation_kink_planes); the contacts given a translation
    // patch, and whether the option is on; the last step's seeds searched, the contacts where one
    // was deeper than the grid's seeds (and Σ µm), and whether they are on.
    const DepthRefinementCounters& r = pipeline->depth_refinement_counters();
    const double n = r.contacts > 0 ? static_cast<double>(r.contacts) : 1.0;
    s["depth_refinement"] = {
        {"contacts", r.contacts},
        {"seeds_per_contact", static_cast<double>(r.seeds) / n},
        {"evaluations_per_contact", static_cast<double>(r.evaluations) / n},
        {"depth_raised_um_mean", static_cast<double>(r.raised_um) / n},
        {"screen_squares_per_contact", static_cast<double>(r.screen_squares) / n},
        {"screen_leaves_per_contact", static_cast<double>(r.screen_leaves) / n},
        {"screen_found_deeper", r.screen_found},
        {"screen_raised_um_sum", r.screen_raised_um},
        {"screen_truncated", r.screen_truncated},
        {"translation_kink_planes", r.translation_kink_planes},
        {"translation_patches", r.translation_patches},
        {"translation_patch", config.pipeline.depth_refinement.translation_patch},
        {"last_step_seeds", r.last_step_seeds},
        {"last_step_found_deeper", r.last_step_found},
        {"last_step_raised_um_sum", r.last_step_raised_um},
        {"seed_from_last_step", config.pipeline.depth_refinement.seed_from_last_step},
        {"parallax_offset_seeds", r.parallax_offset_seeds},
        {"parallax_offset_found_deeper", r.parallax_offset_found},
        {"parallax_offset_raised_um_sum", r.parallax_offset_raised_um},
        {"neighbour_peak_seeds", r.neighbour_peak_seeds},
        {"neighbour_peak_found_deeper", r.neighbour_peak_found},
        {"neighbour_peak_raised_um_sum", r.neighbour_peak_raised_um}};
    // Whether the patches went by the operator's round trip (translation_patch_rtt_ms).
    s["translation_patch_by_rtt"] = {
        {"rtt_ms", std::isfinite(config.translation_patch_rtt_ms)
                       ? nlohmann::json(config.translation_patch_rtt_ms)
                       : nlohmann::json(nullptr)},
        {"operator_rtt_ms_last", static_cast<double>(session.operator_rtt_ns()) * 1e-6},
        {"steps_with_patch_on", steps_with_patch_on},
        {"on_at_end", pipeline->translation_patch()},
        {"switches", patch_switches}};
  }
  s["grazing_dropped_contacts"] = pipeline->step_faults().grazing_dropped;
  s["unreachable_pairs_dropped"] = pipeline->step_faults().unreachable_pairs;
  s["speculative_pairs"] = pipeline->step_faults().speculative_pairs;
  s["speculative_lead_ms"] = config.pipeline.speculative_lead_s * 1e3;
  s["speculative_floor"] = {{"speed_mm_per_s", config.speculative_speed_m_per_s * 1e3},
                            {"max_mm", config.max_speculative_floor_m * 1e3},
                            {"last_mm", pipeline->speculative_floor_m() * 1e3},
                            {"largest_mm", largest_speculative_floor_m * 1e3}};
  s["triangle_lists_overflowed"] = pipeline->step_faults().triangle_lists_overflowed;
  s["region_windows"] = pipeline->step_faults().region_windows;
  // Stage 5a (issue 32, thirty-first stop): asked for, and whether the backend at the end runs it
  // (the CPU texture stage does, the GPU backend does not).
  s["split"] = {{"on", config.pipeline.split_windows_at_separated_overlap},
                {"runs", config.pipeline.split_windows_at_separated_overlap &&
                             pipeline->backend().name() != "gpu"},
                {"link_mm", std::round(config.pipeline.split_link_m * 1e6) / 1e3},
                {"birth_ramp_um", std::round(config.pipeline.split_birth_ramp_m * 1e9) / 1e3},
                {"bridge_fade_um", std::round(config.pipeline.split_bridge_fade_m * 1e9) / 1e3}};
  s["share_connected_contacts"] = config.pipeline.share_connected_contacts;
  s["shared_contacts"] = pipeline->step_faults().shared_contacts;
  s["pd_backend"] = {{"requested", ToString(config.pd_backend)},
                     {"used", backend_at_start},
                     {"used_at_end", std::string(pipeline->backend().name())},
                     {"message", backend_message},
                     {"gl_renderer", gl_renderer},
                     {"gl_version", gl_version},
                     {"gl_vendor", gl_vendor},
                     {"depth_bits", gl_renderer.empty() ? 0 : config.gpu.depth_bits},
                     {"instanced_draws", gpu_instanced_draws},
                     {"failures", pipeline->backend_failures()},
                     {"fallback_reason", pipeline->fallback_reason()}};
  s["transport"] = session.StatsJson(config.scene_objects.size(), scene_bytes);
  s["transport"]["scene"]["reloads_switched"] = scene_reloads;
  s["transport"]["scene"]["reload_bytes_queued"] = reload_bytes;
  return s;
}

}  // namespace ht
