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
#include <mutex>
#include <optional>
#include <stdexcept>
#include <thread>
#include <vector>

#include "codecs/draco_mesh_codec.h"
#include "haptic_core/passivity.h"
#include "haptic_core/statistics.h"
#include "haptic_core/wrench_safety.h"
#include "master_station/operator_tick.h"
#include "master_station/lock_free.h"
#include "transport/link.h"
#include "transport/messages.h"
#include "transport/scene_stream.h"
#include "transport/session.h"
#include "haptic_core/steady_clock.h"

namespace ht {
namespace {

std::int64_t NowNs() noexcept { return SteadyNowNs(); }

void SleepUntilNs(std::int64_t t_ns) noexcept {
  timespec ts{static_cast<time_t>(t_ns / 1000000000), static_cast<long>(t_ns % 1000000000)};
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
  }
}

struct OutgoingToolState {
  wire::ToolStateMessage message;
  std::int64_t time_ns = 0;
  std::uint64_t sequence = 0;
};

struct IncomingModel {
  wire::ContactModelMessage message;
  std::uint64_t sequence = 0;
  std::int64_t built_local_ns = 0;  ///< when the remote node sent it, on the local clock
};

/// One row of trace.csv (one per tick), filled by the loop and written by the recorder thread.
struct TraceRow {
  double t_s = 0.0;
  int phase = 0;
  RigidTransform X_WT;
  Wrench F_contact_T_W;
  int contacts = 0;
  double model_age_ms = -1.0;
  glm::dvec3 p_WH{0.0};
  Wrench F_device_W;
  double depth_m = 0.0;
  float tick_compute_us = 0.0f;
  float remote_collision_us = 0.0f;
  float remote_texture_us = 0.0f;
  float remote_step_us = 0.0f;
};

struct Counters {
  std::atomic<std::uint64_t> model_accepted{0};
  std::atomic<bool> connected{false};
  std::atomic<bool> rejected{false};
};

/// Exchanges datagrams with the remote node; runs on its own thread. Owns the session: Hello until
/// Welcome, Ping every heartbeat (clock offset and round-trip time), loss of the remote node after
/// the peer timeout and a new Hello every reconnect period until it answers; reassembles and
/// repairs the scene stream.
class NetworkWorker {
 public:
  NetworkWorker(const StationConfig& config, TripleBuffer<OutgoingToolState>& outgoing,
                TripleBuffer<IncomingModel>& incoming, Counters& counters)
      : config_(config),
        socket_(config.local_address),
        link_(socket_, config.key, LinkRole::kOperator),
        reassembler_(config.mtu),
        outgoing_(outgoing),
        incoming_(incoming),
        counters_(counters) {
    rtt_ms_.reserve(1 << 20);
    one_way_ms_.reserve(1 << 20);
    remote_step_us_.reserve(1 << 20);
    contact_step_us_.reserve(1 << 20);
    collision_us_.reserve(1 << 20);
    texture_us_.reserve(1 << 20);
    clock_.Reserve(1 << 16);
  }

