#pragma once
// Counts every heap allocation of the test program that includes this header, by replacing the
// global operator new, and the largest single allocation while asked to (a decoder must not
// allocate for counts the bytes cannot hold). Include it in exactly one translation unit of a
// program of its own (the replacement is program-wide): operator_tick_test,
// remote_step_alloc_test, scene_graph_test.

#include <atomic>
#include <cstddef>
#include <cstdlib>
#include <new>

namespace ht::testing_support {
inline std::atomic<long> g_allocations{0};
/// Allocations made so far by the whole program.
inline long Allocations() noexcept { return g_allocations.load(std::memory_order_relaxed); }

inline std::atomic<bool> g_track_largest{false};
inline std::atomic<std::size_t> g_largest{0};
/// Starts recording the largest single allocation (bytes), from 0.
inline void StartLargestAllocation() noexcept {
  g_largest.store(0, std::memory_order_relaxed);
  g_track_largest.store(true, std::memory_order_relaxed);
}
/// Stops recording; returns the largest single allocation (bytes) since
/// StartLargestAllocation().
inline std::size_t StopLargestAllocation() noexcept {
  g_track_largest.store(false, std::memory_order_relaxed);
  return g_largest.load(std::memory_order_relaxed);
}
}  // namespace ht::testing_support

void* operator new(std::size_t n) {
  using namespace ht::testing_support;
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  if (g_track_largest.load(std::memory_order_relaxed)) {
    std::size_t seen = g_largest.load(std::memory_order_relaxed);
    while (n > seen && !g_largest.compare_exchange_weak(seen, n)) {
    }
  }
  if (void* p = std::malloc(n == 0 ? 1 : n)) return p;
  throw std::bad_alloc();
}
// Not inlined: GCC would otherwise see free() on what it takes for a new-expression's pointer.
[[gnu::noinline]] void operator delete(void* p) noexcept { std::free(p); }
[[gnu::noinline]] void operator delete(void* p, std::size_t) noexcept { std::free(p); }
