#pragma once
// Datagram authentication: a pre-shared key, its file, the per-datagram MAC (HMAC-SHA-256-128 since
// protocol version 8: libsodium's crypto_auth_hmacsha256 truncated to 128 bits; versions 2 to 7
// had crypto_auth, HMAC-SHA-512-256) and the anti-replay window on sequence numbers.

#include <array>
#include <cstdint>
#include <span>
#include <string>

#include "transport/protocol.h"

namespace ht {

/// A 32-byte pre-shared key for the MAC. Both sides hold the same key.
struct MacKey {
  std::array<std::uint8_t, wire::kMacKeyBytes> bytes{};

  /// A new key from libsodium's CSPRNG (randombytes_buf).
  static MacKey Generate();
  /// Parses 64 hexadecimal characters (surrounding whitespace ignored). Throws
  /// std::invalid_argument saying what was found when the text is not exactly that.
  static MacKey FromHex(const std::string& text);
  /// 64 lowercase hexadecimal characters.
  std::string ToHex() const;
};

/// Reads a key file (64 hex characters and a newline). Throws std::runtime_error when the file
/// is missing or unreadable, when group or others may read or write it (the message says
/// `chmod 600 PATH`), or when its content is not a key.
MacKey LoadKeyFile(const std::string& path);

/// Writes `key` to `path` with mode 0600 (created exclusively unless `overwrite`). Throws
/// std::runtime_error when the file exists and !overwrite, or cannot be written.
void WriteKeyFile(const std::string& path, const MacKey& key, bool overwrite);

/// Computes the wire MAC of `message` into `mac`: HMAC-SHA-256-128 under `key`, the first
/// kMacBytes (16) of HMAC-SHA-256 (RFC 2104), truncated to half the hash's output, the shortest RFC
/// 2104 §5 recommends, as RFC 4868 specifies for IPsec. Never fails.
void ComputeMac(std::span<const std::uint8_t> message, const MacKey& key,
                std::span<std::uint8_t, wire::kMacBytes> mac) noexcept;

/// Verifies, in constant time, that the last kMacBytes of `datagram` are the wire MAC of the
/// bytes before them. False when the datagram is shorter than a MAC or the MAC does not verify.
bool VerifyMac(std::span<const std::uint8_t> datagram, const MacKey& key) noexcept;

/// The whole 32-byte HMAC-SHA-512-256 (crypto_auth) of `message`: the MAC of protocol versions 2
/// to 7, for answering an older operator's Hello. Never fails.
void ComputeFullMac(std::span<const std::uint8_t> message, const MacKey& key,
                    std::span<std::uint8_t, wire::kFullMacBytes> mac) noexcept;

/// VerifyMac for a datagram of versions 2 to 7, whose last kFullMacBytes are the whole
/// crypto_auth of the bytes before them.
bool VerifyFullMac(std::span<const std::uint8_t> datagram, const MacKey& key) noexcept;

/// BLAKE2b-128 digest (crypto_generichash, unkeyed) of `bytes`: names the content of a scene
/// object end to end, independently of the per-datagram MACs.
std::array<std::uint8_t, wire::kSceneDigestBytes> ContentDigest(
    std::span<const std::uint8_t> bytes) noexcept;

/// Sliding anti-replay window over one stream's sequence numbers (RFC 6479 style bitmap of the
/// last kBits numbers below the highest seen). Fixed size; no allocation.
class ReplayWindow {
 public:
  static constexpr std::uint64_t kBits = 1024;

  /// What a sequence number is relative to those already accepted.
  enum class Verdict : std::uint8_t {
    kNewest,     ///< above every accepted number
    kLate,       ///< below the highest, inside the window, not seen before (reordered)
    kDuplicate,  ///< seen before (a network duplicate or a replay)
    kTooOld,     ///< below the window: cannot tell, so refused
    kZero,       ///< 0 is never a valid sequence number
  };

  /// Classifies `sequence` without changing the window.
  Verdict Check(std::uint64_t sequence) const noexcept;
  /// Marks `sequence` seen (call after the datagram authenticated). Returns Check's verdict.
  Verdict Accept(std::uint64_t sequence) noexcept;
  /// Forgets everything (a new session).
  void Reset() noexcept;
  /// Highest accepted sequence number (0 = none).
  std::uint64_t highest() const noexcept { return highest_; }

 private:
  std::array<std::uint64_t, kBits / 64> bitmap_{};
  std::uint64_t highest_ = 0;
};

}  // namespace ht
