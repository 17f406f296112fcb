#include "slave_sim/remote_node.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <limits>
#include <optional>
#include <stdexcept>
#include <thread>
#include <vector>

#include "codecs/draco_mesh_codec.h"
#include "haptic_core/hull_proximity.h"
#include "haptic_core/procedural_models.h"
#include "haptic_core/statistics.h"
#include "haptic_core/steady_clock.h"
#include "transport/link.h"
#include "transport/messages.h"
#include "transport/scene_stream.h"
#include "transport/session.h"

namespace ht {
namespace {

std::int64_t NowNs() noexcept { return SteadyNowNs(); }

}  // namespace

std::vector<std::pair<std::uint32_t, std::vector<std::uint8_t>>> BlockOnGearSceneObjects() {
  std::vector<std::pair<std::uint32_t, std::vector<std::uint8_t>>> objects;
  objects.emplace_back(1, EncodeMeshDraco(MakeRidgedBlockFullResolution()));
  objects.emplace_back(2, EncodeMeshDraco(MakeRidgedGearFullResolution()));
  return objects;
}

wire::SceneLayout MakeSceneLayout(const HapticScene& scene) {
  wire::SceneLayout layout;
  layout.X_WT_home = scene.X_WT_home;
  if (scene.tool) {
    layout.tool_mass_kg = scene.tool->mass_kg;
    layout.tool_inertia_diagonal_T = scene.tool->inertia_diagonal_O;
    for (const glm::dvec3& p_T : scene.tool->vertices_O) {
      layout.tool_extent_down_m = std::max(layout.tool_extent_down_m, -p_T.z);
    }
  }
  const glm::dvec3 up_W = scene.X_WT_home.rotation * glm::dvec3(0.0, 0.0, 1.0);
  std::vector<std::pair<double, wire::WelcomeTarget>> all;
  for (const TouchableObject& object : scene.touchables) {
    if (!object.model || object.model->vertices_O.empty()) continue;
    wire::WelcomeTarget t;
    t.box_min_W = glm::dvec3(std::numeric_limits<double>::infinity());
    t.box_max_W = -t.box_min_W;
    double top = -std::numeric_limits<double>::infinity();
    for (const glm::dvec3& p_O : object.model->vertices_O) {
      const glm::dvec3 p_W = object.X_WO * p_O;
      t.box_min_W = glm::min(t.box_min_W, p_W);
      t.box_max_W = glm::max(t.box_max_W, p_W);
      if (glm::dot(p_W, up_W) > top) {
        top = glm::dot(p_W, up_W);
        t.top_W = p_W;
      }
    }
    // The textured surface reaches beyond the coarse mesh by up to the texture's outward reach.
    const double reach = object.model->OutwardReach();
    t.box_min_W -= glm::dvec3(reach);
    t.box_max_W += glm::dvec3(reach);
    all.emplace_back(glm::length(t.box_max_W - t.box_min_W), t);
  }
  std::stable_sort(all.begin(), all.end(),
                   [](const auto& a, const auto& b) { return a.first > b.first; });
  // Where the tool, centred over a target's top at the home orientation, touches nothing: from
  // just above the top (by the texture's reach, at most 2 cm, plus 1 cm) up in doubling steps,
  // checked with the coarse proximity query against every touchable at tolerance
  // min(reach, 2 cm) + 1 mm; the home height (clear of everything) at worst.
  HullProximityQuery query(16);
  const auto clear = [&](const RigidTransform& X_WT) {
    for (const TouchableObject& o : scene.touchables) {
      if (!o.model) continue;
      ProximityQueryOptions options;
      options.tolerance_m = std::min(o.model->OutwardReach(), 0.02) + 1e-3;
      options.max_pairs = 1;
      options.temporal_coherence = false;
      if (!query.Query(*scene.tool, X_WT, *o.model, o.X_WO, options).empty()) return false;
    }
    return true;
  };
  const double home_height = glm::dot(scene.X_WT_home.translation, up_W);
  for (const auto& [size, target] : all) {
    if (layout.num_targets >= wire::kMaxWelcomeTargets) break;
    wire::WelcomeTarget t = target;
    const double top = glm::dot(t.top_W, up_W);
    const double reach = glm::dot(t.box_max_W - t.top_W, up_W);  // ≈ the texture's reach
    double height = layout.tool_extent_down_m + std::clamp(reach, 0.0, 0.02) + 0.01;
    for (double step = 0.01; scene.tool && top + height < home_height; step *= 2.0) {
      RigidTransform X_WT = scene.X_WT_home;
      X_WT.translation = t.top_W + height * up_W;
      if (clear(X_WT)) break;
      height = std::min(height + step, home_height - top);
    }
    t.approach_m = std::max(0.0, height);
    layout.targets[layout.num_targets++] = t;
  }
  return layout;
}

nlohmann::json RunRemoteNode(const RemoteNodeConfig& config, const HapticScene& scene,
                             const std::atomic<bool>& stop) {
  config.pipeline.Validate();
  std::string backend_message;
  std::unique_ptr<PenetrationDepthBackend> backend = MakePenetrationDepthBackend(
      config.pd_backend, config.gpu, config.pipeline.grid_resolution, backend_message);
  std::string gl_renderer, gl_version, gl_vendor;
  if (auto* gpu = dynamic_cast<GpuPenetrationDepthBackend*>(backend.get())) {
    gl_renderer = gpu->info().renderer;
    gl_version = gpu->info().version;
    gl_vendor = gpu->info().vendor;
    gpu->Upload(*scene.tool);  // textures once per model, before the first step
    for (const TouchableObject& t : scene.touchables) gpu->Upload(*t.model);
  }
  std::printf("[slave] %s\n", backend_message.c_str());
  std::fflush(stdout);
  HapticTexturePipeline pipeline(scene, config.pipeline, std::move(backend));
  const std::string backend_at_start(pipeline.backend().name());
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
  for (const auto& [id, bytes] : config.scene_objects) {
    scene_sender.Update(id, bytes);
    scene_bytes += bytes.size();
  }
  RemoteCapabilities caps;
  caps.grid = static_cast<std::uint16_t>(config.pipeline.grid_resolution);
  caps.window_m = static_cast<float>(config.pipeline.window_extent_m);
  caps.mtu = static_cast<std::uint16_t>(config.mtu);
  caps.max_model_rate_hz = static_cast<float>(config.max_rate_hz);
  caps.peer_timeout_ms = static_cast<std::uint16_t>(config.peer_timeout_ms);
  caps.scene_objects = static_cast<std::uint16_t>(config.scene_objects.size());
  caps.scene_name = scene.name;
  caps.layout = MakeSceneLayout(scene);
  NonceHistory nonces;
  std::printf(
      "[slave] scene '%s': tool '%s', %zu touchable(s), %zu scene object(s) (%zu bytes); "
      "listening on %s (authenticated)\n",
      scene.name.c_str(), scene.tool->name.c_str(), scene.touchables.size(),
      config.scene_objects.size(), scene_bytes, bound.ToString().c_str());
  std::fflush(stdout);

  std::array<std::uint8_t, wire::kMaxDatagramBytes + 1> buffer{};
  std::uint64_t sessions = 0, goodbyes = 0, peers_lost = 0, hello_replayed = 0, rejects_sent = 0;
  std::uint64_t nacks_accepted = 0, nacks_ignored = 0;
  std::vector<double> step_us, collision_us, texture_us, contact_step_us;
  struct StepRecord {
    double t_s;
    StepTimings timings;
    int contacts;
  };
  std::vector<StepRecord> step_records;
  if (!config.step_trace_path.empty()) step_records.reserve(1 << 20);
  contact_step_us.reserve(1 << 20);
  step_us.reserve(1 << 20);
  collision_us.reserve(1 << 20);
  texture_us.reserve(1 << 20);

  std::uint32_t session = 0;
  std::uint64_t session_nonce = 0, hello_retransmits = 0, pending_nonce = 0, hello_deferred = 0;
  std::int64_t session_start_ns = 0;
  bool scene_enabled = false;
  wire::WelcomeMessage session_welcome;
  SocketAddress peer;
  std::int64_t peer_timeout_ns = 0, model_period_ns = 0, last_model_sent_ns = 0;
  bool have_state = false;
  std::uint64_t state_seq = 0;
  wire::ToolStateMessage latest;
  std::int64_t latest_send_time_ns = 0, latest_recv_ns = 0;
  std::uint64_t step_count = 0;
  int contacts_max = 0;
  const std::int64_t min_period_ns =
      config.max_rate_hz > 0.0 ? static_cast<std::int64_t>(1e9 / config.max_rate_hz) : 0;
  const std::int64_t start_ns = NowNs();
  std::int64_t first_step_ns = 0, last_step_ns = 0;
  std::int64_t last_progress_ns = start_ns;
  std::uint64_t last_progress_steps = 0;
  bool running = true;
  std::int64_t max_gap_ns = 0;
  bool reported_fallback = false;
  double scene_tokens = 0.0;
  std::int64_t last_token_ns = start_ns, last_manifest_ns = 0;
  const double token_cap =
      std::max(16.0 * wire::kMaxDatagramBytes, config.scene_rate_bytes_per_s * 0.01);

  const auto send_manifest = [&] {
    if (!scene_enabled) return;
    for (const wire::SceneManifestMessage& m : scene_sender.Manifest()) {
      link.Send(wire::EncodeSceneManifest(
                    link.NextHeader(wire::MessageType::kSceneManifest, session), m, config.key),
                peer);
    }
    last_manifest_ns = NowNs();
  };
  const auto close_session = [&](const char* why) {
    std::printf("[slave] session %08x closed: %s\n", session, why);
    std::fflush(stdout);
    session = 0;
    have_state = false;
  };

  while (running && !stop.load(std::memory_order_relaxed)) {
    SocketAddress from;
    // At most kDrainPerPass datagrams between steps: a flood delays steps, never stops them.
    constexpr int kDrainPerPass = 256;
    int drained = 0;
    std::optional<std::size_t> n;
    while (drained++ < kDrainPerPass && (n = socket.ReceiveFrom(buffer, from))) {
      const std::int64_t now = NowNs();
      wire::Header header;
      std::span<const std::uint8_t> body;
      bool late = false;
      const std::span<const std::uint8_t> datagram(buffer.data(), std::min(*n, buffer.size()));
      if (link.Open(datagram, session, header, body, late) != wire::DecodeStatus::kOk) continue;
      switch (header.type) {
        case wire::MessageType::kHello: {
          wire::HelloMessage hello;
          if (const auto st = wire::DecodeHello(body, hello); st != wire::DecodeStatus::kOk) {
            link.CountBodyRejected(header.type, st);
            break;
          }
          const bool live =
              session != 0 &&
              now - std::max(link.last_authenticated_ns(), session_start_ns) < peer_timeout_ns;
          if (session != 0 && hello.client_nonce == session_nonce) {
            // The operator retransmitted its Hello before our Welcome reached it (round trip
            // longer than its retry period): the same session, welcomed again (to the session's
            // address only).
            ++hello_retransmits;
            session_start_ns = now;  // an authenticated sign of life of this session's operator
            link.Send(wire::EncodeWelcome(link.NextHeader(wire::MessageType::kWelcome, session),
                                          session_welcome, config.key),
                      peer);
            break;
          }
          if (pending_nonce != 0 && hello.client_nonce == pending_nonce) {
            if (live) {  // still deferred: the current operator is active
              ++hello_deferred;
              break;
            }
          } else {
            if (!nonces.Insert(hello.client_nonce)) {  // a recorded Hello played again
              ++hello_replayed;
              link.CountBodyRejected(header.type, wire::DecodeStatus::kReplayed);
              break;
            }
            if (live) {
              // Another operator (or a recorded Hello this node never saw) while the current one
              // is active: deferred until the current session ends or goes silent, so that a
              // replayed Hello cannot take a live session over. The operator keeps retrying.
              pending_nonce = hello.client_nonce;
              ++hello_deferred;
              break;
            }
          }
          pending_nonce = 0;
          wire::WelcomeMessage welcome;
          wire::RejectMessage reject;
          if (!NegotiateSession(hello, caps, welcome, reject)) {
            ++rejects_sent;
            link.Send(wire::EncodeReject(link.NextHeader(wire::MessageType::kReject, 0), reject,
                                         config.key),
                      from);
            std::printf("[slave] refused operator at %s: %.*s\n", from.ToString().c_str(),
                        static_cast<int>(reject.text_length), reject.text.data());
            std::fflush(stdout);
            break;
          }
          if (session != 0) close_session("replaced by a new session");
          std::uint32_t id = RandomSessionId();
          while (id == session) id = RandomSessionId();
          link.ResetSession();
          session = id;
          session_nonce = hello.client_nonce;
          peer = from;
          ++sessions;
          peer_timeout_ns = std::int64_t{welcome.peer_timeout_ms} * 1000000;
          model_period_ns = welcome.model_rate_hz > 0.0f
                                ? static_cast<std::int64_t>(1e9 / welcome.model_rate_hz)
                                : 0;
          try {
            scene_sender.SetMtu(welcome.mtu);
          } catch (const std::invalid_argument& e) {
            std::printf("[slave] scene not streamed at MTU %u: %s\n", welcome.mtu, e.what());
            welcome.scene_objects = 0;
          }
          scene_enabled = welcome.scene_objects > 0;
          if (scene_enabled) scene_sender.QueueAll();
          scene_tokens = 0.0;
          session_start_ns = now;
          session_welcome = welcome;
          link.Send(wire::EncodeWelcome(link.NextHeader(wire::MessageType::kWelcome, session),
                                        welcome, config.key),
                    peer);
          send_manifest();
          std::printf(
              "[slave] session %08x opened for operator at %s (protocol v%u, mtu %u, grid %u, "
              "peer timeout %u ms)\n",
              session, from.ToString().c_str(), welcome.version, welcome.mtu, welcome.grid,
              welcome.peer_timeout_ms);
          std::fflush(stdout);
          break;
        }
        case wire::MessageType::kToolState: {
          wire::ToolStateMessage message;
          if (const auto st = wire::DecodeToolState(body, message); st != wire::DecodeStatus::kOk) {
            link.CountBodyRejected(header.type, st);
            break;
          }
          if (late) break;  // newest wins: a newer tool state is already in hand
          peer = from;      // authenticated: follow the operator if its address changed
          latest = message;
          state_seq = header.sequence;
          latest_send_time_ns = header.send_time_ns;
          if (latest_recv_ns != 0 && have_state)
            max_gap_ns = std::max(max_gap_ns, now - latest_recv_ns);
          latest_recv_ns = now;
          have_state = true;
          break;
        }
        case wire::MessageType::kPing: {
          if (const auto st = wire::DecodeEmpty(body); st != wire::DecodeStatus::kOk) {
            link.CountBodyRejected(header.type, st);
            break;
          }
          wire::PongMessage pong{header.sequence, header.send_time_ns, now};
          link.Send(wire::EncodePong(link.NextHeader(wire::MessageType::kPong, session), pong,
                                     config.key),
                    peer);
          break;
        }
        case wire::MessageType::kSceneNack: {
          wire::SceneNackMessage nack;
          if (const auto st = wire::DecodeSceneNack(body, nack); st != wire::DecodeStatus::kOk) {
            link.CountBodyRejected(header.type, st);
            break;
          }
          if (scene_sender.OnNack(nack)) {
            ++nacks_accepted;
          } else {
            ++nacks_ignored;
          }
          break;
        }
        case wire::MessageType::kGoodbye: {
          if (wire::DecodeEmpty(body) != wire::DecodeStatus::kOk) {
            link.CountBodyRejected(header.type, wire::DecodeStatus::kTooLong);
            break;
          }
          ++goodbyes;
          close_session("the operator said goodbye");
          if (config.exit_on_goodbye) running = false;
          break;
        }
        default:
          break;  // Open() refuses every other type on this side
      }
    }
    if (!running) break;
    const std::int64_t now_loop = NowNs();
    const std::int64_t last_heard = std::max(link.last_authenticated_ns(), session_start_ns);
    if (session != 0 && now_loop - last_heard > peer_timeout_ns) {
      ++peers_lost;
      char why[96];
      std::snprintf(why, sizeof(why), "operator lost (nothing authenticated for %.0f ms)",
                    (now_loop - last_heard) * 1e-6);
      close_session(why);
    }
    if (session == 0) {
      socket.WaitReadable(50);
      continue;
    }
    // Scene fragments, paced, and the manifest every 250 ms.
    scene_tokens = std::min(token_cap, scene_tokens + config.scene_rate_bytes_per_s *
                                                          (now_loop - last_token_ns) * 1e-9);
    last_token_ns = now_loop;
    wire::SceneFragmentMessage fragment;
    while (scene_tokens > 0.0 && scene_sender.Next(fragment)) {
      const wire::Datagram d = wire::EncodeSceneFragment(
          link.NextHeader(wire::MessageType::kSceneFragment, session), fragment, config.key);
      link.Send(d, peer);
      scene_tokens -= static_cast<double>(d.size);
    }
    if (now_loop - last_manifest_ns > 250000000) send_manifest();
    if (!have_state) {
      socket.WaitReadable(1);
      continue;
    }
    const std::int64_t t_step = NowNs();
    if (config.animate) config.animate(static_cast<double>(t_step - start_ns) * 1e-9);
    StepTimings timings;
    wire::ContactModelMessage out;
    out.model = pipeline.Step(latest.X_WT, state_seq, timings);
    if (pipeline.backend_failures() == 1 && !reported_fallback) {
      reported_fallback = true;
      std::printf("[slave] GPU penetration depth failed (%s); continuing on the CPU reference\n",
                  pipeline.fallback_reason().c_str());
      std::fflush(stdout);
    }
    ++step_count;
    if (first_step_ns == 0) first_step_ns = t_step;
    last_step_ns = NowNs();
    contacts_max = std::max(contacts_max, out.model.num_contacts);
    if (step_us.size() < step_us.capacity()) step_us.push_back(timings.total_us);
    if (out.model.num_contacts > 0 && contact_step_us.size() < contact_step_us.capacity()) {
      contact_step_us.push_back(timings.total_us);  // percentiles over the first 2^20 samples
    }
    if (collision_us.size() < collision_us.capacity()) collision_us.push_back(timings.collision_us);
    if (texture_us.size() < texture_us.capacity()) texture_us.push_back(timings.texture_us);
    if (step_records.size() < step_records.capacity()) {
      step_records.push_back(
          {static_cast<double>(t_step - start_ns) * 1e-9, timings, out.model.num_contacts});
    }
    if (model_period_ns == 0 || last_step_ns - last_model_sent_ns >= model_period_ns) {
      out.tool_state_send_time_ns = latest_send_time_ns;
      out.remote_step_count = step_count;
      out.collision_us = static_cast<float>(timings.collision_us);
      out.texture_us = static_cast<float>(timings.texture_us);
      out.step_us = static_cast<float>(timings.total_us);
      wire::Header header = link.NextHeader(wire::MessageType::kContactModel, session);
      out.hold_ns = header.send_time_ns - latest_recv_ns;
      link.Send(wire::EncodeContactModel(header, out, config.key), peer);
      last_model_sent_ns = last_step_ns;
    }
    const std::int64_t now = NowNs();
    if (config.progress_period_s > 0.0 &&
        (now - last_progress_ns) * 1e-9 >= config.progress_period_s) {
      const double dt = (now - last_progress_ns) * 1e-9;
      std::printf(
          "[slave] %6.0f steps/s  step %6.0f us (collision %4.0f, texture %6.0f)  "
          "contacts %d  tool states %llu  rejected %llu\n",
          (step_count - last_progress_steps) / dt, timings.total_us, timings.collision_us,
          timings.texture_us, out.model.num_contacts,
          static_cast<unsigned long long>(link.stats(wire::MessageType::kToolState).received),
          static_cast<unsigned long long>(link.rejected_total()));
      std::fflush(stdout);
      last_progress_ns = now;
      last_progress_steps = step_count;
    }
    if (min_period_ns > 0) {
      const std::int64_t wait = t_step + min_period_ns - NowNs();
      if (wait > 0) std::this_thread::sleep_for(std::chrono::nanoseconds(wait));
    }
  }
  if (session != 0 &&
      config.goodbye_on_stop) {  // stopped: tell the operator, which reconnects at once
    for (int i = 0; i < 3; ++i) {
      link.Send(
          wire::EncodeGoodbye(link.NextHeader(wire::MessageType::kGoodbye, session), config.key),
          peer);
    }
  }
  if (!config.step_trace_path.empty()) {
    std::FILE* f = std::fopen(config.step_trace_path.c_str(), "w");
    if (f == nullptr) throw std::runtime_error("cannot write " + config.step_trace_path);
    std::fputs(
        "step,t_s,leaf_pairs,clusters,contacts,broad_phase_culled,collision_us,texture_us,"
        "total_us,budget_exhausted\n",
        f);
    for (std::size_t i = 0; i < step_records.size(); ++i) {
      const StepRecord& r = step_records[i];
      std::fprintf(f, "%zu,%.6f,%d,%d,%d,%d,%.2f,%.2f,%.2f,%d\n", i + 1, r.t_s,
                   r.timings.leaf_pairs, r.timings.clusters, r.contacts,
                   r.timings.broad_phase_culled, r.timings.collision_us, r.timings.texture_us,
                   r.timings.total_us, r.timings.collision_budget_exhausted ? 1 : 0);
    }
    if (std::fclose(f) != 0) throw std::runtime_error("cannot write " + config.step_trace_path);
  }
  nlohmann::json s;
  s["scene"] = scene.name;
  s["listen"] = bound.ToString();
  s["steps"] = step_count;
  s["rate_hz"] = last_step_ns > first_step_ns
                     ? (step_count - 1) / ((last_step_ns - first_step_ns) * 1e-9)
                     : 0.0;
  s["step_p50_us"] = Percentile(step_us, 0.5);
  s["step_p99_us"] = Percentile(step_us, 0.99);
  s["step_max_us"] = Percentile(step_us, 1.0);
  s["steps_in_contact"] = contact_step_us.size();
  s["step_in_contact_p50_us"] = Percentile(contact_step_us, 0.5);
  s["step_in_contact_p99_us"] = Percentile(contact_step_us, 0.99);
  s["collision_max_us"] = Percentile(collision_us, 1.0);
  s["texture_max_us"] = Percentile(texture_us, 1.0);
  s["slow_steps_over_5ms"] =
      std::count_if(step_us.begin(), step_us.end(), [](double v) { return v > 5000.0; });
  s["tool_state_gap_max_ms"] = max_gap_ns * 1e-6;
  s["collision_p50_us"] = Percentile(collision_us, 0.5);
  s["texture_p50_us"] = Percentile(texture_us, 0.5);
  s["texture_p99_us"] = Percentile(texture_us, 0.99);
  s["contacts_max"] = contacts_max;
  s["grid_resolution"] = config.pipeline.grid_resolution;
  s["window_extent_m"] = config.pipeline.window_extent_m;
  s["linearization_missing_overlap"] = pipeline.faults().missing_overlap;
  s["pd_backend"] = {{"requested", ToString(config.pd_backend)},
                     {"used", backend_at_start},
                     {"used_at_end", std::string(pipeline.backend().name())},
                     {"message", backend_message},
                     {"gl_renderer", gl_renderer},
                     {"gl_version", gl_version},
                     {"gl_vendor", gl_vendor},
                     {"depth_bits", gl_renderer.empty() ? 0 : config.gpu.depth_bits},
                     {"failures", pipeline.backend_failures()},
                     {"fallback_reason", pipeline.fallback_reason()}};
  nlohmann::json transport = link.StatsJson();
  transport["sessions"] = sessions;
  transport["goodbyes"] = goodbyes;
  transport["peers_lost"] = peers_lost;
  transport["hello_replayed"] = hello_replayed;
  transport["hello_retransmits"] = hello_retransmits;
  transport["hello_deferred"] = hello_deferred;
  transport["rejects_sent"] = rejects_sent;
  transport["mtu"] = config.mtu;
  transport["scene"] = {{"objects", config.scene_objects.size()},
                        {"bytes", scene_bytes},
                        {"fragment_payload_bytes", scene_sender.payload_bytes()},
                        {"nacks_accepted", nacks_accepted},
                        {"nacks_ignored", nacks_ignored},
                        {"fragments_queued_at_end", scene_sender.queued()}};
  s["transport"] = transport;
  return s;
}

}  // namespace ht
