#pragma once
// oneTBB's task objects come from per-thread small-object pools that keep every object they ever
// held: a pool allocates (through the scalable allocator) only when more of its tasks are in
// flight at once than ever before, which on two threads can first happen many steps into a run
// (one allocation in the first 72 steps on hammer-on-torus after a one-pass warm-up).
// WarmTaskPools fills the pools of the arena's threads past what the remote step's nesting needs
// (a parallel_for over contacts or traversal tasks, each with an isolated parallel_for of seven
// renders), so that the step's own tasks find objects waiting.

#include <oneapi/tbb/task_arena.h>

namespace ht::internal {

/// Runs, in `arena`, rounds of a parallel_for of 256 tasks each running an isolated parallel_for
/// of 16 (each spinning about a microsecond so that the threads steal from each other): four, and
/// more until every slot of the arena has run a task that spawned, for at most 250 ms (on a
/// loaded machine a worker may join only after the calling thread has done a round alone: it
/// then held no tasks, and the step's first tasks on it allocated, which the allocation test saw
/// with two busy processes beside it). A few milliseconds unloaded; call it where the arena is
/// made, not in a step. Ignores exceptions (out of memory: the pools stay as they are).
void WarmTaskPools(oneapi::tbb::task_arena& arena) noexcept;

}  // namespace ht::internal
