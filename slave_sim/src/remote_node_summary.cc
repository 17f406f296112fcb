// The remote node's summary (RunRemoteNode's result; remote_node_run.h): the steps' statistics,
// CPU time, the pipeline's options and counters, the backend, and the transport.
#include <cmath>
#include <nlohmann/json.hpp>
#include <string>

#include "haptic_core/gpu_penetration_depth.h"
#include "haptic_core/steady_clock.h"
#include "remote_node_run.h"

namespace ht::remote {

nlohmann::json RemoteNodeRun::Summary() const {
  nlohmann::json s;
  s["scene"] = current_scene_->name;
  s["listen"] = bound_.ToString();
  statistics_.AddTo(s);
  s["tool_state_gap_max_ms"] = session_->tool_state_gap_max_ns() * 1e-6;
  // The process's CPU time over the run (user + system, every thread; getrusage), and its share
  // of one core over the node's wall time; the same from the first step on (the scene built and
  // a session stepping): what issue 33's "idle when nothing changes" is measured by.
  {
    const double cpu_s = ProcessCpuSeconds();
    const std::int64_t end_ns = SteadyNowNs();
    const double wall_s = static_cast<double>(end_ns - start_ns_) * 1e-9;
    s["cpu_s"] = cpu_s;
    s["wall_s"] = wall_s;
    s["cpu_share_of_one_core"] = wall_s > 0.0 ? cpu_s / wall_s : 0.0;
    const double stepping_s =
        first_step_ns_ < 0 ? 0.0 : static_cast<double>(end_ns - first_step_ns_) * 1e-9;
    s["cpu_s_since_first_step"] = first_step_ns_ < 0 ? 0.0 : cpu_s - first_step_cpu_s_;
    s["wall_s_since_first_step"] = stepping_s;
    s["cpu_share_since_first_step"] =
        stepping_s > 0.0 ? (cpu_s - first_step_cpu_s_) / stepping_s : 0.0;
  }
  s["grid_resolution"] = config_.pipeline.grid_resolution;
  s["window_extent_m"] = config_.pipeline.window_extent_m;
  s["max_window_extent_m"] = config_.pipeline.max_window_extent_m;
  s["texture_threads"] = config_.pipeline.texture_threads;
  // The warm-up's count is the backend's it started with (not the CPU's it may have fallen to).
  s["linearization_missing_overlap"] =
      pipeline_->faults().missing_overlap -
      (pipeline_->backend_failures() == 0 ? warm_up_missing_overlap_ : 0);
  s["refine_depth"] = config_.pipeline.refine_depth;
  {
    // Stage 5b (issue 32), warm-up included: contacts refined, and per contact the seeds, the
    // evaluations of b − a and how far δ0 rose above the grid's; the conservative screen's
    // squares and leaves per contact, the contacts where it found a deeper point than the seeds
    // (and Σ µm), and those it stopped at its leaf budget; the last step's seeds searched, the
    // contacts where one was deeper than the grid's seeds (and Σ µm).
    const DepthRefinementCounters& r = pipeline_->depth_refinement_counters();
    const double n = r.contacts > 0 ? static_cast<double>(r.contacts) : 1.0;
    s["depth_refinement"] = {
        {"contacts", r.contacts},
        {"seeds_per_contact", static_cast<double>(r.seeds) / n},
        {"evaluations_per_contact", static_cast<double>(r.evaluations) / n},
        {"depth_raised_um_mean", static_cast<double>(r.raised_um) / n},
        {"screen_squares_per_contact", static_cast<double>(r.screen_squares) / n},
        {"screen_leaves_per_contact", static_cast<double>(r.screen_leaves) / n},
        {"screen_found_deeper", r.screen_found},
        {"screen_raised_um_sum", r.screen_raised_um},
        {"screen_truncated", r.screen_truncated},
        {"last_step_seeds", r.last_step_seeds},
        {"last_step_found_deeper", r.last_step_found},
        {"last_step_raised_um_sum", r.last_step_raised_um},
        {"parallax_offset_seeds", r.parallax_offset_seeds},
        {"parallax_offset_found_deeper", r.parallax_offset_found},
        {"parallax_offset_raised_um_sum", r.parallax_offset_raised_um},
        {"neighbour_peak_seeds", r.neighbour_peak_seeds},
        {"neighbour_peak_found_deeper", r.neighbour_peak_found},
        {"neighbour_peak_raised_um_sum", r.neighbour_peak_raised_um}};
  }
  // The round trip the operator's newest Ping reported (ms; 0: none yet).
  s["operator_rtt_ms_last"] = static_cast<double>(session_->operator_rtt_ns()) * 1e-6;
  s["grazing_dropped_contacts"] = pipeline_->step_faults().grazing_dropped;
  s["unreachable_pairs_dropped"] = pipeline_->step_faults().unreachable_pairs;
  s["speculative_pairs"] = pipeline_->step_faults().speculative_pairs;
  s["speculative_lead_ms"] = config_.pipeline.speculative_lead_s * 1e3;
  s["speculative_floor"] = {{"speed_mm_per_s", config_.speculative_speed_m_per_s * 1e3},
                            {"max_mm", config_.max_speculative_floor_m * 1e3},
                            {"last_mm", pipeline_->speculative_floor_m() * 1e3},
                            {"largest_mm", largest_speculative_floor_m_ * 1e3}};
  s["triangle_lists_overflowed"] = pipeline_->step_faults().triangle_lists_overflowed;
  s["region_windows"] = pipeline_->step_faults().region_windows;
  // Stage 5a: whether the backend at the end runs it (the CPU texture stage does, the GPU
  // backend does not).
  s["split"] = {{"runs", pipeline_->backend().name() != "gpu"}};
  s["shared_contacts"] = pipeline_->step_faults().shared_contacts;
  s["steps_from_kept_fields"] = pipeline_->step_faults().steps_from_kept_fields;
  s["pd_backend"] = {{"requested", ToString(config_.pd_backend)},
                     {"used", backend_at_start_},
                     {"used_at_end", std::string(pipeline_->backend().name())},
                     {"message", backend_message_},
                     {"gl_renderer", gl_renderer_},
                     {"gl_version", gl_version_},
                     {"gl_vendor", gl_vendor_},
                     {"depth_bits", gl_renderer_.empty() ? 0 : config_.gpu.depth_bits},
                     {"instanced_draws", gpu_instanced_draws_},
                     {"failures", pipeline_->backend_failures()},
                     {"fallback_reason", pipeline_->fallback_reason()}};
  s["transport"] = session_->StatsJson(config_.scene_objects.size(), scene_bytes_);
  s["transport"]["scene"]["reloads_switched"] = scene_reloads_;
  s["transport"]["scene"]["reload_bytes_queued"] = reload_bytes_;
  return s;
}

}  // namespace ht::remote
