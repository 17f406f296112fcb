#pragma once
// Summary statistics for run reports: Percentile() copies and sorts (not for the 1 kHz loop);
// ReservoirSamples::Add() neither allocates nor locks (fit for it).

#include <algorithm>
#include <cstdint>
#include <vector>

namespace ht {

/// Nearest-rank quantile `q` ∈ [0, 1] of `samples` (any unit; returned in the same unit).
/// Returns 0 for an empty sample; q outside [0, 1] is clamped. Allocates a sorted copy.
inline double Percentile(std::vector<double> samples, double q) {
  if (samples.empty()) return 0.0;
  std::sort(samples.begin(), samples.end());
  const auto i =
      static_cast<size_t>(std::clamp(q, 0.0, 1.0) * static_cast<double>(samples.size() - 1) + 0.5);
  return samples[std::min(i, samples.size() - 1)];
}

/// A bounded, uniform sample of a stream of values (reservoir sampling, Vitter's Algorithm R),
/// so that percentiles of a run of any length take bounded memory: the first `capacity` values
/// are kept, and afterwards the n-th value replaces a random kept one with probability
/// capacity/n. Add() never allocates (the storage is reserved at construction) and is noexcept;
/// for the 1 kHz loop. Deterministic (fixed-seed xorshift).
class ReservoirSamples {
 public:
  /// Reserves room for `capacity` (≥ 1) values.
  explicit ReservoirSamples(std::size_t capacity) : capacity_(std::max<std::size_t>(capacity, 1)) {
    values_.reserve(capacity_);
  }
  void Add(double v) noexcept {
    ++count_;
    if (values_.size() < capacity_) {
      values_.push_back(v);  // within the reserved capacity: no allocation
      return;
    }
    state_ ^= state_ << 13;
    state_ ^= state_ >> 7;
    state_ ^= state_ << 17;
    const std::uint64_t j = state_ % count_;
    if (j < capacity_) values_[j] = v;
  }
  /// The kept values (at most capacity), a uniform sample of all added.
  const std::vector<double>& values() const noexcept { return values_; }
  /// Values added in all.
  std::uint64_t count() const noexcept { return count_; }

 private:
  std::size_t capacity_;
  std::vector<double> values_;
  std::uint64_t count_ = 0;
  std::uint64_t state_ = 0x9E3779B97F4A7C15ull;
};

}  // namespace ht
