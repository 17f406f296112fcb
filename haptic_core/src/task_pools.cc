#include "task_pools.h"

#include <oneapi/tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>

namespace ht::internal {

void WarmTaskPools(oneapi::tbb::task_arena& arena) noexcept {
  using Clock = std::chrono::steady_clock;
  std::atomic<long> work{0};
  const auto spin = [&work] {
    const auto until = Clock::now() + std::chrono::microseconds(1);
    while (Clock::now() < until) work.fetch_add(1, std::memory_order_relaxed);
  };
  // Which of the arena's slots ran a task that spawned (an outer task's nested parallel_for).
  constexpr int kMaxSlots = 256;
  std::array<std::atomic<bool>, kMaxSlots> spawned_in{};
  const int slots = std::clamp(arena.max_concurrency(), 1, kMaxSlots);
  const auto all_spawned = [&] {
    return std::all_of(spawned_in.begin(), spawned_in.begin() + slots,
                       [](const std::atomic<bool>& s) { return s.load(); });
  };
  const auto deadline = Clock::now() + std::chrono::milliseconds(250);
  try {
    for (int round = 0; round < 4 || (!all_spawned() && Clock::now() < deadline); ++round) {
      arena.execute([&] {
        oneapi::tbb::parallel_for(0, 256, [&](int) {
          const int slot = oneapi::tbb::this_task_arena::current_thread_index();
          if (slot >= 0 && slot < kMaxSlots) spawned_in[static_cast<std::size_t>(slot)] = true;
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
