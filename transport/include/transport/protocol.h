#pragma once
// The wire format, in one place (ENet-style single source of truth). Every datagram is
//
//   header (kHeaderBytes) | body (per message type, fixed or counted size)
//
// All integers and IEEE-754 floats are little-endian, written and read field by field (never by
// casting a struct over bytes). Wire order of 6-vectors: force then torque, linear then angular.
// Quaternions: w, x, y, z. Units are SI (m, rad, N, N·m, s), times in nanoseconds of the sender's
// steady clock.
//
// Header layout (28 bytes):
//   offset 0  u32 magic            kMagic ("HTLP" read as little-endian u32)
//   offset 4  u16 version          kProtocolVersion
//   offset 6  u8  type             MessageType
//   offset 7  u8  flags            0 (reserved; non-zero is rejected)
//   offset 8  u32 session_id       chosen by the operator side, echoed by the remote side
//   offset 12 u64 sequence         per sender and stream, starting at 1, strictly increasing
//   offset 20 i64 send_time_ns     sender's steady clock at send
//
// ToolState body (operator → remote, kToolStateBodyBytes = 104):
//   X_WT: p_WT (3×f64, m), R_WT (4×f64 quaternion w,x,y,z); V_WT_W: linear (3×f64, m/s),
//   angular (3×f64, rad/s). T is the tool frame at its centre of mass, W the remote world.
//
// ContactModel body (remote → operator, kContactModelFixedBytes + n·kContactBytes):
//   u64 tool_state_seq      sequence of the tool state used as q0 (0 = none received yet)
//   i64 tool_state_send_time_ns   that tool state's send_time_ns, echoed (for round-trip time)
//   i64 hold_ns             remote time between receiving that tool state and sending this
//   u64 remote_step_count   steps the remote node has completed since start
//   f32 collision_us, f32 texture_us, f32 step_us   timings of the step that built this model
//   X_WT0: 3×f64 + 4×f64    q0
//   F_T_W at q0: 3×f64 force (N), 3×f64 torque (N·m)
//   u8  num_contacts        0..kMaxWireContacts
//   per contact (kContactBytes = 88):
//     f64 depth_m, 3×f64 ∂δ/∂x (m/m), 3×f64 ∂δ/∂θ (m/rad), f64 stiffness (N/m),
//     3×f32 point_W (m), 3×f32 normal_W (unit)
//
// Goodbye body: empty. Sent by either side on a clean shutdown.

#include <cstddef>
#include <cstdint>

namespace ht::wire {

inline constexpr std::uint32_t kMagic = 0x504C5448u;  // bytes 'H' 'T' 'L' 'P'
inline constexpr std::uint16_t kProtocolVersion = 1;

/// Message types; values are part of the protocol and never reused.
enum class MessageType : std::uint8_t {
  kToolState = 1,
  kContactModel = 2,
  kGoodbye = 3,
};

inline constexpr std::size_t kHeaderBytes = 28;
inline constexpr std::size_t kToolStateBodyBytes = 13 * 8;
inline constexpr std::size_t kContactModelFixedBytes = 8 * 4 + 4 * 3 + 7 * 8 + 6 * 8 + 1;
inline constexpr std::size_t kContactBytes = 8 + 6 * 8 + 8 + 3 * 4 + 3 * 4;
/// Largest datagram either side sends or accepts: an Ethernet MTU (1500) less IPv4 and UDP headers.
inline constexpr std::size_t kMaxDatagramBytes = 1472;
/// Contacts that fit in one contact-model datagram.
inline constexpr int kMaxWireContacts = 14;

static_assert(kHeaderBytes + kContactModelFixedBytes + kMaxWireContacts * kContactBytes <=
                  kMaxDatagramBytes,
              "a full contact model must fit in one datagram");

}  // namespace ht::wire
