// Stress test of the operator station's lock-free hand-offs (master_station/lock_free.h, issue
// 16): a triple buffer (newest wins) and a single-producer single-consumer ring, each between
// two real threads for a few hundred thousand items. No torn value, no reordering, nothing
// lost from the ring, and the triple buffer's reader always ends on the newest value.

#include "master_station/lock_free.h"

#include <gtest/gtest.h>

#include <atomic>
#include <cstdint>
#include <thread>

namespace ht {
namespace {

// A value a torn copy would betray: every field derives from the same sequence number.
struct Item {
  std::uint64_t seq = 0;
  std::uint64_t twice = 0;
  double as_double = 0.0;
  std::uint64_t pad[5] = {};
  static Item Of(std::uint64_t s) {
    Item i;
    i.seq = s;
    i.twice = 2 * s;
    i.as_double = static_cast<double>(s);
    for (auto& p : i.pad) p = ~s;
    return i;
  }
  bool Whole() const {
    if (twice != 2 * seq || as_double != static_cast<double>(seq)) return false;
    for (auto p : pad)
      if (p != ~seq) return false;
    return true;
  }
};

TEST(LockFree, TripleBufferNeverTearsNorGoesBackward) {
  // The writer publishes until the reader has seen enough fresh values (so the two really run
  // side by side, however the machine schedules them); then the reader's last read must be the
  // writer's last value.
  constexpr std::uint64_t kReads = 2000;
  TripleBuffer<Item> buffer;
  std::atomic<bool> stop{false};
  std::atomic<std::uint64_t> written{0};
  std::thread writer([&] {
    std::uint64_t s = 0;
    while (!stop.load(std::memory_order_acquire)) buffer.Write(Item::Of(++s));
    written.store(s, std::memory_order_release);
  });
  std::uint64_t last = 0, reads = 0, torn = 0, backward = 0;
  Item item;
  const auto check = [&] {
    ++reads;
    torn += !item.Whole();
    backward += item.seq <= last;
    last = item.seq;
  };
  while (reads < kReads) {
    if (buffer.Read(item)) {
      check();
    } else {
      std::this_thread::yield();  // nothing fresh: let the writer run (one core is enough)
    }
  }
  stop.store(true, std::memory_order_release);
  writer.join();
  if (buffer.Read(item)) check();  // what was published after our last read, if anything
  EXPECT_EQ(torn, 0u);
  EXPECT_EQ(backward, 0u);
  EXPECT_EQ(last, written.load()) << "the reader must end on the newest value";
  EXPECT_GT(reads, 1u);
}

TEST(LockFree, RingDeliversEveryItemInOrder) {
  constexpr std::uint64_t kItems = 500000;
  SpscRing<Item> ring(1024);
  std::thread producer([&] {
    for (std::uint64_t s = 1; s <= kItems; ++s) {
      while (!ring.Push(Item::Of(s))) std::this_thread::yield();  // full: the consumer catches up
    }
  });
  std::uint64_t expected = 1, torn = 0, out_of_order = 0;
  Item item;
  while (expected <= kItems) {
    if (!ring.Pop(item)) {
      std::this_thread::yield();
      continue;
    }
    torn += !item.Whole();
    out_of_order += item.seq != expected;
    expected = item.seq + 1;
  }
  producer.join();
  EXPECT_EQ(torn, 0u);
  EXPECT_EQ(out_of_order, 0u);
  EXPECT_FALSE(ring.Pop(item)) << "nothing extra";
}

}  // namespace
}  // namespace ht
