#include "transport/messages.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>

namespace ht::wire {
namespace {

class Writer {
 public:
  explicit Writer(Datagram& d) : d_(d) { d_.size = 0; }
  template <typename T>
  void Put(T value) {
    static_assert(std::is_integral_v<T>);
    for (std::size_t i = 0; i < sizeof(T); ++i) {
      d_.bytes[d_.size++] =
          static_cast<std::uint8_t>(static_cast<std::make_unsigned_t<T>>(value) >> (8 * i));
    }
  }
  void F64(double v) { Put(std::bit_cast<std::uint64_t>(v)); }
  void F32(float v) { Put(std::bit_cast<std::uint32_t>(v)); }
  void Vec(const glm::dvec3& v) {
    F64(v.x);
    F64(v.y);
    F64(v.z);
  }
  void Vec32(const glm::dvec3& v) {
    F32(static_cast<float>(v.x));
    F32(static_cast<float>(v.y));
    F32(static_cast<float>(v.z));
  }
  void Bytes(std::span<const std::uint8_t> b) {
    const std::size_t n = std::min(b.size(), d_.bytes.size() - kMacBytes - d_.size);
    std::memcpy(d_.bytes.data() + d_.size, b.data(), n);
    d_.size += n;
  }
  void Seal(const MacKey& key) {
    ComputeMac({d_.bytes.data(), d_.size}, key,
               std::span<std::uint8_t, kMacBytes>(d_.bytes.data() + d_.size, kMacBytes));
    d_.size += kMacBytes;
  }
  void Pose(const RigidTransform& X) {
    Vec(X.translation);
    F64(X.rotation.w);
    F64(X.rotation.x);
    F64(X.rotation.y);
    F64(X.rotation.z);
  }

 private:
  Datagram& d_;
};

class Reader {
 public:
  explicit Reader(std::span<const std::uint8_t> b) : b_(b) {}
  template <typename T>
  T Get() {
    static_assert(std::is_integral_v<T>);
    std::make_unsigned_t<T> v = 0;
    if (pos_ + sizeof(T) > b_.size()) {
      ok_ = false;
      return 0;
    }
    for (std::size_t i = 0; i < sizeof(T); ++i) {
      v |= static_cast<std::make_unsigned_t<T>>(static_cast<std::make_unsigned_t<T>>(b_[pos_ + i])
                                                << (8 * i));
    }
    pos_ += sizeof(T);
    return static_cast<T>(v);
  }
  double F64() { return std::bit_cast<double>(Get<std::uint64_t>()); }
  float F32() { return std::bit_cast<float>(Get<std::uint32_t>()); }
  glm::dvec3 Vec() {
    const double x = F64(), y = F64(), z = F64();
    return {x, y, z};
  }
  glm::dvec3 Vec32() {
    const double x = F32(), y = F32(), z = F32();
    return {x, y, z};
  }
  RigidTransform Pose() {
    RigidTransform X;
    X.translation = Vec();
    const double w = F64(), x = F64(), y = F64(), z = F64();
    X.rotation = glm::dquat(w, x, y, z);
    return X;
  }
  std::span<const std::uint8_t> Take(std::size_t n) {
    if (pos_ + n > b_.size()) {
      ok_ = false;
      return {};
    }
    const auto r = b_.subspan(pos_, n);
    pos_ += n;
    return r;
  }
  bool ok() const { return ok_; }
  std::size_t remaining() const { return b_.size() - pos_; }

