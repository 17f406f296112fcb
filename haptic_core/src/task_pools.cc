#include "task_pools.h"

#include <oneapi/tbb/parallel_for.h>

#include <atomic>
#include <chrono>

namespace ht::internal {

void WarmTaskPools(oneapi::tbb::task_arena& arena) noexcept {
  std::atomic<long> work{0};
  const auto spin = [&work] {
    const auto until = std::chrono::steady_clock::now() + std::chrono::microseconds(1);
    while (std::chrono::steady_clock::now() < until) work.fetch_add(1, std::memory_order_relaxed);
  };
  try {
    for (int round = 0; round < 4; ++round) {
      arena.execute([&] {
        oneapi::tbb::parallel_for(0, 256, [&](int) {
          oneapi::tbb::this_task_arena::isolate(
              [&] { oneapi::tbb::parallel_for(0, 16, [&](int) { spin(); }); });
        });
      });
    }
  } catch (...) {
    // The pools stay as they are; the step still runs (it may then allocate while they grow).
  }
}

}  // namespace ht::internal
