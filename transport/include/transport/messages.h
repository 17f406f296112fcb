#pragma once
// Encoding and decoding of the messages defined in transport/protocol.h. Field by field,
// little-endian, every length checked before it is read; no allocation.

#include <array>
#include <cstdint>
#include <span>

#include "haptic_core/contact_model.h"
#include "haptic_core/spatial.h"
#include "transport/protocol.h"

namespace ht::wire {

/// Decoded header fields.
struct Header {
  MessageType type = MessageType::kToolState;
  std::uint32_t session_id = 0;
  std::uint64_t sequence = 0;
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

/// Why a datagram was rejected.
enum class DecodeStatus : std::uint8_t {
  kOk = 0,
  kTooShort,  ///< shorter than the header or than its body needs
  kTooLong,   ///< longer than kMaxDatagramBytes or than its body allows
  kBadMagic,
  kBadVersion,
  kBadFlags,
  kUnknownType,
  kBadCount,   ///< contact count above kMaxWireContacts
  kNonFinite,  ///< a pose, twist, wrench or contact field is NaN or infinite
  kBadValue,   ///< a finite but impossible value (non-unit quaternion, negative stiffness)
};

/// Human-readable name of a status ("ok", "too_short", ...), for logs and summaries.
const char* ToString(DecodeStatus status) noexcept;

/// Fixed-capacity buffer for one outgoing datagram.
struct Datagram {
  std::array<std::uint8_t, kMaxDatagramBytes> bytes{};
  std::size_t size = 0;
  std::span<const std::uint8_t> view() const noexcept { return {bytes.data(), size}; }
};

/// Encodes a tool state. Returns the datagram (size kHeaderBytes + kToolStateBodyBytes).
Datagram EncodeToolState(const Header& header, const ToolStateMessage& message) noexcept;
/// Encodes a contact model; contacts beyond kMaxWireContacts are not sent (the caller keeps at
/// most kMaxContacts, which equals it).
Datagram EncodeContactModel(const Header& header, const ContactModelMessage& message) noexcept;
/// Encodes a goodbye.
Datagram EncodeGoodbye(const Header& header) noexcept;

/// Reads and checks the header of `bytes` (magic, version, flags, type, size limits).
DecodeStatus DecodeHeader(std::span<const std::uint8_t> bytes, Header& header) noexcept;
/// Decodes a whole tool-state datagram (header included); checks exact length and finiteness.
DecodeStatus DecodeToolState(std::span<const std::uint8_t> bytes, Header& header,
                             ToolStateMessage& message) noexcept;
/// Decodes a whole contact-model datagram (header included); checks exact length for the count,
/// the count, finiteness, unit quaternion and stiffness ≥ 0.
DecodeStatus DecodeContactModel(std::span<const std::uint8_t> bytes, Header& header,
                                ContactModelMessage& message) noexcept;

static_assert(kMaxWireContacts == kMaxContacts, "wire and model contact limits must agree");

}  // namespace ht::wire
