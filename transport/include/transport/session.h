#pragma once
// Session establishment: the remote node's side of capability negotiation, and the memory of
// recent Hello nonces that stops a recorded Hello from being replayed to open a session.

#include <array>
#include <cstdint>
#include <string>

#include "transport/messages.h"

namespace ht {

/// What the remote node offers (its configuration, fixed for its lifetime).
struct RemoteCapabilities {
  std::uint16_t grid = 50;  ///< penetration-depth grid N (N×N per contact)
  float window_m = 0.02f;   ///< contact window side W (m)
  std::uint16_t mtu = wire::kMaxDatagramBytes;
  std::uint32_t codecs = wire::kCodecDracoMesh;
  float max_model_rate_hz = 0.0f;  ///< cap on contact models per second (0 = none)
  std::uint16_t heartbeat_ms = 100;
  std::uint16_t peer_timeout_ms = 500;
  /// Largest perceptual deadband (Weber fraction) this node accepts on either stream; a Hello
  /// asking more is refused (kCapabilities).
  float max_deadband = 0.5f;
  std::uint16_t scene_objects = 0;
  std::string scene_name;
  /// Sent as is in every Welcome: home pose, tool inertia, where the touchables are.
  wire::SceneLayout layout;
};

/// Negotiates a session from an operator's Hello:
/// - version: the highest both speak, else Reject kVersion;
/// - grid: the remote node's, refused (Reject kCapabilities) when above the operator's max_grid;
/// - model rate: the smaller non-zero of the operator's wish and the node's cap;
/// - MTU: the smaller; codecs: the intersection (no Draco ⇒ no scene objects are announced);
/// - heartbeat: the operator's; peer timeout: the larger of the two; the scene layout: the node's;
/// - deadband: the operator's terms, refused (kCapabilities) when either Weber fraction is above
///   the node's max_deadband, when (with either deadband on) the model keep-alive is shorter
///   than the session's model period, or when a tool-state deadband's keep-alive is not shorter
///   than the session's peer timeout (the node extrapolates a tool state for at most that long).
/// Returns true and fills `welcome` (without its session id, which goes in the header), or false
/// and fills `reject` with a reason and a sentence saying what differs.
bool NegotiateSession(const wire::HelloMessage& hello, const RemoteCapabilities& remote,
                      wire::WelcomeMessage& welcome, wire::RejectMessage& reject) noexcept;

/// The Reject (kVersion) for an operator that speaks versions min_version..max_version, none of
/// them this node's: says both ranges, in at most kMaxRejectText bytes.
wire::RejectMessage MakeVersionReject(std::uint64_t client_nonce, std::uint16_t min_version,
                                      std::uint16_t max_version) noexcept;

/// The last kSize Hello nonces seen, so that a replayed Hello is refused (a new Hello carries a
/// fresh random nonce). Not caught: a Hello older than the last kSize, and, after the remote node
/// restarts (the history is in memory), a recorded Hello it never saw. Such a Hello can open a
/// session only when no live session exists (the remote node defers new Hellos while its current
/// operator is active), and the session it opens carries no traffic: it times out.
class NonceHistory {
 public:
  static constexpr std::size_t kSize = 1024;
  /// True (and remembered) when `nonce` was not seen; false for a repeat.
  bool Insert(std::uint64_t nonce) noexcept;

 private:
  std::array<std::uint64_t, kSize> ring_{};
  std::size_t next_ = 0, count_ = 0;
};

/// A random non-zero 32-bit value from libsodium's CSPRNG (session ids) and 64-bit (nonces).
std::uint32_t RandomSessionId() noexcept;
std::uint64_t RandomNonce() noexcept;

}  // namespace ht
