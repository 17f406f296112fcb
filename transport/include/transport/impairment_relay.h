#pragma once
// The impairment relay: a UDP relay that sits between an operator station (client) and a remote
// node (server) and applies one ImpairmentModel (transport/impairment.h) per direction, with
// per-direction statistics broken down by wire message type. Part of the impairment library
// (transport/impairment.h); the ht_relay tool runs it as a process.
//
// Times are nanoseconds of std::chrono::steady_clock; sizes are bytes of UDP payload.

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <nlohmann/json.hpp>
#include <span>
#include <string>

#include "transport/impairment_spec.h"
#include "transport/udp_socket.h"

namespace ht {

/// Classifies a datagram by its wire header (transport/protocol.h, wire::DatagramType): when it
/// starts with this version's magic ("HT") and version, returns the message type byte at offset 3;
/// with the magic of versions 2 to 7 ("HTLP") and at least 7 bytes, the type byte at offset 6
/// (1..255); otherwise 0, meaning "other" (a type byte of 0 is also "other").
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
  struct State;  // sockets, models, queues and statistics; defined in impairment_relay.cc
  std::unique_ptr<State> state_;
};

}  // namespace ht
