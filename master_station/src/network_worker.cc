// The operator station's network worker: the member functions of NetworkWorker
// (network_worker.h), which runs the session, the tool-state and contact-model streams and the
// scene stream's reassembly on its own thread. Internal to master_station.

#include "network_worker.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <exception>
#include <limits>
#include <optional>
#include <thread>

#include "codecs/depth_field_codec.h"
#include "codecs/draco_mesh_codec.h"
#include "haptic_core/statistics.h"

namespace ht::station {

NetworkWorker::NetworkWorker(const StationConfig& config, TripleBuffer<OutgoingToolState>& outgoing,
                             TripleBuffer<IncomingModel>& incoming, Counters& counters,
                             ReceivedScene& scene, FieldHandoff& fields)
    : config_(config),
      socket_(config.local_address),
      link_(socket_, config.key, LinkRole::kOperator),
      reassembler_(config.mtu),
      outgoing_(outgoing),
      incoming_(incoming),
      counters_(counters),
      scene_(scene),
      fields_(fields),
      field_reassembler_(config.mtu) {
  field_decode_ms_.reserve(1 << 16);
  encoded_pool_.reserve(kEncodedFields);
  decoding_ids_.reserve(kEncodedFields);
  for (std::size_t i = 0; i < kEncodedFields; ++i) {
    encoded_pool_.push_back(std::make_unique<EncodedField>());
    encoded_free_.Push(encoded_pool_.back().get());
  }
  rtt_ms_.reserve(1 << 20);
  node_pose_latency_ms_.reserve(1 << 18);
  one_way_ms_.reserve(1 << 20);
  remote_step_us_.reserve(1 << 20);
  contact_step_us_.reserve(1 << 20);
  collision_us_.reserve(1 << 20);
  texture_us_.reserve(1 << 20);
  clock_.Reserve(1 << 16);
}

void NetworkWorker::Run(const std::atomic<bool>& stop) {
  std::atomic<bool> stop_decoder{false};
  std::thread decoder([this, &stop_decoder] { DecodeFields(stop_decoder); });
  RunNetwork(stop);
  stop_decoder.store(true, std::memory_order_release);
  decoder.join();
  TakeDecodedFields();
  if (fields_undecodable_ > 0) {
    std::printf(
        "[master] %llu depth field(s) from the remote node did not decode (first: %s); "
        "their contacts were rendered from their linearizations\n",
        static_cast<unsigned long long>(fields_undecodable_), first_decode_error_.c_str());
    std::fflush(stdout);
  }
}

void NetworkWorker::RunNetwork(const std::atomic<bool>& stop) {
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
    if (session_ != 0 && link_.SequencesNearlyUsedUp()) {
      // A stream's u32 sequence numbers are nearly used up (wire::kSequenceRenewAt, 49 days at
      // 1 kHz): a new session starts them again. No Goodbye (a node run without --stay would
      // exit on it): the new Hello is deferred by the node until this session has been silent
      // for its peer timeout, while the loop renders the model it holds.
      ++sessions_renewed_;
      std::printf("[master] a stream has used %llu sequence numbers; starting a new session\n",
                  static_cast<unsigned long long>(wire::kSequenceRenewAt));
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
      ++tool_states_offered_;
      // The deadband predicts from what the remote node will decode; the state itself is what
      // is encoded (quantizing a quantized rotation again can pick another largest component).
      const wire::ToolStateMessage received = AsReceived(state.message);
      if (tool_deadband_.Decide(received.X_WT, received.V_WT_W, state.time_ns, state.near_contact,
                                &held_model_) != DeadbandReason::kNotSent) {
        Send(state);
        last_send_ns = now;
      } else {
        ++tool_states_held_back_;
        last_send_ns = now;  // the deadband's own keep-alive bounds the gap
      }
    } else if (have_last && now - last_send_ns > 20000000) {
      // Keep-alive while the loop is not running (before the first tick, after the last): the
      // same pose at rest, stamped now, so that round trips measured on it are not inflated and
      // the remote node does not extrapolate a tool that no longer moves.
      last.time_ns = now;
      last.message.V_WT_W = {};
      Send(last);
      const wire::ToolStateMessage received = AsReceived(last.message);
      tool_deadband_.NoteSent(received.X_WT, received.V_WT_W, now);
      ++idle_keepalives_;
      last_send_ns = now;
    }
    if (now - last_ping_ns >= heartbeat_ns_) {
      // The round trip measured so far goes with the probe (the remote node sizes its depth
      // fields' margin and speculative floor from it); 0 until a Pong came back (the handshake's
      // time counts from the first Hello of its nonce, retransmissions included).
      const std::int64_t rtt_ns = clock_.valid() ? clock_.rtt_ns() : 0;
      wire::PingMessage ping;
      ping.operator_rtt_us = static_cast<std::uint32_t>(
          std::clamp<std::int64_t>(rtt_ns / 1000, 0, std::numeric_limits<std::uint32_t>::max()));
      reported_rtt_us_ = ping.operator_rtt_us;
      if (ping.operator_rtt_us > 0) {
        reported_rtt_min_us_ = std::min(reported_rtt_min_us_, ping.operator_rtt_us);
        reported_rtt_max_us_ = std::max(reported_rtt_max_us_, ping.operator_rtt_us);
      }
      link_.Send(
          wire::EncodePing(link_.NextHeader(wire::MessageType::kPing, session_), ping, config_.key),
          config_.remote_address);
      last_ping_ns = now;
    }
    SceneReassembler::RepairTiming repair;
    repair.rtt_ns = clock_.valid() ? clock_.rtt_ns() : handshake_rtt_ns_;
    TakeDecodedFields();
    if (depth_fields_ && session_ != 0) {
      DepthFieldReassembler::RepairTiming field_repair;
      field_repair.rtt_ns = repair.rtt_ns;
      field_reassembler_.CollectNacks(now, field_repair, [&](const wire::SceneNackMessage& nack) {
        ++field_nacks_sent_;
        link_.Send(
            wire::EncodeDepthFieldNack(
                link_.NextHeader(wire::MessageType::kDepthFieldNack, session_), nack, config_.key),
            config_.remote_address);
      });
    }
    reassembler_.CollectNacks(now, repair, [&](const wire::SceneNackMessage& nack) {
      for (int copy = 0; copy < kSceneNackCopies; ++copy) {
        link_.Send(wire::EncodeSceneNack(link_.NextHeader(wire::MessageType::kSceneNack, session_),
                                         nack, config_.key),
                   config_.remote_address);
      }
    });
  }
  SayGoodbye();
}

