// Stage 2 of the remote step (hull_proximity.h): the best-first traversal of two hull
// hierarchies, its front and temporal coherence, and its share-out to worker threads. The hulls'
// geometry: 2_posed_hull.h; the per-node bounds: 2_hull_bounds.cc.
#include <oneapi/tbb/blocked_range.h>
#include <oneapi/tbb/parallel_for.h>
#include <oneapi/tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <glm/geometric.hpp>
#include <stdexcept>
#include <string>

#include "../task_pools.h"
#include "2_node_pair_traversal.h"
#include "2_posed_hull.h"
#include "haptic_core/hull_proximity.h"

namespace ht {
namespace {

using hull_geometry::kInf;
using hull_traversal::FindPair;
using hull_traversal::HeapAfter;
using hull_traversal::ListsOf;
using hull_traversal::NodePairTraversal;
using hull_traversal::PairLess;
using hull_traversal::TraversalLists;
using Clock = std::chrono::steady_clock;
using CoherentPair = HullProximityQuery::CoherentPair;
using FrontPair = HullProximityQuery::FrontPair;
using QueueEntry = HullProximityQuery::QueueEntry;
using Worker = HullProximityQuery::Worker;

// Room for a front (node pairs; front tracking stops for a call whose front would not fit).
constexpr std::size_t kFrontCapacity = 16384;
// A subtree's queue entry, or a front pair, once a worker's task has descended it.
constexpr int kDone = -2;

// Pops and processes t's queue, best first, until it is empty, a budget is spent (sets
// t.st.budget_exhausted) or, with split_at > 0, that many pairs are queued for the workers.
void RunBestFirst(NodePairTraversal& traversal, TraversalLists& t,
                  const ProximityQueryOptions& options, double budget_us, Clock::time_point t0,
                  std::size_t split_at) noexcept {
  while (!t.queue.empty()) {
    if (options.max_node_pair_tests > 0 && t.st.node_pairs_tested >= options.max_node_pair_tests) {
      t.st.budget_exhausted = true;
      break;
    }
    if (budget_us < kInf &&
        std::chrono::duration<double, std::micro>(Clock::now() - t0).count() >= budget_us) {
      t.st.budget_exhausted = true;
      break;
    }
    std::pop_heap(t.queue.begin(), t.queue.end(), HeapAfter);
    const QueueEntry e = t.queue.back();
    t.queue.pop_back();
    traversal.Process(t, e);
    if (split_at > 0 && t.queue.size() >= split_at) break;
  }
}

// Descends every pair on w's queue (any order: without a budget every pair not culled is tested).
void Drain(NodePairTraversal& traversal, Worker& w) noexcept {
  TraversalLists t = ListsOf(w);
  while (!w.queue.empty()) {
    std::pop_heap(w.queue.begin(), w.queue.end(), HeapAfter);
    const QueueEntry e = w.queue.back();
    w.queue.pop_back();
    traversal.Process(t, e);
  }
}

// The rest of the traversal on the workers: each of `queue`'s node pairs' subtrees is one task
// (oneTBB balances them), descended on the queue of the thread that runs it; or, with
// `from_front`, blocks of the previous call's `front` are the tasks. Without a budget every pair
// that is not culled is tested whatever the order, so the pairs found are the serial traversal's
// (Query sorts them). Tasks that could not be spawned run on this thread. Then the workers' pairs,
// directions, fronts and counts are merged into `main`; `queue` is left empty.
void RunOnWorkers(NodePairTraversal& traversal, oneapi::tbb::task_arena& arena,
                  std::vector<Worker>& workers, std::vector<QueueEntry>& queue,
                  std::vector<FrontPair>& front, bool from_front, TraversalLists& main) noexcept {
  for (Worker& w : workers) {
    w.queue.clear();
    w.results.clear();
    w.current.clear();
    w.current_far.clear();
    w.front.clear();
    w.st = ProximityQueryStats{};
  }
  const auto descend = [&](Worker& w, QueueEntry& entry) {
    w.queue.push_back(entry);
    entry.node_A = kDone;
    Drain(traversal, w);
  };
  const auto descend_front = [&](Worker& w, FrontPair& f) {
    TraversalLists t = ListsOf(w);
    traversal.RetestFrontPair(t, f);
    f.node_A = kDone;
    Drain(traversal, w);
  };
  const std::size_t tasks = from_front ? front.size() : queue.size();
  try {
    arena.execute([&] {
      oneapi::tbb::parallel_for(
          oneapi::tbb::blocked_range<std::size_t>(0, tasks, from_front ? 16 : 1),
          [&](const oneapi::tbb::blocked_range<std::size_t>& r) {
            const int slot = oneapi::tbb::this_task_arena::current_thread_index();
            Worker& w = workers[static_cast<std::size_t>(slot)];
            for (std::size_t k = r.begin(); k != r.end(); ++k) {
              if (from_front) {
                descend_front(w, front[k]);
              } else {
                descend(w, queue[k]);
              }
            }
          });
    });
  } catch (...) {
    // Tasks could not be spawned: the subtrees not yet descended, on this thread.
  }
  for (QueueEntry& entry : queue) {
    if (entry.node_A != kDone) descend(workers[0], entry);
  }
  if (from_front) {
    for (FrontPair& f : front) {
      if (f.node_A != kDone) descend_front(workers[0], f);
    }
  }
  queue.clear();
  for (Worker& w : workers) {
    for (const HullPairContact& c : w.results) traversal.Emit(main, c);
    for (const CoherentPair& c : w.current) {
      if (main.current.size() < main.current.capacity()) main.current.push_back(c);
    }
    for (const FrontPair& c : w.current_far) {
      if (main.current_far.size() < main.current_far.capacity()) main.current_far.push_back(c);
    }
    for (const FrontPair& f : w.front) {
      if (main.front.size() < main.front.capacity()) {
        main.front.push_back(f);
      } else {
        traversal.front_overflow.store(true, std::memory_order_relaxed);
      }
    }
    main.st.node_pairs_tested += w.st.node_pairs_tested;
    main.st.leaf_pairs_tested += w.st.leaf_pairs_tested;
    main.st.node_pairs_culled += w.st.node_pairs_culled;
    main.st.pairs_dropped += w.st.pairs_dropped;
    main.st.coherent_hits += w.st.coherent_hits;
    main.st.coherent_culls += w.st.coherent_culls;
    main.st.numerical_faults += w.st.numerical_faults;
  }
}

}  // namespace

HullProximityQuery::HullProximityQuery(int max_pairs) : capacity_(max_pairs) {
  if (max_pairs < 1) {
    throw std::invalid_argument("HullProximityQuery: max_pairs must be >= 1, got " +
                                std::to_string(max_pairs));
  }
  results_.reserve(static_cast<std::size_t>(max_pairs));
  previous_.reserve(static_cast<std::size_t>(max_pairs));
  current_.reserve(static_cast<std::size_t>(max_pairs));
  previous_far_.reserve(static_cast<std::size_t>(max_pairs));
  current_far_.reserve(static_cast<std::size_t>(max_pairs));
  front_.reserve(kFrontCapacity);
  next_front_.reserve(kFrontCapacity);
  queue_.reserve(4096);
}

struct HullProximityQuery::Arena {
  explicit Arena(int threads) : arena(threads) {}
  oneapi::tbb::task_arena arena;
};

void HullProximityQuery::SetThreads(int threads) {
  if (threads < 1 || threads > 256) {
    throw std::invalid_argument("HullProximityQuery: threads must be in [1, 256], got " +
                                std::to_string(threads));
  }
  if (threads == 1) {
    arena_.reset();
    workers_.clear();
    return;
  }
  std::vector<Worker> workers(static_cast<std::size_t>(threads));
  for (Worker& w : workers) {
    w.queue.reserve(4096);
    w.results.reserve(static_cast<std::size_t>(capacity_));
    w.current.reserve(static_cast<std::size_t>(capacity_));
    w.current_far.reserve(static_cast<std::size_t>(capacity_));
    w.front.reserve(kFrontCapacity);
  }
  arena_ = std::make_shared<Arena>(threads);
  internal::WarmTaskPools(arena_->arena);  // so that a query's tasks do not allocate
  workers_ = std::move(workers);
}

void HullProximityQuery::ClearCoherence() noexcept {
  previous_.clear();
  previous_far_.clear();
  front_.clear();
  front_valid_ = false;
  previous_A_ = previous_B_ = 0;
}

std::span<const HullPairContact> HullProximityQuery::Query(const HapticModel& A,
                                                           const RigidTransform& X_WA,
                                                           const HapticModel& B,
                                                           const RigidTransform& X_WB,
                                                           const ProximityQueryOptions& options,
                                                           ProximityQueryStats* stats) noexcept {
  HullBounds bounds_A, bounds_B;
  try {
    bounds_A = HullBounds::Of(A);
    bounds_B = HullBounds::Of(B);
  } catch (...) {
    results_.clear();
    ClearCoherence();
    if (stats != nullptr) {
      *stats = ProximityQueryStats{};
      stats->numerical_faults = 1;
    }
    return {};
  }
  return Query(A, bounds_A, X_WA, B, bounds_B, X_WB, options, stats);
}

std::span<const HullPairContact> HullProximityQuery::Query(
    const HapticModel& A, const HullBounds& bounds_A, const RigidTransform& X_WA,
    const HapticModel& B, const HullBounds& bounds_B, const RigidTransform& X_WB,
    const ProximityQueryOptions& options, ProximityQueryStats* stats) noexcept {
  const Clock::time_point t0 = Clock::now();
  ProximityQueryStats st;
  results_.clear();
  queue_.clear();
  current_.clear();
  current_far_.clear();
  next_front_.clear();
  const double eps = options.tolerance_m;

  auto finish = [&]() {
    st.pairs_found = static_cast<int>(results_.size());
    st.query_us = std::chrono::duration<double, std::micro>(Clock::now() - t0).count();
    if (stats != nullptr) *stats = st;
    return std::span<const HullPairContact>(results_.data(), results_.size());
  };

  if (!IsFiniteRigidTransform(X_WA) || !IsFiniteRigidTransform(X_WB) || !(eps >= 0.0) ||
      !std::isfinite(eps) || !std::isfinite(options.time_budget_us) || !bounds_A.Fits(A) ||
      !bounds_B.Fits(B)) {
    st.invalid_input = 1;
    previous_.clear();
    previous_far_.clear();
    front_valid_ = false;
    return finish();
  }
  const bool a_single = A.hull_hierarchy.nodes.empty();
  const bool b_single = B.hull_hierarchy.nodes.empty();
  if ((a_single && A.hull_vertices_O.empty()) || (b_single && B.hull_vertices_O.empty())) {
    previous_.clear();
    previous_far_.clear();
    front_valid_ = false;
    return finish();
  }
  const double budget_us = options.time_budget_us > 0.0 ? options.time_budget_us : kInf;
  const bool unlimited = !(budget_us < kInf) && options.max_node_pair_tests <= 0;
  const bool coherent = options.temporal_coherence && bounds_A.id != 0 && bounds_B.id != 0 &&
                        previous_A_ == bounds_A.id && previous_B_ == bounds_B.id;
  const bool track_front = options.temporal_coherence && !a_single && !b_single && unlimited;
  NodePairTraversal traversal(
      {A, X_WA, bounds_A, B, X_WB, bounds_B, options, previous_, previous_far_, coherent,
       track_front, unlimited,
       static_cast<std::size_t>(std::clamp(options.max_pairs, 0, capacity_))});
  TraversalLists main_lists{queue_, results_, current_, current_far_, next_front_, st};
  // With workers (SetThreads) and no budget, the traversal moves to them once this many node
  // pairs are queued (a budget needs the one best-first order).
  const std::size_t split_at =
      arena_ != nullptr && unlimited && !a_single && !b_single ? 16 * workers_.size() : 0;

  // Where the traversal starts: the previous call's front (front tracking, on the same two
  // bounds), or the two roots.
  const bool use_front =
      track_front && coherent && front_valid_ && front_.size() <= 2 * front_base_ + 64;
  // With workers, each takes its share of the front (RunOnWorkers).
  const bool front_on_workers = use_front && split_at > 0;
  if (use_front) {
    st.front_pairs = static_cast<int>(front_.size());
    if (!front_on_workers) {
      for (const FrontPair& f : front_) traversal.RetestFrontPair(main_lists, f);
    }
  } else {
    traversal.StartFromRoots(main_lists);
  }
  RunBestFirst(traversal, main_lists, options, budget_us, t0, split_at);
  if (split_at > 0 && (!queue_.empty() || front_on_workers)) {
    RunOnWorkers(traversal, arena_->arena, workers_, queue_, front_, front_on_workers, main_lists);
  }

  // Ties broken by the nodes, so that the order does not depend on the traversal's.
  std::sort(results_.begin(), results_.end(),
            [](const HullPairContact& x, const HullPairContact& y) {
              if (x.signed_distance_m != y.signed_distance_m) {
                return x.signed_distance_m < y.signed_distance_m;
              }
              return x.node_A != y.node_A ? x.node_A < y.node_A : x.node_B < y.node_B;
            });
  // What the next call's coherence reads.
  std::sort(current_.begin(), current_.end(), PairLess<CoherentPair>);
  previous_.swap(current_);
  std::sort(current_far_.begin(), current_far_.end(), PairLess<FrontPair>);
  previous_far_.swap(current_far_);
  front_valid_ = track_front && !st.budget_exhausted && !traversal.front_overflow.load();
  if (front_valid_ && !use_front) front_base_ = next_front_.size();
  front_.swap(next_front_);
  previous_A_ = bounds_A.id;
  previous_B_ = bounds_B.id;
  return finish();
}

}  // namespace ht
