#pragma once
// Counts every heap allocation of the test program that includes this header, by replacing the
// global operator new. Include it in exactly one translation unit of a program of its own (the
// replacement is program-wide): operator_tick_test, remote_step_alloc_test.

#include <atomic>
#include <cstdlib>
#include <new>

namespace ht::testing_support {
inline std::atomic<long> g_allocations{0};
/// Allocations made so far by the whole program.
inline long Allocations() noexcept { return g_allocations.load(std::memory_order_relaxed); }
}  // namespace ht::testing_support

void* operator new(std::size_t n) {
  ht::testing_support::g_allocations.fetch_add(1, std::memory_order_relaxed);
  if (void* p = std::malloc(n == 0 ? 1 : n)) return p;
  throw std::bad_alloc();
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
