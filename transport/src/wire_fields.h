#pragma once
// Every message's wire layout, written once as a Fields(archive, message) function that the
// Writer and the Reader both walk (internal to the wire format's files); the sizes checked against
// protocol.h at compile time.

#include "wire_archive.h"

namespace ht::wire::detail {

/// The header as it is on the wire (protocol.h); the u48 send time as its low 32 and high 16 bits
/// (the same little-endian bytes).
struct WireHeader {
  std::uint16_t magic = kMagic;
  std::uint8_t version = static_cast<std::uint8_t>(kProtocolVersion);
  std::uint8_t type = 0;
  std::uint32_t session_id = 0;
  std::uint32_t sequence = 0;
  std::uint32_t send_time_us_low = 0;
  std::uint16_t send_time_us_high = 0;
};

/// The header of versions 2 to 7 (protocol.h), read from an older operator's Hello and written in
/// the Reject that answers it.
struct LegacyWireHeader {
  std::uint32_t magic = kLegacyMagic;
  std::uint16_t version = 0;
  std::uint8_t type = 0;
  std::uint8_t flags = 0;
  std::uint32_t session_id = 0;
  std::uint64_t sequence = 0;
  std::int64_t send_time_ns = 0;
};

/// The header of `type` for `header`: the sequence saturated at 2³² − 1 (the stream's last) and
/// the send time as whole µs, clamped to [0, kMaxSendTimeUs].
inline WireHeader ToWire(const Header& header, MessageType type) noexcept {
  const std::int64_t us = std::clamp<std::int64_t>(header.send_time_ns / 1000, 0, kMaxSendTimeUs);
  return {.type = static_cast<std::uint8_t>(type),
          .session_id = header.session_id,
          .sequence = static_cast<std::uint32_t>(std::min(header.sequence, kMaxSequence)),
          .send_time_us_low = static_cast<std::uint32_t>(us),
          .send_time_us_high = static_cast<std::uint16_t>(us >> 32)};
}

/// The body of Goodbye.
struct EmptyBody {};

constexpr void Fields(auto& a, Of<WireHeader> auto& h) {
  a(h.magic);
  a(h.version);
  a(h.type);
  a(h.session_id);
  a(h.sequence);
  a(h.send_time_us_low);
  a(h.send_time_us_high);
}

constexpr void Fields(auto& a, Of<LegacyWireHeader> auto& h) {
  a(h.magic);
  a(h.version);
  a(h.type);
  a(h.flags);
  a(h.session_id);
  a(h.sequence);
  a(h.send_time_ns);
}

constexpr void Fields(auto&, Of<EmptyBody> auto&) {}

constexpr void Fields(auto& a, Of<ToolStateMessage> auto& m) {
  Pose(a, m.X_WT);
  Vec(a, m.V_WT_W.linear);
  Vec(a, m.V_WT_W.angular);
}

constexpr void Fields(auto& a, Of<ContactLinearization> auto& c) {
  a(c.depth_m);
  Vec(a, c.gradient.d_translation_W);
  Vec(a, c.gradient.d_rotation_W);
  a(c.stiffness_n_per_m);
  Vec32(a, c.point_W);
  Vec32(a, c.normal_W);
}

/// One entry of the depth-field section (protocol.h, version 12): a contact and its field's id.
struct WireFieldId {
  std::uint8_t contact = 0;
  std::uint32_t id = 0;
};

constexpr void Fields(auto& a, Of<WireFieldId> auto& f) {
  a(f.contact);
  a(f.id);
}

/// The field ids of contacts [0, n) of `model` in wire order (the contacts that have one).
constexpr std::size_t FlattenFieldIds(const ContactModel& model, std::size_t n,
                                      std::span<WireFieldId> out) noexcept {
  std::size_t k = 0;
  for (std::size_t i = 0; i < n && k < out.size(); ++i) {
    const std::uint32_t id = model.contacts[i].depth_field_id;
    if (id != 0) out[k++] = {static_cast<std::uint8_t>(i), id};
  }
  return k;
}

/// Gives each wire entry's id to its contact of `model` (whose first `n` contacts were read; the
/// others' ids are 0); false when one names a contact ≥ n or twice, or an id 0.
inline bool DistributeFieldIds(std::span<const WireFieldId> ids, std::size_t n,
                               ContactModel& model) noexcept {
  for (std::size_t i = 0; i < n; ++i) model.contacts[i].depth_field_id = 0;
  for (const WireFieldId& w : ids) {
    if (w.contact >= n || w.id == 0 || model.contacts[w.contact].depth_field_id != 0) return false;
    model.contacts[w.contact].depth_field_id = w.id;
  }
  return true;
}

/// The depth-field section after the contacts, which ends the body (protocol.h): the Writer and
/// the Sizer flatten the model's ids (the first `capacity`), the Reader reads at most `capacity`
/// and gives them to their contacts. Returns the number of entries.
constexpr std::size_t DepthFieldIds(auto& a, auto& model, std::size_t n, std::size_t capacity) {
  std::array<WireFieldId, kMaxWireContacts> ids{};
  std::size_t k = 0;
  if constexpr (!requires { a.Reject(DecodeStatus::kOk); }) {
    k = FlattenFieldIds(model, n, ids);
    const std::size_t sent = Count<std::uint8_t>(a, k, capacity, kDepthFieldIdBytes);
    for (std::size_t j = 0; j < std::min(sent, k); ++j) Fields(a, ids[j]);
    return std::min(sent, k);
  } else {
    k = Count<std::uint8_t>(a, k, capacity, kDepthFieldIdBytes);
    for (std::size_t j = 0; j < k; ++j) Fields(a, ids[j]);
    if (a.ok() && !DistributeFieldIds({ids.data(), k}, n, model)) a.Reject(DecodeStatus::kBadValue);
    return k;
  }
}

constexpr void Fields(auto& a, Of<ContactModelMessage> auto& m) {
  a(m.model.tool_state_seq);
  a(m.tool_state_send_time_ns);
  a(m.hold_ns);
  a(m.remote_step_count);
  a(m.collision_us);
  a(m.texture_us);
  a(m.step_us);
  Pose(a, m.model.X_WT0);
  Vec(a, m.model.F_T_W_at_q0.force);
  Vec(a, m.model.F_T_W_at_q0.torque);
  const std::size_t n = CountBefore<std::uint8_t>(a, m.model.num_contacts, kMaxWireContacts,
                                                  kContactBytes, kDepthFieldIdCountBytes);
  for (std::size_t i = 0; i < n; ++i) Fields(a, m.model.contacts[i]);
  DepthFieldIds(a, m.model, n,
                static_cast<std::size_t>(DepthFieldIdCapacity(kContactModelFixedBytes,
                                                              kContactBytes, static_cast<int>(n))));
}

/// One contact of a CompactContactModel as it is on the wire (protocol.h).
struct CompactContact {
  float depth_m = 0.0f;
  std::array<float, 3> d_translation{};  ///< ∂δ/∂x
  std::array<float, 3> d_rotation{};     ///< ∂δ/∂θ (m/rad)
  float stiffness_n_per_m = 0.0f;
  std::array<std::int16_t, 3> point_offset{};  ///< point_W − p_WT0 in units of kCompactPointStepM
  std::array<std::int16_t, 2> normal_oct{};    ///< octahedral (u, v)·kCompactI16Max
};

/// A CompactContactModel body as it is on the wire: what QuantizeContactModel() makes of a
/// ContactModelMessage and DequantizeContactModel() turns back into one.
struct CompactContactModelBody {
  std::uint32_t tool_state_seq = 0;
  std::uint32_t tool_state_send_time_us = 0;  ///< the echo's whole µs, low 32 bits
  std::uint32_t hold_us = 0;
  std::uint32_t remote_step_count = 0;  ///< low 32 bits
  std::uint16_t collision_us = 0;
  std::uint16_t texture_us = 0;
  std::uint16_t step_us = 0;
  std::array<float, 3> p_WT0{};
  std::uint64_t q_WT0_low = 0;   ///< bits 0–63 of the 80-bit "smallest three"
  std::uint16_t q_WT0_high = 0;  ///< bits 64–79
  int num_contacts = 0;
  std::array<CompactContact, kMaxWireContacts> contacts{};
  int num_field_ids = 0;
  std::array<WireFieldId, kMaxWireContacts> field_ids{};
};

// Every element of an array of scalars, in order.
constexpr void Each(auto& a, auto& values) {
  for (auto& v : values) a(v);
}

constexpr void Fields(auto& a, Of<CompactContact> auto& c) {
  a(c.depth_m);
  Each(a, c.d_translation);
  Each(a, c.d_rotation);
  a(c.stiffness_n_per_m);
  Each(a, c.point_offset);
  Each(a, c.normal_oct);
}

constexpr void Fields(auto& a, Of<CompactContactModelBody> auto& m) {
  a(m.tool_state_seq);
  a(m.tool_state_send_time_us);
  a(m.hold_us);
  a(m.remote_step_count);
  a(m.collision_us);
  a(m.texture_us);
  a(m.step_us);
  Each(a, m.p_WT0);
  a(m.q_WT0_low);
  a(m.q_WT0_high);
  const std::size_t n = CountBefore<std::uint8_t>(a, m.num_contacts, kMaxWireContacts,
                                                  kCompactContactBytes, kDepthFieldIdCountBytes);
  for (std::size_t i = 0; i < n; ++i) Fields(a, m.contacts[i]);
  const std::size_t nf = Count<std::uint8_t>(
      a, m.num_field_ids,
      static_cast<std::size_t>(DepthFieldIdCapacity(kCompactContactModelFixedBytes,
                                                    kCompactContactBytes, static_cast<int>(n))),
      kDepthFieldIdBytes);
  for (std::size_t j = 0; j < nf; ++j) Fields(a, m.field_ids[j]);
}

/// A CompactToolState body as it is on the wire (protocol.h).
struct CompactToolStateBody {
  std::array<float, 3> p_WT{};            ///< m
  std::uint64_t q_WT_smallest_three = 0;  ///< index and three 20-bit components
  std::array<std::uint16_t, 6> V_WT_W{};  ///< binary16: linear (m/s), then angular (rad/s)
};

constexpr void Fields(auto& a, Of<CompactToolStateBody> auto& m) {
  Each(a, m.p_WT);
  a(m.q_WT_smallest_three);
  Each(a, m.V_WT_W);
}

constexpr void Fields(auto& a, Of<DeadbandTerms> auto& d) {
  a(d.tool_state_deadband);
  a(d.model_deadband);
  a(d.tool_state_keepalive_ms);
  a(d.model_keepalive_ms);
}

constexpr void Fields(auto& a, Of<HelloMessage> auto& m) {
  a(m.min_version);
  a(m.max_version);
  a(m.client_nonce);
  a(m.tool_state_rate_hz);
  a(m.max_model_rate_hz);
  a(m.max_grid);
  a(m.mtu);
  a(m.codecs);
  a(m.heartbeat_ms);
  a(m.peer_timeout_ms);
  Fields(a, m.deadband);
}

constexpr void Fields(auto& a, Of<WelcomeTarget> auto& t) {
  Vec32(a, t.box_min_W);
  Vec32(a, t.box_max_W);
  Vec32(a, t.top_W);
  a.F32(t.approach_m);
}

constexpr void Fields(auto& a, Of<WelcomeMessage> auto& m) {
  a(m.client_nonce);
  a(m.version);
  a(m.tool_state_rate_hz);
  a(m.model_rate_hz);
  a(m.grid);
  a(m.window_m);
  a(m.mtu);
  a(m.codecs);
  a(m.heartbeat_ms);
  a(m.peer_timeout_ms);
  Fields(a, m.deadband);
  a(m.scene_objects);
  a.Text(m.scene_name_length, m.scene_name);
  auto& l = m.layout;
  Pose(a, l.X_WT_home);
  a.F32(l.tool_mass_kg);
  Vec32(a, l.tool_inertia_diagonal_T);
  a.F32(l.tool_extent_down_m);
  const std::size_t n =
      Count<std::uint8_t>(a, l.num_targets, kMaxWelcomeTargets, kWelcomeTargetBytes);
  for (std::size_t i = 0; i < n; ++i) Fields(a, l.targets[i]);
}

constexpr void Fields(auto& a, Of<RejectMessage> auto& m) {
  a(m.client_nonce);
  a(m.reason);
  const std::size_t n = Count<std::uint8_t>(a, m.text_length, kMaxRejectText, 1);
  a.Bytes(m.text, n);
}

constexpr void Fields(auto& a, Of<PingMessage> auto& m) { a(m.operator_rtt_us); }

constexpr void Fields(auto& a, Of<PongMessage> auto& m) {
  a(m.ping_sequence);
  a(m.t1_ns);
  a(m.t2_ns);
}

constexpr void Fields(auto& a, Of<SceneFragmentMessage> auto& m) {
  a(m.object_id);
  a(m.version);
  a(m.object_bytes);
  a(m.fragment_index);
  a(m.fragment_count);
  a.Payload(m.payload);
}

constexpr void Fields(auto& a, Of<ManifestEntry> auto& e) {
  a(e.object_id);
  a(e.version);
  a(e.object_bytes);
  a(e.fragment_count);
  a(e.kind);
  a.Bytes(e.digest, kSceneDigestBytes);
}

constexpr void Fields(auto& a, Of<SceneManifestMessage> auto& m) {
  a(m.total_objects);
  a(m.first_index);
  const std::size_t n = Count<std::uint8_t>(a, m.count, kMaxManifestEntries, kManifestEntryBytes);
  for (std::size_t i = 0; i < n; ++i) Fields(a, m.entries[i]);
}

constexpr void Fields(auto& a, Of<SceneNackMessage> auto& m) {
  a(m.object_id);
  a(m.version);
  const std::size_t n = Count<std::uint16_t>(a, m.count, kMaxNackIndices, 2);
  for (std::size_t i = 0; i < n; ++i) a(m.missing[i]);
}

constexpr void Fields(auto& a, Of<NodePose> auto& p) {
  a(p.node);
  a(p.translation.x);
  a(p.translation.y);
  a(p.translation.z);
  a(p.rotation.w);
  a(p.rotation.x);
  a(p.rotation.y);
  a(p.rotation.z);
  a(p.scale.x);
  a(p.scale.y);
  a(p.scale.z);
}

constexpr void Fields(auto& a, Of<NodePosesMessage> auto& m) {
  a(m.graph_version);
  a(m.scene_time_s);
  const std::size_t n = Count<std::uint8_t>(a, m.count, kMaxNodePosesPerDatagram, kNodePoseBytes);
  for (std::size_t i = 0; i < n; ++i) Fields(a, m.poses[i]);
}

/// Msg's field list measured: bytes with one element per count, and the bytes the counts declare
/// their elements take.
template <class Msg>
constexpr Sizer SizeOf() {
  Sizer s;
  Msg m;
  Fields(s, m);
  return s;
}

static_assert(SizeOf<WireHeader>().bytes == kHeaderBytes);
static_assert(SizeOf<LegacyWireHeader>().bytes == kLegacyHeaderBytes);
static_assert(SizeOf<ToolStateMessage>().bytes == kToolStateBodyBytes);
static_assert(SizeOf<ContactModelMessage>().bytes ==
              kContactModelFixedBytes + kContactBytes + kDepthFieldIdCountBytes);
static_assert(SizeOf<ContactModelMessage>().counted_bytes == kContactBytes + kDepthFieldIdBytes);
static_assert(SizeOf<CompactContactModelBody>().bytes ==
              kCompactContactModelFixedBytes + kCompactContactBytes + kDepthFieldIdCountBytes +
                  kDepthFieldIdBytes);
static_assert(SizeOf<CompactContactModelBody>().counted_bytes ==
              kCompactContactBytes + kDepthFieldIdBytes);
static_assert(SizeOf<WireFieldId>().bytes == kDepthFieldIdBytes);
static_assert(SizeOf<CompactToolStateBody>().bytes == kCompactToolStateBodyBytes);
static_assert(SizeOf<HelloMessage>().bytes == kHelloBodyBytes);
static_assert(SizeOf<WelcomeMessage>().bytes == kWelcomeFixedBytes + kWelcomeTargetBytes);
static_assert(SizeOf<WelcomeMessage>().counted_bytes == kWelcomeTargetBytes);
static_assert(SizeOf<RejectMessage>().bytes == kRejectFixedBytes + 1);
static_assert(SizeOf<PingMessage>().bytes == kPingBodyBytes);
static_assert(SizeOf<PongMessage>().bytes == kPongBodyBytes);
static_assert(SizeOf<SceneFragmentMessage>().bytes == kSceneFragmentFixedBytes);
static_assert(SizeOf<SceneManifestMessage>().bytes ==
              kSceneManifestFixedBytes + kManifestEntryBytes);
static_assert(SizeOf<SceneManifestMessage>().counted_bytes == kManifestEntryBytes);
static_assert(SizeOf<SceneNackMessage>().bytes == kSceneNackFixedBytes + 2);
static_assert(SizeOf<NodePosesMessage>().bytes == kNodePosesFixedBytes + kNodePoseBytes);
static_assert(SizeOf<NodePosesMessage>().counted_bytes == kNodePoseBytes);

}  // namespace ht::wire::detail