void NetworkWorker::SayGoodbye() {
  if (session_ == 0) return;
  // Retries carry new sequence numbers (a copy of the same datagram would be a replay).
  for (int i = 0; i < 3; ++i) {
    link_.Send(
        wire::EncodeGoodbye(link_.NextHeader(wire::MessageType::kGoodbye, session_), config_.key),
        config_.remote_address);
  }
}

double NetworkWorker::RemoteRateHz() const {
  if (last_remote_ns_ <= first_remote_ns_) return 0.0;
  return static_cast<double>(remote_steps_) / ((last_remote_ns_ - first_remote_ns_) * 1e-9);
}

wire::SceneLayout NetworkWorker::layout() const {
  std::lock_guard<std::mutex> lock(layout_mutex_);
  return layout_;
}

nlohmann::json NetworkWorker::Summary() const {
  nlohmann::json t = link_.StatsJson();
  t["sessions"] = sessions_;
  t["peers_lost"] = peers_lost_;
  t["peer_lost_detected_after_ms"] = loss_detected_after_ms_;
  t["remote_goodbyes"] = remote_goodbyes_;
  t["sessions_renewed"] = sessions_renewed_;
  t["hellos_sent"] = hellos_sent_;
  t["mtu"] = mtu_;
  t["scene_name"] = scene_name_;
  {
    t["deadband"] = ToJson(deadband_agreed_);
    t["deadband"].update(nlohmann::json{
        {"velocity_adaptive", config_.tool_state_deadband.velocity_adaptive},
        {"contact_position_floor_scale_mm",
         config_.tool_state_deadband.contact_position_floor_scale_m * 1e3},
        {"contact_rotation_floor_scale_mrad",
         config_.tool_state_deadband.contact_rotation_floor_scale_rad * 1e3},
        {"contact_floor_hold_ms", config_.tool_state_deadband.contact_floor_hold_s * 1e3},
        {"contact_depth_floor_scale_um",
         config_.tool_state_deadband.contact_depth_floor_scale_m * 1e6},
        {"compact_models", compact_models_},
        {"compact_tool_states", compact_tool_states_},
        {"tool_states_offered", tool_states_offered_},
        {"tool_states_held_back", tool_states_held_back_},
        {"tool_states_idle_keepalives", idle_keepalives_},
        {"tool_state_decisions", ToJson(tool_deadband_.counts())}});
  }
  t["clock"] = {
      {"samples", clock_.rtt_ms_samples().size()},
      {"rtt_reported_ms_last", reported_rtt_us_ * 1e-3},
      {"rtt_reported_ms_min", reported_rtt_max_us_ > 0 ? reported_rtt_min_us_ * 1e-3 : 0.0},
      {"rtt_reported_ms_max", reported_rtt_max_us_ * 1e-3},
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
                {"decoded", objects},
                {"versions_published", scene_versions_published_},
                {"object_transfer_ms_p50", Percentile(transfer_ms_, 0.5)},
                {"object_transfer_ms_max", Percentile(transfer_ms_, 1.0)},
                {"updates_received", update_transfer_ms_.size()},
                {"update_transfer_ms_p50", Percentile(update_transfer_ms_, 0.5)},
                {"update_transfer_ms_max", Percentile(update_transfer_ms_, 1.0)}};
  const DepthFieldReassemblyStats& fr = field_reassembler_.stats();
  t["depth_fields"] = {{"agreed", depth_fields_},
                       {"fields_completed", fr.fields_completed},
                       {"fields_handed_to_loop", fields_handed_},
                       {"fields_undecodable", fields_undecodable_},
                       {"fields_without_buffer", fields_without_buffer_},
                       {"fields_decoder_busy", fields_decoder_busy_},
                       {"models_waited_for_fields", models_waited_for_fields_},
                       {"fields_missing_in_loop", fields_missing_in_loop_},
                       {"fields_abandoned", fr.fields_abandoned},
                       {"fragments_accepted", fr.fragments_accepted},
                       {"fragments_duplicate", fr.fragments_duplicate},
                       {"fragments_inconsistent", fr.fragments_inconsistent},
                       {"nacks_sent", fr.nacks_sent},
                       {"decode_ms_p50", Percentile(field_decode_ms_, 0.5)},
                       {"decode_ms_max", Percentile(field_decode_ms_, 1.0)}};
  const ReceivedPoseStats poses = scene_.pose_stats();
  t["node_poses"] = {{"messages", poses.messages},
                     {"messages_before_scene", poses.messages_before_scene},
                     {"entries_applied", poses.entries_applied},
                     {"entries_dropped", poses.entries_dropped},
                     {"latency_ms_p50", Percentile(node_pose_latency_ms_, 0.5)},
                     {"latency_ms_p99", Percentile(node_pose_latency_ms_, 0.99)}};
  nlohmann::json tracks = nlohmann::json::array();
  const auto quat = [](const glm::dquat& q) { return nlohmann::json{q.w, q.x, q.y, q.z}; };
  const auto vec = [](const glm::dvec3& v) { return nlohmann::json{v.x, v.y, v.z}; };
  for (const ReceivedNodeTrack& k : scene_.node_tracks()) {
    tracks.push_back({{"node", k.node},
                      {"name", k.name},
                      {"updates", k.updates},
                      {"first_time_s", k.first_time_s},
                      {"last_time_s", k.last_time_s},
                      {"first_translation", vec(k.first.translation)},
                      {"last_translation", vec(k.last.translation)},
                      {"first_rotation_wxyz", quat(k.first.rotation)},
                      {"last_rotation_wxyz", quat(k.last.rotation)}});
  }
  t["node_poses"]["nodes"] = std::move(tracks);
  return t;
}

