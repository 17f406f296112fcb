#include "transport/messages.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <concepts>
#include <cstring>
#include <limits>
#include <span>
#include <type_traits>

#include "compact_quantization.h"
#include "haptic_core/byte_order.h"
#include "haptic_core/contact_assembly.h"
#include "message_checks.h"
#include "transport/messages.h"
#include "wire_fields.h"

namespace ht::wire {

using namespace detail;  // NOLINT(google-build-using-namespace): the wire format's own internals

namespace {

template <class Body>
Datagram Encode(const Header& header, MessageType type, const Body& body, const MacKey& key,
                std::uint16_t version = kProtocolVersion) noexcept {
  Datagram d;
  Writer w(d);
  WireHeader h = ToWire(header, type);
  h.version = static_cast<std::uint8_t>(version);
  Fields(w, h);
  Fields(w, body);
  w.Seal(key);
  return d;
}

/// Reads `body` into a new Msg (structure checked as it is read), then Check(); `m` is written
/// only on kOk.
template <class Msg>
DecodeStatus Decode(std::span<const std::uint8_t> body, Msg& m) noexcept {
  Reader r(body);
  Msg out;
  Fields(r, out);
  if (const DecodeStatus s = r.Finish(); s != DecodeStatus::kOk) return s;
  if (const DecodeStatus s = Check(out); s != DecodeStatus::kOk) return s;
  m = out;
  return DecodeStatus::kOk;
}

/// Reads a quantized body (`Wire`, its structure and values checked), then the message it stands
/// for, checked as the full-precision decoder checks it (finite by construction once the body
/// passed); `m` is written only on kOk.
template <class Wire, class Msg, class Dequantize>
DecodeStatus DecodeQuantized(std::span<const std::uint8_t> body, Msg& m,
                             Dequantize&& dequantize) noexcept {
  Wire wire;
  if (const DecodeStatus s = Decode(body, wire); s != DecodeStatus::kOk) return s;
  const Msg out = dequantize(wire);
  if (const DecodeStatus s = Check(out); s != DecodeStatus::kOk) return s;
  m = out;
  return DecodeStatus::kOk;
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
    case MessageType::kCompactContactModel:
      return "compact_contact_model";
    case MessageType::kNodePoses:
      return "node_poses";
    case MessageType::kCompactToolState:
      return "compact_tool_state";
    case MessageType::kDepthFieldFragment:
      return "depth_field_fragment";
    case MessageType::kDepthFieldNack:
      return "depth_field_nack";
  }
  return "unknown";
}

Datagram EncodeToolState(const Header& header, const ToolStateMessage& m,
                         const MacKey& key) noexcept {
  return Encode(header, MessageType::kToolState, m, key);
}

Datagram EncodeCompactToolState(const Header& header, const ToolStateMessage& m,
                                const MacKey& key) noexcept {
  return Encode(header, MessageType::kCompactToolState, QuantizeToolState(m), key);
}

ToolStateMessage CompactToolStateAsReceived(const ToolStateMessage& m) noexcept {
  const CompactToolStateBody b = QuantizeToolState(m);
  if (Check(b) != DecodeStatus::kOk) return m;
  const ToolStateMessage out = DequantizeToolState(b);
  return Check(out) == DecodeStatus::kOk ? out : m;
}

Datagram EncodeContactModel(const Header& header, const ContactModelMessage& m,
                            const MacKey& key) noexcept {
  return Encode(header, MessageType::kContactModel, m, key);
}

Datagram EncodeCompactContactModel(const Header& header, const ContactModelMessage& m,
                                   const MacKey& key) noexcept {
  return Encode(header, MessageType::kCompactContactModel, QuantizeContactModel(m), key);
}

Datagram EncodeGoodbye(const Header& header, const MacKey& key) noexcept {
  return Encode(header, MessageType::kGoodbye, EmptyBody{}, key);
}

Datagram EncodePing(const Header& header, const PingMessage& m, const MacKey& key) noexcept {
  return Encode(header, MessageType::kPing, m, key);
}

Datagram EncodeHello(const Header& header, const HelloMessage& m, const MacKey& key) noexcept {
  return Encode(header, MessageType::kHello, m, key);
}

Datagram EncodeWelcome(const Header& header, const WelcomeMessage& m, const MacKey& key) noexcept {
  return Encode(header, MessageType::kWelcome, m, key);
}

Datagram EncodeReject(const Header& header, const RejectMessage& m, const MacKey& key) noexcept {
  return Encode(header, MessageType::kReject, m, key);
}

Datagram EncodeReject(const Header& header, const RejectMessage& m, const MacKey& key,
                      std::uint16_t version) noexcept {
  // An older version in this layout (8 to kProtocolVersion − 1): this layout with its number.
  if (version >= kFirstShortHeaderVersion && version < kProtocolVersion) {
    return Encode(header, MessageType::kReject, m, key, version);
  }
  // This version, or one whose layout is unknown here (the caller only asks for versions a
  // foreign Hello had: 2 to kProtocolVersion − 1), in this version's layout.
  if (version < 2 || version > kLastLegacyVersion) return EncodeReject(header, m, key);
  Datagram d;
  Writer w(d);
  const LegacyWireHeader h{.version = version,
                           .type = static_cast<std::uint8_t>(MessageType::kReject),
                           .session_id = header.session_id,
                           .sequence = header.sequence,
                           .send_time_ns = header.send_time_ns};
  Fields(w, h);
  Fields(w, m);
  w.SealFull(key);
  return d;
}

/// The header of layout `H` (`header_bytes`) and the Hello's first fields, which versions 2 to 9
/// lay out alike: u16 min_version, u16 max_version, u64 client_nonce. kTooShort unless `bytes`
/// holds them and a MAC of `mac_bytes`.
template <class H>
DecodeStatus ReadHelloStart(std::span<const std::uint8_t> bytes, std::size_t header_bytes,
                            std::size_t mac_bytes, H& h, ForeignHello& hello) noexcept {
  if (bytes.size() < header_bytes + 12 + mac_bytes) return DecodeStatus::kTooShort;
  Reader r(bytes.first(header_bytes + 12));
  Fields(r, h);
  r(hello.min_version);
  r(hello.max_version);
  r(hello.client_nonce);
  hello.header_version = h.version;
  return DecodeStatus::kOk;
}

DecodeStatus OpenForeignHello(std::span<const std::uint8_t> bytes, const MacKey& key,
                              ForeignHello& hello) noexcept {
  if (bytes.size() > kMaxDatagramBytes) return DecodeStatus::kTooLong;
  if (bytes.size() < 4) return DecodeStatus::kTooShort;
  constexpr auto kHello = static_cast<std::uint8_t>(MessageType::kHello);
  ForeignHello read;
  // This version's layout: this version (open it with OpenDatagram) or a newer one, whose
  // layout is unknown here (dropped: a newer operator falls back to this version itself), are
  // kBadVersion; an older one (kFirstShortHeaderVersion to kProtocolVersion − 1: the same header
  // and MAC) is read as far as the Hello's first fields.
  if (LoadLe<std::uint32_t>(bytes.data()) != kLegacyMagic) {
    if (LoadLe<std::uint16_t>(bytes.data()) != kMagic) return DecodeStatus::kBadMagic;
    const std::uint8_t version = bytes[kHeaderVersionOffset];
    if (version < kFirstShortHeaderVersion || version >= kProtocolVersion) {
      return DecodeStatus::kBadVersion;
    }
    WireHeader w;
    if (const DecodeStatus s = ReadHelloStart(bytes, kHeaderBytes, kMacBytes, w, read);
        s != DecodeStatus::kOk) {
      return s;
    }
    if (w.type != kHello) return DecodeStatus::kUnexpected;
    if (!VerifyMac(bytes, key)) return DecodeStatus::kBadMac;
    hello = read;
    return DecodeStatus::kOk;
  }
  LegacyWireHeader w;
  if (const DecodeStatus s = ReadHelloStart(bytes, kLegacyHeaderBytes, kLegacyMacBytes, w, read);
      s != DecodeStatus::kOk) {
    return s;
  }
  // Versions 2 to 7 share this header and the Hello's and Reject's first fields.
  if (w.version < 2 || w.version > kLastLegacyVersion) return DecodeStatus::kBadVersion;
  if (w.flags != 0) return DecodeStatus::kBadFlags;
  if (w.type != kHello) return DecodeStatus::kUnexpected;
  if (!VerifyFullMac(bytes, key)) return DecodeStatus::kBadMac;
  hello = read;
  return DecodeStatus::kOk;
}

Datagram EncodePong(const Header& header, const PongMessage& m, const MacKey& key) noexcept {
  return Encode(header, MessageType::kPong, m, key);
}

Datagram EncodeSceneFragment(const Header& header, const SceneFragmentMessage& m,
                             const MacKey& key) noexcept {
  return Encode(header, MessageType::kSceneFragment, m, key);
}

Datagram EncodeSceneManifest(const Header& header, const SceneManifestMessage& m,
                             const MacKey& key) noexcept {
  return Encode(header, MessageType::kSceneManifest, m, key);
}

Datagram EncodeSceneNack(const Header& header, const SceneNackMessage& m,
                         const MacKey& key) noexcept {
  return Encode(header, MessageType::kSceneNack, m, key);
}

Datagram EncodeDepthFieldFragment(const Header& header, const SceneFragmentMessage& m,
                                  const MacKey& key) noexcept {
  return Encode(header, MessageType::kDepthFieldFragment, m, key);
}

Datagram EncodeDepthFieldNack(const Header& header, const SceneNackMessage& m,
                              const MacKey& key) noexcept {
  return Encode(header, MessageType::kDepthFieldNack, m, key);
}

Datagram EncodeNodePoses(const Header& header, const NodePosesMessage& m,
                         const MacKey& key) noexcept {
  return Encode(header, MessageType::kNodePoses, m, key);
}

DecodeStatus PeekHeader(std::span<const std::uint8_t> bytes, Header& h) noexcept {
  if (bytes.size() < kHeaderBytes) return DecodeStatus::kTooShort;
  if (bytes.size() > kMaxDatagramBytes) return DecodeStatus::kTooLong;
  Reader r(bytes.first(kHeaderBytes));
  WireHeader w;
  Fields(r, w);
  if (w.magic != kMagic) return DecodeStatus::kBadMagic;
  if (w.version != kProtocolVersion) return DecodeStatus::kBadVersion;
  if (w.type < 1 || w.type > kMaxMessageType) return DecodeStatus::kUnknownType;
  h.type = static_cast<MessageType>(w.type);
  h.session_id = w.session_id;
  h.sequence = w.sequence;
  h.send_time_ns =
      1000 * (static_cast<std::int64_t>(w.send_time_us_high) << 32 | w.send_time_us_low);
  return DecodeStatus::kOk;
}

int DatagramType(std::span<const std::uint8_t> bytes) noexcept {
  if (bytes.size() > kHeaderTypeOffset && LoadLe<std::uint16_t>(bytes.data()) == kMagic &&
      bytes[kHeaderVersionOffset] == kProtocolVersion) {
    return bytes[kHeaderTypeOffset];
  }
  if (bytes.size() > 6 && LoadLe<std::uint32_t>(bytes.data()) == kLegacyMagic) return bytes[6];
  return 0;
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
  EmptyBody m;
  return Decode(body, m);
}

DecodeStatus DecodePing(std::span<const std::uint8_t> body, PingMessage& m) noexcept {
  return Decode(body, m);
}

DecodeStatus DecodeToolState(std::span<const std::uint8_t> body, ToolStateMessage& m) noexcept {
  return Decode(body, m);
}

DecodeStatus DecodeCompactToolState(std::span<const std::uint8_t> body,
                                    ToolStateMessage& m) noexcept {
  return DecodeQuantized<CompactToolStateBody>(body, m, DequantizeToolState);
}

DecodeStatus DecodeContactModel(std::span<const std::uint8_t> body,
                                ContactModelMessage& m) noexcept {
  return Decode(body, m);
}

DecodeStatus DecodeCompactContactModel(std::span<const std::uint8_t> body, ContactModelMessage& m,
                                       std::int64_t receive_time_ns) noexcept {
  return DecodeQuantized<CompactContactModelBody>(
      body, m, [receive_time_ns](const CompactContactModelBody& b) {
        return DequantizeContactModel(b, receive_time_ns);
      });
}

DecodeStatus DecodeHello(std::span<const std::uint8_t> body, HelloMessage& m) noexcept {
  return Decode(body, m);
}

DecodeStatus DecodeWelcome(std::span<const std::uint8_t> body, WelcomeMessage& m) noexcept {
  return Decode(body, m);
}

DecodeStatus DecodeReject(std::span<const std::uint8_t> body, RejectMessage& m) noexcept {
  return Decode(body, m);
}

DecodeStatus DecodePong(std::span<const std::uint8_t> body, PongMessage& m) noexcept {
  return Decode(body, m);
}

DecodeStatus DecodeSceneFragment(std::span<const std::uint8_t> body,
                                 SceneFragmentMessage& m) noexcept {
  return Decode(body, m);
}

DecodeStatus DecodeSceneManifest(std::span<const std::uint8_t> body,
                                 SceneManifestMessage& m) noexcept {
  return Decode(body, m);
}

DecodeStatus DecodeSceneNack(std::span<const std::uint8_t> body, SceneNackMessage& m) noexcept {
  return Decode(body, m);
}

DecodeStatus DecodeDepthFieldFragment(std::span<const std::uint8_t> body,
                                      SceneFragmentMessage& m) noexcept {
  SceneFragmentMessage out;
  if (const DecodeStatus s = Decode(body, out); s != DecodeStatus::kOk) return s;
  if (out.object_id == 0 || out.version != kDepthFieldVersion ||
      out.object_bytes > kMaxDepthFieldBytes) {
    return DecodeStatus::kBadValue;
  }
  m = out;
  return DecodeStatus::kOk;
}

DecodeStatus DecodeDepthFieldNack(std::span<const std::uint8_t> body,
                                  SceneNackMessage& m) noexcept {
  SceneNackMessage out;
  if (const DecodeStatus s = Decode(body, out); s != DecodeStatus::kOk) return s;
  if (out.object_id == 0 || out.version != kDepthFieldVersion) return DecodeStatus::kBadValue;
  m = out;
  return DecodeStatus::kOk;
}

DecodeStatus DecodeNodePoses(std::span<const std::uint8_t> body, NodePosesMessage& m) noexcept {
  NodePosesMessage out;
  if (const DecodeStatus s = Decode(body, out); s != DecodeStatus::kOk) return s;
  for (int i = 0; i < out.count; ++i) {
    glm::quat& q = out.poses[static_cast<std::size_t>(i)].rotation;
    const double inverse = 1.0 / std::sqrt(Norm2(q));  // Check(): norm ≥ 1e-6, finite
    q = glm::quat(static_cast<float>(q.w * inverse), static_cast<float>(q.x * inverse),
                  static_cast<float>(q.y * inverse), static_cast<float>(q.z * inverse));
  }
  m = out;
  return DecodeStatus::kOk;
}

}  // namespace ht::wire