 private:
  std::span<const std::uint8_t> b_;
  std::size_t pos_ = 0;
  bool ok_ = true;
};

void PutHeader(Writer& w, const Header& h, MessageType type) {
  w.Put(kMagic);
  w.Put(kProtocolVersion);
  w.Put(static_cast<std::uint8_t>(type));
  w.Put(std::uint8_t{0});
  w.Put(h.session_id);
  w.Put(h.sequence);
  w.Put(h.send_time_ns);
}

bool Finite3(const glm::dvec3& v) {
  return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}

DecodeStatus CheckPose(const RigidTransform& X) {
  const glm::dquat& q = X.rotation;
  if (!Finite3(X.translation) || !std::isfinite(q.w) || !std::isfinite(q.x) ||
      !std::isfinite(q.y) || !std::isfinite(q.z)) {
    return DecodeStatus::kNonFinite;
  }
  return IsFiniteRigidTransform(X) ? DecodeStatus::kOk : DecodeStatus::kBadValue;
}

DecodeStatus ExactLength(std::span<const std::uint8_t> body, std::size_t n) {
  if (body.size() < n) return DecodeStatus::kTooShort;
  if (body.size() > n) return DecodeStatus::kTooLong;
  return DecodeStatus::kOk;
}

bool FinitePositive(float v) { return std::isfinite(v) && v >= 0.0f; }

template <std::size_t N>
void PutText(Writer& w, const std::array<char, N>& text, std::uint8_t length, bool padded) {
  const std::size_t n = std::min<std::size_t>(length, N);
  w.Bytes({reinterpret_cast<const std::uint8_t*>(text.data()), n});
  if (padded) {
    for (std::size_t i = n; i < N; ++i) w.Put(std::uint8_t{0});
  }
}

}  // namespace

const char* ToString(DecodeStatus s) noexcept {
  switch (s) {
    case DecodeStatus::kOk:
      return "ok";
    case DecodeStatus::kTooShort:
      return "too_short";
    case DecodeStatus::kTooLong:
      return "too_long";
    case DecodeStatus::kBadMagic:
      return "bad_magic";
    case DecodeStatus::kBadVersion:
      return "bad_version";
    case DecodeStatus::kBadFlags:
      return "bad_flags";
    case DecodeStatus::kUnknownType:
      return "unknown_type";
    case DecodeStatus::kBadCount:
      return "bad_count";
    case DecodeStatus::kNonFinite:
      return "non_finite";
    case DecodeStatus::kBadValue:
      return "bad_value";
    case DecodeStatus::kBadMac:
      return "bad_mac";
    case DecodeStatus::kReplayed:
      return "replayed";
    case DecodeStatus::kWrongSession:
      return "wrong_session";
    case DecodeStatus::kUnexpected:
      return "unexpected";
  }
  return "unknown";
}

const char* ToString(MessageType t) noexcept {
  switch (t) {
    case MessageType::kToolState:
      return "tool_state";
    case MessageType::kContactModel:
      return "contact_model";
    case MessageType::kGoodbye:
      return "goodbye";
    case MessageType::kHello:
      return "hello";
    case MessageType::kWelcome:
      return "welcome";
    case MessageType::kReject:
      return "reject";
    case MessageType::kPing:
      return "ping";
    case MessageType::kPong:
      return "pong";
    case MessageType::kSceneFragment:
      return "scene_fragment";
    case MessageType::kSceneNack:
      return "scene_nack";
    case MessageType::kSceneManifest:
      return "scene_manifest";
  }
  return "unknown";
}

Datagram EncodeToolState(const Header& header, const ToolStateMessage& m,
                         const MacKey& key) noexcept {
  Datagram d;
  Writer w(d);
  PutHeader(w, header, MessageType::kToolState);
  w.Pose(m.X_WT);
  w.Vec(m.V_WT_W.linear);
  w.Vec(m.V_WT_W.angular);
  w.Seal(key);
  return d;
}

Datagram EncodeContactModel(const Header& header, const ContactModelMessage& m,
                            const MacKey& key) noexcept {
  Datagram d;
  Writer w(d);
  PutHeader(w, header, MessageType::kContactModel);
  w.Put(m.model.tool_state_seq);
  w.Put(m.tool_state_send_time_ns);
  w.Put(m.hold_ns);
  w.Put(m.remote_step_count);
  w.F32(m.collision_us);
  w.F32(m.texture_us);
  w.F32(m.step_us);
  w.Pose(m.model.X_WT0);
  w.Vec(m.model.F_T_W_at_q0.force);
  w.Vec(m.model.F_T_W_at_q0.torque);
  const int n = std::clamp(m.model.num_contacts, 0, kMaxWireContacts);
  w.Put(static_cast<std::uint8_t>(n));
  for (int i = 0; i < n; ++i) {
    const ContactLinearization& c = m.model.contacts[i];
    w.F64(c.depth_m);
    w.Vec(c.gradient.d_translation_W);
    w.Vec(c.gradient.d_rotation_W);
    w.F64(c.stiffness_n_per_m);
    w.Vec32(c.point_W);
    w.Vec32(c.normal_W);
  }
  w.Seal(key);
  return d;
}

Datagram EncodeGoodbye(const Header& header, const MacKey& key) noexcept {
  Datagram d;
  Writer w(d);
  PutHeader(w, header, MessageType::kGoodbye);
  w.Seal(key);
  return d;
}

Datagram EncodePing(const Header& header, const MacKey& key) noexcept {
  Datagram d;
  Writer w(d);
  PutHeader(w, header, MessageType::kPing);
  w.Seal(key);
  return d;
}

Datagram EncodeHello(const Header& header, const HelloMessage& m, const MacKey& key) noexcept {
  Datagram d;
  Writer w(d);
  PutHeader(w, header, MessageType::kHello);
  w.Put(m.min_version);
  w.Put(m.max_version);
  w.Put(m.client_nonce);
  w.F32(m.tool_state_rate_hz);
  w.F32(m.max_model_rate_hz);
  w.Put(m.max_grid);
  w.Put(m.mtu);
  w.Put(m.codecs);
  w.Put(m.heartbeat_ms);
  w.Put(m.peer_timeout_ms);
  w.Seal(key);
  return d;
}

Datagram EncodeWelcome(const Header& header, const WelcomeMessage& m, const MacKey& key) noexcept {
  Datagram d;
  Writer w(d);
  PutHeader(w, header, MessageType::kWelcome);
  w.Put(m.client_nonce);
  w.Put(m.version);
  w.F32(m.tool_state_rate_hz);
  w.F32(m.model_rate_hz);
  w.Put(m.grid);
  w.F32(m.window_m);
  w.Put(m.mtu);
  w.Put(m.codecs);
  w.Put(m.heartbeat_ms);
  w.Put(m.peer_timeout_ms);
  w.Put(m.scene_objects);
  const auto n =
      static_cast<std::uint8_t>(std::min<std::size_t>(m.scene_name_length, kSceneNameBytes));
  w.Put(n);
  PutText(w, m.scene_name, n, true);
  const SceneLayout& l = m.layout;
  w.Pose(l.X_WT_home);
  w.F32(static_cast<float>(l.tool_mass_kg));
  w.Vec32(l.tool_inertia_diagonal_T);
  w.F32(static_cast<float>(l.tool_extent_down_m));
  const auto targets = static_cast<std::uint8_t>(std::min<int>(l.num_targets, kMaxWelcomeTargets));
  w.Put(targets);
  for (int i = 0; i < targets; ++i) {
    w.Vec32(l.targets[i].box_min_W);
    w.Vec32(l.targets[i].box_max_W);
    w.Vec32(l.targets[i].top_W);
    w.F32(static_cast<float>(l.targets[i].approach_m));
  }
  w.Seal(key);
  return d;
}

Datagram EncodeReject(const Header& header, const RejectMessage& m, const MacKey& key) noexcept {
  Datagram d;
  Writer w(d);
  PutHeader(w, header, MessageType::kReject);
  w.Put(m.client_nonce);
  w.Put(static_cast<std::uint8_t>(m.reason));
  const auto n = static_cast<std::uint8_t>(std::min<std::size_t>(m.text_length, kMaxRejectText));
  w.Put(n);
  PutText(w, m.text, n, false);
  w.Seal(key);
  return d;
}

Datagram EncodePong(const Header& header, const PongMessage& m, const MacKey& key) noexcept {
  Datagram d;
  Writer w(d);
  PutHeader(w, header, MessageType::kPong);
  w.Put(m.ping_sequence);
  w.Put(m.t1_ns);
  w.Put(m.t2_ns);
  w.Seal(key);
  return d;
}

Datagram EncodeSceneFragment(const Header& header, const SceneFragmentMessage& m,
                             const MacKey& key) noexcept {
  Datagram d;
  Writer w(d);
  PutHeader(w, header, MessageType::kSceneFragment);
  w.Put(m.object_id);
  w.Put(m.version);
  w.Put(m.object_bytes);
  w.Put(m.fragment_index);
  w.Put(m.fragment_count);
  w.Bytes(m.payload);
  w.Seal(key);
  return d;
}

Datagram EncodeSceneManifest(const Header& header, const SceneManifestMessage& m,
                             const MacKey& key) noexcept {
  Datagram d;
  Writer w(d);
  PutHeader(w, header, MessageType::kSceneManifest);
  const int n = std::clamp<int>(m.count, 0, kMaxManifestEntries);
  w.Put(m.total_objects);
  w.Put(m.first_index);
  w.Put(static_cast<std::uint8_t>(n));
  for (int i = 0; i < n; ++i) {
    const ManifestEntry& e = m.entries[static_cast<std::size_t>(i)];
    w.Put(e.object_id);
    w.Put(e.version);
    w.Put(e.object_bytes);
    w.Put(e.fragment_count);
    w.Put(static_cast<std::uint8_t>(e.kind));
    w.Bytes(e.digest);
  }
  w.Seal(key);
  return d;
}

Datagram EncodeSceneNack(const Header& header, const SceneNackMessage& m,
                         const MacKey& key) noexcept {
  Datagram d;
  Writer w(d);
  PutHeader(w, header, MessageType::kSceneNack);
  const int n = std::clamp<int>(m.count, 0, kMaxNackIndices);
  w.Put(m.object_id);
  w.Put(m.version);
  w.Put(static_cast<std::uint16_t>(n));
  for (int i = 0; i < n; ++i) w.Put(m.missing[static_cast<std::size_t>(i)]);
  w.Seal(key);
  return d;
}

DecodeStatus PeekHeader(std::span<const std::uint8_t> bytes, Header& h) noexcept {
  if (bytes.size() < kHeaderBytes) return DecodeStatus::kTooShort;
  if (bytes.size() > kMaxDatagramBytes) return DecodeStatus::kTooLong;
  Reader r(bytes);
  if (r.Get<std::uint32_t>() != kMagic) return DecodeStatus::kBadMagic;
  if (r.Get<std::uint16_t>() != kProtocolVersion) return DecodeStatus::kBadVersion;
  const auto type = r.Get<std::uint8_t>();
  if (r.Get<std::uint8_t>() != 0) return DecodeStatus::kBadFlags;
  if (type < 1 || type > kMaxMessageType) return DecodeStatus::kUnknownType;
  h.type = static_cast<MessageType>(type);
  h.session_id = r.Get<std::uint32_t>();
  h.sequence = r.Get<std::uint64_t>();
  h.send_time_ns = r.Get<std::int64_t>();
  return DecodeStatus::kOk;
}

DecodeStatus OpenDatagram(std::span<const std::uint8_t> bytes, const MacKey& key, Header& h,
                          std::span<const std::uint8_t>& body) noexcept {
  if (bytes.size() > kMaxDatagramBytes) return DecodeStatus::kTooLong;
  if (bytes.size() < kHeaderBytes + kMacBytes) return DecodeStatus::kTooShort;
  Header header;
  if (const DecodeStatus s = PeekHeader(bytes, header); s != DecodeStatus::kOk) return s;
  if (!VerifyMac(bytes, key)) return DecodeStatus::kBadMac;
  h = header;
  body = bytes.subspan(kHeaderBytes, bytes.size() - kHeaderBytes - kMacBytes);
  return DecodeStatus::kOk;
}

DecodeStatus DecodeEmpty(std::span<const std::uint8_t> body) noexcept {
  return body.empty() ? DecodeStatus::kOk : DecodeStatus::kTooLong;
}

DecodeStatus DecodeToolState(std::span<const std::uint8_t> body, ToolStateMessage& m) noexcept {
  if (const DecodeStatus s = ExactLength(body, kToolStateBodyBytes); s != DecodeStatus::kOk)
    return s;
  Reader r(body);
  ToolStateMessage out;
  out.X_WT = r.Pose();
  out.V_WT_W.linear = r.Vec();
  out.V_WT_W.angular = r.Vec();
  if (const DecodeStatus s = CheckPose(out.X_WT); s != DecodeStatus::kOk) return s;
  if (!IsFinite(out.V_WT_W)) return DecodeStatus::kNonFinite;
  m = out;
  return DecodeStatus::kOk;
}

DecodeStatus DecodeContactModel(std::span<const std::uint8_t> body,
                                ContactModelMessage& m) noexcept {
  if (body.size() < kContactModelFixedBytes) return DecodeStatus::kTooShort;
  Reader r(body);
  ContactModelMessage out;
  out.model.tool_state_seq = r.Get<std::uint64_t>();
  out.tool_state_send_time_ns = r.Get<std::int64_t>();
  out.hold_ns = r.Get<std::int64_t>();
  out.remote_step_count = r.Get<std::uint64_t>();
  out.collision_us = r.F32();
  out.texture_us = r.F32();
  out.step_us = r.F32();
  out.model.X_WT0 = r.Pose();
  out.model.F_T_W_at_q0.force = r.Vec();
  out.model.F_T_W_at_q0.torque = r.Vec();
  const int n = r.Get<std::uint8_t>();
  if (n > kMaxWireContacts) return DecodeStatus::kBadCount;
  const std::size_t expected = kContactBytes * static_cast<std::size_t>(n);
  if (r.remaining() < expected) return DecodeStatus::kTooShort;
  if (r.remaining() > expected) return DecodeStatus::kTooLong;
  out.model.num_contacts = n;
  for (int i = 0; i < n; ++i) {
    ContactLinearization& c = out.model.contacts[i];
    c.depth_m = r.F64();
    c.gradient.d_translation_W = r.Vec();
    c.gradient.d_rotation_W = r.Vec();
    c.stiffness_n_per_m = r.F64();
    c.point_W = r.Vec32();
    c.normal_W = r.Vec32();
    if (!std::isfinite(c.depth_m) || !Finite3(c.gradient.d_translation_W) ||
        !Finite3(c.gradient.d_rotation_W) || !std::isfinite(c.stiffness_n_per_m) ||
        !Finite3(c.point_W) || !Finite3(c.normal_W)) {
      return DecodeStatus::kNonFinite;
    }
    if (c.stiffness_n_per_m < 0.0) return DecodeStatus::kBadValue;
  }
  if (!r.ok()) return DecodeStatus::kTooShort;
  if (const DecodeStatus s = CheckPose(out.model.X_WT0); s != DecodeStatus::kOk) return s;
  if (!IsFinite(out.model.F_T_W_at_q0) || !std::isfinite(out.collision_us) ||
      !std::isfinite(out.texture_us) || !std::isfinite(out.step_us)) {
    return DecodeStatus::kNonFinite;
  }
  m = out;
  return DecodeStatus::kOk;
}

DecodeStatus DecodeHello(std::span<const std::uint8_t> body, HelloMessage& m) noexcept {
  if (const DecodeStatus s = ExactLength(body, kHelloBodyBytes); s != DecodeStatus::kOk) return s;
  Reader r(body);
  HelloMessage out;
  out.min_version = r.Get<std::uint16_t>();
  out.max_version = r.Get<std::uint16_t>();
  out.client_nonce = r.Get<std::uint64_t>();
  out.tool_state_rate_hz = r.F32();
  out.max_model_rate_hz = r.F32();
  out.max_grid = r.Get<std::uint16_t>();
  out.mtu = r.Get<std::uint16_t>();
  out.codecs = r.Get<std::uint32_t>();
  out.heartbeat_ms = r.Get<std::uint16_t>();
  out.peer_timeout_ms = r.Get<std::uint16_t>();
  if (!std::isfinite(out.tool_state_rate_hz) || !std::isfinite(out.max_model_rate_hz)) {
    return DecodeStatus::kNonFinite;
  }
  if (out.min_version > out.max_version || !(out.tool_state_rate_hz > 0.0f) ||
      !FinitePositive(out.max_model_rate_hz) || out.mtu < kMinMtuBytes ||
      out.mtu > kMaxDatagramBytes || out.heartbeat_ms == 0 ||
      out.peer_timeout_ms <= out.heartbeat_ms) {
    return DecodeStatus::kBadValue;
  }
  m = out;
  return DecodeStatus::kOk;
}

DecodeStatus DecodeWelcome(std::span<const std::uint8_t> body, WelcomeMessage& m) noexcept {
  if (body.size() < kWelcomeFixedBytes) return DecodeStatus::kTooShort;
  Reader r(body);
  WelcomeMessage out;
  out.client_nonce = r.Get<std::uint64_t>();
  out.version = r.Get<std::uint16_t>();
  out.tool_state_rate_hz = r.F32();
  out.model_rate_hz = r.F32();
  out.grid = r.Get<std::uint16_t>();
  out.window_m = r.F32();
  out.mtu = r.Get<std::uint16_t>();
  out.codecs = r.Get<std::uint32_t>();
  out.heartbeat_ms = r.Get<std::uint16_t>();
  out.peer_timeout_ms = r.Get<std::uint16_t>();
  out.scene_objects = r.Get<std::uint16_t>();
  out.scene_name_length = r.Get<std::uint8_t>();
  const auto name = r.Take(kSceneNameBytes);
  SceneLayout& l = out.layout;
  l.X_WT_home = r.Pose();
  l.tool_mass_kg = r.F32();
  l.tool_inertia_diagonal_T = r.Vec32();
  l.tool_extent_down_m = r.F32();
  l.num_targets = r.Get<std::uint8_t>();
  if (l.num_targets > kMaxWelcomeTargets) return DecodeStatus::kBadCount;
  if (body.size() != kWelcomeFixedBytes + l.num_targets * kWelcomeTargetBytes) {
    return body.size() < kWelcomeFixedBytes + l.num_targets * kWelcomeTargetBytes
               ? DecodeStatus::kTooShort
               : DecodeStatus::kTooLong;
  }
  for (int i = 0; i < l.num_targets; ++i) {
    WelcomeTarget& t = l.targets[i];
    t.box_min_W = r.Vec32();
    t.box_max_W = r.Vec32();
    t.top_W = r.Vec32();
    t.approach_m = r.F32();
    if (!Finite3(t.box_min_W) || !Finite3(t.box_max_W) || !Finite3(t.top_W) ||
        !std::isfinite(t.approach_m)) {
      return DecodeStatus::kNonFinite;
    }
    if (t.box_min_W.x > t.box_max_W.x || t.box_min_W.y > t.box_max_W.y ||
        t.box_min_W.z > t.box_max_W.z || t.approach_m < 0.0) {
      return DecodeStatus::kBadValue;
    }
  }
  if (const DecodeStatus s = CheckPose(l.X_WT_home); s != DecodeStatus::kOk) return s;
  if (!std::isfinite(l.tool_mass_kg) || !Finite3(l.tool_inertia_diagonal_T) ||
      !std::isfinite(l.tool_extent_down_m)) {
    return DecodeStatus::kNonFinite;
  }
  if (l.tool_mass_kg < 0.0 || l.tool_extent_down_m < 0.0 ||
      (l.tool_mass_kg > 0.0 &&
       !(l.tool_inertia_diagonal_T.x > 0.0 && l.tool_inertia_diagonal_T.y > 0.0 &&
         l.tool_inertia_diagonal_T.z > 0.0))) {
    return DecodeStatus::kBadValue;
  }
  if (!std::isfinite(out.tool_state_rate_hz) || !std::isfinite(out.model_rate_hz) ||
      !std::isfinite(out.window_m)) {
    return DecodeStatus::kNonFinite;
  }
  if (out.scene_name_length > kSceneNameBytes || !(out.tool_state_rate_hz > 0.0f) ||
      !FinitePositive(out.model_rate_hz) || !(out.window_m > 0.0f) || out.grid < 2 ||
      out.mtu < kMinMtuBytes || out.mtu > kMaxDatagramBytes || out.heartbeat_ms == 0 ||
      out.peer_timeout_ms <= out.heartbeat_ms) {
    return DecodeStatus::kBadValue;
  }
  std::memcpy(out.scene_name.data(), name.data(), kSceneNameBytes);
  m = out;
  return DecodeStatus::kOk;
}

DecodeStatus DecodeReject(std::span<const std::uint8_t> body, RejectMessage& m) noexcept {
  if (body.size() < kRejectFixedBytes) return DecodeStatus::kTooShort;
  Reader r(body);
  RejectMessage out;
  out.client_nonce = r.Get<std::uint64_t>();
  const auto reason = r.Get<std::uint8_t>();
  const auto n = r.Get<std::uint8_t>();
  if (n > kMaxRejectText) return DecodeStatus::kBadCount;
  if (r.remaining() < n) return DecodeStatus::kTooShort;
  if (r.remaining() > n) return DecodeStatus::kTooLong;
  if (reason < 1 || reason > 3) return DecodeStatus::kBadValue;
  out.reason = static_cast<RejectReason>(reason);
  const auto text = r.Take(n);
  std::memcpy(out.text.data(), text.data(), n);
  out.text_length = n;
  m = out;
  return DecodeStatus::kOk;
}

DecodeStatus DecodePong(std::span<const std::uint8_t> body, PongMessage& m) noexcept {
  if (const DecodeStatus s = ExactLength(body, kPongBodyBytes); s != DecodeStatus::kOk) return s;
  Reader r(body);
  PongMessage out;
  out.ping_sequence = r.Get<std::uint64_t>();
  out.t1_ns = r.Get<std::int64_t>();
  out.t2_ns = r.Get<std::int64_t>();
  if (out.ping_sequence == 0) return DecodeStatus::kBadValue;
  m = out;
  return DecodeStatus::kOk;
}

DecodeStatus DecodeSceneFragment(std::span<const std::uint8_t> body,
                                 SceneFragmentMessage& m) noexcept {
  if (body.size() <= kSceneFragmentFixedBytes) return DecodeStatus::kTooShort;
  Reader r(body);
  SceneFragmentMessage out;
  out.object_id = r.Get<std::uint32_t>();
  out.version = r.Get<std::uint32_t>();
  out.object_bytes = r.Get<std::uint32_t>();
  out.fragment_index = r.Get<std::uint16_t>();
  out.fragment_count = r.Get<std::uint16_t>();
  out.payload = r.Take(r.remaining());
  if (out.object_bytes == 0 || out.object_bytes > kMaxSceneObjectBytes || out.fragment_count == 0 ||
      out.fragment_index >= out.fragment_count || out.payload.size() > out.object_bytes) {
    return DecodeStatus::kBadValue;
  }
  m = out;
  return DecodeStatus::kOk;
}

DecodeStatus DecodeSceneManifest(std::span<const std::uint8_t> body,
                                 SceneManifestMessage& m) noexcept {
  if (body.size() < kSceneManifestFixedBytes) return DecodeStatus::kTooShort;
  Reader r(body);
  const auto total = r.Get<std::uint16_t>();
  const auto first = r.Get<std::uint16_t>();
  const auto n = r.Get<std::uint8_t>();
  if (n > kMaxManifestEntries) return DecodeStatus::kBadCount;
  const std::size_t expected = kManifestEntryBytes * n;
  if (r.remaining() < expected) return DecodeStatus::kTooShort;
  if (r.remaining() > expected) return DecodeStatus::kTooLong;
  if (static_cast<std::size_t>(first) + n > total) return DecodeStatus::kBadValue;
  SceneManifestMessage out;
  out.total_objects = total;
  out.first_index = first;
  out.count = n;
  for (int i = 0; i < n; ++i) {
    ManifestEntry& e = out.entries[static_cast<std::size_t>(i)];
    e.object_id = r.Get<std::uint32_t>();
    e.version = r.Get<std::uint32_t>();
    e.object_bytes = r.Get<std::uint32_t>();
    e.fragment_count = r.Get<std::uint16_t>();
    const auto kind = r.Get<std::uint8_t>();
    const auto digest = r.Take(kSceneDigestBytes);
    if (kind != static_cast<std::uint8_t>(SceneObjectKind::kDracoMesh) || e.object_bytes == 0 ||
        e.object_bytes > kMaxSceneObjectBytes || e.fragment_count == 0) {
      return DecodeStatus::kBadValue;
    }
    e.kind = static_cast<SceneObjectKind>(kind);
    std::memcpy(e.digest.data(), digest.data(), kSceneDigestBytes);
  }
  m = out;
  return DecodeStatus::kOk;
}

DecodeStatus DecodeSceneNack(std::span<const std::uint8_t> body, SceneNackMessage& m) noexcept {
  if (body.size() < kSceneNackFixedBytes) return DecodeStatus::kTooShort;
  Reader r(body);
  SceneNackMessage out;
  out.object_id = r.Get<std::uint32_t>();
  out.version = r.Get<std::uint32_t>();
  out.count = r.Get<std::uint16_t>();
  if (out.count > kMaxNackIndices) return DecodeStatus::kBadCount;
  const std::size_t expected = 2u * out.count;
  if (r.remaining() < expected) return DecodeStatus::kTooShort;
  if (r.remaining() > expected) return DecodeStatus::kTooLong;
  for (int i = 0; i < out.count; ++i)
    out.missing[static_cast<std::size_t>(i)] = r.Get<std::uint16_t>();
  m = out;
  return DecodeStatus::kOk;
}

}  // namespace ht::wire
