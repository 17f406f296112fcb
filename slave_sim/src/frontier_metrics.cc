// The speed-vs-error frontier's measures (frontier_records.h): each setting's errors against the
// texture-stage ground truth, the pipeline truth and the volume truth, the model-prediction
// measure, and the Pareto marks.
#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <vector>

#include "frontier_records.h"

namespace ht::frontier {
namespace {

double AngleDeg(const glm::dvec3& a, const glm::dvec3& b) {
  const double c = glm::dot(a, b) / (glm::length(a) * glm::length(b));
  return std::acos(std::clamp(c, -1.0, 1.0)) * 180.0 / std::numbers::pi;
}

double SquaredNorm(const glm::dvec3& v) { return glm::dot(v, v); }

}  // namespace

void ComputeMetrics(SettingRun& run, const std::vector<GtJob>& jobs,
                    const std::vector<Wrench>& reference_gt, const std::vector<bool>& touching,
                    const std::vector<PoseTruth>& pipeline) {
  Metrics& m = run.m;
  std::vector<double> coll, tex, tot, dir, derr, rel;
  double contacts = 0, leaf = 0;
  for (const PoseRecord& p : run.poses) {
    coll.push_back(p.timings.collision_us);
    tex.push_back(p.timings.texture_us);
    tot.push_back(p.timings.total_us);
    contacts += p.contacts;
    leaf += p.timings.leaf_pairs;
  }
  const double n = std::max<double>(1.0, static_cast<double>(run.poses.size()));
  m.collision_p50 = Percentile(coll, 0.5);
  m.collision_p95 = Percentile(coll, 0.95);
  m.texture_p50 = Percentile(tex, 0.5);
  m.texture_p95 = Percentile(tex, 0.95);
  m.total_p50 = Percentile(tot, 0.5);
  m.total_p95 = Percentile(tot, 0.95);
  m.contacts_mean = contacts / n;
  m.leaf_pairs_mean = leaf / n;
  // The truth per pose: the ground truth on this setting's own windows (the baselines, which
  // have none, against the default setting's).
  std::vector<Wrench> gt(run.poses.size());
  const bool own = run.setting.method == FrontierMethod::kTexture;
  if (own) {
    for (const ContactRecord& c : run.contacts) gt[c.pose] += jobs[c.gt].result.F_T_W;
  } else {
    gt = reference_gt;
  }
  double fe = 0, fg = 0, te = 0, tg = 0;
  for (std::size_t k = 0; k < run.poses.size(); ++k) {
    const Wrench& F = run.poses[k].F;
    const Wrench& G = gt[k];
    fe += glm::dot(F.force - G.force, F.force - G.force);
    fg += glm::dot(G.force, G.force);
    te += glm::dot(F.torque - G.torque, F.torque - G.torque);
    tg += glm::dot(G.torque, G.torque);
    if (glm::length(G.force) > 1e-9 && glm::length(F.force) > 1e-9) {
      dir.push_back(AngleDeg(F.force, G.force));
    }
    if (glm::length(G.force) > 1e-9) {
      rel.push_back(glm::length(F.force - G.force) / glm::length(G.force));
    }
    const bool method_contact = run.poses[k].contacts > 0;
    if (k < touching.size()) {
      m.poses_missed += touching[k] && !method_contact;
      m.poses_invented += !touching[k] && method_contact;
    }
  }
  // The pipeline truth (T1) and the volume truth (T2), per pose.
  double pfe = 0, pfg = 0, pte = 0, ptg = 0;
  std::vector<double> vdir, varm;
  for (std::size_t k = 0; k < run.poses.size() && k < pipeline.size(); ++k) {
    const Wrench& F = run.poses[k].F;
    const PoseTruth& t = pipeline[k];
    const Wrench& G = t.F_T_W;
    pfe += glm::dot(F.force - G.force, F.force - G.force);
    pfg += glm::dot(G.force, G.force);
    pte += glm::dot(F.torque - G.torque, F.torque - G.torque);
    ptg += glm::dot(G.torque, G.torque);
    const bool force = glm::length(F.force) > 1e-9;
    m.poses_truth_without_force += t.pairs > 0 && !force;
    m.poses_force_without_truth += t.pairs == 0 && force;
    const double gx = glm::length(t.dV_dx_W);
    if (force && gx > 0.0) {
      vdir.push_back(AngleDeg(F.force, -t.dV_dx_W));
      const double arm_gt = glm::length(t.dV_dtheta_W) / gx;
      const double arm = glm::length(F.torque) / glm::length(F.force);
      if (arm_gt > 0.0) varm.push_back(std::abs(arm - arm_gt) / arm_gt);
    }
  }
  const double nan = std::numeric_limits<double>::quiet_NaN();
  m.pipeline_force_rel_rms = pfg > 0 ? std::sqrt(pfe / pfg) : nan;
  m.pipeline_torque_rel_rms = ptg > 0 ? std::sqrt(pte / ptg) : nan;
  m.volume_dir_p50_deg = Percentile(vdir, 0.5);
  m.volume_dir_p95_deg = Percentile(vdir, 0.95);
  m.volume_arm_rel_p50 = Percentile(varm, 0.5);
  m.force_rel_rms = fg > 0 ? std::sqrt(fe / fg) : std::numeric_limits<double>::quiet_NaN();
  m.torque_rel_rms = tg > 0 ? std::sqrt(te / tg) : std::numeric_limits<double>::quiet_NaN();
  m.force_rel_p50 = Percentile(rel, 0.5);
  m.dir_p50_deg = Percentile(dir, 0.5);
  m.dir_p95_deg = Percentile(dir, 0.95);
  for (const ContactRecord& c : run.contacts) {
    const double d = c.lin.depth_m, g = jobs[c.gt].result.linearization.depth_m;
    ++m.windows;
    const bool dc = std::isfinite(d) && d > 0.0, gc = std::isfinite(g) && g > 0.0;
    m.missed += gc && !dc;
    m.invented += dc && !gc;
    if ((dc || gc) && std::isfinite(d) && std::isfinite(g)) derr.push_back(std::abs(d - g) * 1e6);
  }
  m.delta_p50_um = Percentile(derr, 0.5);
  m.delta_p95_um = Percentile(derr, 0.95);
}

void MarkPareto(std::vector<SettingRun>& runs) {
  for (SettingRun& a : runs) {
    if (!a.skipped.empty() || !std::isfinite(a.m.pipeline_force_rel_rms)) continue;
    a.m.pareto = true;
    for (const SettingRun& b : runs) {
      if (&a == &b || !b.skipped.empty() || !std::isfinite(b.m.pipeline_force_rel_rms)) continue;
      const bool no_worse = b.m.total_p50 <= a.m.total_p50 &&
                            b.m.pipeline_force_rel_rms <= a.m.pipeline_force_rel_rms;
      const bool better =
          b.m.total_p50 < a.m.total_p50 || b.m.pipeline_force_rel_rms < a.m.pipeline_force_rel_rms;
      if (no_worse && better) a.m.pareto = false;
    }
  }
}

// The model-prediction measure of `run`: its contact models' wrenches at the displaced poses
// against the pipeline truth there (relative RMS), where both exist.
void ScorePressure(const std::vector<PoseTruth>& pipeline, double k_p, SettingRun& run) {
  if (run.setting.force_law != ForceLaw::kPressure) return;
  double fe = 0, fg = 0, te = 0, tg = 0;
  for (std::size_t k = 0; k < run.poses.size() && k < pipeline.size(); ++k) {
    const Wrench& F = run.poses[k].F;
    const glm::dvec3 g = k_p * pipeline[k].pressure_per_kp.force;
    const glm::dvec3 t = k_p * pipeline[k].pressure_per_kp.torque;
    fe += glm::dot(F.force - g, F.force - g);
    fg += glm::dot(g, g);
    te += glm::dot(F.torque - t, F.torque - t);
    tg += glm::dot(t, t);
  }
  const double nan = std::numeric_limits<double>::quiet_NaN();
  run.m.pressure_force_rel_rms = fg > 0 ? std::sqrt(fe / fg) : nan;
  run.m.pressure_torque_rel_rms = tg > 0 ? std::sqrt(te / tg) : nan;
}

void ScorePrediction(const std::vector<PoseTruth>& displaced_truth, SettingRun& run) {
  if (run.predicted.size() != displaced_truth.size() || run.predicted.empty()) return;
  double fe = 0, fr = 0, te = 0, tr = 0;
  for (std::size_t i = 0; i < displaced_truth.size(); ++i) {
    const Wrench& F = run.predicted[i];
    const Wrench& G = displaced_truth[i].F_T_W;
    fe += SquaredNorm(F.force - G.force);
    fr += SquaredNorm(G.force);
    te += SquaredNorm(F.torque - G.torque);
    tr += SquaredNorm(G.torque);
  }
  const double nan = std::numeric_limits<double>::quiet_NaN();
  run.m.prediction_force_rel_rms = fr > 0 ? std::sqrt(fe / fr) : nan;
  run.m.prediction_torque_rel_rms = tr > 0 ? std::sqrt(te / tr) : nan;
}

}  // namespace ht::frontier
