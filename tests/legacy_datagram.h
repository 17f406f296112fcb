#pragma once
// Datagrams of protocol versions 2 to 7 (transport/protocol.h): a 28-byte header (u32 magic
// "HTLP", u16 version, u8 type, u8 flags, u32 session_id, u64 sequence, i64 send_time_ns) and the
// whole 32-byte HMAC-SHA-512-256 (crypto_auth) after the body. Written byte by byte here, not by
// the product's encoder, so that a test of the remote node's answer to an older operator does not
// read that answer back through the code that wrote it.

#include <sodium.h>

#include <algorithm>
#include <cstdint>
#include <span>

#include "transport/auth.h"
#include "transport/messages.h"
#include "transport/protocol.h"

namespace ht::test {

/// The body of a datagram of this version: the bytes between its header and its MAC.
inline std::span<const std::uint8_t> BodyOf(const wire::Datagram& d) {
  return d.view().subspan(wire::kHeaderBytes, d.size - wire::kHeaderBytes - wire::kMacBytes);
}

/// A datagram of `version` (2 to 7, or any number: the layout is the same) and `type` around
/// `body`, sealed with the whole crypto_auth under `key` as those versions did.
inline wire::Datagram LegacyDatagram(std::uint16_t version, wire::MessageType type,
                                     std::uint64_t sequence, std::span<const std::uint8_t> body,
                                     const MacKey& key) {
  wire::Datagram d;
  auto put = [&](std::uint64_t value, int bytes) {
    for (int i = 0; i < bytes; ++i) d.bytes[d.size++] = static_cast<std::uint8_t>(value >> (8 * i));
  };
  put(0x504C5448u, 4);  // "HTLP"
  put(version, 2);
  put(static_cast<std::uint8_t>(type), 1);
  put(0, 1);  // flags
  put(0, 4);  // session_id
  put(sequence, 8);
  put(123456789, 8);  // send_time_ns
  std::copy(body.begin(), body.end(), d.bytes.begin() + static_cast<long>(d.size));
  d.size += body.size();
  crypto_auth(d.bytes.data() + d.size, d.bytes.data(), d.size, key.bytes.data());
  d.size += crypto_auth_BYTES;
  return d;
}

/// The header fields of a datagram of versions 2 to 7, read byte by byte.
struct LegacyHeader {
  std::uint32_t magic = 0;
  std::uint16_t version = 0;
  std::uint8_t type = 0;
  std::uint8_t flags = 0;
};
inline LegacyHeader ReadLegacyHeader(std::span<const std::uint8_t> d) {
  LegacyHeader h;
  if (d.size() < 8) return h;
  h.magic = static_cast<std::uint32_t>(d[0] | d[1] << 8 | d[2] << 16) |
            static_cast<std::uint32_t>(d[3]) << 24;
  h.version = static_cast<std::uint16_t>(d[4] | d[5] << 8);
  h.type = d[6];
  h.flags = d[7];
  return h;
}

/// True when the last 32 bytes of `d` are the whole crypto_auth of the bytes before them.
inline bool LegacyMacVerifies(std::span<const std::uint8_t> d, const MacKey& key) {
  if (d.size() < crypto_auth_BYTES) return false;
  const std::size_t n = d.size() - crypto_auth_BYTES;
  return crypto_auth_verify(d.data() + n, d.data(), n, key.bytes.data()) == 0;
}

}  // namespace ht::test
