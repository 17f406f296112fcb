#pragma once
// Network impairment for UDP, in user space (tc netem is not available everywhere): a spec
// (delay, jitter, random or bursty loss, reordering, duplication, rate limit), a seeded model
// that decides the fate of each packet of one direction, per-direction statistics broken down by
// wire message type, and a relay that sits between an operator station (client) and a remote
// node (server) and applies one model per direction.
//
// Times are nanoseconds of std::chrono::steady_clock (the caller reads the clock and passes it
// in); sizes are bytes of UDP payload.

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <nlohmann/json.hpp>
#include <random>
#include <span>
#include <string>
#include <vector>

#include "transport/udp_socket.h"

namespace ht {

/// What to do to one direction of traffic. Parsed from, and printed as, the spec string
///
///   comma-separated key=value, any order, e.g.
///   delay=50ms,jitter=10ms,loss=5%,burst=4,reorder=2%,dup=1%,rate=20mbit,seed=7
///   ("none" or empty = no impairment)
///
/// Keys: delay, jitter, reorder-gap (times: us, ms, s; a bare number is ms); loss, reorder, dup
/// (P% or a fraction 0..1); burst (mean loss burst in packets, >= 1); rate (bit, kbit, mbit,
/// gbit per second; a bare number is bit/s); limit (packets, integer >= 1); seed (integer).
/// A default-constructed spec is "none".
struct ImpairmentSpec {
  /// One-way base delay added to every packet. Unit: ns, >= 0.
  std::int64_t delay_ns = 0;
  /// Half-width J of the per-packet uniform jitter in [-J, +J] added to delay_ns (the sum is
  /// clipped at 0, so jitter alone can reorder packets, as netem does). Unit: ns, >= 0.
  std::int64_t jitter_ns = 0;
  /// Long-run fraction of packets lost, 0..1. Independent per packet unless burst_packets > 0.
  double loss = 0.0;
  /// Mean loss burst length B in packets (>= 1), or 0 for independent (Bernoulli) loss. When set,
  /// loss follows a Gilbert–Elliott two-state chain: every packet is lost in Bad and none in
  /// Good, r = p(Bad→Good) = 1/B and p(Good→Bad) = loss·r/(1 − loss), so the stationary
  /// probability of Bad (the loss rate) is `loss` and Bad runs last B packets on average
  /// (Gilbert 1960; Elliott 1963). Requires loss < 1 and p(Good→Bad) <= 1, i.e.
  /// loss <= B/(B + 1).
  double burst_packets = 0.0;
  /// Fraction of packets, 0..1, held an extra reorder_gap_ns so that later packets overtake them.
  double reorder = 0.0;
  /// Extra hold of a reordered packet. Unit: ns, >= 0; default 5 ms.
  std::int64_t reorder_gap_ns = 5'000'000;
  /// Fraction of packets, 0..1, delivered twice (the copy right after the original).
  double dup = 0.0;
  /// Link rate, or 0 for an unlimited link. Unit: bit/s. Packets are serialised before the delay:
  /// transmission starts at max(arrival, link free) and keeps the link busy size·8/rate.
  double rate_bps = 0.0;
  /// Most packets in the rate queue (waiting for or in transmission on the link); packets beyond
  /// it are tail-dropped. Only a rate-limited link ever has a queue. Unit: packets, 1..1'000'000.
  std::size_t limit_packets = 1000;
  /// Seed of the model's std::mt19937_64.
  std::uint64_t seed = 1;

  /// Parses a spec string (see the struct comment). Surrounding spaces around items are ignored.
  /// Throws std::invalid_argument naming the key, the bad text and the accepted form on an
  /// unknown or repeated key, a bad number, a bad unit, or a value out of range.
  static ImpairmentSpec Parse(const std::string& text);

  /// The canonical spec string: "none" when IsNone(), else the impairments that are set, then
  /// limit and reorder-gap when not at their defaults, then seed. Parse(ToString()) gives back
  /// this spec exactly (when IsNone(), a spec with no impairment and the default seed).
  std::string ToString() const;

  /// True when the spec changes nothing: no delay, jitter, loss, reordering, duplication, or rate
  /// limit (the seed and the limit do not matter then).
  bool IsNone() const noexcept;