  void Run(const std::atomic<bool>& stop) {
    std::array<std::uint8_t, wire::kMaxDatagramBytes + 1> buffer{};
    OutgoingToolState last{};
    bool have_last = false;
    std::int64_t last_send_ns = 0, last_hello_ns = 0, last_ping_ns = 0;
    while (!stop.load(std::memory_order_acquire)) {
      socket_.WaitReadable(0);
      timespec pause{0, 200000};  // 0.2 ms between polls: bounded latency, little CPU
      nanosleep(&pause, nullptr);
      SocketAddress from;
      // At most kDrainPerPass datagrams per pass: a flood delays this thread's other duties
      // (tool states, pings), never stops them.
      constexpr int kDrainPerPass = 256;
      int drained = 0;
      std::optional<std::size_t> n;
      while (drained++ < kDrainPerPass && (n = socket_.ReceiveFrom(buffer, from))) {
        Handle({buffer.data(), std::min(*n, buffer.size())}, from);
      }
      const std::int64_t now = SteadyNowNs();
      const std::int64_t last_heard = std::max(link_.last_authenticated_ns(), session_start_ns_);
      if (session_ != 0 && now - last_heard > peer_timeout_ns_) {
        ++peers_lost_;
        loss_detected_after_ms_.push_back((now - last_heard) * 1e-6);
        std::printf("[master] remote node lost (nothing authenticated for %.0f ms); reconnecting\n",
                    (now - last_heard) * 1e-6);
        std::fflush(stdout);
        EndSession();
      }
      if (session_ == 0) {
        if (counters_.rejected.load()) break;
        if (hello_nonce_ != 0 &&
            now - attempt_start_ns_ > 2LL * config_.peer_timeout_ms * 1000000LL) {
          hello_nonce_ = 0;  // no Welcome for two peer timeouts: a new attempt, with a new nonce
        }
        if (now - last_hello_ns >= config_.reconnect_period_ms * 1000000LL) {
          SendHello();
          last_hello_ns = now;
        }
        OutgoingToolState state;
        if (outgoing_.Read(state)) {
          last = state;
          have_last = true;
        }
        continue;
      }
      OutgoingToolState state;
      if (outgoing_.Read(state)) {
        last = state;
        have_last = true;
        Send(state);
        last_send_ns = now;
      } else if (have_last && now - last_send_ns > 20000000) {
        // Keep-alive while the loop is not running (before the first tick, after the last): the
        // same pose, stamped now, so that round trips measured on it are not inflated.
        last.time_ns = now;
        Send(last);
        last_send_ns = now;
      }
      if (now - last_ping_ns >= heartbeat_ns_) {
        link_.Send(
            wire::EncodePing(link_.NextHeader(wire::MessageType::kPing, session_), config_.key),
            config_.remote_address);
        last_ping_ns = now;
      }
      const std::int64_t quiet = std::max<std::int64_t>(30000000, 2 * clock_.rtt_ns());
      reassembler_.CollectNacks(now, quiet, [&](const wire::SceneNackMessage& nack) {
        link_.Send(wire::EncodeSceneNack(link_.NextHeader(wire::MessageType::kSceneNack, session_),
                                         nack, config_.key),
                   config_.remote_address);
      });
    }
    if (session_ != 0) {
      const wire::Datagram d =
          wire::EncodeGoodbye(link_.NextHeader(wire::MessageType::kGoodbye, session_), config_.key);
      link_.Send(d, config_.remote_address);
      // Retries carry new sequence numbers (a copy of the same datagram would be a replay).
      for (int i = 0; i < 2; ++i) {
        link_.Send(wire::EncodeGoodbye(link_.NextHeader(wire::MessageType::kGoodbye, session_),
                                       config_.key),
                   config_.remote_address);
      }
    }
  }

  const std::vector<double>& rtt_ms() const { return rtt_ms_; }
  const std::vector<double>& one_way_ms() const { return one_way_ms_; }
  const std::vector<double>& remote_step_us() const { return remote_step_us_; }
  const std::vector<double>& contact_step_us() const { return contact_step_us_; }
  const std::vector<double>& collision_us() const { return collision_us_; }
  const std::vector<double>& texture_us() const { return texture_us_; }
  double RemoteRateHz() const {
    if (last_remote_ns_ <= first_remote_ns_) return 0.0;
    return static_cast<double>(last_remote_steps_ - first_remote_steps_) /
           ((last_remote_ns_ - first_remote_ns_) * 1e-9);
  }
  SocketAddress local_address() const { return socket_.local_address(); }
  const std::string& reject_text() const { return reject_text_; }
  /// The scene layout of the last Welcome (read once the session is connected).
  wire::SceneLayout layout() const {
    std::lock_guard<std::mutex> lock(layout_mutex_);
    return layout_;
  }
  std::uint64_t rejected_total() const { return link_.rejected_total(); }

