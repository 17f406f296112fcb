#pragma once
// Encoding and decoding of the messages defined in transport/protocol.h. Field by field,
// little-endian, every length checked before it is read; no allocation. Encoders append the MAC;
// OpenDatagram checks the header and the MAC before any body decoder runs.

#include <array>
#include <cstdint>
#include <span>
#include <string_view>

#include "haptic_core/contact_model.h"
#include "haptic_core/spatial.h"
#include "transport/auth.h"
#include "transport/protocol.h"

namespace ht::wire {

/// Decoded header fields.
struct Header {
  MessageType type = MessageType::kToolState;
  std::uint32_t session_id = 0;
  /// On the wire a u32: an encoder sends a larger number as 2³² − 1 (protocol.h).
  std::uint64_t sequence = 0;
  /// The sender's steady clock (ns). On the wire whole µs: an encoder sends ⌊ns/1000⌋ clamped to
  /// [0, kMaxSendTimeUs], a decoder gives that times 1000.
  std::int64_t send_time_ns = 0;
};

/// Operator → remote: the simulated tool's state.
struct ToolStateMessage {
  RigidTransform X_WT;
  Twist V_WT_W;
};

/// Remote → operator: a contact model plus the bookkeeping needed for round-trip time and rates.
struct ContactModelMessage {
  ContactModel model;  ///< model.tool_state_seq is the wire field tool_state_seq.
  std::int64_t tool_state_send_time_ns = 0;
  std::int64_t hold_ns = 0;
  std::uint64_t remote_step_count = 0;
  float collision_us = 0.0f;
  float texture_us = 0.0f;
  float step_us = 0.0f;
};

/// The perceptual deadband of a session's two streams (transport/deadband.h): asked in Hello,
/// agreed in Welcome. A Weber fraction of 0 turns a stream's deadband off (every sample sent).
struct DeadbandTerms {
  float tool_state_deadband = 0.0f;  ///< k the operator applies to its tool states, [0, 1)
  float model_deadband = 0.0f;       ///< k the remote node applies to its contact models, [0, 1)
  /// Longest time between two tool states / two contact models while the deadband holds them
  /// back (ms, > 0).
  std::uint16_t tool_state_keepalive_ms = 100;
  std::uint16_t model_keepalive_ms = 100;
};

/// Operator → remote: opens (or reopens) a session and states what the operator can do.
struct HelloMessage {
  std::uint16_t min_version = kMinProtocolVersion;
  std::uint16_t max_version = kProtocolVersion;
  std::uint64_t client_nonce = 0;      ///< random per attempt; Welcome/Reject echo it
  float tool_state_rate_hz = 1000.0f;  ///< the operator's loop rate
  float max_model_rate_hz = 0.0f;      ///< most contact models per second wanted (0 = any)
  std::uint16_t max_grid = 0;          ///< largest penetration-depth grid accepted (0 = any)
  std::uint16_t mtu = kMaxDatagramBytes;
  std::uint32_t codecs = kCodecDracoMesh;
  std::uint16_t heartbeat_ms = 100;
  std::uint16_t peer_timeout_ms = 500;
  DeadbandTerms deadband;  ///< what the operator asks
};

/// Where one touchable object of the scene is, so that an operator (or a scripted one) can find it:
/// its bounds in W at rest and its highest point along the scene's up direction.
struct WelcomeTarget {
  glm::dvec3 box_min_W{0.0};  ///< Axis-aligned bounds in W (m), min ≤ max per axis, widened by
                              ///< the object's texture outward reach.
  glm::dvec3 box_max_W{0.0};
  /// The object's top along up_W (m), inside the box: the middle of its upward-facing coarse
  /// triangles near its highest vertex where that middle lies on them (a plate's top face),
  /// else its highest coarse vertex.
  glm::dvec3 top_W{0.0};
  /// Height (m, along up_W, ≥ 0) above top_W where the hand can bring the tool (at the home
  /// orientation) without it touching any object: the remote node checked it.
  double approach_m = 0.0;
};

/// What the remote node tells the operator about its scene when a session opens.
struct SceneLayout {
  /// The tool's home pose X_WT_home: the operator's workspace centre lands here, and its +z axis
  /// is the scene's up direction (up_W = R_WT_home·ẑ).
  RigidTransform X_WT_home;
  /// Mass (kg) and principal moments along T (kg·m²) of the tool; mass 0 = not given (the
  /// operator keeps its own).
  double tool_mass_kg = 0.0;
  glm::dvec3 tool_inertia_diagonal_T{0.0};
  /// How far the tool reaches below T along −z of T (m): at the home pose, the hand is this high
  /// above the point of the tool that touches first.
  double tool_extent_down_m = 0.0;
  /// The touchable objects (at most kMaxWelcomeTargets: the largest ones), num_targets used.
  std::array<WelcomeTarget, kMaxWelcomeTargets> targets{};
  std::uint8_t num_targets = 0;
};

/// Remote → operator: the session's parameters, as negotiated.
struct WelcomeMessage {
  std::uint64_t client_nonce = 0;
  std::uint16_t version = kProtocolVersion;
  float tool_state_rate_hz = 1000.0f;
  float model_rate_hz = 0.0f;  ///< 0 = as fast as the remote node steps
  std::uint16_t grid = 0;
  float window_m = 0.0f;
  std::uint16_t mtu = kMaxDatagramBytes;
  std::uint32_t codecs = 0;
  std::uint16_t heartbeat_ms = 100;
  std::uint16_t peer_timeout_ms = 500;
  DeadbandTerms deadband;  ///< what both sides apply in this session
  std::uint16_t scene_objects = 0;
  std::array<char, kSceneNameBytes> scene_name{};  ///< zero padded, not terminated when full
  std::uint8_t scene_name_length = 0;
  SceneLayout layout;
  std::string_view name() const noexcept { return {scene_name.data(), scene_name_length}; }
};

/// Remote → operator: a Hello refused, and why.
struct RejectMessage {
  std::uint64_t client_nonce = 0;
  RejectReason reason = RejectReason::kVersion;
  std::array<char, kMaxRejectText> text{};
  std::uint8_t text_length = 0;
  std::string_view message() const noexcept { return {text.data(), text_length}; }
};

/// Operator → remote: a clock-sync probe (its header's send time is t1) that also tells the remote
/// node the round trip the operator measured (protocol version 10).
struct PingMessage {
  /// The operator's round trip (µs): ClockSync::rtt_ns, the smallest of its last 8 samples;
  /// 0 before the first Pong. Saturates at 2³² − 1.
  std::uint32_t operator_rtt_us = 0;
};

/// Remote → operator: answer to a Ping (NTP-style timestamps; t3 is the header's send time).
struct PongMessage {
  std::uint64_t ping_sequence = 0;
  std::int64_t t1_ns = 0;  ///< the ping's send time, operator clock
  std::int64_t t2_ns = 0;  ///< the ping's receive time, remote clock
};

/// Remote → operator: one fragment of a scene object. `payload` points into the datagram.
struct SceneFragmentMessage {
  std::uint32_t object_id = 0;
  std::uint32_t version = 0;
  std::uint32_t object_bytes = 0;
  std::uint16_t fragment_index = 0;
  std::uint16_t fragment_count = 0;
  std::span<const std::uint8_t> payload;
};

/// One scene object as announced by the remote node.
struct ManifestEntry {
  std::uint32_t object_id = 0;
  std::uint32_t version = 0;
  std::uint32_t object_bytes = 0;
  std::uint16_t fragment_count = 0;
  SceneObjectKind kind = SceneObjectKind::kDracoMesh;
  std::array<std::uint8_t, kSceneDigestBytes> digest{};
};

/// Remote → operator: part of the list of current scene objects (periodic, so that an object
/// whose fragments were all lost is still known).
struct SceneManifestMessage {
  std::uint16_t total_objects = 0;
  std::uint16_t first_index = 0;
  std::uint8_t count = 0;
  std::array<ManifestEntry, kMaxManifestEntries> entries{};
};

/// Operator → remote: fragments of one object version that did not arrive.
struct SceneNackMessage {
  std::uint32_t object_id = 0;
  std::uint32_t version = 0;
  std::uint16_t count = 0;  ///< 0 = resend every fragment
  std::array<std::uint16_t, kMaxNackIndices> missing{};
};

/// One node's local pose X_PN in its parent frame P (f32 on the wire), replacing the scene graph's
/// rest translation, rotation and scale of that node.
struct NodePose {
  std::uint16_t node = 0;                      ///< index into the scene graph's nodes
  glm::vec3 translation{0.0f};                 ///< p_PN (m)
  glm::quat rotation{1.0f, 0.0f, 0.0f, 0.0f};  ///< R_PN; w, x, y, z on the wire; unit once decoded
  glm::vec3 scale{1.0f};
};

/// Remote → operator: local poses of moving scene-graph nodes at one instant of the remote scene.
/// One frame may take several datagrams (same scene_time_s); the receiver keeps per node the entry
/// of the newest scene_time_s (transport/scene_graph.h: SceneNodePoses).
struct NodePosesMessage {
  std::uint32_t graph_version = 0;  ///< version of the scene-graph object the node indices are of
  double scene_time_s = 0.0;        ///< the remote scene's clock at this frame (s)
  std::uint8_t count = 0;           ///< entries used, ≤ kMaxNodePosesPerDatagram
  std::array<NodePose, kMaxNodePosesPerDatagram> poses{};
};

/// Why a datagram was dropped. Counted per reason in the summaries.
enum class DecodeStatus : std::uint8_t {
  kOk = 0,
  kTooShort,  ///< shorter than header + MAC or than its body needs
  kTooLong,   ///< longer than kMaxDatagramBytes or than its body allows
  kBadMagic,
  kBadVersion,
  kBadFlags,
  kUnknownType,
  kBadCount,      ///< a count above its limit (contacts, manifest entries, NACK indices)
  kNonFinite,     ///< a pose, twist, wrench or contact field is NaN or infinite
  kBadValue,      ///< a finite but impossible value (non-unit quaternion, index ≥ count, ...)
  kBadMac,        ///< the MAC does not verify under the pre-shared key
  kReplayed,      ///< a sequence number already seen, 0, or too old for the replay window
  kWrongSession,  ///< authenticated, but for another session than the current one
  kUnexpected,    ///< authenticated, but a type this side does not accept (or not now)
};
inline constexpr int kDecodeStatusCount = 14;

/// Human-readable name of a status ("ok", "too_short", "bad_mac", ...), for logs and summaries.
const char* ToString(DecodeStatus status) noexcept;
/// Name of a message type ("tool_state", ...; "unknown" outside the enum).
const char* ToString(MessageType type) noexcept;

/// Fixed-capacity buffer for one outgoing datagram.
struct Datagram {
  std::array<std::uint8_t, kMaxDatagramBytes> bytes{};
  std::size_t size = 0;
  std::span<const std::uint8_t> view() const noexcept { return {bytes.data(), size}; }
};

// Encoders: header (its type is set by the encoder) + body + MAC under `key`.
Datagram EncodeToolState(const Header& header, const ToolStateMessage& message,
                         const MacKey& key) noexcept;
/// Contacts beyond kMaxWireContacts are not sent (the caller keeps at most kMaxContacts);
/// depth-field ids beyond DepthFieldIdCapacity() (11 with 14 float contacts) are not sent: those
/// contacts go without their field.
Datagram EncodeContactModel(const Header& header, const ContactModelMessage& message,
                            const MacKey& key) noexcept;
/// The same model quantized as CompactContactModel (protocol.h states the layout and each field's
/// largest error; F_T_W_at_q0 is not sent, the receiver sums it from the contacts). Contacts beyond
/// kMaxWireContacts are not sent. Never undefined for any input: a NaN or infinite field, a zero
/// normal, a pose that is not a finite rigid transform or a position beyond f32's range, is sent
/// marked so that the receiver rejects the datagram (kNonFinite), as it would the float encoding
/// of it; a point farther than
/// kCompactPointRangeM from X_WT0 along an axis is clamped to that range; times are clamped to
/// [0, kCompactMaxTimeUs].
Datagram EncodeCompactContactModel(const Header& header, const ContactModelMessage& message,
                                   const MacKey& key) noexcept;
/// The same tool state quantized as CompactToolState (protocol.h states the layout and each
/// field's largest error): p_WT as f32, R_WT as "smallest three" in 20 bits each, the twist as
/// binary16. Never undefined for any input: a non-finite field is sent non-finite (a quaternion
/// with one as a NaN position) so that the receiver rejects the datagram (kNonFinite), as it would
/// the f64 encoding; so is a position coordinate beyond f32's range (±3.4e38 m), which the f64
/// encoding would carry; a twist component beyond ±kCompactTwistMax is sent as
/// ±kCompactTwistMax.
Datagram EncodeCompactToolState(const Header& header, const ToolStateMessage& message,
                                const MacKey& key) noexcept;
/// What the receiver of EncodeCompactToolState(message) decodes, without the wire: the sender's
/// perceptual deadband predicts from this (transport/deadband.h), so that both sides extrapolate
/// the same state. A message the receiver would reject comes back unchanged. Encode `message`,
/// not this: quantizing the result again is not always the identity (where two quaternion
/// components tie, the restored largest can come out below the other and the second encoding
/// leaves out another component, 1.6e-6 rad away).
ToolStateMessage CompactToolStateAsReceived(const ToolStateMessage& message) noexcept;
Datagram EncodeGoodbye(const Header& header, const MacKey& key) noexcept;
Datagram EncodeHello(const Header& header, const HelloMessage& message, const MacKey& key) noexcept;
Datagram EncodeWelcome(const Header& header, const WelcomeMessage& message,
                       const MacKey& key) noexcept;
Datagram EncodeReject(const Header& header, const RejectMessage& message,
                      const MacKey& key) noexcept;
/// A Ping (operator → remote): the header's send time is t1 of the clock sync; the body carries
/// the operator's round trip (PingMessage). Never fails.
Datagram EncodePing(const Header& header, const PingMessage& message, const MacKey& key) noexcept;
Datagram EncodePong(const Header& header, const PongMessage& message, const MacKey& key) noexcept;
/// The payload is cut to what fits in kMaxDatagramBytes.
Datagram EncodeSceneFragment(const Header& header, const SceneFragmentMessage& message,
                             const MacKey& key) noexcept;
Datagram EncodeSceneManifest(const Header& header, const SceneManifestMessage& message,
                             const MacKey& key) noexcept;
Datagram EncodeSceneNack(const Header& header, const SceneNackMessage& message,
                         const MacKey& key) noexcept;
/// A fragment of an encoded depth field (protocol.h, DepthFieldFragment: SceneFragment's layout,
/// object_id the field's id, version kDepthFieldVersion); the payload is cut to what fits.
Datagram EncodeDepthFieldFragment(const Header& header, const SceneFragmentMessage& message,
                                  const MacKey& key) noexcept;
/// Fragments of a depth field that did not arrive (DepthFieldNack: SceneNack's layout).
Datagram EncodeDepthFieldNack(const Header& header, const SceneNackMessage& message,
                              const MacKey& key) noexcept;
/// Entries beyond kMaxNodePosesPerDatagram are not sent. Fields are sent as given (f32); a
/// non-finite field or a zero rotation makes the receiver reject the datagram.
Datagram EncodeNodePoses(const Header& header, const NodePosesMessage& message,
                         const MacKey& key) noexcept;

/// A Hello of an older protocol version (2 to 7: their 28-byte header and 32-byte MAC; 8 to
/// kProtocolVersion − 1: this header and MAC), read only as far as those versions agree.
struct ForeignHello {
  std::uint16_t header_version = 0;  ///< the version in its header (the sender's own)
  std::uint16_t min_version = 0, max_version = 0;
  std::uint64_t client_nonce = 0;
};
/// Opens a Hello of an older protocol version (2 ≤ version ≤ 7, kLegacyHeaderBytes header,
/// kLegacyMacBytes MAC; or kFirstShortHeaderVersion ≤ version < kProtocolVersion in this header
/// and MAC), so that the remote node can refuse that operator with a Reject it understands. kOk
/// when the magic, flags and type match, the MAC verifies under `key` and the body has at least
/// its first 12 bytes; otherwise the first problem: kTooLong, kTooShort, kBadMagic (neither
/// layout's magic), kBadVersion (a datagram of this version, to be opened with OpenDatagram, a
/// newer one, or a legacy-layout version outside 2 to 7), kBadFlags, kUnexpected (not a Hello),
/// kBadMac.
DecodeStatus OpenForeignHello(std::span<const std::uint8_t> datagram, const MacKey& key,
                              ForeignHello& hello) noexcept;
/// A Reject with `version` in its header: for 2 ≤ version ≤ kLastLegacyVersion the layout of
/// those versions (28-byte header, 32-byte MAC; the body is laid out alike in versions 2 to
/// kProtocolVersion);
/// for kFirstShortHeaderVersion ≤ version < kProtocolVersion this layout with that version;
/// else this version's own Reject.
Datagram EncodeReject(const Header& header, const RejectMessage& message, const MacKey& key,
                      std::uint16_t version) noexcept;

/// Checks a received datagram's size limits, header (magic, version, known type) and MAC, in that
/// order, and on kOk gives the header (send_time_ns is the sender's whole µs times 1000; sequence
/// is at most 2³² − 1) and the body (between header and MAC).
DecodeStatus OpenDatagram(std::span<const std::uint8_t> datagram, const MacKey& key, Header& header,
                          std::span<const std::uint8_t>& body) noexcept;
/// Reads only the header fields (no MAC check); for relays and counters. kOk or the first problem.
DecodeStatus PeekHeader(std::span<const std::uint8_t> datagram, Header& header) noexcept;
/// The message type byte of a datagram of this version's layout, or of versions 2 to 7 (their
/// magic); 0 for anything else. No MAC check: for counters and the impairment relay.
int DatagramType(std::span<const std::uint8_t> datagram) noexcept;

// Body decoders: `body` is what OpenDatagram gave; exact length, counts, finiteness and values are
// checked; `message` is written only on kOk.
DecodeStatus DecodeToolState(std::span<const std::uint8_t> body,
                             ToolStateMessage& message) noexcept;
/// CompactToolState into the message the f64 encoding decodes to (R_WT unit). kTooShort/kTooLong
/// unless the length is exactly kCompactToolStateBodyBytes, kNonFinite for a non-finite f32 or
/// f16, kBadValue for a quaternion field with bits 62–63 set, a component of −2¹⁹, or the three
/// components' squares summing above 1 + 1e-9 (an encoder never sends more than 0.75).
DecodeStatus DecodeCompactToolState(std::span<const std::uint8_t> body,
                                    ToolStateMessage& message) noexcept;
DecodeStatus DecodeContactModel(std::span<const std::uint8_t> body,
                                ContactModelMessage& message) noexcept;
/// CompactContactModel (protocol version 11) into the message the float encoding decodes to:
/// X_WT0's rotation unit, normals unit; F_T_W_at_q0, which the compact body does not carry, summed
/// from the decoded contacts at q0 (ContactModelWrenchAtQ0, as the sender's AssembleContactModel
/// made it); tool_state_send_time_ns, sent as the low 32 bits of its whole µs,
/// taken as the time within ±2³¹ µs (±35.8 min) of `receive_time_ns`, the receiver's steady clock
/// in ns (the clock whose times its tool states carry): so the echo is right for any model whose
/// pose answered a tool state sent within 35 minutes; hold_ns and the echo come back as whole µs;
/// remote_step_count is the low 32 bits of the sender's count. kBadCount for more than
/// kMaxWireContacts contacts, kTooShort/kTooLong unless the length is exact, kNonFinite for a
/// non-finite field or a marked one (a pose the sender could not send arrives as a NaN
/// position), kBadValue for a negative stiffness or quaternion bits no unit quaternion encodes
/// to. On any failure `message` is left as it was.
DecodeStatus DecodeCompactContactModel(std::span<const std::uint8_t> body,
                                       ContactModelMessage& message,
                                       std::int64_t receive_time_ns) noexcept;
/// The remote node's steps between two contact models, from the low 32 bits of their
/// remote_step_count (all a compact model carries): the difference modulo 2³², or, when that is
/// 2³¹ or more (the count went back: a restarted node counts from 0 again), the newer count
/// itself.
constexpr std::uint32_t RemoteStepsBetween(std::uint32_t previous_low, std::uint32_t low) noexcept {
  const std::uint32_t delta = low - previous_low;
  return delta < 0x8000'0000u ? delta : low;
}
DecodeStatus DecodeHello(std::span<const std::uint8_t> body, HelloMessage& message) noexcept;
DecodeStatus DecodeWelcome(std::span<const std::uint8_t> body, WelcomeMessage& message) noexcept;
DecodeStatus DecodeReject(std::span<const std::uint8_t> body, RejectMessage& message) noexcept;
DecodeStatus DecodePong(std::span<const std::uint8_t> body, PongMessage& message) noexcept;
DecodeStatus DecodeSceneFragment(std::span<const std::uint8_t> body,
                                 SceneFragmentMessage& message) noexcept;
DecodeStatus DecodeSceneManifest(std::span<const std::uint8_t> body,
                                 SceneManifestMessage& message) noexcept;
DecodeStatus DecodeSceneNack(std::span<const std::uint8_t> body,
                             SceneNackMessage& message) noexcept;
/// DepthFieldFragment: checked as SceneFragment, and kBadValue for a field id 0, a version other
/// than kDepthFieldVersion or field bytes above kMaxDepthFieldBytes.
DecodeStatus DecodeDepthFieldFragment(std::span<const std::uint8_t> body,
                                      SceneFragmentMessage& message) noexcept;
/// DepthFieldNack: checked as SceneNack, and kBadValue for a field id 0 or a version other than
/// kDepthFieldVersion.
DecodeStatus DecodeDepthFieldNack(std::span<const std::uint8_t> body,
                                  SceneNackMessage& message) noexcept;
/// NodePoses: kBadCount for more than kMaxNodePosesPerDatagram entries, kTooShort/kTooLong unless
/// the length is exactly that of its entries, kNonFinite for a non-finite scene_time_s,
/// translation, rotation or scale, kBadValue for a rotation of norm below
/// kMinNodePoseQuaternionNorm. On kOk every rotation is normalized. The node indices are not
/// checked here (the receiver checks them against its scene graph).
DecodeStatus DecodeNodePoses(std::span<const std::uint8_t> body,
                             NodePosesMessage& message) noexcept;
/// Bodies that must be empty (Goodbye).
DecodeStatus DecodeEmpty(std::span<const std::uint8_t> body) noexcept;
/// Ping: kTooShort / kTooLong unless the body is kPingBodyBytes; every value is valid.
DecodeStatus DecodePing(std::span<const std::uint8_t> body, PingMessage& message) noexcept;

static_assert(kMaxWireContacts == kMaxContacts, "wire and model contact limits must agree");

}  // namespace ht::wire