  bool operator==(const ImpairmentSpec&) const = default;
};

/// Why a packet was not delivered.
enum class PacketFate : std::uint8_t {
  kDelivered = 0,     ///< delivered (once or twice)
  kDroppedLoss = 1,   ///< random or burst loss
  kDroppedQueue = 2,  ///< tail drop: the rate queue already held `limit_packets`
};

/// The model's decision for one packet.
struct PacketDecision {
  PacketFate fate = PacketFate::kDelivered;
  /// Number of deliveries: 0 when dropped, 1, or 2 when duplicated.
  int copies = 0;
  /// Delivery time of the packet; the copy (if any) is delivered at the same time, right after
  /// the original. Unit: ns, same clock as the arrival time. Valid when copies > 0.
  std::int64_t deliver_ns = 0;
  /// True when the packet was held the extra reorder gap.
  bool reordered = false;
};

/// The impairment of one direction: decides, packet by packet, drop or one/two delivery times.
///
/// Deterministic: for a given spec (seed included) and the same sequence of Decide() calls, the
/// decisions are identical on every platform (std::mt19937_64 raw output, converted to doubles
/// with 53 bits by hand; exactly four draws per packet, whatever its fate, so changing one
/// probability does not shift the random stream of the others). Decide() does not allocate.
///
/// Per packet, in order: loss (Bernoulli or Gilbert–Elliott) → rate queue limit (tail drop) →
/// serialisation on the link (tx_end = max(arrival, link free) + size·8/rate) → delay and jitter
/// (deliver = tx_end + max(0, delay + j), j uniform over the integers in [-J, +J] ns) → reorder
/// hold (+ reorder gap) → duplication (same delivery time; the copy does not use the link).
class ImpairmentModel {
 public:
  /// Builds the model; preallocates the rate queue (limit_packets entries). Throws
  /// std::invalid_argument when the spec is out of range (as Parse would reject it).
  explicit ImpairmentModel(const ImpairmentSpec& spec);

  /// Decides the fate of one packet arriving at `arrival_ns` (steady clock, ns; expected
  /// non-decreasing across calls) with `size_bytes` of payload. noexcept, no allocation.
  PacketDecision Decide(std::int64_t arrival_ns, std::size_t size_bytes) noexcept;

  /// The spec the model was built with.
  const ImpairmentSpec& spec() const noexcept { return spec_; }

  /// True while the Gilbert–Elliott chain is in its Bad (losing) state.
  bool in_bad_state() const noexcept { return bad_; }

 private:
  double Uniform01() noexcept;  // [0, 1) with 53 random bits

  ImpairmentSpec spec_;
  std::mt19937_64 rng_;
  double p_good_to_bad_ = 0.0;
  double p_bad_to_good_ = 1.0;
  bool bad_ = false;
  std::int64_t link_free_ns_ = 0;  // when the link finishes the last accepted packet
  // Transmission end times of the packets in the rate queue (FIFO ring, capacity limit_packets).
  std::vector<std::int64_t> queue_tx_end_ns_;
  std::size_t queue_head_ = 0;
  std::size_t queue_count_ = 0;
};

/// Classifies a datagram by its wire header (transport/protocol.h): when its first 4 bytes are
/// the little-endian u32 wire::kMagic ("HTLP") and it has at least 7 bytes, returns the message
/// type byte at offset 6 (1..255); otherwise returns 0, meaning "other" (a type byte of 0 is
/// also "other").
std::uint8_t ClassifyDatagram(std::span<const std::uint8_t> bytes) noexcept;

/// Name of a message type for the statistics: 0 "other", 1 tool_state, 2 contact_model,
/// 3 goodbye, 4 hello, 5 welcome, 6 reject, 7 ping, 8 pong, 9 scene_fragment, 10 scene_nack,
/// 11 scene_manifest, any other N "type_N".
std::string MessageTypeName(std::uint8_t type);

/// Counters of one direction (or of one message type in it). Units: datagrams, except bytes_*.
/// At any time (and so at exit):
///   forwarded + send_errors + in_flight_at_exit
///     = received − dropped_loss − dropped_queue − dropped_oversize + duplicated.
struct TrafficCounters {
  std::uint64_t received = 0;          ///< datagrams that arrived at the relay
  std::uint64_t dropped_loss = 0;      ///< dropped by random / burst loss
  std::uint64_t dropped_queue = 0;     ///< tail-dropped: rate queue limit or relay queue full
  std::uint64_t dropped_oversize = 0;  ///< longer than wire::kMaxDatagramBytes (1472)
  std::uint64_t duplicated = 0;        ///< packets scheduled twice (each counts once here)
  std::uint64_t reordered = 0;         ///< packets held the extra reorder gap
  std::uint64_t forwarded = 0;         ///< datagrams actually sent out, copies included
  std::uint64_t send_errors = 0;       ///< sends the system refused (or had no destination)
  std::uint64_t bytes_in = 0;          ///< payload bytes received. Unit: bytes
  std::uint64_t bytes_out = 0;         ///< payload bytes sent (copies included). Unit: bytes
  /// Scheduled datagrams not yet sent (copies included) when the statistics were taken; in the
  /// final statistics, those never sent because the relay stopped.
  std::uint64_t in_flight_at_exit = 0;

