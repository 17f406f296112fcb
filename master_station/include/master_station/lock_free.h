#pragma once
// Wait-free handoffs between the 1 kHz loop and the other threads: a triple buffer (newest value
// wins) and a single-producer/single-consumer ring (every value, dropped and counted when full).
// Neither allocates after construction, locks, or blocks.

#include <array>
#include <atomic>
#include <cstdint>
#include <vector>

namespace ht {

/// Newest-wins handoff of a copyable T from one writer thread to one reader thread.
template <typename T>
class TripleBuffer {
 public:
  /// Writer side: publishes a copy of `value`.
  void Write(const T& value) noexcept {
    buffers_[write_] = value;
    write_ =
        shared_.exchange(static_cast<std::uint8_t>(write_ | kFresh), std::memory_order_acq_rel) &
        kIndexMask;
  }
  /// Reader side: copies the newest value into `out` if one was published since the last Read.
  bool Read(T& out) noexcept {
    if ((shared_.load(std::memory_order_acquire) & kFresh) == 0) return false;
    read_ = shared_.exchange(read_, std::memory_order_acq_rel) & kIndexMask;
    out = buffers_[read_];
    return true;
  }

 private:
  static constexpr std::uint8_t kFresh = 0x4;
  static constexpr std::uint8_t kIndexMask = 0x3;
  std::array<T, 3> buffers_{};
  std::uint8_t write_ = 0;               // owned by the writer
  std::uint8_t read_ = 1;                // owned by the reader
  std::atomic<std::uint8_t> shared_{2};  // the middle buffer, with the fresh flag
};

/// Bounded single-producer/single-consumer queue.
template <typename T>
class SpscRing {
 public:
  /// Allocates room for `capacity` elements (rounded up to a power of two).
  explicit SpscRing(std::size_t capacity) {
    std::size_t n = 1;
    while (n < capacity) n <<= 1;
    slots_.resize(n);
    mask_ = n - 1;
  }
  /// Producer: appends a copy; returns false (value dropped) when full.
  bool Push(const T& value) noexcept {
    const std::size_t head = head_.load(std::memory_order_relaxed);
    if (head - tail_.load(std::memory_order_acquire) > mask_) return false;
    slots_[head & mask_] = value;
    head_.store(head + 1, std::memory_order_release);
    return true;
  }
  /// Consumer: removes the oldest element into `out`; false when empty.
  bool Pop(T& out) noexcept {
    const std::size_t tail = tail_.load(std::memory_order_relaxed);
    if (tail == head_.load(std::memory_order_acquire)) return false;
    out = slots_[tail & mask_];
    tail_.store(tail + 1, std::memory_order_release);
    return true;
  }

 private:
  std::vector<T> slots_;
  std::size_t mask_ = 0;
  alignas(64) std::atomic<std::size_t> head_{0};
  alignas(64) std::atomic<std::size_t> tail_{0};
};

}  // namespace ht
