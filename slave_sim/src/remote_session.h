#pragma once
// The remote node's side of the session protocol (docs/DESIGN.md §6, transport/protocol.h): one
// operator session at a time, opened by an authenticated Hello with a fresh nonce, welcomed or
// refused after negotiation (transport/session.h), closed on Goodbye or when the operator is
// silent for the peer timeout; the newest tool state kept for the next remote step; pings
// answered, and the round trip they report kept; scene fragments paced and NACKs served; contact
// models sent at the negotiated rate.
// Private to slave_sim: RunRemoteNode (remote_node.cc) drives it.

#include <cstdint>
#include <limits>
#include <nlohmann/json.hpp>
#include <span>
#include <vector>

#include "haptic_core/depth_field.h"
#include "slave_sim/remote_node_config.h"
#include "transport/depth_field_stream.h"
#include "transport/link.h"
#include "transport/messages.h"
#include "transport/scene_stream.h"
#include "transport/session.h"

namespace ht {

/// Why the remote node stepped on a loop pass, or kWait when it waited on its socket instead
/// (RemoteSession::WhyStep). Reported per cause in remote_summary.json
/// (transport.deadband.steps_by_cause, names from StepCauseName).
enum class StepCause : int {
  kWait = 0,        ///< no step: nothing new since the last one
  kFirst,           ///< the session's first step
  kToolState,       ///< a tool state arrived since the last step
  kSceneMoves,      ///< the scene is animated (--animate)
  kModelPeriodEnd,  ///< the last step's model was held by the model period, which has passed
  kPoseMoved,       ///< the extrapolated pose moved out of the last step's free space
};
inline constexpr int kStepCauses = 6;
/// With depth fields agreed, the shortest time (ns) between two steps on an extrapolated pose
/// (StepCause::kPoseMoved); a tool state is always stepped at once. In the lockstep (gear and
/// Fig. 76 at 25 ms, gear at 150 ms with 10 % loss) 10 ms left the device force within 0.1
/// point of stepping every millisecond and cut the contact-model stream 2.3–3.1×; 50 ms doubled
/// the gear's error at 25 ms.
inline constexpr std::int64_t kFieldPoseStepPeriodNs = 10'000'000;
/// The cause's name in remote_summary.json ("wait", "first", "tool_state", "scene_moves",
/// "model_period_end", "pose_moved").
const char* StepCauseName(StepCause cause) noexcept;

/// Session state and counters of the remote node. Not thread-safe: one thread (the node's loop)
/// calls everything. Sends through `link` to the session's operator; never throws after
/// construction except std::bad_alloc from the scene sender's queue.
class RemoteSession {
 public:
  /// Keeps references to `config`, `link` and `scene_sender`, which must outlive the session.
  /// `caps` is what this node offers in negotiation; `start_ns` the node's start (local clock,
  /// SteadyNowNs()), from which the scene stream's pacing budget accrues.
  RemoteSession(const RemoteNodeConfig& config, SecureLink& link, SceneSender& scene_sender,
                const RemoteCapabilities& caps, std::int64_t start_ns);

