#pragma once
// The wire format, in one place (ENet-style single source of truth). Every datagram is
//
//   header (kHeaderBytes) | body (per message type, fixed or counted size) | MAC (kMacBytes)
//
// All integers and IEEE-754 floats are little-endian, written and read field by field (never by
// casting a struct over bytes). Wire order of 6-vectors: force then torque, linear then angular.
// Quaternions: w, x, y, z. Units are SI (m, rad, N, N·m, s); times in bodies are nanoseconds of
// the sender's steady clock, the header's send time whole µs of it (the clocks of the two sides
// are unrelated; see Ping/Pong).
//
// Header layout (kHeaderBytes, 18; version 8):
//   offset 0  u16 magic            kMagic ("HT" read as little-endian u16)
//   offset 2  u8  version          kProtocolVersion
//   offset 3  u8  type             MessageType
//   offset 4  u32 session_id       0 in Hello; otherwise the id the remote node gave in Welcome
//   offset 8  u32 sequence         per sender, session and message type, starting at 1, at most
//                                  2³² − 1 (kMaxSequence). When one of a side's streams reaches
//                                  kSequenceRenewAt (49 days at 1 kHz) the session ends: the remote
//                                  node says Goodbye and the operator reconnects; the operator
//                                  sends a new Hello, which the node takes once the old session
//                                  has been silent for its peer timeout
//   offset 12 u48 send_time_us     sender's steady clock at send, whole µs (the low 48 bits: 8.9
//                                  years of uptime), read back as send_time_ns = 1000·send_time_us
//
// MAC (kMacBytes, 16, last in the datagram): HMAC-SHA-256-128 under the pre-shared key, over every
// byte before it (header and body): HMAC-SHA-256 (libsodium crypto_auth_hmacsha256) truncated to
// its first 128 bits: half the hash's output, the shortest RFC 2104 §5 recommends (IPsec's
// HMAC-SHA-256-128, RFC 4868). Verified in constant time. A datagram whose MAC does not verify is
// dropped before any body field is read.
//
// Versions 2 to 7 had a 28-byte header (u32 magic kLegacyMagic "HTLP", u16 version, u8 type, u8
// flags = 0, u32 session_id, u64 sequence, i64 send_time_ns) and a 32-byte MAC, libsodium
// crypto_auth (HMAC-SHA-512-256) (kLegacyHeaderBytes, kLegacyMacBytes). A remote node still reads a
// Hello of that layout, only to answer it with a Reject of that layout (OpenForeignHello,
// EncodeReject with a version).
//
// Bodies (operator = O, remote node = R):
//   ToolState O→R (104): X_WT: p_WT 3×f64 (m), R_WT 4×f64 quaternion; V_WT_W: linear 3×f64 (m/s),
//     angular 3×f64 (rad/s). T is the tool frame at its centre of mass, W the remote world.
//   CompactToolState O→R (kCompactToolStateBodyBytes, 32): the same tool state quantized, sent
//     instead of ToolState when both sides set kCodecCompactToolState and decoded into the same
//     message (the f64 encoding stays available). p_WT 3×f32 (m); R_WT as u64 "smallest three":
//     bits 0–1 the index (0 w, 1 x, 2 y, 3 z) of the component of largest magnitude, made
//     positive (q and −q are one rotation), bits 2–21, 22–41, 42–61 the other three in w, x, y, z
//     order as signed 20-bit integers (two's complement) in units of
//     kCompactQuaternionStep = (1/√2)/(2¹⁹ − 1), bits 62–63 zero; the receiver restores the
//     largest as √(1 − Σ others²) and normalizes. V_WT_W: linear 3×f16 (m/s), angular 3×f16
//     (rad/s), IEEE-754 binary16, round to nearest, clamped to ±65504 at the sender. Rejected:
//     a non-finite f32 or f16 (kNonFinite), bits 62–63 set, a component of −2¹⁹ or the three
//     others' squares summing above 1 + 1e-9 (kBadValue; an encoder never sends above 0.75).
//     Errors: kCompactToolState*Error* below.
//   ContactModel R→O (kContactModelFixedBytes + n·kContactBytes):
//     u64 tool_state_seq  i64 tool_state_send_time_ns (echoed)  i64 hold_ns (remote time between
//     receiving that tool state and sending this)  u64 remote_step_count. Under a tool-state
//     deadband the model answers the tool state extrapolated by Δ (remote time since it arrived,
//     at most its keep-alive): the echo is then send time + Δ and hold_ns counts from arrival +
//     Δ, so that now − echo is the age of the pose answered and now − echo − hold_ns stays the
//     round trip; a keep-alive copy of a held model repeats its echo with a new hold_ns.
//     f32 collision_us, f32 texture_us, f32 step_us
//     X_WT0: 3×f64 + 4×f64   F_T_W at q0: 3×f64 force (N), 3×f64 torque (N·m)
//     u8 num_contacts (0..kMaxWireContacts), then per contact (88): f64 depth_m, 3×f64 ∂δ/∂x,
//     3×f64 ∂δ/∂θ (m/rad), f64 stiffness (N/m), 3×f32 point_W (m), 3×f32 normal_W (unit);
//     then the depth-field section, which ends the body: u8 n (≤ num_contacts, at most
//     DepthFieldIdCapacity(): as many as fit the datagram), per contact that has a depth field
//     (kDepthFieldIdBytes, 5), in the contacts' order: u8 contact (< num_contacts), u32 field id
//     (≠ 0: the DepthFieldFragment object that carries the field). A contact without an entry
//     has no field (the operator evaluates its linearization). Rejected: a contact ≥
//     num_contacts or named twice, or an id 0 (kBadValue); bytes after the last entry (kTooLong).
//   CompactContactModel R→O (kCompactContactModelFixedBytes + n·kCompactContactBytes): the same
//     model quantized, sent instead of ContactModel when both sides set kCodecCompactContactModel
//     and decoded into the same message (the float encoding stays available). Version 11 (issue
//     33) cut its fixed part from 103 to 45 bytes:
//     u32 tool_state_seq (the tool state's header sequence, a u32 since version 8);
//     u32 tool_state_send_time_us: the echo (as in ContactModel) in whole µs of the operator's
//       clock, rounded to nearest, its low 32 bits: the receiver takes the time within ±2³¹ µs
//       (±35.8 min) of its own clock whose low bits these are (DecodeCompactContactModel);
//     u32 hold_us: ContactModel's hold_ns rounded to whole µs, clamped to [0, 2³² − 1] (71.6 min;
//       a remote node's hold is never negative);
//     u32 remote_step_count, its low 32 bits (a receiver counts steps between models modulo 2³²);
//     u16 collision_us, u16 texture_us, u16 step_us (rounded to µs, clamped to [0, 65534];
//     65535 = not finite);
//     X_WT0: p_WT0 3×f32 (m; a coordinate beyond f32's range is sent as NaN and rejected), R_WT0
//       as "smallest three" in 80 bits, u64 low then u16 high: bits 0–1 the index (0 w, 1 x, 2 y,
//       3 z) of the component of largest magnitude, made positive, bits 2–27, 28–53, 54–79 the
//       other three in w, x, y, z order as signed 26-bit integers in units of
//       kCompactModelQuaternionStep = (1/√2)/(2²⁵ − 1); rejected as CompactToolState's is (a
//       component of −2²⁵, or the three squares summing above 1 + 1e-9: kBadValue);
//     u8 num_contacts (0..kMaxWireContacts).
//     F_T_W at q0 is not sent: the receiver sums it from the contacts it decoded, each at q0 as
//     the operator's loop evaluates it (ContactModelWrenchAtQ0, haptic_core/contact_assembly.h),
//     which is how the sender's AssembleContactModel made it.
//     Per contact (42): f32 depth_m, 3×f32 ∂δ/∂x,
//     3×f32 ∂δ/∂θ (m/rad), f32 stiffness (N/m), 3×i16 point_W − p_WT0
//     (units of kCompactPointStepM, each axis clamped to ±32767: the point is for display),
//     2×i16 normal_W octahedral (u, v)·32767: p = n/‖n‖₁, (u, v) = (p_x, p_y) where p_z ≥ 0, else
//     ((1 − |p_y|)·sgn p_x, (1 − |p_x|)·sgn p_y), sgn 0 = +1; the receiver unfolds and normalizes
//     (Meyer et al. 2010; Cigolle et al. 2014). Every i16 is rounded to nearest within ±32767;
//     −32768 (kCompactNotFinite) marks a value, or normal, that was not finite (or a zero normal)
//     at the sender, and the receiver rejects the datagram (kNonFinite) as it would ContactModel
//     with a NaN. The largest error of each field is a kCompact*Error* constant below. Then the
//     depth-field section as in ContactModel, which ends the body.
//   Goodbye O↔R (0): clean close of the session (the operator at the end of a run, the remote
//     node when stopped); sent three times with new sequence numbers.
//   Hello O→R (44): u16 min_version, u16 max_version, u64 client_nonce, f32 tool_state_rate_hz,
//     f32 max_model_rate_hz (0 = any), u16 max_grid (0 = any), u16 mtu, u32 codecs (kCodec*),
//     u16 heartbeat_ms, u16 peer_timeout_ms, then the deadband terms asked (12): f32
//     tool_state_deadband (the Weber fraction k ∈ [0, 1) the operator applies to its tool states;
//     0 = every tick), f32 model_deadband (k asked of the remote node for contact models),
//     u16 tool_state_keepalive_ms, u16 model_keepalive_ms (> 0; the longest gap either stream
//     leaves while its deadband holds samples back). transport/deadband.h has the rules.
//   Welcome R→O (kWelcomeFixedBytes + n·kWelcomeTargetBytes): u64 client_nonce (echoed),
//     u16 version, f32 tool_state_rate_hz, f32 model_rate_hz (0 = as fast as the remote steps),
//     u16 grid, f32 window_m, u16 mtu, u32 codecs, u16 heartbeat_ms, u16 peer_timeout_ms,
//     the deadband terms agreed (12, as in Hello), u16 scene_objects, u8 name_length, 32 bytes
//     scene name (zero padded); then the scene's layout: X_WT_home 3×f64 + 4×f64 (the tool's home
//     pose: where the operator's workspace centre lands; its +z is the scene's up), f32
//     tool_mass_kg (0 = not given), 3×f32 tool principal moments along T (kg·m²), f32
//     tool_extent_down_m (how far the tool reaches below T along −z, m), u8 n (≤
//     kMaxWelcomeTargets), per target (40): 3×f32 box_min_W, 3×f32 box_max_W (m, the object's
//     bounds in W at rest, widened by its texture's outward reach), 3×f32 top_W (its top along the
//     scene's up: the middle of its flat top, else its highest coarse vertex), f32 approach_m (the
//     hand height above top_W at which the tool is clear of every touchable). The header carries
//     the new session id.
//   Reject R→O (10 + n): u64 client_nonce, u8 RejectReason, u8 n, n bytes of UTF-8 text (n ≤ 200)
//   Ping O→R (4): u32 operator_rtt_us, the operator's round trip (µs): the smallest of its clock
//     sync's last 8 samples (ClockSync::rtt_ns), 0 before its first Pong, saturated at 2³² − 1;
//     so that the remote node can send what a model needs a round trip old (its depth fields'
//     travel margin, its speculative floor). Its header's send_time_ns is t1.
//   Pong R→O (24): u64 ping_sequence, i64 t1 (echoed), i64 t2 (remote receive time); the header's
//     send_time_ns is t3 (NTP's four timestamps with the operator's receive time t4).
//   SceneFragment R→O (16 + payload, payload ≥ 1): u32 object_id, u32 version, u32 object_bytes,
//     u16 fragment_index, u16 fragment_count, then bytes [index·P, min((index+1)·P, object_bytes))
//     of the object where P = FragmentPayloadBytes(mtu).
//   SceneManifest R→O (5 + n·31): u16 total_objects, u16 first_index, u8 n (≤ kMaxManifestEntries),
//     per entry: u32 object_id, u32 version, u32 object_bytes, u16 fragment_count, u8
//     SceneObjectKind, 16 bytes BLAKE2b-128 digest of the object's bytes.
//   SceneNack O→R (10 + 2n): u32 object_id, u32 version, u16 n (≤ kMaxNackIndices; 0 = resend all),
//     n × u16 missing fragment indices.
//   DepthFieldFragment R→O (16 + payload; version 12, with kCodecDepthFields): one fragment of an
//     encoded depth field (codecs/depth_field_codec.h), laid out as SceneFragment: u32 field id
//     (≠ 0, the id the contact model's depth-field section names), u32 version (1: a field never
//     changes), u32 field_bytes (≤ kMaxDepthFieldBytes), u16 fragment_index, u16 fragment_count,
//     then bytes [index·P, min((index+1)·P, field_bytes)) of the encoded field, P =
//     FragmentPayloadBytes(mtu). The remote node sends a field's fragments before the first
//     contact model that names it, and keeps its last fields to answer DepthFieldNacks.
//   DepthFieldNack O→R (10 + 2n; version 12): laid out as SceneNack, for a field id that a
//     contact model named and that has not arrived whole a round trip later: u32 field id,
//     u32 version (1), u16 n (≤ kMaxNackIndices; 0 = resend all), n × u16 missing indices.
//   NodePoses R→O (kNodePosesFixedBytes + n·kNodePoseBytes): u32 graph_version (the version of
//     the scene-graph object whose node indices these are), f64 scene_time_s (the remote scene's
//     clock at this frame, s), u8 n (≤ kMaxNodePosesPerDatagram), per entry (42): u16 node (index
//     into the graph's nodes), 3×f32 translation (m), 4×f32 rotation w, x, y, z, 3×f32 scale: the
//     node's local pose X_PN in its parent P, replacing the graph's rest translation, rotation and
//     scale for that node. Sent at a display rate (60 Hz) for the nodes flagged kSceneNodeMoving; a
//     frame with more entries goes in several datagrams with the same scene_time_s. The receiver
//     keeps per node the entry of the newest scene_time_s (newest wins; a lost datagram is not
//     repaired). Rejected: n above the limit (kBadCount), a length other than exactly n entries,
//     a non-finite field (kNonFinite), a rotation of norm below kMinNodePoseQuaternionNorm
//     (kBadValue); the decoder hands on the rotation normalized.
//
// Scene objects (reassembled from SceneFragments; the manifest gives each one's SceneObjectKind).
// A scene is sent as a scene: one kDracoMesh object per distinct mesh, its positions in its own
// frame; one kImage object per base-colour texture (the source file's PNG or JPEG bytes); one
// kSceneGraph object that places them. The scene-graph object's bytes (all little-endian, written
// and read field by field by transport/scene_graph.h, which checks every count against the bytes
// left before allocating):
//   u32 magic kSceneGraphMagic ("HTSG")   u16 format_version kSceneGraphFormatVersion
//   u8 n, n bytes scene name (UTF-8)   u16 node_count (≤ 65535)   u16 material_count (≤ 4096)
//   node_count nodes, parents first (≥ 94 bytes each):
//     u8 n, n bytes name   i32 parent (−1 = root, whose parent frame is W; else < this index)
//     3×f64 translation p_PN (m)   4×f64 rotation R_PN w, x, y, z (not zero; normalized on use)
//     3×f64 scale   u32 mesh_object (kDracoMesh object id, positions in N; 0 = none)
//     i32 material (−1 = default, else < material_count)   u8 flags (kSceneNode*: 1 tool,
//     2 touchable, 4 moving; other bits rejected)
//   material_count materials (≥ 22 bytes each):
//     u8 n, n bytes name   4×f32 base_colour_rgba (linear, glTF baseColorFactor)
//     u32 base_colour_texture_object (kImage object id; 0 = none)   u8 n, n bytes MIME type
//     ("image/png", "image/jpeg"; empty when there is no texture)
//   u8 has_camera (0 or 1); when 1 (28): i32 node (−1 = W itself, else < node_count; the camera
//     looks along −z of that node's frame, +y up, as in glTF), f64 yfov_rad (0, π),
//     f64 znear_m > 0, f64 zfar_m (0 = infinite, else > znear_m)
// and nothing after it. Every f64 and f32 is finite. A node's pose in W is X_WN = X_WP·X_PN with
// X_PN = T(translation)·R(rotation)·S(scale) (glTF's order).

