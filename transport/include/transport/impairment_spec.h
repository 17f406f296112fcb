#pragma once
// The impairment spec: what the impairment relay does to one direction of UDP traffic (delay,
// jitter, random or bursty loss, reordering, duplication, rate limit), parsed from and printed as
// text like "delay=75ms,loss=10%". Part of the impairment library (transport/impairment.h).
//
// Times are nanoseconds; sizes are bytes of UDP payload.

#include <cstddef>
#include <cstdint>
#include <string>

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

}  // namespace ht