  /// The transport's part of summary.json (call after the thread has stopped).
  nlohmann::json Summary() const {
    nlohmann::json t = link_.StatsJson();
    t["sessions"] = sessions_;
    t["peers_lost"] = peers_lost_;
    t["peer_lost_detected_after_ms"] = loss_detected_after_ms_;
    t["remote_goodbyes"] = remote_goodbyes_;
    t["hellos_sent"] = hellos_sent_;
    t["mtu"] = mtu_;
    t["scene_name"] = scene_name_;
    t["clock"] = {{"samples", clock_.rtt_ms_samples().size()},
                  {"offset_ms", clock_.offset_ns() * 1e-6},
                  {"offset_uncertainty_ms", clock_.rtt_ns() * 0.5e-6},
                  {"rtt_ms_p50", Percentile(clock_.rtt_ms_samples(), 0.5)},
                  {"rtt_ms_p99", Percentile(clock_.rtt_ms_samples(), 0.99)}};
    t["streams"]["contact_model"]["rtt_ms_p50"] = Percentile(rtt_ms_, 0.5);
    t["streams"]["contact_model"]["rtt_ms_p99"] = Percentile(rtt_ms_, 0.99);
    t["streams"]["contact_model"]["one_way_ms_p50"] = Percentile(one_way_ms_, 0.5);
    t["streams"]["contact_model"]["one_way_ms_p99"] = Percentile(one_way_ms_, 0.99);
    const ReassemblyStats& r = reassembler_.stats();
    nlohmann::json objects = nlohmann::json::array();
    for (const auto& o : scene_objects_) objects.push_back(o);
    t["scene"] = {{"announced_objects", expected_objects_},
                  {"manifest_objects", reassembler_.manifest_objects()},
                  {"verified_objects", reassembler_.verified_objects()},
                  {"complete", scene_complete_},
                  {"complete_after_ms", scene_complete_ms_},
                  {"bytes_held", reassembler_.bytes_held()},
                  {"fragments_accepted", r.fragments_accepted},
                  {"fragments_duplicate", r.fragments_duplicate},
                  {"fragments_stale", r.fragments_stale},
                  {"fragments_inconsistent", r.fragments_inconsistent},
                  {"fragments_over_limit", r.fragments_over_limit},
                  {"objects_completed", r.objects_completed},
                  {"objects_superseded", r.objects_superseded},
                  {"digest_mismatches", r.digest_mismatches},
                  {"nacks_sent", r.nacks_sent},
                  {"fragments_nacked", r.fragments_nacked},
                  {"decoded", objects}};
    return t;
  }

 private:
  /// Sends (or resends) the Hello of the current connection attempt. One attempt keeps its nonce
  /// over retransmissions, so that a round trip longer than the reconnect period still completes:
  /// the remote node answers a repeated nonce with the same session.
  void SendHello() {
    if (hello_nonce_ == 0) {  // a new attempt
      link_.ResetSession();
      hello_nonce_ = RandomNonce();
      attempt_start_ns_ = SteadyNowNs();
    }
    wire::HelloMessage hello;
    hello.client_nonce = hello_nonce_;
    hello.tool_state_rate_hz = static_cast<float>(config_.loop_rate_hz);
    hello.max_grid = static_cast<std::uint16_t>(config_.max_grid);
    hello.max_model_rate_hz = static_cast<float>(
        config_.max_model_rate_hz > 0.0 ? config_.max_model_rate_hz : config_.loop_rate_hz);
    hello.mtu = static_cast<std::uint16_t>(config_.mtu);
    hello.heartbeat_ms = static_cast<std::uint16_t>(config_.heartbeat_ms);
    hello.peer_timeout_ms = static_cast<std::uint16_t>(config_.peer_timeout_ms);
    link_.Send(
        wire::EncodeHello(link_.NextHeader(wire::MessageType::kHello, 0), hello, config_.key),
        config_.remote_address);
    ++hellos_sent_;
  }

  void EndSession() {
    session_ = 0;
    counters_.connected.store(false);
  }

