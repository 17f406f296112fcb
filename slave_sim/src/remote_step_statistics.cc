#include "remote_step_statistics.h"

#include <algorithm>
#include <cstdio>
#include <stdexcept>

namespace ht {
namespace {

constexpr std::size_t kKeptSteps = std::size_t{1} << 20;

}  // namespace

RemoteStepStatistics::RemoteStepStatistics(bool keep_trace)
    : step_us_(kKeptSteps),
      contact_step_us_(kKeptSteps),
      collision_us_(kKeptSteps),
      texture_us_(kKeptSteps) {
  if (keep_trace) records_.reserve(kKeptSteps);
}

void RemoteStepStatistics::Record(double t_s, std::int64_t begin_ns, std::int64_t end_ns,
                                  const StepTimings& timings, int contacts,
                                  std::uint64_t tool_state_seq, int cause,
                                  std::span<const ContactQuery> windows) noexcept {
  ++steps_;
  if (first_step_ns_ == 0) first_step_ns_ = begin_ns;
  last_step_ns_ = end_ns;
  contacts_max_ = std::max(contacts_max_, contacts);
  step_us_.Add(timings.total_us);
  if (timings.total_us > 5000.0) ++slow_steps_over_5ms_;
  if (contacts > 0) {
    ++steps_in_contact_;
    contact_step_us_.Add(timings.total_us);
  }
  collision_us_.Add(timings.collision_us);
  texture_us_.Add(timings.texture_us);
  if (records_.size() < records_.capacity()) {
    StepRecord r{t_s, timings, contacts, tool_state_seq, cause, 0, {}};
    r.windows = static_cast<int>(windows.size());
    for (std::size_t k = 0; k < windows.size() && k < r.grids.size(); ++k) {
      r.grids[k] = static_cast<std::uint16_t>(std::clamp(windows[k].window.resolution, 0, 65535));
    }
    records_.push_back(r);
  }
}

void RemoteStepStatistics::WriteTrace(const std::string& path) const {
  std::FILE* f = std::fopen(path.c_str(), "w");
  if (f == nullptr) throw std::runtime_error("cannot write " + path);
  std::fputs(
      "step,t_s,leaf_pairs,clusters,contacts,broad_phase_culled,collision_us,texture_us,"
      "total_us,budget_exhausted,tool_state_seq,cause,free_space_clearance_mm,windows,cells",
      f);
  for (int k = 1; k <= kMaxContacts; ++k) std::fprintf(f, ",grid_%d", k);
  std::fputs("\n", f);
  for (std::size_t i = 0; i < records_.size(); ++i) {
    const StepRecord& r = records_[i];
    long long cells = 0;  // Σ N² over the windows kept
    for (const std::uint16_t n : r.grids) cells += static_cast<long long>(n) * n;
    std::fprintf(f, "%zu,%.6f,%d,%d,%d,%d,%.2f,%.2f,%.2f,%d,%llu,%d,%.3f,%d,%lld", i + 1, r.t_s,
                 r.timings.leaf_pairs, r.timings.clusters, r.contacts, r.timings.broad_phase_culled,
                 r.timings.collision_us, r.timings.texture_us, r.timings.total_us,
                 r.timings.collision_budget_exhausted ? 1 : 0,
                 static_cast<unsigned long long>(r.tool_state_seq), r.cause,
                 r.timings.free_space_clearance_m * 1e3, r.windows, cells);
    for (const std::uint16_t n : r.grids) std::fprintf(f, ",%d", static_cast<int>(n));
    std::fputs("\n", f);
  }
  if (std::fclose(f) != 0) throw std::runtime_error("cannot write " + path);
}

void RemoteStepStatistics::AddTo(nlohmann::json& s) const {
  s["steps"] = steps_;
  s["rate_hz"] = last_step_ns_ > first_step_ns_
                     ? (steps_ - 1) / ((last_step_ns_ - first_step_ns_) * 1e-9)
                     : 0.0;
  s["step_p50_us"] = Percentile(step_us_.values(), 0.5);
  s["step_p99_us"] = Percentile(step_us_.values(), 0.99);
  s["step_max_us"] = Percentile(step_us_.values(), 1.0);
  s["steps_in_contact"] = steps_in_contact_;
  s["step_in_contact_p50_us"] = Percentile(contact_step_us_.values(), 0.5);
  s["step_in_contact_p99_us"] = Percentile(contact_step_us_.values(), 0.99);
  s["collision_max_us"] = Percentile(collision_us_.values(), 1.0);
  s["texture_max_us"] = Percentile(texture_us_.values(), 1.0);
  s["slow_steps_over_5ms"] = slow_steps_over_5ms_;
  s["collision_p50_us"] = Percentile(collision_us_.values(), 0.5);
  s["texture_p50_us"] = Percentile(texture_us_.values(), 0.5);
  s["texture_p99_us"] = Percentile(texture_us_.values(), 0.99);
  s["contacts_max"] = contacts_max_;
}

}  // namespace ht
