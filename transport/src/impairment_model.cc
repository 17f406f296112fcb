// The impairment model (transport/impairment.h): the seeded decision, packet by packet, of loss,
// rate-queue drop, delivery time (serialisation, delay, jitter, reorder hold) and duplication.

#include <algorithm>
#include <cmath>
#include <cstdint>

#include "impairment_internal.h"
#include "transport/impairment.h"

namespace ht {

ImpairmentModel::ImpairmentModel(const ImpairmentSpec& spec) : spec_(spec), rng_(spec.seed) {
  impairment_internal::Validate(spec_);
  if (spec_.burst_packets != 0.0) {
    p_bad_to_good_ = 1.0 / spec_.burst_packets;
    p_good_to_bad_ = spec_.loss * p_bad_to_good_ / (1.0 - spec_.loss);
  }
  if (spec_.rate_bps > 0.0) queue_tx_end_ns_.assign(spec_.limit_packets, 0);
}

double ImpairmentModel::Uniform01() noexcept {
  // The top 53 bits of the raw 64-bit output, scaled by 2^-53: exactly representable, in [0, 1).
  return static_cast<double>(rng_() >> 11) * 0x1.0p-53;
}

PacketDecision ImpairmentModel::Decide(std::int64_t arrival_ns, std::size_t size_bytes) noexcept {
  // Always four draws, in this order, whatever the packet's fate.
  const double u_loss = Uniform01();
  const double u_jitter = Uniform01();
  const double u_reorder = Uniform01();
  const double u_dup = Uniform01();

  PacketDecision d;
  bool lost = false;
  if (spec_.burst_packets != 0.0) {
    // Gilbert–Elliott: move the chain one step, then the packet is lost iff the state is Bad.
    if (bad_) {
      if (u_loss < p_bad_to_good_) bad_ = false;
    } else if (u_loss < p_good_to_bad_) {
      bad_ = true;
    }
    lost = bad_;
  } else {
    lost = u_loss < spec_.loss;
  }
  if (lost) {
    d.fate = PacketFate::kDroppedLoss;
    return d;
  }

  std::int64_t tx_end_ns = arrival_ns;
  if (spec_.rate_bps > 0.0) {
    const std::size_t capacity = queue_tx_end_ns_.size();
    while (queue_count_ > 0 && queue_tx_end_ns_[queue_head_] <= arrival_ns) {
      queue_head_ = (queue_head_ + 1) % capacity;
      --queue_count_;
    }
    if (queue_count_ >= capacity) {
      d.fate = PacketFate::kDroppedQueue;
      return d;
    }
    const std::int64_t tx_start_ns = std::max(arrival_ns, link_free_ns_);
    const std::int64_t tx_ns =
        std::llround(static_cast<double>(size_bytes) * 8.0 * 1e9 / spec_.rate_bps);
    tx_end_ns = tx_start_ns + tx_ns;
    link_free_ns_ = tx_end_ns;
    queue_tx_end_ns_[(queue_head_ + queue_count_) % capacity] = tx_end_ns;
    ++queue_count_;
  }

  std::int64_t delay_ns = spec_.delay_ns;
  if (spec_.jitter_ns > 0) {
    // Uniform over the 2J + 1 integers in [-J, +J].
    const std::int64_t span = 2 * spec_.jitter_ns + 1;
    auto k = static_cast<std::int64_t>(u_jitter * static_cast<double>(span));
    k = std::min(k, span - 1);
    delay_ns = std::max<std::int64_t>(0, delay_ns + k - spec_.jitter_ns);
  }
  d.reordered = u_reorder < spec_.reorder;
  if (d.reordered) delay_ns += spec_.reorder_gap_ns;
  d.deliver_ns = tx_end_ns + delay_ns;
  d.copies = u_dup < spec_.dup ? 2 : 1;
  return d;
}

}  // namespace ht
