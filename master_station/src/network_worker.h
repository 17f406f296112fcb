#pragma once
// The operator station's network side (one concern of RunOperatorStation): the session
// (Hello until Welcome, heartbeat, loss and reconnect), the tool-state and contact-model streams
// through lock-free hand-offs with the haptic loop, and the scene stream's reassembly and repair.
// Internal to master_station.

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <nlohmann/json.hpp>
#include <span>
#include <string>
#include <vector>

#include "codecs/depth_map_codec.h"
#include "haptic_core/depth_field.h"
#include "haptic_core/steady_clock.h"
#include "master_station/lock_free.h"
#include "master_station/received_scene.h"
#include "master_station/station_config.h"
#include "transport/deadband.h"
#include "transport/depth_field_stream.h"
#include "transport/link.h"
#include "transport/messages.h"
#include "transport/scene_stream.h"
#include "transport/session.h"

namespace ht::station {

struct OutgoingToolState {
  wire::ToolStateMessage message;
  std::int64_t time_ns = 0;
  std::uint64_t sequence = 0;
  /// The tick's held contact model has contacts: the tool-state deadband's contact floors apply.
  bool near_contact = false;
};

struct IncomingModel {
  wire::ContactModelMessage message;
  std::uint32_t field_epoch = 0;  ///< the session's epoch (FieldHandoff)
  std::uint64_t sequence = 0;
  std::int64_t built_local_ns = 0;  ///< when the remote node sent it, on the local clock
};

/// Depth fields from the network worker to the haptic loop, with no copy and no allocation on
/// the loop: the worker decodes each field that arrived whole into a DepthField taken from
/// `free` and hands its pointer on through `ready`; the loop gives every pointer it took back
/// through `free` after its tick (OperatorTickInput::arrived_fields: the pointer then holds the
/// buffers of the field its cache evicted).
///
/// Each field and each model carries the session's epoch (the network worker counts sessions): a
/// remote node restarted under the same station names its fields from 1 again, so the loop forgets
/// the fields it holds when the first field or model of a newer epoch comes, and drops fields of
/// an older one. `missing` carries back the ids of fields the loop's model names and it lacks (a
/// field its cache evicted, or that never came), which the network worker asks for again.
struct FieldHandoff {
  static constexpr std::size_t kFields = 16;
  struct Handed {
    DepthField* field = nullptr;
    std::uint32_t epoch = 0;
  };
  FieldHandoff() : ready(kFields), free(kFields), missing(64) {
    pool.reserve(kFields);
    for (std::size_t i = 0; i < kFields; ++i) {
      pool.push_back(std::make_unique<DepthField>());
      free.Push(pool.back().get());
    }
  }
  std::vector<std::unique_ptr<DepthField>> pool;
  SpscRing<Handed> ready;
  SpscRing<DepthField*> free;
  SpscRing<std::uint32_t> missing;
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
  /// `scene` receives the decoded scene and the moving nodes' poses (for the display).
  /// `fields` receives the contacts' depth fields (when the session agreed them).
  NetworkWorker(const StationConfig& config, TripleBuffer<OutgoingToolState>& outgoing,
                TripleBuffer<IncomingModel>& incoming, Counters& counters, ReceivedScene& scene,
                FieldHandoff& fields);

  /// Runs the network side until `stop`, with the depth fields' decoder on a thread of its own.
  void Run(const std::atomic<bool>& stop);

  const std::vector<double>& rtt_ms() const { return rtt_ms_; }
  const std::vector<double>& one_way_ms() const { return one_way_ms_; }
  const std::vector<double>& remote_step_us() const { return remote_step_us_; }
  const std::vector<double>& contact_step_us() const { return contact_step_us_; }
  const std::vector<double>& collision_us() const { return collision_us_; }
  const std::vector<double>& texture_us() const { return texture_us_; }
  double RemoteRateHz() const;
  SocketAddress local_address() const { return socket_.local_address(); }
  const std::string& reject_text() const { return reject_text_; }
  /// The scene layout of the last Welcome (read once the session is connected).
  wire::SceneLayout layout() const;
  std::uint64_t rejected_total() const { return link_.rejected_total(); }

  /// The transport's part of summary.json (call after the thread has stopped).
  nlohmann::json Summary() const;

 private:
  /// Sends (or resends) the Hello of the current connection attempt. One attempt keeps its nonce
  /// over retransmissions, so that a round trip longer than the reconnect period still completes:
  /// the remote node answers a repeated nonce with the same session.
  void SendHello();
  /// The network loop of Run.
  void RunNetwork(const std::atomic<bool>& stop);

  void EndSession();
  /// Goodbye three times (new sequence numbers each) when a session is open.
  void SayGoodbye();

  void Handle(std::span<const std::uint8_t> datagram, const SocketAddress& from);

  /// When the whole scene has arrived and matches the manifest (and again whenever an object's
  /// new version completes), decode every object (the graph, Draco meshes, images) and publish
  /// them to the received scene.
  void CheckScene(std::int64_t now);

  /// A DepthFieldFragment: reassembled; a field that arrived whole goes to the decoder thread.
  void OnDepthFieldFragment(const wire::SceneFragmentMessage& fragment, std::int64_t now);
  /// The decoder thread: decodes (and prepares) each encoded field into a DepthField from the
  /// hand-off's free ring and hands it to the loop, so that the network thread never waits on a
  /// field's milliseconds of decoding. Says each field's outcome back (DecodedField).
  void DecodeFields(const std::atomic<bool>& stop);
  /// The decoder's outcomes: a field handed to the loop is held; one that did not decode is held
  /// too (asking again would not help); one that found no buffer is asked for again.
  void TakeDecodedFields();