#include <cstddef>
#include <cstdint>

namespace ht::wire {

inline constexpr std::uint16_t kMagic = 0x5448u;  // bytes 'H' 'T'
/// The header's first four bytes in versions 2 to 7 ("HTLP" read as little-endian u32).
inline constexpr std::uint32_t kLegacyMagic = 0x504C5448u;  // bytes 'H' 'T' 'L' 'P'
/// Version 2 added authentication, sessions, clock sync and scene streaming; version 3 the scene
/// layout in Welcome (home pose, tool inertia, where the touchable objects are); version 4 the
/// perceptual deadband terms in Hello and Welcome and the compact contact model; version 5 the
/// scene as a scene: meshes in their own frames, the scene-graph and image objects
/// (SceneObjectKind kSceneGraph, kImage) and NodePoses. Version 6 added the kink planes after the
/// contacts of ContactModel and CompactContactModel; version 7 each plane's own translation
/// slope (the arms of δ's V along the window's axes). Version 8 (tool states within 50 kbit/s) has
/// the 18-byte header above instead of 28 bytes and a 16-byte MAC (HMAC-SHA-256-128) instead of 32
/// (HMAC-SHA-512-256); every body is as in version 7. Version 9 adds the translation patches after
/// the kink planes of ContactModel and CompactContactModel; header, MAC and every other body are as
/// in version 8. Version 10 gives Ping a body, the operator's measured round trip; every other body
/// is as in version 9. Version 11 (contact models toward 100 kbit/s) has the leaner
/// CompactContactModel above (a 45-byte fixed part instead of 103: u32 sequence, echo, hold and
/// step count, f32 position, an 80-bit quaternion, no wrench at q0; a kink plane that shares its
/// contact's translation slope in 17 bytes instead of 29); every other body is as in version 10.
/// Version 12 (the contact model as depth fields) adds the depth-field section after the contacts
/// of ContactModel and CompactContactModel (each contact's field id) and the DepthFieldFragment
/// and DepthFieldNack messages; every other body is as in version 11. Version 13 drops the
/// translation patches' section after the kink planes (the depth fields hold the surface where
/// the tool is); every other body is as in version 12. Version 14 drops the kink planes: the
/// depth-field section ends ContactModel and CompactContactModel; every other body is as in
/// version 13. Version 15 adds the force law to each depth field (kDepthFieldFormat 2: its law,
/// the pressure law's reference area and its node-stride hint); every message body is as in
/// version 14.
/// Only version 15 is accepted. A remote node answers a Hello of versions 2 to 14 whose MAC
/// verifies with a Reject (kVersion) in that Hello's own layout and header version (the Hello's
/// first 12 body bytes and the Reject body are laid out alike in versions 2 to 15), so that an
/// older operator is told why.
inline constexpr std::uint16_t kProtocolVersion = 15;
inline constexpr std::uint16_t kMinProtocolVersion = 15;

/// Message types; values are part of the protocol and never reused.
enum class MessageType : std::uint8_t {
  kToolState = 1,
  kContactModel = 2,
  kGoodbye = 3,
  kHello = 4,
  kWelcome = 5,
  kReject = 6,
  kPing = 7,
  kPong = 8,
  kSceneFragment = 9,
  kSceneNack = 10,
  kSceneManifest = 11,
  kCompactContactModel = 12,
  kNodePoses = 13,
  kCompactToolState = 14,
  kDepthFieldFragment = 15,
  kDepthFieldNack = 16,
};
inline constexpr int kMaxMessageType = 16;

/// Why a remote node refused a Hello.
enum class RejectReason : std::uint8_t {
  kVersion = 1,       ///< no protocol version in common
  kCapabilities = 2,  ///< grid, codecs or rates the remote node cannot meet
  kBusy = 3,          ///< reserved: another operator holds the node
};

/// Codec bits of Hello/Welcome `codecs`.
inline constexpr std::uint32_t kCodecDracoMesh = 1u << 0;
/// Contact models go as CompactContactModel (quantized) instead of ContactModel when both sides
/// set it.
inline constexpr std::uint32_t kCodecCompactContactModel = 1u << 1;
/// Tool states go as CompactToolState (quantized, 66 bytes a datagram instead of 138) instead of
/// ToolState when both sides set it.
inline constexpr std::uint32_t kCodecCompactToolState = 1u << 2;
/// Each contact of a contact model comes with its depth field (DepthFieldFragment, the codec of
/// codecs/depth_field_codec.h), which the operator's loop evaluates at its own tool pose, when
/// both sides set it.
inline constexpr std::uint32_t kCodecDepthFields = 1u << 3;

/// What a scene object's bytes are.
enum class SceneObjectKind : std::uint8_t {
  kDracoMesh = 1,   ///< a Draco bitstream of a triangle mesh, positions in the object's frame (m)
  kSceneGraph = 2,  ///< an encoded SceneGraphDescription (layout above; transport/scene_graph.h)
  kImage = 3,       ///< a base-colour texture, the source file's bytes as they are (PNG or JPEG;
                    ///< the scene graph's material gives its MIME type)
};
/// Largest SceneObjectKind value.
inline constexpr int kMaxSceneObjectKind = 3;

/// The scene-graph object's magic ("HTSG" read as little-endian u32) and format version.
inline constexpr std::uint32_t kSceneGraphMagic = 0x47535448u;  // bytes 'H' 'T' 'S' 'G'
inline constexpr std::uint16_t kSceneGraphFormatVersion = 1;
/// Smallest encoded node (empty name), material (empty name and MIME type) and camera.
inline constexpr std::size_t kSceneGraphNodeMinBytes = 1 + 4 + 10 * 8 + 4 + 4 + 1;
inline constexpr std::size_t kSceneMaterialMinBytes = 1 + 4 * 4 + 4 + 1;
inline constexpr std::size_t kSceneGraphCameraBytes = 4 + 3 * 8;

inline constexpr std::size_t kHeaderBytes = 18;
/// Offsets of the version and type bytes in the header.
inline constexpr std::size_t kHeaderVersionOffset = 2;
inline constexpr std::size_t kHeaderTypeOffset = 3;
/// The header's send time is whole µs in 48 bits.
inline constexpr std::int64_t kMaxSendTimeUs = (std::int64_t{1} << 48) - 1;
/// The header's sequence is a u32: a stream's last number, and the number at which its sender ends
/// the session so that a new one starts (2¹⁶ numbers before the last are left for the datagrams
/// still sent while it does).
inline constexpr std::uint64_t kMaxSequence = 0xFFFF'FFFFu;
inline constexpr std::uint64_t kSequenceRenewAt = kMaxSequence - (1u << 16);
/// The newest protocol version whose header and MAC are the 28-byte, 32-byte ones.
inline constexpr std::uint16_t kLastLegacyVersion = 7;
/// The first protocol version with this header and MAC (versions from it to kProtocolVersion − 1
/// are older operators in this layout).
inline constexpr std::uint16_t kFirstShortHeaderVersion = 8;
/// The MAC on the wire: HMAC-SHA-256's 32 bytes truncated to 16.
inline constexpr std::size_t kMacBytes = 16;
/// crypto_auth's output (crypto_auth_BYTES, HMAC-SHA-512-256): the MAC of versions 2 to 7.
inline constexpr std::size_t kFullMacBytes = 32;
/// Header and MAC of versions 2 to 7.
inline constexpr std::size_t kLegacyHeaderBytes = 28;
inline constexpr std::size_t kLegacyMacBytes = kFullMacBytes;
inline constexpr std::size_t kMacKeyBytes = 32;  // crypto_auth(_hmacsha256)_KEYBYTES
inline constexpr std::size_t kToolStateBodyBytes = 13 * 8;
inline constexpr std::size_t kCompactToolStateBodyBytes = 3 * 4 + 8 + 6 * 2;
inline constexpr std::size_t kContactModelFixedBytes = 8 * 4 + 4 * 3 + 7 * 8 + 6 * 8 + 1;
inline constexpr std::size_t kContactBytes = 8 + 6 * 8 + 8 + 3 * 4 + 3 * 4;
/// u32 sequence, echo, hold and step count; 3×u16 times; 3×f32 position; 80-bit quaternion
/// (u64 + u16); u8 contact count (version 11; 103 bytes in versions 4 to 10).
inline constexpr std::size_t kCompactContactModelFixedBytes = 4 * 4 + 3 * 2 + 3 * 4 + 8 + 2 + 1;
inline constexpr std::size_t kCompactContactBytes = 4 + 6 * 4 + 4 + 3 * 2 + 2 * 2;
/// The depth-field section after the contacts: u8 count, then per contact with a field u8 contact
/// and u32 field id.
inline constexpr std::size_t kDepthFieldIdCountBytes = 1;
inline constexpr std::size_t kDepthFieldIdBytes = 1 + 4;
/// Bytes of the depth-field section that carries `num_field_ids` ids.
constexpr std::size_t DepthFieldIdSectionBytes(int num_field_ids) noexcept {
  return kDepthFieldIdCountBytes +
         static_cast<std::size_t>(num_field_ids < 0 ? 0 : num_field_ids) * kDepthFieldIdBytes;
}
/// DepthFieldFragment and DepthFieldNack bodies: laid out as SceneFragment and SceneNack.
inline constexpr std::size_t kDepthFieldFragmentFixedBytes = 16;
inline constexpr std::size_t kDepthFieldNackFixedBytes = 10;
/// Largest encoded depth field (bytes) a sender fragments or a receiver reassembles: two
/// kMaxDepthFieldSide² maps at well under 8 bytes a node each.
inline constexpr std::uint32_t kMaxDepthFieldBytes = 1u << 20;
/// The version field of DepthFieldFragment and DepthFieldNack (a field never changes).
inline constexpr std::uint32_t kDepthFieldVersion = 1;
inline constexpr std::size_t kDeadbandTermsBytes = 12;
inline constexpr std::size_t kHelloBodyBytes = 32 + kDeadbandTermsBytes;
inline constexpr std::size_t kSceneNameBytes = 32;
inline constexpr std::size_t kWelcomeFixedBytes =
    37 + kDeadbandTermsBytes + kSceneNameBytes + 7 * 8 + 5 * 4 + 1;
inline constexpr std::size_t kWelcomeTargetBytes = 10 * 4;
/// Touchable objects described in a Welcome (the largest ones when a scene has more).
inline constexpr int kMaxWelcomeTargets = 8;
inline constexpr std::size_t kRejectFixedBytes = 10;
inline constexpr std::size_t kMaxRejectText = 200;
inline constexpr std::size_t kPingBodyBytes = 4;
inline constexpr std::size_t kPongBodyBytes = 24;
inline constexpr std::size_t kSceneFragmentFixedBytes = 16;
inline constexpr std::size_t kSceneManifestFixedBytes = 5;
inline constexpr std::size_t kManifestEntryBytes = 31;
inline constexpr std::size_t kSceneDigestBytes = 16;
inline constexpr int kMaxManifestEntries = 15;
inline constexpr std::size_t kSceneNackFixedBytes = 10;
inline constexpr int kMaxNackIndices = 200;
inline constexpr std::size_t kNodePosesFixedBytes = 4 + 8 + 1;
inline constexpr std::size_t kNodePoseBytes = 2 + 10 * 4;
/// Node poses per NodePoses datagram: as many as fit the smallest MTU.
inline constexpr int kMaxNodePosesPerDatagram = 11;
/// A NodePoses rotation of smaller norm is refused (it has no direction to normalize to).
inline constexpr double kMinNodePoseQuaternionNorm = 1e-6;

/// Largest datagram either side sends or accepts: an Ethernet MTU (1500) less IPv4 and UDP headers.
inline constexpr std::size_t kMaxDatagramBytes = 1472;
/// Smallest configurable MTU (largest datagram for scene fragments): IPv4's 576 less headers.
inline constexpr std::size_t kMinMtuBytes = 548;
/// Contacts that fit in one contact-model datagram.
inline constexpr int kMaxWireContacts = 14;
/// Depth-field ids that fit one datagram after `num_contacts` contacts of `contact_bytes` each and
/// a fixed part of `fixed_bytes` (kContactModelFixedBytes and kContactBytes, or the compact ones):
/// at most num_contacts. A sender leaves the rest out (those contacts go without a field); a
/// receiver refuses a larger count (kBadCount).
constexpr int DepthFieldIdCapacity(std::size_t fixed_bytes, std::size_t contact_bytes,
                                   int num_contacts) noexcept {
  const int n = num_contacts < 0 ? 0 : num_contacts;
  const std::size_t used = kHeaderBytes + fixed_bytes +
                           static_cast<std::size_t>(n) * contact_bytes + kDepthFieldIdCountBytes +
                           kMacBytes;
  if (used >= kMaxDatagramBytes) return 0;
  const std::size_t fit = (kMaxDatagramBytes - used) / kDepthFieldIdBytes;
  return fit < static_cast<std::size_t>(n) ? static_cast<int>(fit) : n;
}
/// Largest scene object (bytes) a sender fragments or a receiver reassembles.
inline constexpr std::uint32_t kMaxSceneObjectBytes = 64u << 20;

// CompactContactModel: its steps and markers, and the largest difference between each field as
// decoded and as the sender had it (tests/compact_contact_model_test.cc checks each on random
// models, and the wrench and stiffness they give).
/// Largest magnitude of a quantized i16 field.
inline constexpr int kCompactI16Max = 32767;
/// An i16 field that was not finite at the sender (the receiver rejects the datagram).
inline constexpr std::int16_t kCompactNotFinite = -32768;
/// Largest time (µs) a u16 time field carries; larger times are sent as this.
inline constexpr double kCompactMaxTimeUs = 65534.0;
/// A u16 time field that was not finite at the sender (the receiver rejects the datagram).
inline constexpr std::uint16_t kCompactTimeNotFinite = 65535;
/// Step (m) of a contact point's offset from p_WT0, and the offset's reach per axis (±0.655 m).
inline constexpr double kCompactPointStepM = 20e-6;
inline constexpr double kCompactPointRangeM = kCompactI16Max * kCompactPointStepM;
/// f32 fields (depth_m, gradients, stiffness): |error| ≤ 2⁻²⁴·|value| + 2⁻¹⁵⁰
/// (round to nearest; the 2⁻¹⁵⁰ is for f32 subnormals). Beyond f32's range a value becomes infinite
/// and the receiver rejects the datagram.
inline constexpr double kCompactF32RelativeError = 0x1p-24;
/// Gradients ∂δ/∂x, ∂δ/∂θ are f32 fields too (each component to 2⁻²⁴ of itself). An i16 with a
/// per-message step (max |component|/32767) was tried first: it zeroed every component below half
/// a step (1.5e-5 beside the normal's −1), and on the fig75 run that held the block exactly on a
/// ridge crest, where the float model lets the tool roll off the crest sideways (1.1 mm, 0.4 N)
/// once rounding noise breaks the symmetry: a 33 % RMS difference in the device force. Small
/// components matter; f32 keeps them.
/// Contact point: per axis |error| ≤ kCompactPointStepM/2 (plus the double rounding of the
/// receiver's p_WT0 + offset; the offset is taken from p_WT0 as the receiver reads it, f32 since
/// version 11) where |point_W − p_WT0| ≤ kCompactPointRangeM − kCompactPointErrorM on that axis;
/// beyond, the axis is clamped to ±kCompactPointRangeM from p_WT0.
inline constexpr double kCompactPointErrorM = 0.5 * kCompactPointStepM;
/// Normal: angle ≤ √18/65534 = 6.474e-5 rad. Rounding moves (u, v) by ≤ √2/65534; unfolding (u, v)
/// onto the octahedron ‖p‖₁ = 1 is √3-Lipschitz; the octahedron is ≥ 1/√3 from the origin.
/// (The bound is nearly reached: 4·10⁶ random directions gave 6.45e-5 rad.)
inline constexpr double kCompactNormalErrorRad = 6.5e-5;
/// X_WT0's rotation, "smallest three" in 26 bits each (version 11), and its step: the largest
/// magnitude of a component that is not the largest is 1/√2.
inline constexpr int kCompactModelQuaternionBits = 26;
inline constexpr std::int64_t kCompactModelQuaternionMax =
    (std::int64_t{1} << (kCompactModelQuaternionBits - 1)) - 1;
inline constexpr double kCompactModelQuaternionStep =
    0.70710678118654752 / static_cast<double>(kCompactModelQuaternionMax);
/// X_WT0's rotation: angle ≤ 2⁻²² rad (2.4e-7; 5 nm at a 20 mm lever). By CompactToolState's
/// argument (kCompactToolStateRotationErrorRad) the angle is ≤ 9.5·kCompactModelQuaternionStep
/// = 2.0e-7 rad. (Versions 4 to 10 sent 4×f32 within the same bound.)
inline constexpr double kCompactRotationErrorRad = 0x1p-22;
/// p_WT0: per axis |error| ≤ 2⁻²⁴·|p| + 2⁻¹⁵⁰ (f32, round to nearest: 0.06 µm at 1 m from W's
/// origin, the tool state's own precision, kCompactToolStatePositionRelativeError).
inline constexpr double kCompactModelPositionRelativeError = 0x1p-24;
/// Times: |error| ≤ 0.5 µs within [0, kCompactMaxTimeUs]; below 0 they are sent as 0, above as
/// kCompactMaxTimeUs. The echo and the hold: |error| ≤ 0.5 µs (rounded to whole µs; the echo
/// within ±2³¹ µs of the receiver's clock, the hold within [0, 2³² − 1] µs).
inline constexpr double kCompactTimeErrorUs = 0.5;

// CompactToolState: its quaternion step and the largest difference between each field as decoded
// and as the sender had it (tests/compact_tool_state_test.cc checks each on random states).
/// Bits of each of the three smaller quaternion components, and their step: the largest magnitude
/// of a component that is not the largest is 1/√2.
inline constexpr int kCompactQuaternionBits = 20;
inline constexpr std::int32_t kCompactQuaternionMax = (1 << (kCompactQuaternionBits - 1)) - 1;
inline constexpr double kCompactQuaternionStep = 0.70710678118654752 / kCompactQuaternionMax;
/// p_WT: per axis |error| ≤ 2⁻²⁴·|p| + 2⁻¹⁵⁰ (f32, round to nearest: 0.06 µm at 1 m from W's
/// origin; the 2⁻¹⁵⁰ is for f32 subnormals). Beyond f32's range the coordinate is sent as NaN and
/// the receiver rejects the datagram.
inline constexpr double kCompactToolStatePositionRelativeError = 0x1p-24;
/// R_WT: angle ≤ 1.3e-5 rad (0.26 µm at a 20 mm lever). Each of the three components moves by
/// ≤ step/2 (‖Δ‖ ≤ √3·step/2); the restored largest, ≥ 1/2, moves by ≤ ‖c‖·‖Δ‖/(1/2) with
/// ‖c‖ ≤ √3/2; so the quaternion moves by ≤ (1 + √3)·√3·step/2 = 2.37·step, normalizing at most
/// doubles that, and the angle is twice the chord: ≤ 9.5·step = 1.28e-5 rad.
inline constexpr double kCompactToolStateRotationErrorRad = 1.3e-5;
/// V_WT_W: per component |error| ≤ 2⁻¹¹·|v| + 2⁻²⁵ (binary16 round to nearest; the 2⁻²⁵ is for
/// its subnormals below 6.1e-5) within ±65504; beyond, the component is sent as ±65504.
inline constexpr double kCompactTwistRelativeError = 0x1p-11;
inline constexpr double kCompactTwistAbsoluteError = 0x1p-25;
inline constexpr double kCompactTwistMax = 65504.0;

/// Bytes of one object carried per SceneFragment when datagrams are at most `mtu` bytes.
constexpr std::size_t FragmentPayloadBytes(std::size_t mtu) noexcept {
  return mtu - kHeaderBytes - kSceneFragmentFixedBytes - kMacBytes;
}

static_assert(kHeaderBytes + kContactModelFixedBytes + kMaxWireContacts * kContactBytes +
                      kDepthFieldIdCountBytes + kMacBytes <=
                  kMaxDatagramBytes,
              "a full contact model must fit in one datagram");
static_assert(
    kHeaderBytes + kCompactContactModelFixedBytes +
            kMaxWireContacts * (kCompactContactBytes + kDepthFieldIdBytes) +
            kDepthFieldIdCountBytes + kMacBytes <=
        kMaxDatagramBytes,
    "a full compact contact model with a field for each contact must fit in one datagram");
static_assert(DepthFieldIdCapacity(kCompactContactModelFixedBytes, kCompactContactBytes,
                                   kMaxWireContacts) == kMaxWireContacts);
static_assert(kHeaderBytes + kSceneManifestFixedBytes + kMaxManifestEntries * kManifestEntryBytes +
                      kMacBytes <=
                  kMinMtuBytes,
              "a full manifest must fit in the smallest MTU");
static_assert(kHeaderBytes + kSceneNackFixedBytes + 2 * kMaxNackIndices + kMacBytes <= kMinMtuBytes,
              "a full NACK must fit in the smallest MTU");
static_assert(kHeaderBytes + kWelcomeFixedBytes + kMaxWelcomeTargets * kWelcomeTargetBytes +
                      kMacBytes <=
                  kMinMtuBytes,
              "a full Welcome must fit in the smallest MTU");
static_assert(kHeaderBytes + kRejectFixedBytes + kMaxRejectText + kMacBytes <= kMinMtuBytes);
static_assert(kHeaderBytes + kNodePosesFixedBytes + kMaxNodePosesPerDatagram * kNodePoseBytes +
                      kMacBytes <=
                  kMinMtuBytes,
              "a full NodePoses must fit in the smallest MTU");
static_assert(kHeaderBytes + kNodePosesFixedBytes +
                      (kMaxNodePosesPerDatagram + 1) * kNodePoseBytes + kMacBytes >
                  kMinMtuBytes,
              "kMaxNodePosesPerDatagram is as many as fit");

}  // namespace ht::wire
