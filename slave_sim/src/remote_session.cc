#include "remote_session.h"

#include <algorithm>
#include <cstdio>
#include <stdexcept>

#include "codecs/depth_field_codec.h"
#include "haptic_core/steady_clock.h"

namespace ht {

RemoteSession::RemoteSession(const RemoteNodeConfig& config, SecureLink& link,
                             SceneSender& scene_sender, const RemoteCapabilities& caps,
                             std::int64_t start_ns)
    : config_(config),
      link_(link),
      scene_sender_(scene_sender),
      caps_(caps),
      last_token_ns_(start_ns),
      token_cap_(std::max(16.0 * wire::kMaxDatagramBytes, config.scene_rate_bytes_per_s * 0.01)),
      start_ns_(start_ns),
      node_poses_period_ns_(static_cast<std::int64_t>(1e9 / config.display_rate_hz)) {
  for (const SceneObject& o : scene_sender.objects()) {
    if (o.kind == wire::SceneObjectKind::kSceneGraph) graph_version_ = o.version;
  }
}

bool RemoteSession::OnDatagram(std::span<const std::uint8_t> datagram, const SocketAddress& from,
                               std::int64_t now) {
  wire::Header header;
  std::span<const std::uint8_t> body;
  bool late = false;
  const wire::DecodeStatus status =
      link_.Open(datagram, session_ != 0 ? session_ : goodbye_session_, header, body, late);
  if (status == wire::DecodeStatus::kBadVersion) {
    RefuseForeignHello(datagram, from);
    return true;
  }
  if (status != wire::DecodeStatus::kOk) return true;
  if (session_ == 0 && goodbye_session_ != 0 && header.type != wire::MessageType::kHello) {
    // The session the operator closed: its Goodbye's copies, or what it sent just before.
    if (header.type == wire::MessageType::kGoodbye) ++goodbye_copies_;
    return true;
  }
  // Any datagram of the open session other than a Hello shows that the operator holds our
  // Welcome: only then does the scene stream start (before that, its fragments would reach an
  // operator without the session id and be dropped as out of session: with the Welcome lost, the
  // whole first burst was wasted and only NACK repair, a round trip at a time, could recover it).
  if (session_ != 0 && header.session_id == session_ && header.type != wire::MessageType::kHello) {
    operator_confirmed_ = true;
  }
  switch (header.type) {
    case wire::MessageType::kHello:
      OnHello(header, body, from, now);
      break;
    case wire::MessageType::kToolState:
    case wire::MessageType::kCompactToolState: {
      wire::ToolStateMessage message;
      const auto st = header.type == wire::MessageType::kToolState
                          ? wire::DecodeToolState(body, message)
                          : wire::DecodeCompactToolState(body, message);
      if (st != wire::DecodeStatus::kOk) {
        link_.CountBodyRejected(header.type, st);
        break;
      }
      if (late) break;  // newest wins: a newer tool state is already in hand
      peer_ = from;     // authenticated: follow the operator if its address changed
      latest_ = message;
      state_seq_ = header.sequence;
      latest_send_time_ns_ = header.send_time_ns;
      if (latest_recv_ns_ != 0 && have_state_) {
        max_gap_ns_ = std::max(max_gap_ns_, now - latest_recv_ns_);
      }
      latest_recv_ns_ = now;
      have_state_ = true;
      fresh_state_ = true;
      break;
    }
    case wire::MessageType::kPing: {
      wire::PingMessage ping;
      if (const auto st = wire::DecodePing(body, ping); st != wire::DecodeStatus::kOk) {
        link_.CountBodyRejected(header.type, st);
        break;
      }
      // A Ping that arrived after a newer one (reordered) answers its Pong but does not replace
      // the newer round trip.
      if (!late) operator_rtt_ns_ = std::int64_t{ping.operator_rtt_us} * 1000;
      wire::PongMessage pong{header.sequence, header.send_time_ns, now};
      link_.Send(
          wire::EncodePong(link_.NextHeader(wire::MessageType::kPong, session_), pong, config_.key),
          peer_);
      break;
    }
    case wire::MessageType::kSceneNack: {
      wire::SceneNackMessage nack;
      if (const auto st = wire::DecodeSceneNack(body, nack); st != wire::DecodeStatus::kOk) {
        link_.CountBodyRejected(header.type, st);
        break;
      }
      if (scene_sender_.OnNack(nack)) {
        ++nacks_accepted_;
      } else {
        ++nacks_ignored_;
      }
      break;
    }
    case wire::MessageType::kDepthFieldNack: {
      wire::SceneNackMessage nack;
      if (const auto st = wire::DecodeDepthFieldNack(body, nack); st != wire::DecodeStatus::kOk) {
        link_.CountBodyRejected(header.type, st);
        break;
      }
      // Answered at once: the operator renders that contact from its linearization meanwhile.
      last_field_nack_ns_ = now;
      if (depth_fields_ && field_sender_.OnNack(nack)) SendQueuedFieldFragments();
      break;
    }
    case wire::MessageType::kGoodbye: {
      if (wire::DecodeEmpty(body) != wire::DecodeStatus::kOk) {
        link_.CountBodyRejected(header.type, wire::DecodeStatus::kTooLong);
        break;
      }
      ++goodbyes_;
      goodbye_session_ = session_;
      Close("the operator said goodbye");
      if (config_.exit_on_goodbye) return false;
      break;
    }
    default:
      break;  // Open() refuses every other type on this side
  }
  return true;
}

void RemoteSession::OnHello(const wire::Header& header, std::span<const std::uint8_t> body,
                            const SocketAddress& from, std::int64_t now) {
  wire::HelloMessage hello;
  if (const auto st = wire::DecodeHello(body, hello); st != wire::DecodeStatus::kOk) {
    link_.CountBodyRejected(header.type, st);
    return;
  }
  const bool live =
      session_ != 0 &&
      now - std::max(link_.last_authenticated_ns(), session_start_ns_) < peer_timeout_ns_;
  if (session_ != 0 && hello.client_nonce == session_nonce_) {
    // The operator retransmitted its Hello before our Welcome reached it (round trip longer than
    // its retry period): the same session, welcomed again (to the session's address only).
    ++hello_retransmits_;
    session_start_ns_ = now;  // an authenticated sign of life of this session's operator
    link_.Send(wire::EncodeWelcome(link_.NextHeader(wire::MessageType::kWelcome, session_),
                                   session_welcome_, config_.key),
               peer_);
    return;
  }
  if (pending_nonce_ != 0 && hello.client_nonce == pending_nonce_) {
    if (live) {  // still deferred: the current operator is active
      ++hello_deferred_;
      return;
    }
  } else {
    if (!nonces_.Insert(hello.client_nonce)) {  // a recorded Hello played again
      ++hello_replayed_;
      link_.CountBodyRejected(header.type, wire::DecodeStatus::kReplayed);
      return;
    }
    if (live) {
      // Another operator (or a recorded Hello this node never saw) while the current one is
      // active: deferred until the current session ends or goes silent, so that a replayed Hello
      // cannot take a live session over. The operator keeps retrying.
      pending_nonce_ = hello.client_nonce;
      ++hello_deferred_;
      return;
    }
  }
  pending_nonce_ = 0;
  wire::WelcomeMessage welcome;
  wire::RejectMessage reject;
  if (!NegotiateSession(hello, caps_, welcome, reject)) {
    ++rejects_sent_;
    link_.Send(
        wire::EncodeReject(link_.NextHeader(wire::MessageType::kReject, 0), reject, config_.key),
        from);
    std::printf("[slave] refused operator at %s: %.*s\n", from.ToString().c_str(),
                static_cast<int>(reject.text_length), reject.text.data());
    std::fflush(stdout);
    return;
  }
  if (session_ != 0) Close("replaced by a new session");
  std::uint32_t id = RandomSessionId();
  while (id == session_) id = RandomSessionId();
  link_.ResetSession();
  if (config_.start_sequences_at != 0) link_.StartSequencesAt(config_.start_sequences_at);
  session_ = id;
  goodbye_session_ = 0;
  session_nonce_ = hello.client_nonce;
  peer_ = from;
  ++sessions_;
  peer_timeout_ns_ = std::int64_t{welcome.peer_timeout_ms} * 1000000;
  model_period_ns_ =
      welcome.model_rate_hz > 0.0f ? static_cast<std::int64_t>(1e9 / welcome.model_rate_hz) : 0;
  try {
    scene_sender_.SetMtu(welcome.mtu);
  } catch (const std::invalid_argument& e) {
    std::printf("[slave] scene not streamed at MTU %u: %s\n", welcome.mtu, e.what());
    welcome.scene_objects = 0;
  }
  scene_enabled_ = welcome.scene_objects > 0;
  operator_confirmed_ = false;
  if (scene_enabled_) scene_sender_.QueueAll();
  scene_tokens_ = 0.0;
  session_start_ns_ = now;
  session_welcome_ = welcome;
  ContactModelDeadbandConfig deadband = config_.model_deadband;
  deadband.weber_fraction = welcome.deadband.model_deadband;
  deadband.keepalive_s = welcome.deadband.model_keepalive_ms * 1e-3;
  model_deadband_.Configure(deadband);
  tool_state_deadband_ = welcome.deadband.tool_state_deadband > 0.0f;
  tool_state_keepalive_ns_ = std::int64_t{welcome.deadband.tool_state_keepalive_ms} * 1000000;
  model_keepalive_ns_ = std::int64_t{welcome.deadband.model_keepalive_ms} * 1000000;
  compact_models_ = (welcome.codecs & wire::kCodecCompactContactModel) != 0;
  depth_fields_ = (welcome.codecs & wire::kCodecDepthFields) != 0;
  field_sender_.Reset(welcome.mtu);
  have_step_pose_ = have_sent_model_ = model_pending_ = have_held_echo_ = false;
  operator_rtt_ns_ = 0;
  link_.Send(wire::EncodeWelcome(link_.NextHeader(wire::MessageType::kWelcome, session_), welcome,
                                 config_.key),
             peer_);
  SendManifest(now);
  std::printf(
      "[slave] session %08x opened for operator at %s (protocol v%u, mtu %u, grid %u, "
      "peer timeout %u ms, deadband tool states %.0f %% / contact models %.0f %%, %s models%s)\n",
      session_, from.ToString().c_str(), welcome.version, welcome.mtu, welcome.grid,
      welcome.peer_timeout_ms, 100.0 * welcome.deadband.tool_state_deadband,
      100.0 * welcome.deadband.model_deadband, compact_models_ ? "compact" : "float",
      !depth_fields_                                      ? ""
      : config_.pipeline.force_law == ForceLaw::kPressure ? " with depth fields, pressure law"
                                                          : " with depth fields");
  if (!depth_fields_ && config_.pipeline.force_law == ForceLaw::kPressure) {
    std::printf(
        "[slave] warning: the operator takes no depth fields (master_station "
        "--no-depth-fields), so this session renders the seed's law, not --force-law pressure\n");
  }
  std::fflush(stdout);
}

void RemoteSession::CheckPeerTimeout(std::int64_t now) {
  const std::int64_t last_heard = std::max(link_.last_authenticated_ns(), session_start_ns_);
  if (session_ != 0 && now - last_heard > peer_timeout_ns_) {
    ++peers_lost_;
    char why[96];
    std::snprintf(why, sizeof(why), "operator lost (nothing authenticated for %.0f ms)",
                  (now - last_heard) * 1e-6);
    Close(why);
    return;
  }
  if (session_ != 0 && link_.SequencesNearlyUsedUp()) {
    // One of this side's streams has nearly used its u32 sequence numbers: the operator reconnects
    // on the Goodbye, and the new session starts them again.
    ++sessions_renewed_;
    SayGoodbye();
    Close("a stream's sequence numbers are nearly used up; the operator reconnects");
  }
}

void RemoteSession::MaybeSendNodePoses(std::int64_t now) {
  if (session_ == 0 || !operator_confirmed_ || !scene_enabled_ || !config_.display_poses ||
      graph_version_ == 0) {
    return;
  }
  if (now - last_node_poses_ns_ < node_poses_period_ns_) return;
  last_node_poses_ns_ = now;
  const double scene_time_s = static_cast<double>(now - start_ns_) * 1e-9;
  config_.display_poses(scene_time_s, &node_poses_);
  if (node_poses_.empty()) return;
  wire::NodePosesMessage m;
  m.graph_version = graph_version_;
  m.scene_time_s = scene_time_s;
  for (std::size_t first = 0; first < node_poses_.size(); first += wire::kMaxNodePosesPerDatagram) {
    const std::size_t n =
        std::min<std::size_t>(wire::kMaxNodePosesPerDatagram, node_poses_.size() - first);
    m.count = static_cast<std::uint8_t>(n);
    std::copy_n(node_poses_.begin() + static_cast<std::ptrdiff_t>(first), n, m.poses.begin());
    link_.Send(wire::EncodeNodePoses(link_.NextHeader(wire::MessageType::kNodePoses, session_), m,
                                     config_.key),
               peer_);
  }
  ++node_pose_frames_;
  node_pose_entries_ += node_poses_.size();
}

void RemoteSession::StreamScene(std::int64_t now) {
  if (session_ == 0 || !operator_confirmed_) return;
  scene_tokens_ = std::min(
      token_cap_, scene_tokens_ + config_.scene_rate_bytes_per_s * (now - last_token_ns_) * 1e-9);
  last_token_ns_ = now;
  wire::SceneFragmentMessage fragment;
  while (scene_tokens_ > 0.0 && scene_sender_.Next(fragment)) {
    const wire::Datagram d = wire::EncodeSceneFragment(
        link_.NextHeader(wire::MessageType::kSceneFragment, session_), fragment, config_.key);
    link_.Send(d, peer_);
    scene_tokens_ -= static_cast<double>(d.size);
  }
  if (now - last_manifest_ns_ > 250000000) SendManifest(now);
}

RigidTransform RemoteSession::ToolPoseForStep(std::int64_t now) noexcept {
  if (!tool_state_deadband_) {
    step_extrapolation_ns_ = 0;
    return latest_.X_WT;
  }
  step_extrapolation_ns_ =
      std::clamp<std::int64_t>(now - latest_recv_ns_, 0, tool_state_keepalive_ns_);
  return ExtrapolatePose(latest_.X_WT, latest_.V_WT_W, step_extrapolation_ns_ * 1e-9);
}

const char* StepCauseName(StepCause cause) noexcept {
  switch (cause) {
    case StepCause::kWait:
      return "wait";
    case StepCause::kFirst:
      return "first";
    case StepCause::kToolState:
      return "tool_state";
    case StepCause::kSceneMoves:
      return "scene_moves";
    case StepCause::kModelPeriodEnd:
      return "model_period_end";
    case StepCause::kPoseMoved:
      return "pose_moved";
  }
  return "unknown";
}

StepCause RemoteSession::WhyStep(const RigidTransform& X_WT, bool scene_moves, double tool_motion_m,
                                 std::int64_t now) const noexcept {
  // Without depth fields, steps in contact follow the extrapolated pose as fast as they run (a
  // linearization answers a change only from the pose it was taken at: pacing them to the model
  // period raised fig75's device-force error from 3.7 to 5.0 %). With fields the operator
  // evaluates the surfaces at its own pose, and extrapolated steps come at most every
  // kFieldPoseStepPeriodNs.
  if (fresh_state_) return StepCause::kToolState;
  if (!have_step_pose_) return StepCause::kFirst;
  if (scene_moves) return StepCause::kSceneMoves;
  // A model held by the model period goes out at the period's end, stepped then at the newest
  // pose: a step before then, moved pose or not, could not go out either (stepping on every
  // pass of an extrapolated pose was a busy loop of 10 µs steps until the period's end).
  if (model_pending_) return ModelDueInNs(now) > 0 ? StepCause::kWait : StepCause::kModelPeriodEnd;
  if (AtLastStepPose(X_WT) || tool_motion_m < last_step_clearance_m_) return StepCause::kWait;
  if (depth_fields_ && now - last_step_ns_ < kFieldPoseStepPeriodNs) return StepCause::kWait;
  return StepCause::kPoseMoved;
}

bool RemoteSession::MaybeSendContactModel(wire::ContactModelMessage& out,
                                          const StepTimings& timings, std::uint64_t step_count,
                                          std::int64_t now,
                                          std::span<const DepthField* const> fields,
                                          std::span<const DepthField* const> kept_fields) {
  if (session_ == 0) return false;
  if (model_period_ns_ != 0 && now - last_model_sent_ns_ < model_period_ns_) {
    // Too soon after the last model: this one is not sent, and the next pass must step again
    // even if the pose has not changed, or it would never go out.
    model_pending_ = true;
    return false;
  }
  model_pending_ = false;
  if (model_deadband_.Decide(out.model, now, kept_fields) == DeadbandReason::kNotSent) {
    ++models_held_back_;
    // The model the operator holds answers this pose too, to within the deadband: its next
    // keep-alive echoes this tool state, so that the operator's model age stays the age of the
    // newest pose answered (not of the last pose whose model changed).
    held_echo_send_ns_ = latest_send_time_ns_ + step_extrapolation_ns_;
    held_answer_recv_ns_ = latest_recv_ns_ + step_extrapolation_ns_;
    have_held_echo_ = true;
    return false;
  }
  have_held_echo_ = false;
  // The pose the model answers is the tool state's extrapolated by step_extrapolation_ns_: its
  // operator time is the state's send time plus that, and it "arrived" as much later here, so
  // that the operator's round trip (now − echo − hold) stays the network's.
  out.tool_state_send_time_ns = latest_send_time_ns_ + step_extrapolation_ns_;
  out.remote_step_count = step_count;
  out.collision_us = static_cast<float>(timings.collision_us);
  out.texture_us = static_cast<float>(timings.texture_us);
  out.step_us = static_cast<float>(timings.total_us);
  last_sent_answer_recv_ns_ = latest_recv_ns_ + step_extrapolation_ns_;
  SendDepthFields(out.model, fields, now);
  SendModel(out, now);
  return true;
}

bool RemoteSession::MaybeSendKeepAlive(std::int64_t now) {
  if (session_ == 0 || !have_sent_model_ || now - last_model_sent_ns_ < model_keepalive_ns_) {
    return false;
  }
  ++keepalives_sent_;
  wire::ContactModelMessage again = last_sent_;
  if (have_held_echo_) {  // a newer pose was answered by the same model (deadband)
    again.tool_state_send_time_ns = held_echo_send_ns_;
    last_sent_answer_recv_ns_ = held_answer_recv_ns_;
  }
  SendModel(again, now);
  model_deadband_.NoteResent(now);
  return true;
}

void RemoteSession::SendQueuedFieldFragments() {
  wire::SceneFragmentMessage fragment;
  while (field_sender_.Next(fragment)) {
    link_.Send(wire::EncodeDepthFieldFragment(
                   link_.NextHeader(wire::MessageType::kDepthFieldFragment, session_), fragment,
                   config_.key),
               peer_);
  }
}

void RemoteSession::SendDepthFields(ContactModel& model, std::span<const DepthField* const> fields,
                                    std::int64_t now) {
  // A field whose fragments all have to arrive before the loop can use it: on a link that lost
  // some lately (the operator asked for a field again), each new field goes twice, so that one
  // lost fragment does not cost a round trip. At 20 % loss a field of 10 fragments arrives whole
  // with one copy 11 % of the time, with two 66 %.
  constexpr std::int64_t kFieldCopiesAfterNackNs = 2'000'000'000;
  const bool twice = now - last_field_nack_ns_ < kFieldCopiesAfterNackNs;
  const int n = std::clamp(model.num_contacts, 0, wire::kMaxWireContacts);
  for (int i = 0; i < n; ++i) {
    std::uint32_t& id = model.contacts[static_cast<std::size_t>(i)].depth_field_id;
    if (id == 0) continue;
    if (!depth_fields_) {  // the operator does not take fields: its linearization alone
      id = 0;
      continue;
    }
    if (field_sender_.Named(id)) continue;
    const auto it = std::find_if(fields.begin(), fields.end(),
                                 [id](const DepthField* f) { return f != nullptr && f->id == id; });
    if (it == fields.end()) {
      id = 0;
      ++contacts_without_field_;
      continue;
    }
    const std::int64_t t0 = SteadyNowNs();
    std::vector<std::uint8_t> bytes;
    try {
      bytes = EncodeDepthField(**it);
    } catch (const std::invalid_argument&) {  // a field the codec cannot carry: none for it
      id = 0;
      ++contacts_without_field_;
      continue;
    }
    field_encode_ms_ += static_cast<double>(SteadyNowNs() - t0) * 1e-6;
    ++fields_encoded_;
    field_bytes_encoded_ += bytes.size();
    field_sender_.Add(id, std::move(bytes));
    if (twice) {
      SendQueuedFieldFragments();
      field_sender_.QueueAgain(id);
      ++fields_sent_twice_;
    }
  }
  SendQueuedFieldFragments();
}

void RemoteSession::SendModel(wire::ContactModelMessage& out, std::int64_t now) {
  const wire::MessageType type =
      compact_models_ ? wire::MessageType::kCompactContactModel : wire::MessageType::kContactModel;
  wire::Header header = link_.NextHeader(type, session_);
  out.hold_ns = header.send_time_ns - last_sent_answer_recv_ns_;
  // The field ids that fit the datagram go (contact by contact); the rest are counted (a float
  // model of more than 11 contacts).
  const int contacts = std::clamp(out.model.num_contacts, 0, wire::kMaxWireContacts);
  int field_ids = 0;
  for (int i = 0; i < contacts; ++i) {
    field_ids += out.model.contacts[static_cast<std::size_t>(i)].depth_field_id != 0 ? 1 : 0;
  }
  const int fit = compact_models_ ? wire::DepthFieldIdCapacity(wire::kCompactContactModelFixedBytes,
                                                               wire::kCompactContactBytes, contacts)
                                  : wire::DepthFieldIdCapacity(wire::kContactModelFixedBytes,
                                                               wire::kContactBytes, contacts);
  field_ids_left_out_ += static_cast<std::uint64_t>(std::max(field_ids - fit, 0));
  link_.Send(compact_models_ ? wire::EncodeCompactContactModel(header, out, config_.key)
                             : wire::EncodeContactModel(header, out, config_.key),
             peer_);
  last_model_sent_ns_ = now;
  last_sent_ = out;
  have_sent_model_ = true;
}

void RemoteSession::RefuseForeignHello(std::span<const std::uint8_t> datagram,
                                       const SocketAddress& from) {
  wire::ForeignHello hello;
  if (wire::OpenForeignHello(datagram, config_.key, hello) != wire::DecodeStatus::kOk) return;
  if (!nonces_.Insert(hello.client_nonce)) {  // a recorded Hello played again: no answer
    ++hello_replayed_;
    return;
  }
  ++foreign_hellos_;
  const wire::RejectMessage reject =
      MakeVersionReject(hello.client_nonce, hello.min_version, hello.max_version);
  ++rejects_sent_;
  link_.Send(wire::EncodeReject(link_.NextHeader(wire::MessageType::kReject, 0), reject,
                                config_.key, hello.header_version),
             from);
  std::printf("[slave] refused an operator of protocol v%u at %s\n", hello.header_version,
              from.ToString().c_str());
  std::fflush(stdout);
}

void RemoteSession::SayGoodbye() {
  if (session_ == 0) return;
  for (int i = 0; i < 3; ++i) {
    link_.Send(
        wire::EncodeGoodbye(link_.NextHeader(wire::MessageType::kGoodbye, session_), config_.key),
        peer_);
  }
}

void RemoteSession::SendManifest(std::int64_t now) {
  if (!scene_enabled_) return;
  for (const wire::SceneManifestMessage& m : scene_sender_.Manifest()) {
    link_.Send(wire::EncodeSceneManifest(
                   link_.NextHeader(wire::MessageType::kSceneManifest, session_), m, config_.key),
               peer_);
  }
  last_manifest_ns_ = now;
}

void RemoteSession::Close(const char* why) {
  std::printf("[slave] session %08x closed: %s\n", session_, why);
  std::fflush(stdout);
  session_ = 0;
  have_state_ = false;
}

nlohmann::json RemoteSession::StatsJson(std::size_t scene_objects, std::size_t scene_bytes) const {
  nlohmann::json transport = link_.StatsJson();
  nlohmann::json steps_by_cause = nlohmann::json::object();
  for (int c = 1; c < kStepCauses; ++c) {
    steps_by_cause[StepCauseName(static_cast<StepCause>(c))] = steps_by_cause_[c];
  }
  transport["sessions"] = sessions_;
  transport["goodbyes"] = goodbyes_;
  transport["goodbye_copies"] = goodbye_copies_;
  transport["sessions_renewed"] = sessions_renewed_;
  transport["peers_lost"] = peers_lost_;
  transport["hello_replayed"] = hello_replayed_;
  transport["hello_retransmits"] = hello_retransmits_;
  transport["hello_deferred"] = hello_deferred_;
  transport["rejects_sent"] = rejects_sent_;
  transport["foreign_version_hellos"] = foreign_hellos_;
  transport["deadband"] = ToJson(session_welcome_.deadband);
  transport["deadband"].update(
      nlohmann::json{{"compact_models", compact_models_},
                     {"models_held_back", models_held_back_},
                     {"steps_skipped", steps_skipped_},
                     {"steps_by_cause", steps_by_cause},
                     {"keepalives_sent", keepalives_sent_},
                     {"model_decisions", ToJson(model_deadband_.counts())}});
  transport["depth_fields"] = {
      {"agreed", depth_fields_},
      {"force_law", config_.pipeline.force_law == ForceLaw::kPressure ? "pressure" : "seed"},
      {"fields_sent", fields_encoded_},
      {"field_ids_left_out", field_ids_left_out_},
      {"field_bytes", field_bytes_encoded_},
      {"encode_ms_mean", fields_encoded_ > 0 ? field_encode_ms_ / fields_encoded_ : 0.0},
      {"fragments_sent", field_sender_.fragments_sent()},
      {"nacks_answered", field_sender_.nacks_answered()},
      {"nacks_refused", field_sender_.nacks_refused()},
      {"fields_sent_twice", fields_sent_twice_},
      {"contacts_without_field", contacts_without_field_}};
  transport["mtu"] = config_.mtu;
  transport["node_poses"] = {{"rate_hz", config_.display_rate_hz},
                             {"graph_version", graph_version_},
                             {"frames_sent", node_pose_frames_},
                             {"entries_sent", node_pose_entries_}};
  transport["scene"] = {{"objects", scene_objects},
                        {"bytes", scene_bytes},
                        {"fragment_payload_bytes", scene_sender_.payload_bytes()},
                        {"nacks_accepted", nacks_accepted_},
                        {"nacks_ignored", nacks_ignored_},
                        {"fragments_queued_at_end", scene_sender_.queued()}};
  return transport;
}

}  // namespace ht
