#pragma once
// Statistics of the remote node's steps for its run summary (rate, step/collision/texture time
// percentiles, contacts) and the per-step trace remote_steps.csv (the split of seed Fig. 77).
// Private to slave_sim: RunRemoteNode (remote_node.cc) records every step here.

#include <array>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <span>
#include <string>
#include <vector>

#include "haptic_core/remote_step.h"
#include "haptic_core/statistics.h"

namespace ht {

/// Bounded statistics of a run of remote steps of any length: the percentiles are over a uniform
/// reservoir sample of 2^20 steps (all of them in a run shorter than that), and the trace keeps
/// the first 2^20 steps, in memory reserved at construction, so that Record() never allocates
/// and the step loop never writes a file.
class RemoteStepStatistics {
 public:
  /// `keep_trace`: reserve and keep the per-step records for WriteTrace().
  explicit RemoteStepStatistics(bool keep_trace);

  /// One step that began `t_s` seconds after the node started at local time `begin_ns` and ended
  /// at `end_ns` (ns), with its timings, the contacts of its model, the sequence number of the
  /// newest tool state it answered and why it ran (`cause`: RemoteSession's StepCause code,
  /// remote_session.h). noexcept, no allocation.
  /// `windows`: the step's contact windows (HapticTexturePipeline::last_contact_queries()), whose
  /// grid N (ContactWindow::resolution, chosen per window from its cluster's extent) the trace
  /// keeps, the first kMaxContacts of them.
  void Record(double t_s, std::int64_t begin_ns, std::int64_t end_ns, const StepTimings& timings,
              int contacts, std::uint64_t tool_state_seq, int cause,
              std::span<const ContactQuery> windows = {}) noexcept;

  std::uint64_t steps() const noexcept { return steps_; }

  /// Writes remote_steps.csv to `path`: `step, t_s, leaf_pairs, clusters, contacts,
  /// broad_phase_culled, collision_us, texture_us, total_us, budget_exhausted, tool_state_seq,
  /// cause, free_space_clearance_mm, windows, cells, grid_1 … grid_14`, one row per kept step
  /// (`cause`: 1 first step, 2 a tool state arrived, 3 the scene moves, 4 a model held by the
  /// model period, 5 the extrapolated pose left the last step's free space; StepCause in
  /// remote_session.h; `windows` the contact windows linearized, `cells` their Σ N², the texture
  /// stage's work, and grid_k the k-th window's N, 0 past the last). Throws
  /// std::runtime_error naming the path when it cannot be written.
  void WriteTrace(const std::string& path) const;

  /// Adds steps, rate_hz, step_p50/p99/max_us, steps_in_contact, step_in_contact_p50/p99_us,
  /// collision/texture max and p50 (texture p99), slow_steps_over_5ms and contacts_max to `s`.
  void AddTo(nlohmann::json& s) const;

 private:
  struct StepRecord {
    double t_s;
    StepTimings timings;
    int contacts;
    std::uint64_t tool_state_seq;
    int cause;
    int windows;
    std::array<std::uint16_t, kMaxContacts> grids;  // each window's N, 0 past the last
  };
  std::uint64_t steps_ = 0;
  std::uint64_t steps_in_contact_ = 0;
  std::uint64_t slow_steps_over_5ms_ = 0;
  int contacts_max_ = 0;
  std::int64_t first_step_ns_ = 0, last_step_ns_ = 0;
  ReservoirSamples step_us_, contact_step_us_, collision_us_, texture_us_;
  std::vector<StepRecord> records_;
};

}  // namespace ht
