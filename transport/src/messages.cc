#include "transport/messages.h"

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
  bool ok() const { return ok_; }
  std::size_t remaining() const { return b_.size() - pos_; }

 private:
  std::span<const std::uint8_t> b_;
  std::size_t pos_ = 0;
  bool ok_ = true;
};

void PutHeader(Writer& w, const Header& h) {
  w.Put(kMagic);
  w.Put(kProtocolVersion);
  w.Put(static_cast<std::uint8_t>(h.type));
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
  }
  return "unknown";
}

Datagram EncodeToolState(const Header& header, const ToolStateMessage& m) noexcept {
  Datagram d;
  Writer w(d);
  Header h = header;
  h.type = MessageType::kToolState;
  PutHeader(w, h);
  w.Pose(m.X_WT);
  w.Vec(m.V_WT_W.linear);
  w.Vec(m.V_WT_W.angular);
  return d;
}

Datagram EncodeContactModel(const Header& header, const ContactModelMessage& m) noexcept {
  Datagram d;
  Writer w(d);
  Header h = header;
  h.type = MessageType::kContactModel;
  PutHeader(w, h);
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
  const int n = m.model.num_contacts < 0                  ? 0
                : m.model.num_contacts > kMaxWireContacts ? kMaxWireContacts
                                                          : m.model.num_contacts;
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
  return d;
}

Datagram EncodeGoodbye(const Header& header) noexcept {
  Datagram d;
  Writer w(d);
  Header h = header;
  h.type = MessageType::kGoodbye;
  PutHeader(w, h);
  return d;
}

DecodeStatus DecodeHeader(std::span<const std::uint8_t> bytes, Header& h) noexcept {
  if (bytes.size() < kHeaderBytes) return DecodeStatus::kTooShort;
  if (bytes.size() > kMaxDatagramBytes) return DecodeStatus::kTooLong;
  Reader r(bytes);
  if (r.Get<std::uint32_t>() != kMagic) return DecodeStatus::kBadMagic;
  if (r.Get<std::uint16_t>() != kProtocolVersion) return DecodeStatus::kBadVersion;
  const auto type = r.Get<std::uint8_t>();
  if (r.Get<std::uint8_t>() != 0) return DecodeStatus::kBadFlags;
  if (type < 1 || type > 3) return DecodeStatus::kUnknownType;
  h.type = static_cast<MessageType>(type);
  h.session_id = r.Get<std::uint32_t>();
  h.sequence = r.Get<std::uint64_t>();
  h.send_time_ns = r.Get<std::int64_t>();
  return DecodeStatus::kOk;
}

DecodeStatus DecodeToolState(std::span<const std::uint8_t> bytes, Header& h,
                             ToolStateMessage& m) noexcept {
  if (const DecodeStatus s = DecodeHeader(bytes, h); s != DecodeStatus::kOk) return s;
  if (h.type != MessageType::kToolState) return DecodeStatus::kUnknownType;
  if (bytes.size() < kHeaderBytes + kToolStateBodyBytes) return DecodeStatus::kTooShort;
  if (bytes.size() > kHeaderBytes + kToolStateBodyBytes) return DecodeStatus::kTooLong;
  Reader r(bytes.subspan(kHeaderBytes));
  ToolStateMessage out;
  out.X_WT = r.Pose();
  out.V_WT_W.linear = r.Vec();
  out.V_WT_W.angular = r.Vec();
  if (const DecodeStatus s = CheckPose(out.X_WT); s != DecodeStatus::kOk) return s;
  if (!IsFinite(out.V_WT_W)) return DecodeStatus::kNonFinite;
  m = out;
  return DecodeStatus::kOk;
}

DecodeStatus DecodeContactModel(std::span<const std::uint8_t> bytes, Header& h,
                                ContactModelMessage& m) noexcept {
  if (const DecodeStatus s = DecodeHeader(bytes, h); s != DecodeStatus::kOk) return s;
  if (h.type != MessageType::kContactModel) return DecodeStatus::kUnknownType;
  if (bytes.size() < kHeaderBytes + kContactModelFixedBytes) return DecodeStatus::kTooShort;
  Reader r(bytes.subspan(kHeaderBytes));
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

}  // namespace ht::wire