  /// Sends `s` as the session agreed: CompactToolState (quantized from s as it is) or ToolState.
  void Send(const OutgoingToolState& s);
  /// The tool state `m` as the remote node will decode it in this session (the compact encoding's
  /// rounding, or `m` itself): what the tool-state deadband predicts from.
  wire::ToolStateMessage AsReceived(const wire::ToolStateMessage& m) const noexcept;

  const StationConfig& config_;
  UdpSocket socket_;
  SecureLink link_;
  SceneReassembler reassembler_;
  ClockSync clock_;
  TripleBuffer<OutgoingToolState>& outgoing_;
  TripleBuffer<IncomingModel>& incoming_;
  Counters& counters_;
  ReceivedScene& scene_;
  bool scene_dirty_ = false;  ///< an object completed since the scene was last published
  std::uint64_t scene_versions_published_ = 0;
  std::vector<double> node_pose_latency_ms_;
  /// Per object id: the version in transfer and when its first fragment arrived (local ns).
  std::map<std::uint32_t, std::pair<std::uint32_t, std::int64_t>> object_first_fragment_;
  /// Transfer times (first fragment to complete, ms) of first versions and of later ones.
  std::vector<double> transfer_ms_, update_transfer_ms_;
  /// Decoded meshes by object id (with their version), so that an update decodes only what changed.
  std::map<std::uint32_t, ReceivedSceneContent::Mesh> decoded_meshes_;
  std::uint32_t session_ = 0;
  /// The tool-state stream's perceptual deadband, as agreed in the Welcome.
  ToolStateDeadband tool_deadband_{{}};
  /// The newest contact model received (the loop renders from it or blends towards it), for the
  /// tool-state deadband's depth criterion (ToolStateDeadbandConfig::contact_depth_floor_scale_m).
  /// Written and read on the network thread only.
  ContactModel held_model_{};
  wire::DeadbandTerms deadband_agreed_;
  bool compact_models_ = false;
  bool compact_tool_states_ = false;  ///< agreed in Welcome
  std::uint64_t tool_states_offered_ = 0, tool_states_held_back_ = 0, idle_keepalives_ = 0;
  std::uint64_t hello_nonce_ = 0;
  std::int64_t attempt_start_ns_ = 0;
  /// First Hello of the attempt to its Welcome (ns): the round trip until Ping/Pong measure it
  /// (an over-estimate when a Hello was retransmitted, which only delays the first repairs).
  std::int64_t handshake_rtt_ns_ = 0;
  // The round trip the last Ping told the remote node (µs, PingMessage::operator_rtt_us), and the
  // smallest and largest non-zero one told.
  std::uint32_t reported_rtt_us_ = 0;
  std::uint32_t reported_rtt_min_us_ = 0xFFFF'FFFFu, reported_rtt_max_us_ = 0;
  std::int64_t heartbeat_ns_ = 100000000, peer_timeout_ns_ = 500000000, session_start_ns_ = 0;
  std::uint64_t sessions_ = 0, peers_lost_ = 0, remote_goodbyes_ = 0, hellos_sent_ = 0;
  std::uint64_t sessions_renewed_ = 0;  // ended because a stream's sequence numbers ran low
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
  /// The remote node's steps since the first model, counted modulo 2³² between models (a compact
  /// model carries the low 32 bits of its step count; a count that goes back is a restarted
  /// node's, counted from its 0), and the last model's low 32 bits.
  std::uint64_t remote_steps_ = 0;
  std::uint32_t last_remote_steps_low_ = 0;
  // Depth fields (kCodecDepthFields, agreed in the Welcome): reassembly (network thread),
  // decoding (decoder thread), hand-off to the loop.
  FieldHandoff& fields_;
  bool depth_fields_ = false;
  DepthFieldReassembler field_reassembler_;
  /// An encoded field on its way to the decoder thread, and the decoder's outcome for it.
  struct EncodedField {
    std::uint32_t id = 0;
    std::uint32_t epoch = 0;
    std::vector<std::uint8_t> bytes;
  };
  /// Sessions opened so far: the epoch of their fields and models (FieldHandoff).
  std::uint32_t field_epoch_ = 0;
  std::uint64_t fields_missing_in_loop_ = 0;
  enum class DecodeOutcome : std::uint8_t { kHanded, kUndecodable, kNoBuffer };
  struct DecodedField {
    std::uint32_t id = 0;
    DecodeOutcome outcome = DecodeOutcome::kHanded;
  };
  static constexpr std::size_t kEncodedFields = 8;
  std::vector<std::unique_ptr<EncodedField>> encoded_pool_;
  SpscRing<EncodedField*> to_decode_{kEncodedFields}, encoded_free_{kEncodedFields};
  SpscRing<DecodedField> decoded_{2 * kEncodedFields};
  // Written by the decoder thread only (read after it stopped).
  DepthField* spare_field_ = nullptr;  ///< taken from the free ring, not handed on yet
  DecodedDepthMap field_scratch_;
  std::vector<double> field_decode_ms_;
  std::string first_decode_error_;
  // Network thread: the ids with the decoder, and the newest model that names one of them (it
  // goes to the loop once they are decoded, so that the loop has a model's fields when it takes
  // the model).
  std::vector<std::uint32_t> decoding_ids_;
  IncomingModel model_waiting_;
  bool have_model_waiting_ = false;
  std::uint64_t models_waited_for_fields_ = 0;
  /// Whether `model` names a field the decoder has not finished.
  bool NamesFieldInDecoding(const ContactModel& model) const noexcept;
  std::uint64_t fields_handed_ = 0, fields_undecodable_ = 0, fields_without_buffer_ = 0;
  std::uint64_t fields_decoder_busy_ = 0, field_nacks_sent_ = 0;
};

}  // namespace ht::station
