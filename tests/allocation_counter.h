#pragma once
// Counts every heap allocation of the test program that includes this header, through every
// allocator a step or tick can reach, and the largest single allocation while asked to (a
// decoder must not allocate for counts the bytes cannot hold):
//  - the C allocator (malloc, calloc, realloc, aligned_alloc, posix_memalign, memalign, valloc,
//    pvalloc), replaced by definitions that count and forward to glibc's own (__libc_*); the C++
//    operator new of every form reaches it through libstdc++, and so does Eigen;
//  - oneTBB's scalable allocator (scalable_malloc / scalable_aligned_malloc), which oneTBB's own
//    task and arena allocations use when libtbbmalloc is installed (Debian's libtbb12 pulls it
//    in): oneTBB dlopen()s libtbbmalloc and dlsym()s those four names, so dlopen is replaced too,
//    and a request for libtbbmalloc gets the program's own handle, whose definitions below count
//    and forward to the C allocator. Any other dlopen goes to glibc's.
// Include it in exactly one translation unit of a program of its own (the replacement is
// program-wide; glibc only) whose target has ENABLE_EXPORTS, so that libtbb's dlsym finds the
// definitions: operator_tick_test, remote_step_alloc_test, scene_graph_test.

#include <dlfcn.h>

#include <atomic>
#include <cstddef>
#include <cstdlib>
#include <cstring>
#include <new>

namespace ht::testing_support {
inline std::atomic<long> g_allocations{0};
/// Allocations made so far by the whole program, through any of the allocators above.
inline long Allocations() noexcept { return g_allocations.load(std::memory_order_relaxed); }

inline std::atomic<long> g_tbb_allocations{0};
/// Of Allocations(), those made through oneTBB's scalable allocator (its tasks and containers).
inline long TbbAllocations() noexcept { return g_tbb_allocations.load(std::memory_order_relaxed); }

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

inline void CountAllocation(std::size_t n) noexcept {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  if (g_track_largest.load(std::memory_order_relaxed)) {
    std::size_t seen = g_largest.load(std::memory_order_relaxed);
    while (n > seen && !g_largest.compare_exchange_weak(seen, n)) {
    }
  }
}
}  // namespace ht::testing_support

extern "C" {
// glibc's allocator under its own names (exported by libc.so.6 since 2.0).
void* __libc_malloc(std::size_t n) noexcept;
void* __libc_calloc(std::size_t count, std::size_t n) noexcept;
void* __libc_realloc(void* p, std::size_t n) noexcept;
void* __libc_memalign(std::size_t alignment, std::size_t n) noexcept;
void* __libc_valloc(std::size_t n) noexcept;
void* __libc_pvalloc(std::size_t n) noexcept;
void __libc_free(void* p) noexcept;

void* malloc(std::size_t n) noexcept {
  ht::testing_support::CountAllocation(n);
  return __libc_malloc(n);
}
void* calloc(std::size_t count, std::size_t n) noexcept {
  ht::testing_support::CountAllocation(count * n);
  return __libc_calloc(count, n);
}
void* realloc(void* p, std::size_t n) noexcept {
  ht::testing_support::CountAllocation(n);
  return __libc_realloc(p, n);
}
void* aligned_alloc(std::size_t alignment, std::size_t n) noexcept {
  ht::testing_support::CountAllocation(n);
  return __libc_memalign(alignment, n);
}
int posix_memalign(void** out, std::size_t alignment, std::size_t n) noexcept {
  if (alignment < sizeof(void*) || (alignment & (alignment - 1)) != 0) return 22;  // EINVAL
  ht::testing_support::CountAllocation(n);
  void* p = __libc_memalign(alignment, n);
  if (p == nullptr) return 12;  // ENOMEM
  *out = p;
  return 0;
}
void* memalign(std::size_t alignment, std::size_t n) noexcept {
  ht::testing_support::CountAllocation(n);
  return __libc_memalign(alignment, n);
}
void* valloc(std::size_t n) noexcept {
  ht::testing_support::CountAllocation(n);
  return __libc_valloc(n);
}
void* pvalloc(std::size_t n) noexcept {
  ht::testing_support::CountAllocation(n);
  return __libc_pvalloc(n);
}
void free(void* p) noexcept { __libc_free(p); }

// oneTBB's scalable allocator (the four entry points oneTBB's allocator links; see above).
// Visible to libtbb.so through the program's exported symbols.
__attribute__((visibility("default"))) void* scalable_malloc(std::size_t n) {
  ht::testing_support::g_tbb_allocations.fetch_add(1, std::memory_order_relaxed);
  return malloc(n);
}
__attribute__((visibility("default"))) void scalable_free(void* p) { free(p); }
__attribute__((visibility("default"))) void* scalable_aligned_malloc(std::size_t n,
                                                                     std::size_t alignment) {
  ht::testing_support::g_tbb_allocations.fetch_add(1, std::memory_order_relaxed);
  return memalign(alignment, n);
}
__attribute__((visibility("default"))) void scalable_aligned_free(void* p) { free(p); }

// libtbbmalloc is the program itself (see above).
__attribute__((visibility("default"))) void* dlopen(const char* file, int mode) noexcept {
  using Dlopen = void* (*)(const char*, int);
  static const Dlopen glibc_dlopen = reinterpret_cast<Dlopen>(dlsym(RTLD_NEXT, "dlopen"));
  if (file != nullptr && std::strstr(file, "tbbmalloc") != nullptr) {
    return glibc_dlopen(nullptr, RTLD_LAZY);
  }
  return glibc_dlopen(file, mode);
}
}