void NetworkWorker::SendHello() {
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
  hello.codecs = wire::kCodecDracoMesh |
                 (config_.compact_models ? wire::kCodecCompactContactModel : 0u) |
                 (config_.compact_tool_states ? wire::kCodecCompactToolState : 0u) |
                 (config_.depth_fields ? wire::kCodecDepthFields : 0u);
  hello.deadband.tool_state_deadband =
      static_cast<float>(config_.tool_state_deadband.weber_fraction);
  hello.deadband.model_deadband = static_cast<float>(config_.model_deadband);
  hello.deadband.tool_state_keepalive_ms =
      static_cast<std::uint16_t>(std::lround(config_.tool_state_deadband.keepalive_s * 1e3));
  hello.deadband.model_keepalive_ms =
      static_cast<std::uint16_t>(std::lround(config_.model_keepalive_s * 1e3));
  link_.Send(wire::EncodeHello(link_.NextHeader(wire::MessageType::kHello, 0), hello, config_.key),
             config_.remote_address);
  ++hellos_sent_;
}

void NetworkWorker::OnDepthFieldFragment(const wire::SceneFragmentMessage& fragment,
                                         std::int64_t now) {
  if (field_reassembler_.Add(fragment, now) != DepthFieldReassembler::Outcome::kCompleted) return;
  EncodedField* e = nullptr;
  if (!encoded_free_.Pop(e)) {
    // The decoder has kEncodedFields fields queued: this one is asked for again when a model
    // names it.
    ++fields_decoder_busy_;
    return;
  }
  e->id = field_reassembler_.completed_id();
  e->epoch = field_epoch_;
  e->bytes.assign(field_reassembler_.completed().begin(), field_reassembler_.completed().end());
  decoding_ids_.push_back(e->id);
  to_decode_.Push(e);  // cannot fail: the ring holds the whole pool
  // Held from now on: a model naming it asks for no repair while it decodes (which can take
  // longer than the repair gap on a loaded machine), and a resent copy is a duplicate rather
  // than a second decode. A field that finds no buffer is asked for again (TakeDecodedFields).
  field_reassembler_.Held(e->id);
}