  /// Handles one received datagram from `from` at local time `now_ns` (ns, SteadyNowNs()).
  /// Datagrams that fail to open or decode are counted by the link and dropped. Returns false
  /// when the node should stop (a Goodbye with config.exit_on_goodbye).
  bool OnDatagram(std::span<const std::uint8_t> datagram, const SocketAddress& from,
                  std::int64_t now_ns);
  /// Closes the session when nothing authenticated has come from the operator for the peer
  /// timeout (counted in peers_lost), or, after a Goodbye, when one of this side's streams has
  /// nearly used its sequence numbers (SecureLink::SequencesNearlyUsedUp; sessions_renewed).
  void CheckPeerTimeout(std::int64_t now_ns);
  /// Sends scene fragments as the pacing budget (config.scene_rate_bytes_per_s) allows, and the
  /// manifest every 250 ms. Only while a session is open and the operator has shown that it holds
  /// the Welcome (a datagram of the session other than a Hello has come from it).
  void StreamScene(std::int64_t now_ns);
  /// Sends the moving scene nodes' local poses (config.display_poses at the node's clock) as one
  /// NodePoses frame (as many datagrams as the nodes need) every 1/config.display_rate_hz, while
  /// a session that takes the scene is open. Allocates nothing once the pose buffer has grown.
  void MaybeSendNodePoses(std::int64_t now_ns);
  /// The scene graph object's version that NodePoses name (after a new version was queued).
  void SetGraphVersion(std::uint32_t version) noexcept { graph_version_ = version; }
  /// The scene changed (a rebuilt file): the next Welcome offers `layout`, the next pass steps
  /// (even at an unchanged pose) and the manifest goes out at once.
  void SceneChanged(const wire::SceneLayout& layout) noexcept {
    caps_.layout = layout;
    have_step_pose_ = false;
    last_manifest_ns_ = 0;
  }
  /// The tool pose the next remote step uses at `now_ns` (ns, SteadyNowNs()): with the
  /// session's tool-state deadband on, the newest tool state extrapolated at its own twist for
  /// the time since it arrived (ExtrapolatePose, the prediction the operator's deadband makes;
  /// at most the tool-state keep-alive ahead, then held); without it, the newest state as is.
  RigidTransform ToolPoseForStep(std::int64_t now_ns) noexcept;
  /// Why the remote node steps on a loop pass (StepCause), or kWait when a step at X_WT (from
  /// ToolPoseForStep) would see nothing new, so the node waits on its socket instead.
  /// In order:
  /// - kToolState: a tool state arrived since the last step (always stepped, so that its answer
  ///   and its echo go out); kFirst: no step yet; kSceneMoves: the scene is animated.
  /// - a model held by the model period (its step came less than a period after the last model
  ///   sent): kWait until the period's end at `now_ns` + ModelDueInNs(now_ns), whatever the
  ///   pose (a step before then could not go out either), then kModelPeriodEnd at the newest
  ///   pose.
  /// - kWait when X_WT is the last step's pose, or when the last step was in free space and no
  ///   tool point has moved as far since (`tool_motion_m`, the pipeline's ToolMotionBound from
  ///   the last step's pose to X_WT, below that step's StepTimings::free_space_clearance_m: the
  ///   same empty model), or, with depth fields agreed, when the last step came less than
  ///   kFieldPoseStepPeriodNs ago (the operator evaluates the fields at its own pose; a new step
  ///   on the extrapolated pose only moves their q0); kPoseMoved otherwise (an extrapolated pose
  ///   in contact, or out of the last step's free space).
  StepCause WhyStep(const RigidTransform& X_WT, bool scene_moves, double tool_motion_m,
                    std::int64_t now_ns) const noexcept;
  /// Time (ns) until a model held by the model period may go out: 0 when none is held or the
  /// period has passed.
  std::int64_t ModelDueInNs(std::int64_t now_ns) const noexcept {
    if (!model_pending_) return 0;
    const std::int64_t due = last_model_sent_ns_ + model_period_ns_ - now_ns;
    return due > 0 ? due : 0;
  }
  /// The pose of the last step (identity before the first).
  const RigidTransform& last_step_pose() const noexcept { return last_step_pose_; }
  /// X_WT is exactly the last step's pose (a step there would give the same model).
  bool AtLastStepPose(const RigidTransform& X_WT) const noexcept {
    return X_WT.translation == last_step_pose_.translation &&
           X_WT.rotation == last_step_pose_.rotation;
  }
  /// Counts a loop pass that did not step (WhyStep gave kWait).
  void CountSkippedStep() noexcept { ++steps_skipped_; }
  /// Counts a step by its cause (WhyStep), reported in StatsJson's "steps_by_cause".
  void CountStep(StepCause cause) noexcept { ++steps_by_cause_[static_cast<int>(cause)]; }
  /// Records that a step ran at X_WT at `now_ns` (the newest tool state is then used) and found
  /// `free_space_clearance_m` (StepTimings) of free space around the tool.
  void SteppedAt(const RigidTransform& X_WT, double free_space_clearance_m,
                 std::int64_t now_ns) noexcept {
    fresh_state_ = false;
    last_step_ns_ = now_ns;
    last_step_pose_ = X_WT;
    last_step_clearance_m_ = free_space_clearance_m;
    have_step_pose_ = true;
  }
  /// Sends `out` (its model filled by the step at the pose ToolPoseForStep gave) unless the
  /// negotiated model period since the last one sent has not passed at `now_ns` or the session's
  /// contact-model deadband holds it back; fills its timing fields from `timings`, its step
  /// count, its echo of the tool state (send time plus the extrapolation, so that the operator's
  /// model age is the age of the pose answered) and its hold time. Sends in the compact encoding
  /// when both sides have it. Returns true when sent.
  /// With depth fields agreed, the fields the model names that this session has not sent yet
  /// (from `fields`, the step's HapticTexturePipeline::last_depth_fields()) are encoded and
  /// their DepthFieldFragments sent first; a contact naming a field not in `fields` goes
  /// without one. `kept_fields` (HapticTexturePipeline::kept_depth_fields()) are the fields the
  /// deadband evaluates both models with (ContactModelDeadband::Decide).
  bool MaybeSendContactModel(wire::ContactModelMessage& out, const StepTimings& timings,
                             std::uint64_t step_count, std::int64_t now_ns,
                             std::span<const DepthField* const> fields = {},
                             std::span<const DepthField* const> kept_fields = {});
  /// While steps wait (WhyStep gave kWait): sends the last model again (new header, same
  /// content) when the contact-model keep-alive has passed, echoing the newest tool state whose
  /// step gave a model the deadband held back (it answers that state too, to within the
  /// deadband). Returns true when sent.
  bool MaybeSendKeepAlive(std::int64_t now_ns);
  /// Tells the operator the node is stopping (three Goodbyes), when a session is open.
  void SayGoodbye();