  void Handle(std::span<const std::uint8_t> datagram, const SocketAddress& from) {
    const std::int64_t now = SteadyNowNs();
    wire::Header header;
    std::span<const std::uint8_t> body;
    bool late = false;
    if (link_.Open(datagram, session_, header, body, late) != wire::DecodeStatus::kOk) return;
    (void)from;
    switch (header.type) {
      case wire::MessageType::kWelcome: {
        wire::WelcomeMessage w;
        if (const auto st = wire::DecodeWelcome(body, w); st != wire::DecodeStatus::kOk) {
          link_.CountBodyRejected(header.type, st);
          return;
        }
        if (session_ != 0 || w.client_nonce != hello_nonce_ || header.session_id == 0) {
          link_.CountBodyRejected(header.type, wire::DecodeStatus::kUnexpected);
          return;  // an answer to an older Hello, or a replay
        }
        link_.ResetSession();
        session_ = header.session_id;
        ++sessions_;
        hello_nonce_ = 0;  // the next attempt (after a loss) gets a new nonce
        mtu_ = w.mtu;
        heartbeat_ns_ = std::int64_t{w.heartbeat_ms} * 1000000;
        peer_timeout_ns_ = std::int64_t{w.peer_timeout_ms} * 1000000;
        expected_objects_ = w.scene_objects;
        scene_name_ = std::string(w.name());
        {
          std::lock_guard<std::mutex> lock(layout_mutex_);
          layout_ = w.layout;
        }
        reassembler_.Reset(w.mtu);
        scene_complete_ = false;
        scene_objects_.clear();
        session_start_ns_ = now;
        clock_.Reset();
        counters_.connected.store(true);
        std::printf(
            "[master] session %08x with remote node %s: scene '%s' (%u objects), grid %u, "
            "window %.3f m, mtu %u, protocol v%u\n",
            session_, config_.remote_address.ToString().c_str(), scene_name_.c_str(),
            w.scene_objects, w.grid, static_cast<double>(w.window_m), w.mtu, w.version);
        std::fflush(stdout);
        return;
      }
      case wire::MessageType::kReject: {
        wire::RejectMessage r;
        if (const auto st = wire::DecodeReject(body, r); st != wire::DecodeStatus::kOk) {
          link_.CountBodyRejected(header.type, st);
          return;
        }
        if (session_ != 0 || r.client_nonce != hello_nonce_) {
          link_.CountBodyRejected(header.type, wire::DecodeStatus::kUnexpected);
          return;
        }
        reject_text_ = std::string(r.message());
        counters_.rejected.store(true);
        return;
      }
      case wire::MessageType::kContactModel: {
        IncomingModel model;
        if (const auto st = wire::DecodeContactModel(body, model.message);
            st != wire::DecodeStatus::kOk) {
          link_.CountBodyRejected(header.type, st);
          return;
        }
        if (late) return;  // newest wins: a newer model is already in use
        model.sequence = header.sequence;
        model.built_local_ns = clock_.valid() ? clock_.RemoteToLocal(header.send_time_ns) : now;
        counters_.model_accepted.fetch_add(1, std::memory_order_relaxed);
        // Samples for percentiles: the first 2^20 of each (reserved), then no more growth.
        if (model.message.model.tool_state_seq != 0 && rtt_ms_.size() < rtt_ms_.capacity()) {
          rtt_ms_.push_back((now - model.message.tool_state_send_time_ns - model.message.hold_ns) *
                            1e-6);
        }
        if (clock_.valid() && one_way_ms_.size() < one_way_ms_.capacity())
          one_way_ms_.push_back((now - model.built_local_ns) * 1e-6);
        if (remote_step_us_.size() < remote_step_us_.capacity()) {
          remote_step_us_.push_back(model.message.step_us);
          collision_us_.push_back(model.message.collision_us);
          texture_us_.push_back(model.message.texture_us);
        }
        if (model.message.model.num_contacts > 0 &&
            contact_step_us_.size() < contact_step_us_.capacity()) {
          contact_step_us_.push_back(model.message.step_us);
        }
        if (first_remote_ns_ == 0) {
          first_remote_ns_ = now;
          first_remote_steps_ = model.message.remote_step_count;
        }
        last_remote_ns_ = now;
        last_remote_steps_ = model.message.remote_step_count;
        incoming_.Write(model);
        return;
      }
      case wire::MessageType::kPong: {
        wire::PongMessage p;
        if (const auto st = wire::DecodePong(body, p); st != wire::DecodeStatus::kOk) {
          link_.CountBodyRejected(header.type, st);
          return;
        }
        clock_.AddSample(p.t1_ns, p.t2_ns, header.send_time_ns, now);
        return;
      }
      case wire::MessageType::kSceneManifest: {
        wire::SceneManifestMessage m;
        if (const auto st = wire::DecodeSceneManifest(body, m); st != wire::DecodeStatus::kOk) {
          link_.CountBodyRejected(header.type, st);
          return;
        }
        reassembler_.OnManifest(m, now);
        CheckScene(now);
        return;
      }
      case wire::MessageType::kSceneFragment: {
        wire::SceneFragmentMessage f;
        if (const auto st = wire::DecodeSceneFragment(body, f); st != wire::DecodeStatus::kOk) {
          link_.CountBodyRejected(header.type, st);
          return;
        }
        if (reassembler_.Add(f, now) == SceneReassembler::Outcome::kCompleted) CheckScene(now);
        return;
      }
      case wire::MessageType::kGoodbye: {
        if (wire::DecodeEmpty(body) != wire::DecodeStatus::kOk) return;
        ++remote_goodbyes_;
        std::printf("[master] the remote node closed the session; reconnecting\n");
        std::fflush(stdout);
        EndSession();
        return;
      }
      default:
        return;
    }
  }