bool NetworkWorker::NamesFieldInDecoding(const ContactModel& model) const noexcept {
  for (int i = 0; i < std::clamp(model.num_contacts, 0, kMaxContacts); ++i) {
    const std::uint32_t id = model.contacts[static_cast<std::size_t>(i)].depth_field_id;
    if (id != 0 && std::ranges::find(decoding_ids_, id) != decoding_ids_.end()) return true;
  }
  return false;
}

void NetworkWorker::TakeDecodedFields() {
  // Fields the loop lacks though its model names them: asked for again (unless on their way).
  std::uint32_t lacked = 0;
  while (fields_.missing.Pop(lacked)) {
    if (std::ranges::find(decoding_ids_, lacked) != decoding_ids_.end()) continue;
    ++fields_missing_in_loop_;
    field_reassembler_.Lost(lacked, SteadyNowNs());
  }
  DecodedField d;
  bool any = false;
  while (decoded_.Pop(d)) {
    any = true;
    std::erase(decoding_ids_, d.id);
    switch (d.outcome) {
      case DecodeOutcome::kHanded:  // held since it was queued (OnDepthFieldFragment)
        ++fields_handed_;
        break;
      case DecodeOutcome::kUndecodable:  // stays held: asking again would not help
        ++fields_undecodable_;
        break;
      case DecodeOutcome::kNoBuffer:
        ++fields_without_buffer_;
        field_reassembler_.Lost(d.id, SteadyNowNs());  // asked for again
        break;
    }
  }
  if (any && have_model_waiting_ && !NamesFieldInDecoding(model_waiting_.message.model)) {
    incoming_.Write(model_waiting_);
    have_model_waiting_ = false;
  }
}

