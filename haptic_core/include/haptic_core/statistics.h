#pragma once
// Summary statistics for run reports (not for the 1 kHz loop: it copies and sorts).

#include <algorithm>
#include <vector>

namespace ht {

/// Nearest-rank quantile `q` ∈ [0, 1] of `samples` (any unit; returned in the same unit).
/// Returns 0 for an empty sample; q outside [0, 1] is clamped. Allocates a sorted copy.
inline double Percentile(std::vector<double> samples, double q) {
  if (samples.empty()) return 0.0;
  std::sort(samples.begin(), samples.end());
  const auto i = static_cast<size_t>(std::clamp(q, 0.0, 1.0) * (samples.size() - 1) + 0.5);
  return samples[std::min(i, samples.size() - 1)];
}

}  // namespace ht
