#include "slave_sim/remote_node.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <stdexcept>
#include <thread>
#include <vector>

#include "haptic_core/statistics.h"
#include "transport/messages.h"

namespace ht {
namespace {

std::int64_t NowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

}  // namespace

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
  std::printf("[slave] scene '%s': tool '%s', %zu touchable(s); listening on %s\n",
              scene.name.c_str(), scene.tool->name.c_str(), scene.touchables.size(),
              bound.ToString().c_str());
  std::fflush(stdout);

  std::array<std::uint8_t, wire::kMaxDatagramBytes + 1> buffer{};
  std::uint64_t received = 0, accepted = 0, stale = 0, lost = 0, malformed = 0, goodbyes = 0,
                sessions = 0, bytes_received = 0;
  std::array<std::uint64_t, 16> malformed_by_reason{};
  std::uint64_t models_sent = 0, send_failed = 0, bytes_sent = 0;
  std::vector<double> step_us, collision_us, texture_us, contact_step_us;
  contact_step_us.reserve(1 << 20);
  step_us.reserve(1 << 20);
  collision_us.reserve(1 << 20);
  texture_us.reserve(1 << 20);

  bool have_peer = false;
  SocketAddress peer;
  std::uint32_t session = 0;
  std::uint64_t last_seq = 0;
  wire::ToolStateMessage latest;
  std::int64_t latest_send_time_ns = 0, latest_recv_ns = 0;
  std::uint64_t step_count = 0, model_seq = 0;
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

  while (running && !stop.load(std::memory_order_relaxed)) {
    SocketAddress from;
    while (auto n = socket.ReceiveFrom(buffer, from)) {
      ++received;
      bytes_received += *n;
      const std::int64_t now = NowNs();
      wire::Header header;
      wire::DecodeStatus status = *n > wire::kMaxDatagramBytes
                                      ? wire::DecodeStatus::kTooLong
                                      : wire::DecodeHeader({buffer.data(), *n}, header);
      wire::ToolStateMessage message;
      if (status == wire::DecodeStatus::kOk && header.type == wire::MessageType::kToolState) {
        status = wire::DecodeToolState({buffer.data(), *n}, header, message);
      } else if (status == wire::DecodeStatus::kOk &&
                 header.type == wire::MessageType::kContactModel) {
        status = wire::DecodeStatus::kUnknownType;  // not a message this side accepts
      }
      if (status != wire::DecodeStatus::kOk) {
        ++malformed;
        ++malformed_by_reason[static_cast<int>(status)];
        continue;
      }
      if (header.type == wire::MessageType::kGoodbye) {
        if (have_peer && header.session_id == session && from == peer) {
          ++goodbyes;
          if (config.exit_on_goodbye) running = false;
        }
        continue;
      }
      if (!have_peer || header.session_id != session) {  // a new operator session
        have_peer = true;
        peer = from;
        session = header.session_id;
        last_seq = 0;
        ++sessions;
        std::printf("[slave] operator session %08x from %s\n", session, from.ToString().c_str());
        std::fflush(stdout);
      }
      if (header.sequence <= last_seq) {
        ++stale;
        continue;
      }
      if (last_seq != 0) lost += header.sequence - last_seq - 1;
      last_seq = header.sequence;
      ++accepted;
      latest = message;
      latest_send_time_ns = header.send_time_ns;
      if (latest_recv_ns != 0) max_gap_ns = std::max(max_gap_ns, now - latest_recv_ns);
      latest_recv_ns = now;
    }
    if (!running) break;
    if (!have_peer) {
      socket.WaitReadable(50);
      continue;
    }
    const std::int64_t t_step = NowNs();
    StepTimings timings;
    wire::ContactModelMessage out;
    out.model = pipeline.Step(latest.X_WT, last_seq, timings);
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
    step_us.push_back(timings.total_us);
    if (out.model.num_contacts > 0) contact_step_us.push_back(timings.total_us);
    collision_us.push_back(timings.collision_us);
    texture_us.push_back(timings.texture_us);
    out.tool_state_send_time_ns = latest_send_time_ns;
    out.remote_step_count = step_count;
    out.collision_us = static_cast<float>(timings.collision_us);
    out.texture_us = static_cast<float>(timings.texture_us);
    out.step_us = static_cast<float>(timings.total_us);
    wire::Header header;
    header.session_id = session;
    header.sequence = ++model_seq;
    header.send_time_ns = NowNs();
    out.hold_ns = header.send_time_ns - latest_recv_ns;
    const wire::Datagram d = wire::EncodeContactModel(header, out);
    if (socket.SendTo(d.view(), peer)) {
      ++models_sent;
      bytes_sent += d.size;
    } else {
      ++send_failed;
    }
    const std::int64_t now = NowNs();
    if (config.progress_period_s > 0.0 &&
        (now - last_progress_ns) * 1e-9 >= config.progress_period_s) {
      const double dt = (now - last_progress_ns) * 1e-9;
      std::printf(
          "[slave] %6.0f steps/s  step %6.0f us (collision %4.0f, texture %6.0f)  "
          "contacts %d  tool states %llu\n",
          (step_count - last_progress_steps) / dt, timings.total_us, timings.collision_us,
          timings.texture_us, out.model.num_contacts, static_cast<unsigned long long>(accepted));
      std::fflush(stdout);
      last_progress_ns = now;
      last_progress_steps = step_count;
    }
    if (min_period_ns > 0) {
      const std::int64_t wait = t_step + min_period_ns - NowNs();
      if (wait > 0) std::this_thread::sleep_for(std::chrono::nanoseconds(wait));
    }
  }

  nlohmann::json reasons = nlohmann::json::object();
  for (int i = 1; i < 16; ++i) {
    if (malformed_by_reason[i]) {
      reasons[wire::ToString(static_cast<wire::DecodeStatus>(i))] = malformed_by_reason[i];
    }
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
  s["sessions"] = sessions;
  s["datagrams"]["tool_state"] = {
      {"received", received},           {"accepted", accepted},
      {"dropped_stale", stale},         {"lost", lost},
      {"dropped_malformed", malformed}, {"dropped_malformed_by_reason", reasons},
      {"goodbyes", goodbyes},           {"bytes_received", bytes_received}};
  s["datagrams"]["contact_model"] = {
      {"sent", models_sent}, {"send_failed", send_failed}, {"bytes_sent", bytes_sent}};
  return s;
}

}  // namespace ht