void NetworkWorker::DecodeFields(const std::atomic<bool>& stop) {
  std::string error;
  while (true) {
    EncodedField* e = nullptr;
    if (!to_decode_.Pop(e)) {
      if (stop.load(std::memory_order_acquire)) return;
      timespec pause{0, 500000};  // 0.5 ms: a field waits at most that long to start decoding
      nanosleep(&pause, nullptr);
      continue;
    }
    DecodedField result{e->id, DecodeOutcome::kHanded};
    if (spare_field_ == nullptr && !fields_.free.Pop(spare_field_)) {
      result.outcome = DecodeOutcome::kNoBuffer;  // every buffer is on its way to the loop
    } else {
      const std::int64_t t0 = SteadyNowNs();
      if (!DecodeDepthField(e->bytes, *spare_field_, field_scratch_, error)) {
        result.outcome = DecodeOutcome::kUndecodable;
        if (first_decode_error_.empty()) first_decode_error_ = error;
      } else {
        if (field_decode_ms_.size() < field_decode_ms_.capacity()) {
          field_decode_ms_.push_back(static_cast<double>(SteadyNowNs() - t0) * 1e-6);
        }
        // The ready ring holds the whole pool: a push cannot fail.
        if (fields_.ready.Push({spare_field_, e->epoch})) {
          spare_field_ = nullptr;
        } else {
          result.outcome = DecodeOutcome::kNoBuffer;
        }
      }
    }
    encoded_free_.Push(e);
    decoded_.Push(result);  // room for every pool entry twice: cannot fail
  }
}

void NetworkWorker::EndSession() {
  session_ = 0;
  counters_.connected.store(false);
}

