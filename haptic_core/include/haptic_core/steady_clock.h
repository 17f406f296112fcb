#pragma once
// The one monotonic clock of the project (STYLE.md: clocks are read at the edges and passed in;
// time is std::chrono::steady_clock). Every send_time_ns on the wire and every *_ns timestamp in
// the processes is on it.

#include <chrono>
#include <cstdint>

namespace ht {

/// std::chrono::steady_clock now, in nanoseconds since its epoch. Never allocates or throws.
inline std::int64_t SteadyNowNs() noexcept {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

}  // namespace ht
