// The figures a deadband lockstep run is judged by (deadband_lockstep_arm.h).
#include <algorithm>
#include <cmath>
#include <fstream>
#include <glm/geometric.hpp>
#include <stdexcept>
#include <string>
#include <vector>

#include "deadband_lockstep_arm.h"
#include "haptic_core/statistics.h"

namespace lockstep {

/// 100 · √(Σ|b − a|² / Σ|a|²) over the ticks (the runs are tick for tick on one clock).
double RmsErrorPct(const std::vector<glm::dvec3>& ref, const std::vector<glm::dvec3>& run) {
  double num = 0.0, den = 0.0;
  const std::size_t n = std::min(ref.size(), run.size());
  for (std::size_t i = 0; i < n; ++i) {
    const glm::dvec3 d = run[i] - ref[i];
    num += glm::dot(d, d);
    den += glm::dot(ref[i], ref[i]);
  }
  return den > 0.0 ? 100.0 * std::sqrt(num / den) : 0.0;
}

double LargestStep(const std::vector<glm::dvec3>& v) {
  double m = 0.0;
  for (std::size_t i = 1; i < v.size(); ++i) m = std::max(m, glm::length(v[i] - v[i - 1]));
  return m;
}

/// One row per tick: what the operator felt and why; tool_x..tool_z and tool_rx..tool_rz are X_WT
/// as master_station's trace.csv has it (speed_error_frontier --trace reads it).
void WriteTrace(const std::string& path, const ArmRun& r) {
  std::ofstream f(path);
  if (!f) throw std::runtime_error("cannot write " + path);
  f << "t_s,device_fx,device_fy,device_fz,device_tx,device_ty,device_tz,contact_fx,contact_fy,"
       "contact_fz,passivity_removed_n,model_age_ms,contacts,model_arrived,tool_x,tool_y,tool_z,"
       "hand_x,hand_y,hand_z,depth_offset_um,tool_rx,tool_ry,tool_rz,field_contacts,"
       "field_fallbacks,field_beyond_margin,tick_us\n";
  for (std::size_t i = 0; i < r.device_force_W.size(); ++i) {
    const auto v = [&](const glm::dvec3& a) { f << ',' << a.x << ',' << a.y << ',' << a.z; };
    f << static_cast<double>(i) * 1e-3;
    v(r.device_force_W[i]);
    v(r.device_torque_W[i]);
    v(r.contact_force_W[i]);
    f << ',' << r.passivity_removed_n[i] << ',' << r.model_age_ms[i] << ',' << r.contacts[i] << ','
      << r.model_arrived[i];
    v(r.p_WT[i]);
    v(r.p_WH[i]);
    f << ',' << r.depth_offset_m[i] * 1e6;
    v(r.theta_WT[i]);
    f << ',' << (i < r.field_contacts.size() ? r.field_contacts[i] : 0) << ','
      << (i < r.field_fallbacks.size() ? r.field_fallbacks[i] : 0) << ','
      << (i < r.field_beyond_margin.size() ? r.field_beyond_margin[i] : 0) << ','
      << (i < r.tick_us.size() ? r.tick_us[i] : 0.0);
    f << '\n';
  }
}

int StepsAbove(const std::vector<glm::dvec3>& v, double n) {
  int c = 0;
  for (std::size_t i = 1; i < v.size(); ++i) c += glm::length(v[i] - v[i - 1]) > n ? 1 : 0;
  return c;
}

/// The q-quantile of the one-tick change |v[i] − v[i−1]| (nearest rank, Percentile; 0 for fewer
/// than two).
double StepQuantile(const std::vector<glm::dvec3>& v, double q) {
  std::vector<double> d;
  for (std::size_t i = 1; i < v.size(); ++i) d.push_back(glm::length(v[i] - v[i - 1]));
  return ht::Percentile(std::move(d), q);
}

/// What a hand feels as ripple (mN): the RMS of v less its centred 50-tick moving mean (a
/// high-pass at about 20 Hz; the eleventh stop's stick_ripple measure on one clock).
double HighPassRmsMilli(const std::vector<glm::dvec3>& v) {
  constexpr std::size_t kHalf = 25;
  if (v.size() <= 2 * kHalf) return 0.0;
  std::vector<glm::dvec3> prefix(v.size() + 1, glm::dvec3(0.0));
  for (std::size_t i = 0; i < v.size(); ++i) prefix[i + 1] = prefix[i] + v[i];
  double sum = 0.0;
  std::size_t n = 0;
  for (std::size_t i = kHalf; i + kHalf < v.size(); ++i) {
    const glm::dvec3 mean =
        (prefix[i + kHalf + 1] - prefix[i - kHalf]) / static_cast<double>(2 * kHalf + 1);
    const glm::dvec3 d = v[i] - mean;
    sum += glm::dot(d, d);
    ++n;
  }
  return 1e3 * std::sqrt(sum / static_cast<double>(n));
}

double PassivityShare(const ArmRun& r) {
  double removed = 0.0, impulse = 0.0;
  for (std::size_t i = 0; i < r.device_force_W.size(); ++i) {
    removed += r.passivity_removed_n[i];
    impulse += glm::length(r.device_force_W[i]);
  }
  return impulse > 0.0 ? 100.0 * removed / impulse : 0.0;
}

double Quantile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  const auto k =
      static_cast<std::size_t>(std::clamp(q, 0.0, 1.0) * static_cast<double>(v.size() - 1));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

double FieldTickShare(const std::vector<int>& per_tick) {
  if (per_tick.empty()) return 0.0;
  const auto n = std::count_if(per_tick.begin(), per_tick.end(), [](int c) { return c > 0; });
  return 100.0 * static_cast<double>(n) / static_cast<double>(per_tick.size());
}

}  // namespace lockstep