  /// A session is open.
  bool open() const noexcept { return session_ != 0; }
  /// The open session's operator takes depth fields (both sides set kCodecDepthFields).
  bool depth_fields() const noexcept { return session_ != 0 && depth_fields_; }
  /// A tool state has arrived in the open session (the node steps only then).
  bool have_tool_state() const noexcept { return have_state_; }
  /// The newest tool state of the session and its sequence number (the contact model's q0 tag).
  const wire::ToolStateMessage& latest_tool_state() const noexcept { return latest_; }
  std::uint64_t latest_tool_state_seq() const noexcept { return state_seq_; }
  /// Longest gap between two tool states of one session (ns).
  std::int64_t tool_state_gap_max_ns() const noexcept { return max_gap_ns_; }
  /// The round trip the operator's newest Ping reported (ns, PingMessage::operator_rtt_us; 0:
  /// none yet in this session, or the operator has not measured one yet).
  std::int64_t operator_rtt_ns() const noexcept { return operator_rtt_ns_; }

  /// The link's statistics with the session counters (sessions, goodbyes, peers lost, Hello
  /// replays, retransmits, deferrals, rejects) and the scene stream's, for the run summary.
  nlohmann::json StatsJson(std::size_t scene_objects, std::size_t scene_bytes) const;

 private:
  void OnHello(const wire::Header& header, std::span<const std::uint8_t> body,
               const SocketAddress& from, std::int64_t now_ns);
  void RefuseForeignHello(std::span<const std::uint8_t> datagram, const SocketAddress& from);
  void SendModel(wire::ContactModelMessage& out, std::int64_t now_ns);
  /// Encodes and queues the fields `model` names that the operator was not sent (from `fields`),
  /// and sends every queued DepthFieldFragment.
  void SendDepthFields(ContactModel& model, std::span<const DepthField* const> fields,
                       std::int64_t now_ns);
  void SendQueuedFieldFragments();
  void SendManifest(std::int64_t now_ns);
  void Close(const char* why);

  const RemoteNodeConfig& config_;
  SecureLink& link_;
  SceneSender& scene_sender_;
  RemoteCapabilities caps_;
  NonceHistory nonces_;

  std::uint32_t session_ = 0;
  // The session the operator's Goodbye closed (0: none since the last Hello): the copies of that
  // Goodbye (it is sent three times) and datagrams sent before it are its session's, not
  // rejections.
  std::uint32_t goodbye_session_ = 0;
  std::uint64_t session_nonce_ = 0, pending_nonce_ = 0;
  std::int64_t session_start_ns_ = 0;
  wire::WelcomeMessage session_welcome_;
  SocketAddress peer_;
  std::int64_t peer_timeout_ns_ = 0, model_period_ns_ = 0, last_model_sent_ns_ = 0;
  bool scene_enabled_ = false;
  /// A datagram of this session (not a Hello) came from the operator: it holds the Welcome.
  bool operator_confirmed_ = false;
  double scene_tokens_ = 0.0;
  std::int64_t last_token_ns_ = 0, last_manifest_ns_ = 0;
  double token_cap_ = 0.0;

