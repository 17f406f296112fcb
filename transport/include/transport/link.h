#pragma once
// One side of an authenticated session over a UDP socket: sealing and opening datagrams,
// per-stream sequence numbers and replay windows, per-stream statistics, and the clock-offset
// estimate. Used by the remote node and by the operator station's network thread; never by the
// 1 kHz loop. After construction nothing here allocates.

#include <array>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <vector>

#include "haptic_core/steady_clock.h"  // SteadyNowNs: the clock every send_time_ns is on
#include "transport/messages.h"
#include "transport/udp_socket.h"

namespace ht {

/// Counters of one stream (one message type, one direction pair) of a link.
struct StreamStats {
  std::uint64_t sent = 0;         ///< datagrams handed to the socket
  std::uint64_t send_failed = 0;  ///< refused by the socket (buffer full, no route)
  std::uint64_t bytes_sent = 0;
  std::uint64_t received = 0;  ///< authenticated, in session, not a duplicate (late ones included;
                               ///< Hello/Welcome/Reject: authenticated)
  std::uint64_t bytes_received = 0;  ///< of those
  std::uint64_t late = 0;            ///< arrived after a higher sequence number (reordered)
  std::uint64_t duplicate = 0;  ///< authenticated, but a sequence number already received, 0, or
                                ///< below the replay window (a network copy or a replay)
  std::uint64_t lost = 0;       ///< sequence numbers never received below the highest one
  std::uint64_t rejected = 0;   ///< claimed this type but failed MAC, session, replay or decode
};

/// NTP-style round-trip time and clock offset from Ping/Pong timestamps (Mills' clock filter: of
/// the last kSamples samples, the one with the smallest round trip is used).
class ClockSync {
 public:
  static constexpr int kSamples = 8;
  /// t1: ping sent (local clock), t2: ping received (remote), t3: pong sent (remote), t4: pong
  /// received (local). t1 and t3 come from headers, in whole µs (protocol.h), so t3 may read up to
  /// 1 µs before t2: then t3 is taken as t2. Samples with t4 < t1 or t3 < t2 − 1 µs are ignored
  /// (returns false).
  bool AddSample(std::int64_t t1, std::int64_t t2, std::int64_t t3, std::int64_t t4) noexcept;
  /// True once a sample has been taken.
  bool valid() const noexcept { return count_ > 0; }
  /// Estimated remote clock minus local clock (ns); its error is at most rtt_ns()/2.
  std::int64_t offset_ns() const noexcept;
  /// Round trip of the sample used for offset_ns() (ns).
  std::int64_t rtt_ns() const noexcept;
  /// A remote steady-clock time expressed on the local clock (ns).
  std::int64_t RemoteToLocal(std::int64_t remote_ns) const noexcept {
    return remote_ns - offset_ns();
  }
  /// Every round trip measured (ms), for percentiles; capped at the capacity given to Reserve.
  const std::vector<double>& rtt_ms_samples() const noexcept { return rtt_ms_; }
  void Reserve(std::size_t capacity) { rtt_ms_.reserve(capacity); }
  void Reset() noexcept {
    count_ = 0;
    next_ = 0;
  }

 private:
  struct Sample {
    std::int64_t offset_ns = 0, rtt_ns = 0;
  };
  std::array<Sample, kSamples> samples_{};
  int count_ = 0, next_ = 0;
  std::vector<double> rtt_ms_;
};

/// Which side of the protocol a link is: decides which message types it accepts.
enum class LinkRole : std::uint8_t { kOperator, kRemote };

/// True when `role` accepts datagrams of `type` (e.g. the remote node accepts ToolState, Hello,
/// Ping, SceneNack, Goodbye).
bool Accepts(LinkRole role, wire::MessageType type) noexcept;

/// Sealing, opening and counting over one socket.
class SecureLink {
 public:
  SecureLink(UdpSocket& socket, const MacKey& key, LinkRole role);

  /// The header for the next datagram of `type` in `session` (sequence assigned, send time now).
  /// A stream's sequence stops at wire::kMaxSequence (its later datagrams are refused as replays):
  /// end the session before, when SequencesNearlyUsedUp().
  wire::Header NextHeader(wire::MessageType type, std::uint32_t session_id) noexcept;
  /// True when one of the streams this side sends has reached wire::kSequenceRenewAt in this
  /// session (49 days at 1 kHz): the session should end and a new one start.
  bool SequencesNearlyUsedUp() const noexcept;
  /// Makes every stream's last sent number `last_sent` (at most wire::kMaxSequence), as if that
  /// many had been sent in this session; for tests of what happens near the end. ResetSession
  /// undoes it.
  void StartSequencesAt(std::uint64_t last_sent) noexcept;
  /// Sends a sealed datagram to `to` and counts it under its type. False if the socket refused.
  bool Send(const wire::Datagram& datagram, const SocketAddress& to) noexcept;

  /// Opens one received datagram: size, header and accepted type, then the MAC, then (except for
  /// Hello, Welcome and Reject) the session (`session_id` 0 = none open: every such datagram is
  /// refused) and the replay window of its stream. On kOk gives header, body and whether it arrived
  /// late; on failure counts it by reason (and under its claimed type when the header parsed).
  wire::DecodeStatus Open(std::span<const std::uint8_t> datagram, std::uint32_t session_id,
                          wire::Header& header, std::span<const std::uint8_t>& body,
                          bool& late) noexcept;
  /// Counts a datagram that opened but whose body failed to decode.
  void CountBodyRejected(wire::MessageType type, wire::DecodeStatus status) noexcept;
  /// A new session: replay windows and send sequences restart (lost counts so far are kept).
  void ResetSession() noexcept;

  const StreamStats& stats(wire::MessageType type) const noexcept;
  /// Streams with any traffic, by name, each {sent, received, lost, late, duplicate, rejected,
  /// bytes_sent, bytes_received, send_failed}; plus "rejected_by_reason" {reason: count} and
  /// "rejected_total".
  nlohmann::json StatsJson() const;
  std::uint64_t rejected_total() const noexcept { return rejected_total_; }
  std::uint64_t rejected(wire::DecodeStatus reason) const noexcept {
    return rejected_by_reason_[static_cast<int>(reason)];
  }
  /// Local time (ns) of the last in-session datagram that opened (0 = none); handshake datagrams
  /// do not count, so that a replayed one cannot keep a dead peer "alive".
  std::int64_t last_authenticated_ns() const noexcept { return last_authenticated_ns_; }
  UdpSocket& socket() noexcept { return socket_; }
  const MacKey& key() const noexcept { return key_; }

 private:
  static constexpr int kTypes = wire::kMaxMessageType + 1;
  void CountRejected(const wire::Header* header, wire::DecodeStatus status) noexcept;

  UdpSocket& socket_;
  MacKey key_;
  LinkRole role_;
  std::array<std::uint64_t, kTypes> next_sequence_{};
  std::array<ReplayWindow, kTypes> windows_{};
  std::array<std::uint64_t, kTypes> unique_in_session_{};
  std::array<StreamStats, kTypes> stats_{};
  std::array<std::uint64_t, wire::kDecodeStatusCount> rejected_by_reason_{};
  std::uint64_t rejected_total_ = 0;
  std::int64_t last_authenticated_ns_ = 0;
  std::uint64_t last_open_bytes_ = 0;
};

}  // namespace ht
