#pragma once
// Network impairment for UDP, in user space (tc netem is not available everywhere): the seeded
// model that decides the fate of each packet of one direction. This header also includes the
// spec (delay, jitter, random or bursty loss, reordering, duplication, rate limit;
// transport/impairment_spec.h) and the relay between an operator station (client) and a remote
// node (server) that applies one model per direction, with per-direction statistics broken down
// by wire message type (transport/impairment_relay.h): including it gives the whole impairment
// library.
//
// Times are nanoseconds of std::chrono::steady_clock (the caller reads the clock and passes it
// in); sizes are bytes of UDP payload.

#include <cstddef>
#include <cstdint>
#include <random>
#include <vector>

#include "transport/impairment_relay.h"
#include "transport/impairment_spec.h"

namespace ht {

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

}  // namespace ht