  /// When the whole scene has arrived and matches the manifest, decode every object (Draco).
  void CheckScene(std::int64_t now) {
    if (scene_complete_ || !reassembler_.SceneComplete()) return;
    scene_complete_ = true;
    scene_complete_ms_ = (now - session_start_ns_) * 1e-6;
    for (std::uint32_t id = 0;
         id < 65536 && scene_objects_.size() < reassembler_.manifest_objects(); ++id) {
      const auto bytes = reassembler_.CompletedBytes(id);
      if (bytes.empty()) continue;
      nlohmann::json o = {{"object_id", id}, {"bytes", bytes.size()}};
      try {
        const TriangleMesh mesh = DecodeMeshDraco(bytes);
        o["vertices"] = mesh.vertices.size();
        o["triangles"] = mesh.triangles.size();
      } catch (const std::exception& e) {
        o["error"] = e.what();
      }
      scene_objects_.push_back(o);
    }
    std::printf("[master] scene complete after %.0f ms: %zu object(s) verified\n",
                scene_complete_ms_, reassembler_.verified_objects());
    std::fflush(stdout);
  }

  void Send(const OutgoingToolState& s) {
    wire::Header h = link_.NextHeader(wire::MessageType::kToolState, session_);
    h.send_time_ns = s.time_ns;
    link_.Send(wire::EncodeToolState(h, s.message, config_.key), config_.remote_address);
  }