  // Perceptual deadband (transport/deadband.h) of this session.
  ContactModelDeadband model_deadband_{{}};
  bool tool_state_deadband_ = false, compact_models_ = false, fresh_state_ = false;
  bool have_step_pose_ = false, have_sent_model_ = false;
  bool model_pending_ = false;  ///< the last step's model was held by the model period
  std::int64_t tool_state_keepalive_ns_ = 0, model_keepalive_ns_ = 0;
  std::int64_t step_extrapolation_ns_ = 0;  ///< of the pose the newest step used
  RigidTransform last_step_pose_;
  double last_step_clearance_m_ = 0.0;  ///< StepTimings::free_space_clearance_m of the last step
  std::int64_t last_step_ns_ = 0;       ///< when the last step ran (local clock, ns)
  wire::ContactModelMessage last_sent_;
  std::int64_t last_sent_answer_recv_ns_ = 0;  ///< receive time + extrapolation of its pose
  /// The newest step whose model the deadband held back (the same model to within it): its tool
  /// state's echo and answer time, which the next keep-alive carries.
  std::int64_t held_echo_send_ns_ = 0, held_answer_recv_ns_ = 0;
  bool have_held_echo_ = false;
  std::uint64_t steps_skipped_ = 0, models_held_back_ = 0, keepalives_sent_ = 0;
  std::uint64_t steps_by_cause_[kStepCauses] = {};
  std::uint64_t foreign_hellos_ = 0;
  /// Depth-field ids of models sent that did not fit their datagram (protocol.h
  /// DepthFieldIdCapacity): those contacts reached the operator without their field.
  std::uint64_t field_ids_left_out_ = 0;
  // Display poses (NodePoses) of the moving scene nodes.
  std::int64_t start_ns_ = 0;  ///< the node's start: the scene's clock (animate) counts from it
  std::uint32_t graph_version_ = 0;  ///< version of the kSceneGraph object (0 = none streamed)
  std::int64_t node_poses_period_ns_ = 0, last_node_poses_ns_ = 0;
  std::vector<wire::NodePose> node_poses_;
  std::uint64_t node_pose_frames_ = 0, node_pose_entries_ = 0;

  bool have_state_ = false;
  std::uint64_t state_seq_ = 0;
  wire::ToolStateMessage latest_;
  std::int64_t latest_send_time_ns_ = 0, latest_recv_ns_ = 0, max_gap_ns_ = 0;
  std::int64_t operator_rtt_ns_ = 0;

  std::uint64_t goodbye_copies_ = 0;  // Goodbyes of goodbye_session_ after the first
  std::uint64_t sessions_ = 0, goodbyes_ = 0, peers_lost_ = 0, hello_replayed_ = 0;
  std::uint64_t sessions_renewed_ = 0;
  std::uint64_t hello_retransmits_ = 0, hello_deferred_ = 0, rejects_sent_ = 0;
  std::uint64_t nacks_accepted_ = 0, nacks_ignored_ = 0;
  // Depth fields (kCodecDepthFields): agreed for this session, their sender, and counters.
  bool depth_fields_ = false;
  DepthFieldSender field_sender_{wire::kMaxDatagramBytes, 2 * kMaxContacts};
  std::uint64_t fields_encoded_ = 0, field_bytes_encoded_ = 0, contacts_without_field_ = 0;
  /// When the operator last asked for a field again (DepthFieldNack): the link loses datagrams,
  /// and for kFieldCopiesAfterNackNs after it a new field goes twice (fields_sent_twice_).
  std::int64_t last_field_nack_ns_ = std::numeric_limits<std::int64_t>::min() / 2;
  std::uint64_t fields_sent_twice_ = 0;
  double field_encode_ms_ = 0.0;
};

}  // namespace ht