void NetworkWorker::Handle(std::span<const std::uint8_t> datagram, const SocketAddress& from) {
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
      if (config_.start_sequences_at != 0) link_.StartSequencesAt(config_.start_sequences_at);
      session_ = header.session_id;
      ++sessions_;
      hello_nonce_ = 0;  // the next attempt (after a loss) gets a new nonce
      handshake_rtt_ns_ = now - attempt_start_ns_;
      mtu_ = w.mtu;
      heartbeat_ns_ = std::int64_t{w.heartbeat_ms} * 1000000;
      peer_timeout_ns_ = std::int64_t{w.peer_timeout_ms} * 1000000;
      expected_objects_ = w.scene_objects;
      {
        ToolStateDeadbandConfig deadband = config_.tool_state_deadband;
        deadband.weber_fraction = w.deadband.tool_state_deadband;
        deadband.keepalive_s = w.deadband.tool_state_keepalive_ms * 1e-3;
        tool_deadband_.Configure(deadband);
        held_model_ = {};  // a new session: no model yet
      }
      deadband_agreed_ = w.deadband;
      compact_models_ = (w.codecs & wire::kCodecCompactContactModel) != 0;
      compact_tool_states_ = (w.codecs & wire::kCodecCompactToolState) != 0;
      depth_fields_ = (w.codecs & wire::kCodecDepthFields) != 0;
      field_reassembler_.Reset(w.mtu);
      have_model_waiting_ = false;
      ++field_epoch_;
      scene_name_ = std::string(w.name());
      {
        std::lock_guard<std::mutex> lock(layout_mutex_);
        layout_ = w.layout;
      }
      reassembler_.Reset(w.mtu);
      scene_complete_ = false;
      scene_dirty_ = false;
      object_first_fragment_.clear();
      decoded_meshes_.clear();
      scene_objects_.clear();
      session_start_ns_ = now;
      clock_.Reset();
      counters_.connected.store(true);
      std::printf(
          "[master] session %08x with remote node %s: scene '%s' (%u objects), grid %u, "
          "window %.3f m, mtu %u, protocol v%u\n",
          session_, config_.remote_address.ToString().c_str(), scene_name_.c_str(), w.scene_objects,
          w.grid, static_cast<double>(w.window_m), w.mtu, w.version);
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
    case wire::MessageType::kContactModel:
    case wire::MessageType::kCompactContactModel: {
      IncomingModel model;
      if (const auto st = header.type == wire::MessageType::kContactModel
                              ? wire::DecodeContactModel(body, model.message)
                              : wire::DecodeCompactContactModel(body, model.message, now);
          st != wire::DecodeStatus::kOk) {
        link_.CountBodyRejected(header.type, st);
        return;
      }
      if (late) return;  // newest wins: a newer model is already in use
      model.sequence = header.sequence;
      model.field_epoch = field_epoch_;
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
      const auto steps_low = static_cast<std::uint32_t>(model.message.remote_step_count);
      if (first_remote_ns_ == 0) {
        first_remote_ns_ = now;
      } else {
        remote_steps_ += wire::RemoteStepsBetween(last_remote_steps_low_, steps_low);
      }
      last_remote_ns_ = now;
      last_remote_steps_low_ = steps_low;
      held_model_ = model.message.model;
      if (depth_fields_) {
        // A field the model names that has not arrived is asked for again (CollectNacks).
        for (int i = 0; i < std::clamp(model.message.model.num_contacts, 0, kMaxContacts); ++i) {
          field_reassembler_.Wanted(
              model.message.model.contacts[static_cast<std::size_t>(i)].depth_field_id, now);
        }
      }
      if (NamesFieldInDecoding(model.message.model)) {
        // Its field is still being decoded (a few ms): it goes to the loop when the field does.
        model_waiting_ = model;
        have_model_waiting_ = true;
        ++models_waited_for_fields_;
        return;
      }
      have_model_waiting_ = false;  // newest wins
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
      const SceneReassembler::Outcome outcome = reassembler_.Add(f, now);
      if (outcome == SceneReassembler::Outcome::kAccepted ||
          outcome == SceneReassembler::Outcome::kCompleted) {
        // Transfer time of each object version: its first fragment here to its completion.
        auto [it, fresh] = object_first_fragment_.try_emplace(f.object_id, f.version, now);
        if (!fresh && it->second.first != f.version) it->second = {f.version, now};
      }
      if (outcome == SceneReassembler::Outcome::kCompleted) {
        if (const auto it = object_first_fragment_.find(f.object_id);
            it != object_first_fragment_.end() && it->second.first == f.version) {
          (f.version > 1 ? update_transfer_ms_ : transfer_ms_)
              .push_back((now - it->second.second) * 1e-6);
        }
        scene_dirty_ = true;
        CheckScene(now);
      }
      return;
    }
    case wire::MessageType::kDepthFieldFragment: {
      wire::SceneFragmentMessage f;
      if (const auto st = wire::DecodeDepthFieldFragment(body, f); st != wire::DecodeStatus::kOk) {
        link_.CountBodyRejected(header.type, st);
        return;
      }
      if (depth_fields_) OnDepthFieldFragment(f, now);
      return;
    }
    case wire::MessageType::kNodePoses: {
      wire::NodePosesMessage m;
      if (const auto st = wire::DecodeNodePoses(body, m); st != wire::DecodeStatus::kOk) {
        link_.CountBodyRejected(header.type, st);
        return;
      }
      // Newest wins per node (by the remote scene's clock), whatever the arrival order.
      scene_.ApplyPoses(m);
      if (clock_.valid() && node_pose_latency_ms_.size() < node_pose_latency_ms_.capacity()) {
        node_pose_latency_ms_.push_back((now - clock_.RemoteToLocal(header.send_time_ns)) * 1e-6);
      }
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

void NetworkWorker::CheckScene(std::int64_t now) {
  if (!reassembler_.SceneComplete() || (scene_complete_ && !scene_dirty_)) return;
  const bool first = !scene_complete_;
  scene_complete_ = true;
  scene_dirty_ = false;
  if (first) scene_complete_ms_ = (now - session_start_ns_) * 1e-6;
  auto content = std::make_shared<ReceivedSceneContent>();
  bool have_graph = false;
  scene_objects_.clear();
  for (std::uint32_t id = 0; id < 65536 && scene_objects_.size() < reassembler_.manifest_objects();
       ++id) {
    const auto bytes = reassembler_.CompletedBytes(id);
    if (bytes.empty()) continue;
    const std::optional<wire::SceneObjectKind> kind = reassembler_.ObjectKind(id);
    const std::uint32_t version = reassembler_.CompletedVersion(id);
    nlohmann::json o = {{"object_id", id}, {"version", version}, {"bytes", bytes.size()}};
    try {
      switch (kind.value_or(wire::SceneObjectKind::kDracoMesh)) {
        case wire::SceneObjectKind::kSceneGraph: {
          std::string error;
          if (!DecodeSceneGraph(bytes, &content->graph, &error)) throw std::runtime_error(error);
          content->graph_version = version;
          have_graph = true;
          o["kind"] = "scene_graph";
          o["nodes"] = content->graph.nodes.size();
          o["materials"] = content->graph.materials.size();
          break;
        }
        case wire::SceneObjectKind::kImage:
          content->images.push_back(
              {id, version, std::vector<std::uint8_t>(bytes.begin(), bytes.end())});
          o["kind"] = "image";
          break;
        case wire::SceneObjectKind::kDracoMesh: {
          // Decoded once per version: an update re-decodes only the objects that changed.
          auto cached = decoded_meshes_.find(id);
          if (cached == decoded_meshes_.end() || cached->second.version != version) {
            DracoMesh decoded = DecodeMeshDracoWithUv(bytes);
            cached = decoded_meshes_
                         .insert_or_assign(
                             id, ReceivedSceneContent::Mesh{id, version, std::move(decoded.mesh),
                                                            std::move(decoded.uv)})
                         .first;
          }
          const ReceivedSceneContent::Mesh& mesh = cached->second;
          o["kind"] = "draco_mesh";
          o["vertices"] = mesh.mesh_N.vertices.size();
          o["triangles"] = mesh.mesh_N.triangles.size();
          o["texture_coordinates"] = !mesh.uv_N.empty();
          content->meshes.push_back(mesh);
          break;
        }
      }
    } catch (const std::exception& e) {
      o["error"] = e.what();
      content->errors.emplace_back(id, e.what());
    }
    scene_objects_.push_back(o);
  }
  if (!have_graph) {
    // No scene graph in the stream: each mesh as a root at the identity (posed in W).
    content->graph.scene_name = scene_name_;
    for (const ReceivedSceneContent::Mesh& m : content->meshes) {
      SceneGraphNode n;
      n.name = "object " + std::to_string(m.object_id);
      n.mesh_object = m.object_id;
      content->graph.nodes.push_back(n);
    }
  }
  const std::size_t nodes = content->graph.nodes.size();
  const std::size_t meshes = content->meshes.size();
  scene_.Set(std::move(content));
  ++scene_versions_published_;
  if (first) {
    std::printf(
        "[master] scene complete after %.0f ms: %zu object(s) verified, %zu node(s), %zu "
        "mesh(es)%s\n",
        scene_complete_ms_, reassembler_.verified_objects(), nodes, meshes,
        have_graph ? "" : " (no scene graph: meshes shown as sent)");
  } else {
    std::printf("[master] scene updated: a new object version arrived (%zu mesh(es))\n", meshes);
  }
  std::fflush(stdout);
}

wire::ToolStateMessage NetworkWorker::AsReceived(const wire::ToolStateMessage& m) const noexcept {
  return compact_tool_states_ ? wire::CompactToolStateAsReceived(m) : m;
}

void NetworkWorker::Send(const OutgoingToolState& s) {
  if (compact_tool_states_) {
    wire::Header h = link_.NextHeader(wire::MessageType::kCompactToolState, session_);
    h.send_time_ns = s.time_ns;
    link_.Send(wire::EncodeCompactToolState(h, s.message, config_.key), config_.remote_address);
    return;
  }
  wire::Header h = link_.NextHeader(wire::MessageType::kToolState, session_);
  h.send_time_ns = s.time_ns;
  link_.Send(wire::EncodeToolState(h, s.message, config_.key), config_.remote_address);
}

}  // namespace ht::station