  /// {"received": N, "dropped_loss": N, ...}, every counter by its field name.
  nlohmann::json ToJson() const;
  TrafficCounters& operator+=(const TrafficCounters& other) noexcept;
};

/// Statistics of one direction with a per-message-type breakdown (index = ClassifyDatagram()).
struct DirectionStats {
  /// Counters per message type; [0] is "other" (no wire magic).
  std::array<TrafficCounters, 256> by_type{};
  /// Datagrams on the server-side socket from an address other than --forward; dropped, and not
  /// in by_type (they are not part of the impaired traffic).
  std::uint64_t dropped_unknown_source = 0;

  /// Sum over all types.
  TrafficCounters Total() const noexcept;

  /// The totals' counters at the top level, plus one object per message type that has received
  /// anything, keyed by MessageTypeName() (e.g. "tool_state", "other"), plus
  /// "dropped_unknown_source".
  nlohmann::json ToJson() const;
};

/// Configuration of an ImpairmentRelay.
struct RelayConfig {
  /// Client-side address to listen on (port 0 = any free port).
  SocketAddress listen_address;
  /// Server address; datagrams from the client are sent here from a second socket (ephemeral
  /// port, same address family), and datagrams from here on that socket go back to the client.
  SocketAddress forward_address;
  /// Impairment client → server.
  ImpairmentSpec up;
  /// Impairment server → client.
  ImpairmentSpec down;
  /// Capacity of each direction's scheduled-packet queue (preallocated slots of 1473 bytes);
  /// a packet arriving when it is full is counted in dropped_queue. Unit: packets, >= 1.
  std::size_t queue_slots = 4096;
  /// When non-empty, the bound listen port is written here (tmp file, then rename).
  std::string port_file;
  /// When non-empty, StatsJson() is written here atomically every stats_period_s and at exit.
  std::string stats_file;
  /// Period of the statistics file. Unit: s, > 0.
  double stats_period_s = 1.0;
  /// Period of the progress line on stdout, or 0 for none. Unit: s.
  double progress_period_s = 1.0;
  /// Run at most this long, or 0 until stopped. Unit: s.
  double duration_s = 0.0;
};

/// The relay: receives on the listen socket (client side) and on a second socket (server side),
/// passes each datagram through the direction's ImpairmentModel, keeps the scheduled ones in a
/// bounded time-ordered queue (a preallocated binary heap of slots; ties leave in arrival order)
/// and sends each at its departure time, waiting with ppoll on both sockets with a nanosecond
/// timeout up to the next departure. Datagrams from the server go back to the last client
/// address seen on the listen socket. Nothing is allocated per packet.
class ImpairmentRelay {
 public:
  /// Binds both sockets, preallocates the queues and writes the port file. Throws
  /// std::invalid_argument on a bad configuration and std::runtime_error when a socket cannot be
  /// bound or the port file cannot be written.
  explicit ImpairmentRelay(const RelayConfig& config);
  ~ImpairmentRelay();
  ImpairmentRelay(const ImpairmentRelay&) = delete;
  ImpairmentRelay& operator=(const ImpairmentRelay&) = delete;

  /// The bound listen address (with the port the system chose).
  SocketAddress listen_address() const;
  /// The bound address of the server-side socket.
  SocketAddress server_side_address() const;

  /// Relays until `stop` becomes true or duration_s has passed, then writes the final statistics
  /// file (when configured) and returns. Throws std::runtime_error when the statistics file
  /// cannot be written.
  void Run(const std::atomic<bool>& stop);

  /// {"spec": {"up": "...", "down": "..."}, "listen": "...", "forward": "...", "elapsed_s": s,
  ///  "final": bool, "up": DirectionStats::ToJson(), "down": ...}.
  nlohmann::json StatsJson() const;

  /// Statistics client → server.
  const DirectionStats& up_stats() const noexcept;
  /// Statistics server → client.
  const DirectionStats& down_stats() const noexcept;

 private:
  struct State;  // sockets, models, queues and statistics; defined in impairment.cc
  std::unique_ptr<State> state_;
};

}  // namespace ht