  const StationConfig& config_;
  UdpSocket socket_;
  SecureLink link_;
  SceneReassembler reassembler_;
  ClockSync clock_;
  TripleBuffer<OutgoingToolState>& outgoing_;
  TripleBuffer<IncomingModel>& incoming_;
  Counters& counters_;
  std::uint32_t session_ = 0;
  std::uint64_t hello_nonce_ = 0;
  std::int64_t attempt_start_ns_ = 0;
  std::int64_t heartbeat_ns_ = 100000000, peer_timeout_ns_ = 500000000, session_start_ns_ = 0;
  std::uint64_t sessions_ = 0, peers_lost_ = 0, remote_goodbyes_ = 0, hellos_sent_ = 0;
  std::size_t mtu_ = 0, expected_objects_ = 0;
  std::string scene_name_, reject_text_;
  mutable std::mutex layout_mutex_;
  wire::SceneLayout layout_;
  bool scene_complete_ = false;
  double scene_complete_ms_ = -1.0;
  std::vector<nlohmann::json> scene_objects_;
  std::vector<double> loss_detected_after_ms_;
  std::vector<double> rtt_ms_, one_way_ms_, remote_step_us_, contact_step_us_, collision_us_,
      texture_us_;
  std::int64_t first_remote_ns_ = 0, last_remote_ns_ = 0;
  std::uint64_t first_remote_steps_ = 0, last_remote_steps_ = 0;
};

void WriteTraceHeader(std::FILE* f) {
  std::fputs(
      "t_s,phase,tool_x,tool_y,tool_z,tool_rx,tool_ry,tool_rz,fx,fy,fz,tx,ty,tz,contacts,"
      "model_age_ms,hand_x,hand_y,hand_z,device_fx,device_fy,device_fz,device_tx,device_ty,"
      "device_tz,depth_m,tick_compute_us,remote_collision_us,remote_texture_us,remote_step_us\n",
      f);
}

void WriteTraceRow(std::FILE* f, const TraceRow& r, const std::vector<std::string>& phases) {
  const glm::dvec3 rv = RotationVectorFromQuaternion(r.X_WT.rotation);
  const glm::dvec3& p = r.X_WT.translation;
  const char* phase = r.phase >= 0 && r.phase < static_cast<int>(phases.size())
                          ? phases[r.phase].c_str()
                          : "unknown";
  std::fprintf(f,
               "%.6f,%s,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%d,%.4f,"
               "%.9g,%.9g,%.9g,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%.2f,%.2f,%.2f,%.2f\n",
               r.t_s, phase, p.x, p.y, p.z, rv.x, rv.y, rv.z, r.F_contact_T_W.force.x,
               r.F_contact_T_W.force.y, r.F_contact_T_W.force.z, r.F_contact_T_W.torque.x,
               r.F_contact_T_W.torque.y, r.F_contact_T_W.torque.z, r.contacts, r.model_age_ms,
               r.p_WH.x, r.p_WH.y, r.p_WH.z, r.F_device_W.force.x, r.F_device_W.force.y,
               r.F_device_W.force.z, r.F_device_W.torque.x, r.F_device_W.torque.y,
               r.F_device_W.torque.z, r.depth_m, static_cast<double>(r.tick_compute_us),
               static_cast<double>(r.remote_collision_us), static_cast<double>(r.remote_texture_us),
               static_cast<double>(r.remote_step_us));
}

}  // namespace

