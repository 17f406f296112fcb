// The operator station's summary (summary.json; station_run.h): the run, the loop's timing, the
// remote node's and the link's figures, passivity and safety counters, and the transport.
#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "haptic_core/passivity.h"
#include "haptic_core/statistics.h"
#include "haptic_core/wrench_safety.h"
#include "station_run.h"

namespace ht::station {

nlohmann::json OperatorStationRun::Summary() const {
  const LoopRecord& rec = *record_;
  const PassivityController& passivity = tick_->passivity();
  const SafetyLimits& safety_limits = tick_->safety().limits();
  const std::vector<double>& ages = rec.model_age_ms.values();
  const std::int64_t ticks_run = rec.ticks_done.load();
  nlohmann::json s;
  s["experiment"] = experiment_.name();
  s["workspace"] = {
      {"origin_W_at_start",
       {X_WM_start_.translation.x, X_WM_start_.translation.y, X_WM_start_.translation.z}},
      {"rotation_WM_wxyz",
       {X_WM_start_.rotation.w, X_WM_start_.rotation.x, X_WM_start_.rotation.y,
        X_WM_start_.rotation.z}},
      {"from_remote", config_.workspace_from_remote},
      {"targets", scene_M_.targets.size()},
      {"jumps", tick_->counters().workspace_jumps},
      {"models_dropped_from_before_a_jump", tick_->counters().models_from_before_jump},
      {"targets_M",
       [&] {
         nlohmann::json list = nlohmann::json::array();
         for (const ExperimentTarget& t : scene_M_.targets) {
           list.push_back({{"box_min", {t.box_min_M.x, t.box_min_M.y, t.box_min_M.z}},
                           {"box_max", {t.box_max_M.x, t.box_max_M.y, t.box_max_M.z}},
                           {"top", {t.top_M.x, t.top_M.y, t.top_M.z}}});
         }
         return list;
       }()},
      {"shift_M",
       {tick_->workspace_shift_M().x, tick_->workspace_shift_M().y, tick_->workspace_shift_M().z}}};
  if (display_) {
    s["display"] = display_->Summary();
  } else {
    s["display"] = {{"mode", "none"}};
  }
  s["contact_force_bound_n"] = config_.max_contact_force_n;
  s["contact_damping_hunt_crossley_s_per_m"] = config_.hunt_crossley_s_per_m;
  s["saturated_contact_ticks"] = tick_->counters().saturated_contact_ticks;
  // Ticks that rendered a contact from its depth field (beyond its margin), that fell back to a
  // contact's linearization for want of its field, and fields the loop's cache refused.
  s["depth_fields"] = {{"field_ticks", tick_->counters().field_ticks},
                       {"beyond_margin_ticks", tick_->counters().field_beyond_margin_ticks},
                       {"fallback_ticks", tick_->counters().field_fallback_ticks},
                       {"fields_refused", tick_->counters().fields_refused},
                       {"fields_over_node_budget", tick_->depth_fields_over_budget()}};
  s["tool_mass_kg"] = tool_inertia_.mass_kg;
  s["device"] = caps_.name;
  s["duration_s"] =
      config_.run_until_stopped || rec.stopped_by_request ? elapsed_s_ : experiment_.duration_s();
  s["run_until_stopped"] = config_.run_until_stopped;
  s["stopped_by_request"] = rec.stopped_by_request;
  s["ticks"] = ticks_run;
  s["operator_rate_hz"] = ticks_run / std::max(elapsed_s_, 1e-9);
  // Percentiles over a uniform sample of at most 2^20 ticks (all of them in runs up to 17 min).
  s["tick_statistics_sampled"] = rec.compute_us.count() > rec.compute_us.values().size();
  s["operator_period_p50_us"] = Percentile(rec.period_us.values(), 0.5);
  s["operator_period_p99_us"] = Percentile(rec.period_us.values(), 0.99);
  s["operator_period_max_us"] = Percentile(rec.period_us.values(), 1.0);
  s["operator_tick_p50_us"] = Percentile(rec.compute_us.values(), 0.5);
  s["operator_tick_p99_us"] = Percentile(rec.compute_us.values(), 0.99);
  s["operator_tick_max_us"] = Percentile(rec.compute_us.values(), 1.0);
  s["operator_overruns"] = rec.overruns;
  s["realtime_priority"] = rec.realtime_note;
  s["remote_rate_hz"] = network_->RemoteRateHz();
  // The remote node's compute time of the steps whose contact models arrived here (each model
  // carries its step's time): not a round trip (rtt_ms_*), and not the node's own percentiles
  // over every step it took (remote.step_p50_us: free-space steps of a few µs included).
  s["remote_step_of_models_p50_us"] = Percentile(network_->remote_step_us(), 0.5);
  s["remote_step_of_models_p99_us"] = Percentile(network_->remote_step_us(), 0.99);
  s["remote_step_of_models_in_contact_p50_us"] = Percentile(network_->contact_step_us(), 0.5);
  s["remote_step_of_models_in_contact_p99_us"] = Percentile(network_->contact_step_us(), 0.99);
  s["remote_collision_p50_us"] = Percentile(network_->collision_us(), 0.5);
  s["remote_texture_p50_us"] = Percentile(network_->texture_us(), 0.5);
  s["rtt_ms_p50"] = Percentile(network_->rtt_ms(), 0.5);
  s["rtt_ms_p99"] = Percentile(network_->rtt_ms(), 0.99);
  s["model_age_ms_p50"] = Percentile(ages, 0.5);
  s["model_age_ms_p99"] = Percentile(ages, 0.99);
  s["contacts_max"] = rec.contacts_max;
  {
    // Phases that should end with the tool free (explore's releases and transfers) but ended
    // with it still loaded: the tool was wedged in the part it left.
    nlohmann::json ends = nlohmann::json::array();
    const auto kept = std::min<std::int64_t>(rec.wedged_count, LoopRecord::kWedgedKept);
    for (std::int64_t i = 0; i < kept; ++i) {
      const LoopRecord::WedgedPhaseEnd& w = rec.wedged[static_cast<std::size_t>(i)];
      const auto& names = experiment_.phase_names();
      ends.push_back({{"phase", w.phase >= 0 && w.phase < static_cast<int>(names.size())
                                    ? names[static_cast<std::size_t>(w.phase)]
                                    : std::to_string(w.phase)},
                      {"t_s", w.t_s},
                      {"contact_force_n", w.force_n}});
    }
    s["wedged"] = {{"count", rec.wedged_count},
                   {"phase_ends_checked", rec.free_ends_seen},
                   {"above_n", LoopRecord::kWedgedForceN},
                   {"phase_ends", ends}};
  }
  s["contact_force_max_n"] = rec.contact_force_max_n;
  s["device_max_force_n"] = caps_.max_force_n;
  s["device_max_torque_nm"] = caps_.max_torque_nm;
  const SafetyCounters& sc = tick_->safety().counters();
  s["force_clamped_ticks"] = sc.clamped;
  s["operator_energy_in_J"] = passivity.energy_in_j();
  s["operator_energy_out_J"] = passivity.energy_out_j();
  s["passivity"] = {
      {"enabled", config_.passivity},
      {"observed_energy_J", passivity.observed_energy_j()},
      {"dissipated_J", passivity.dissipated_j()},
      {"active_ticks", passivity.active_ticks()},
      {"max_damping_ns_per_m", passivity.max_alpha()},
      {"scaled_ticks", passivity.scaled_ticks()},
      {"force_scaled_away_Ns", passivity.force_scaled_away_ns()},
      {"force_damped_away_Ns", passivity.force_damped_away_ns()},
      {"scaled_away_J", passivity.scaled_away_j()},
      {"reserve_J", config_.passivity_reserve_j},
      {"refill_fraction", config_.passivity_refill_fraction},
      {"release_ms", config_.passivity_release_ms},
      {"energy_bounded_switch", config_.energy_bounded_switch},
      {"switch_offset_release_ms", std::isfinite(config_.switch_offset_release_ms)
                                       ? nlohmann::json(config_.switch_offset_release_ms)
                                       : nlohmann::json(nullptr)},
      {"switch_offset_ticks", tick_->counters().switch_offset_ticks},
      {"switch_offset_max_um", tick_->counters().switch_offset_max_m * 1e6},
      {"refill_ticks", passivity.refill_ticks()},
      {"refilled_J", passivity.refilled_j()},
      {"force_refilled_Ns", passivity.force_refilled_ns()}};
  {
    // Issue 33: where the loop's energy comes from. Within one contact model the loop is
    // conservative; the switches (a new model, each blend step, a model dropped mid-blend)
    // change the contact potential at the tool's pose: what they created is what the
    // controller (dissipated_J + scaled_away_J) may have to remove.
    const OperatorTickCounters& tc = tick_->counters();
    const double removed = passivity.dissipated_j() + passivity.scaled_away_j();
    s["passivity"]["attribution"] = {
        {"switch_energy_created_J", tc.switch_energy_created_j},
        {"switch_energy_absorbed_J", tc.switch_energy_absorbed_j},
        {"switch_ticks", tc.switch_ticks},
        {"switch_ticks_creating", tc.switch_ticks_creating},
        {"switch_energy_created_by_model_age_J",
         {{"below_50ms", tc.switch_energy_created_by_age_j[0]},
          {"50_to_150ms", tc.switch_energy_created_by_age_j[1]},
          {"above_150ms", tc.switch_energy_created_by_age_j[2]}}},
        {"controller_removed_J", removed},
        {"created_over_removed", removed > 0.0 ? tc.switch_energy_created_j / removed : 0.0}};
  }
  s["safety"] = {{"nonfinite_ticks", sc.nonfinite},
                 {"fading_ticks", sc.fading},
                 {"braking_ticks", sc.braking},
                 {"clamped_ticks", sc.clamped},
                 {"rate_limited_ticks", sc.rate_limited},
                 {"max_force_n", safety_limits.max_force_n},
                 {"max_torque_nm", safety_limits.max_torque_nm},
                 {"model_timeout_s", safety_limits.model_timeout_s}};
  s["nonfinite_count"] = tick_->counters().nonfinite;
  s["device_faults"] = tick_->counters().device_faults + rec.device_write_faults;
  s["device_read_faults"] = tick_->counters().device_faults;
  s["device_write_faults"] = rec.device_write_faults;
  s["trace_rows_dropped"] = rows_dropped_.load();
  s["trace_rows_over_cap"] = rows_over_cap_;
  s["transport"] = network_->Summary();
  // Packet and bit rates per stream: this side's datagrams (sent plus received) of the whole
  // session, handshake and scene included, over the loop's run time (payload bytes: header,
  // body and MAC; UDP and IP headers not counted). The remote node's own counts are merged under
  // each stream's "remote". (deploy/deadband-table divides the same counts by duration_s.)
  for (auto& [type, stream] : s["transport"]["streams"].items()) {
    const double packets = stream.value("sent", 0.0) + stream.value("received", 0.0);
    const double bytes = stream.value("bytes_sent", 0.0) + stream.value("bytes_received", 0.0);
    stream["packets_per_s"] = packets / std::max(elapsed_s_, 1e-9);
    stream["kbit_per_s"] = bytes * 8e-3 / std::max(elapsed_s_, 1e-9);
  }
  s["clock_offset_ms"] = s["transport"]["clock"]["offset_ms"];
  s["model_one_way_ms_p50"] = Percentile(network_->one_way_ms(), 0.5);
  s["model_one_way_ms_p99"] = Percentile(network_->one_way_ms(), 0.99);
  return s;
}

nlohmann::json OperatorStationRun::FailureSummary(const std::string& error) {
  StopWorkers();
  nlohmann::json s;
  s["error"] = error;
  s["experiment"] = experiment_.name();
  s["device"] = caps_.name;
  s["remote_address"] = config_.remote_address.ToString();
  s["session_opened"] = counters_.connected.load();
  s["session_refused"] = counters_.rejected.load();
  s["models_received"] = counters_.model_accepted.load();
  s["stopped_by_request"] = StopRequested();
  s["duration_s"] = 0.0;
  s["ticks"] = 0;
  s["transport"] = network_->Summary();
  return s;
}

}  // namespace ht::station