void StationConfig::Validate() const {
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
  if (max_grid < 0 || max_grid > 65535) throw std::invalid_argument("max grid must be 0..65535");
  coupling.Validate();
  safety.Validate();
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
  NetworkWorker network(config, outgoing, incoming, counters);

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
        const long before = std::ftell(trace);
        WriteTraceRow(trace, row, experiment.phase_names());
        written += std::ftell(trace) - before;
      }
      if (stopping && !any) break;
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
  });
  const auto stop_threads = [&] {
    stop_network.store(true, std::memory_order_release);
    stop_recorder.store(true, std::memory_order_release);
    network_thread.join();
    recorder_thread.join();
    if (trace) std::fclose(trace);
    trace = nullptr;
    device.Close();
  };

  // The session first: its Welcome says where the workspace goes (the tool's home pose), the
  // tool's inertia and where the touchable objects are.
  const std::int64_t connect_deadline =
      NowNs() + static_cast<std::int64_t>(config.connect_timeout_s * 1e9);
  while (!counters.connected.load() && !counters.rejected.load() && NowNs() < connect_deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  RigidTransform X_WM = config.X_WM;
  ToolInertia tool_inertia = config.tool_inertia;
  ExperimentScene scene_M;
  std::vector<ExperimentTarget>& targets_M = scene_M.targets;
  if (counters.connected.load()) {
    const wire::SceneLayout layout = network.layout();
    if (config.workspace_from_remote) {
      X_WM = layout.X_WT_home;
      if (config.workspace_origin_W) X_WM.translation = *config.workspace_origin_W;
    }
    scene_M.tool_extent_down_m = layout.tool_extent_down_m;
    if (layout.tool_mass_kg > 0.0) {
      tool_inertia = {layout.tool_mass_kg, layout.tool_inertia_diagonal_T};
    }
    const RigidTransform X_MW = X_WM.Inverse();
    for (int i = 0; i < layout.num_targets; ++i) {
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
      targets_M.push_back(e);
    }
  }
  const ToolSimulator simulator(tool_inertia, config.coupling);
  const RigidTransform X_WM_start = X_WM;
  experiment.SetScene(scene_M);
  std::printf("[master] workspace centre in W %.4f,%.4f,%.4f (%s); %zu object(s) described\n",
              X_WM.translation.x, X_WM.translation.y, X_WM.translation.z,
              !config.workspace_from_remote ? "as configured"
              : config.workspace_origin_W   ? "--workspace-origin"
                                            : "the remote node's home pose",
              targets_M.size());
  std::fflush(stdout);
  // The tool starts where the experiment's first target puts the handle.
  ToolState tool;
  tool.X_WT = X_WM * experiment.Target(0.0).X_MH;
  std::uint64_t tool_seq = 1;
  outgoing.Write({{tool.X_WT, tool.V_WT_W}, NowNs(), tool_seq});

  // Then the remote node's first contact model (it answers our first tool state).
  while (counters.model_accepted.load() == 0 && !counters.rejected.load() &&
         NowNs() < connect_deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
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
                   : "no session (is slave_sim running and listening there, and do both sides "
                     "use the same --key file?)") +
        "; datagrams rejected here: " + std::to_string(network.rejected_total()));
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
  SafetyLimits safety_limits = config.safety;
  // The device's own limits bound the configured ones (a device without force output gets a
  // vanishing limit: it renders nothing).
  safety_limits.max_force_n = std::max(1e-9, std::min(safety_limits.max_force_n, caps.max_force_n));
  safety_limits.max_torque_nm =
      std::max(1e-9, std::min(safety_limits.max_torque_nm, caps.max_torque_nm));
  OperatorTickConfig tick_config;
  tick_config.inertia = tool_inertia;
  tick_config.coupling = config.coupling;
  tick_config.safety = safety_limits;
  tick_config.model_blend_ticks = config.model_blend_ticks;
  tick_config.passivity = config.passivity;
  // The added damping is capped (4 x the device's rated damping: the controller acts for single
  // ticks, well inside what a 1 kHz device renders); energy it cannot dissipate in one tick stays
  // in the observer (E < 0) and is dissipated on the next ones.
  tick_config.passivity_max_damping_ns_per_m = 4.0 * caps.max_damping_ns_per_m;
  tick_config.h_s = h;
  OperatorTick tick(tick_config, X_WM, tool);
  const PassivityController& passivity = tick.passivity();
  const WrenchSafetyFilter& safety = tick.safety();
  int contacts_max = 0;
  double force_max = 0.0;
  std::string realtime_note = "SCHED_FIFO priority 80";

  std::thread loop_thread([&] {
    sched_param sp{};
    sp.sched_priority = 80;
    if (pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp) != 0) {
      realtime_note = "not permitted (run as root or grant CAP_SYS_NICE / rtprio); normal priority";
    }
    IncomingModel received{};
    ArrivedModel arrived{};
    std::int64_t experiment_t0 = -1;
    std::int64_t stop_ramp_start = -1;
    const double stop_ramp_ticks = std::max(1.0, config.stop_ramp_s * config.loop_rate_hz);
    std::int64_t next = NowNs() + period_ns;
    std::int64_t previous = next - period_ns;
    const std::int64_t t0 = next;
    for (std::int64_t k = 0; k < ticks; ++k) {
      SleepUntilNs(next);
      const std::int64_t now = NowNs();
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
        in.workspace_shift_M = experiment.Target((now - experiment_t0) * 1e-9).workspace_shift_M;
      }
      if (incoming.Read(received)) {
        arrived.model = received.message.model;
        arrived.tool_state_sent_ns = received.message.tool_state_send_time_ns;
        arrived.built_local_ns = received.built_local_ns;
        arrived.collision_us = received.message.collision_us;
        arrived.texture_us = received.message.texture_us;
        arrived.step_us = received.message.step_us;
        in.arrived = &arrived;
      }
      OperatorTickOutput out = tick.Step(in);
      // Asked to stop (Ctrl-C, SIGTERM): ramp the device's wrench to zero, then end the run.
      if (stop_ramp_start < 0 && config.stop_requested != nullptr &&
          config.stop_requested->load(std::memory_order_relaxed)) {
        stop_ramp_start = k;
      }
      if (stop_ramp_start >= 0) {
        const double gain =
            std::max(0.0, 1.0 - static_cast<double>(k - stop_ramp_start + 1) / stop_ramp_ticks);
        out.F_H_M = {gain * out.F_H_M.force, gain * out.F_H_M.torque};
        out.F_device_W = {gain * out.F_device_W.force, gain * out.F_device_W.torque};
      }
      if (!device.WriteWrench(out.F_H_M, now)) ++device_write_faults;
      if (in.device_ok) {
        ++tool_seq;
        outgoing.Write({{tick.tool().X_WT, tick.tool().V_WT_W}, now, tool_seq});
        const ToolStepResult& step = out.step;
        row.X_WT = tick.tool().X_WT;
        row.F_contact_T_W = step.F_contact_T_W;
        row.contacts = step.active_contacts;
        row.depth_m = step.max_depth_m;
        row.p_WH = out.X_WH.translation;
        row.F_device_W = out.F_device_W;
        row.model_age_ms = out.model_age_ms;
        row.remote_collision_us = tick.last_arrived().collision_us;
        row.remote_texture_us = tick.last_arrived().texture_us;
        row.remote_step_us = tick.last_arrived().step_us;
        contacts_max = std::max(contacts_max, step.active_contacts);
        force_max = std::max(force_max, glm::length(step.F_contact_T_W.force));
      }
      // The phase the simulated hand was following, when the device is scripted.
      row.phase = experiment.Target(row.t_s).phase;
      if (row.model_age_ms >= 0.0) model_age_samples.Add(row.model_age_ms);
      const std::int64_t end = NowNs();
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
    device.WriteWrench({}, NowNs());
    loop_done.store(true, std::memory_order_release);
  });

  // Progress while the loop runs.
  const std::int64_t started = NowNs();
  std::int64_t last_print = started;
  std::int64_t last_ticks = 0;
  std::uint64_t last_models = counters.model_accepted.load();
  while (!loop_done.load(std::memory_order_acquire)) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    const std::int64_t now = NowNs();
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
  const double elapsed_s = (NowNs() - started) * 1e-9;
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
  s["tool_mass_kg"] = tool_inertia.mass_kg;
  s["device"] = caps.name;
  s["duration_s"] =
      config.run_until_stopped || stopped_by_request ? elapsed_s : experiment.duration_s();
  s["run_until_stopped"] = config.run_until_stopped;
  s["stopped_by_request"] = stopped_by_request;
  s["ticks"] = ticks_run;
  s["master_rate_hz"] = ticks_run / std::max(elapsed_s, 1e-9);
  // Percentiles over a uniform sample of at most 2^20 ticks (all of them in runs up to 17 min).
  s["tick_statistics_sampled"] = compute_us.count() > compute_us.values().size();
  s["master_period_p50_us"] = Percentile(period_us.values(), 0.5);
  s["master_period_p99_us"] = Percentile(period_us.values(), 0.99);
  s["master_period_max_us"] = Percentile(period_us.values(), 1.0);
  s["master_tick_p50_us"] = Percentile(compute_us.values(), 0.5);
  s["master_tick_p99_us"] = Percentile(compute_us.values(), 0.99);
  s["master_tick_max_us"] = Percentile(compute_us.values(), 1.0);
  s["master_overruns"] = overruns;
  s["realtime_priority"] = realtime_note;
  s["slave_rate_hz"] = network.RemoteRateHz();
  s["slave_step_p50_us"] = Percentile(network.remote_step_us(), 0.5);
  s["slave_step_p99_us"] = Percentile(network.remote_step_us(), 0.99);
  s["slave_step_in_contact_p50_us"] = Percentile(network.contact_step_us(), 0.5);
  s["slave_step_in_contact_p99_us"] = Percentile(network.contact_step_us(), 0.99);
  s["slave_collision_p50_us"] = Percentile(network.collision_us(), 0.5);
  s["slave_texture_p50_us"] = Percentile(network.texture_us(), 0.5);
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
  s["passivity"] = {{"enabled", config.passivity},
                    {"observed_energy_J", passivity.observed_energy_j()},
                    {"dissipated_J", passivity.dissipated_j()},
                    {"active_ticks", passivity.active_ticks()},
                    {"max_damping_ns_per_m", passivity.max_alpha()},
                    {"scaled_ticks", passivity.scaled_ticks()},
                    {"force_scaled_away_Ns", passivity.force_scaled_away_ns()}};
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
