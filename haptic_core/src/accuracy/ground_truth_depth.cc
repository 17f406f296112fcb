#include "haptic_core/accuracy/ground_truth_depth.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

namespace ht {

// ------------------------------------------------------------------------------------------------
// GroundTruthDepthSolver

void GroundTruthOptions::Validate() const {
  if (initial_samples < 2 || initial_samples > 8192) {
    throw std::invalid_argument("ground truth: initial_samples must be in [2, 8192], got " +
                                std::to_string(initial_samples));
  }
  if (max_samples < initial_samples || max_samples > 8192) {
    throw std::invalid_argument(
        "ground truth: max_samples must be in [initial_samples, 8192], got " +
        std::to_string(max_samples));
  }
  if (!(tolerance_m > 0.0) || !(refine_step_m > 0.0) || refine_seeds < 0) {
    throw std::invalid_argument(
        "ground truth: tolerance and refine step must be positive, refine_seeds >= 0");
  }
}

GroundTruthDepthSolver::GroundTruthDepthSolver(const RayCastSurface& tool_F,
                                               const RayCastSurface& environment_F,
                                               const GroundTruthOptions& options)
    : tool_(tool_F), environment_(environment_F), options_(options) {
  options_.Validate();
}

void GroundTruthDepthSolver::SetPoses(const RigidTransform& X_WFt, const RigidTransform& X_WFe,
                                      const ContactWindow& w) noexcept {
  const RigidTransform X_FtW = X_WFt.Inverse();
  const RigidTransform X_FeW = X_WFe.Inverse();
  c_t_ = X_FtW * w.center_W;
  u_t_ = X_FtW.rotation * w.axis_u_W;
  v_t_ = X_FtW.rotation * w.axis_v_W;
  n_t_ = X_FtW.rotation * w.normal_W;
  c_e_ = X_FeW * w.center_W;
  u_e_ = X_FeW.rotation * w.axis_u_W;
  v_e_ = X_FeW.rotation * w.axis_v_W;
  n_e_ = X_FeW.rotation * w.normal_W;
  range_m_ = w.depth_range_m();
}

bool GroundTruthDepthSolver::ProbeEnvironment(double s, double t, double& b) noexcept {
  // From +R along −n: the first surface facing the ray faces +n, and it is the highest one.
  ++rays_;
  const glm::dvec3 org = c_e_ + s * u_e_ + t * v_e_ + range_m_ * n_e_;
  const double hit = environment_.FirstFacingHit(org, -n_e_, 2.0 * range_m_);
  if (hit < 0.0) return false;
  b = range_m_ - hit;
  return true;
}

bool GroundTruthDepthSolver::ProbeTool(double s, double t, double& a) noexcept {
  // From −R along +n: the first surface facing the ray faces −n, and it is the lowest one.
  ++rays_;
  const glm::dvec3 org = c_t_ + s * u_t_ + t * v_t_ - range_m_ * n_t_;
  const double hit = tool_.FirstFacingHit(org, n_t_, 2.0 * range_m_);
  if (hit < 0.0) return false;
  a = hit - range_m_;
  return true;
}

GroundTruthPressure GroundTruthDepthSolver::PressureAt(const RigidTransform& X_WT,
                                                       const RigidTransform& X_TFt,
                                                       const RigidTransform& X_WFe,
                                                       const ContactWindow& w, int m) {
  m = std::clamp(m, 2, 8192);
  const long long rays_before = rays_;
  SetPoses(X_WT * X_TFt, X_WFe, w);
  const double cell = w.extent_m / m, area = cell * cell, half_cell = 0.5 * cell;
  const auto coord = [&](int i) { return ((i + 0.5) / m - 0.5) * w.extent_m; };
  // The environment's slope along one axis at (s, t): central over ±half a cell where both
  // sides have a surface, else one-sided, else 0.
  const auto slope = [&](double s, double t, double b, bool along_u) {
    double lo = 0.0, hi = 0.0;
    const double ds = along_u ? half_cell : 0.0, dt = along_u ? 0.0 : half_cell;
    const bool has_lo = ProbeEnvironment(s - ds, t - dt, lo);
    const bool has_hi = ProbeEnvironment(s + ds, t + dt, hi);
    if (has_lo && has_hi) return (hi - lo) / cell;
    if (has_hi) return (hi - b) / half_cell;
    if (has_lo) return (b - lo) / half_cell;
    return 0.0;
  };
  GroundTruthPressure out;
  out.samples_per_side = m;
  glm::dvec3 force{0.0}, torque{0.0};
  for (int j = 0; j < m; ++j) {
    for (int i = 0; i < m; ++i) {
      const double s = coord(i), t = coord(j);
      const Sample x = Probe(s, t);
      if (!x.hit_b || !x.hit_a) continue;
      const double d = x.b - x.a;
      if (!(d > 0.0)) continue;
      const glm::dvec3 g =
          slope(s, t, x.b, true) * w.axis_u_W + slope(s, t, x.b, false) * w.axis_v_W - w.normal_W;
      const glm::dvec3 r =
          w.center_W + s * w.axis_u_W + t * w.axis_v_W + x.a * w.normal_W - X_WT.translation;
      out.volume_m3 += area * d;
      force -= (area * d) * g;
      torque -= (area * d) * glm::cross(r, g);
    }
  }
  out.per_kp = {force, torque};
  out.rays = rays_ - rays_before;
  return out;
}

GroundTruthPressure GroundTruthDepthSolver::ConvergedPressure(const RigidTransform& X_WT,
                                                              const RigidTransform& X_TFt,
                                                              const RigidTransform& X_WFe,
                                                              const ContactWindow& w,
                                                              double tolerance, int max_samples) {
  GroundTruthPressure out = PressureAt(X_WT, X_TFt, X_WFe, w, options_.initial_samples);
  long long rays = out.rays;
  for (int m = 2 * options_.initial_samples; m <= max_samples; m *= 2) {
    GroundTruthPressure next = PressureAt(X_WT, X_TFt, X_WFe, w, m);
    rays += next.rays;
    const double f = glm::length(next.per_kp.force);
    const double df = glm::length(next.per_kp.force - out.per_kp.force);
    const double dt = glm::length(next.per_kp.torque - out.per_kp.torque);
    const double t_scale = glm::length(next.per_kp.torque) + f * 0.5 * w.extent_m;
    next.change = f > 0.0 ? std::max(df / f, dt / t_scale) : (df > 0.0 ? 1.0 : 0.0);
    next.converged = next.change < tolerance;
    out = next;
    if (out.converged) break;
  }
  out.rays = rays;
  return out;
}

GroundTruthDepthSolver::Sample GroundTruthDepthSolver::Probe(double s, double t) noexcept {
  Sample out;
  out.hit_b = ProbeEnvironment(s, t, out.b);
  if (out.hit_b) out.hit_a = ProbeTool(s, t, out.a);
  return out;
}

GroundTruthDepth GroundTruthDepthSolver::DepthAt(const RigidTransform& X_WFt,
                                                 const RigidTransform& X_WFe,
                                                 const ContactWindow& w, int m) {
  constexpr double kNone = -std::numeric_limits<double>::infinity();
  m = std::clamp(m, 2, 8192);
  const long long rays_before = rays_;
  SetPoses(X_WFt, X_WFe, w);
  const double half = 0.5 * w.extent_m;
  const double cell = w.extent_m / m;
  const auto coord = [&](int i) { return ((i + 0.5) / m - 0.5) * w.extent_m; };

  // The environment's heights on this grid, reused while neither the window nor its pose changes.
  const EnvKey key{m, c_e_, u_e_, v_e_, w.extent_m};
  if (!(key == env_key_) || env_b_.size() != static_cast<std::size_t>(m) * m) {
    env_b_.assign(static_cast<std::size_t>(m) * m, 0.0);
    env_hit_.assign(static_cast<std::size_t>(m) * m, 0);
    for (int j = 0; j < m; ++j) {
      for (int i = 0; i < m; ++i) {
        double b = 0.0;
        env_hit_[j * m + i] = ProbeEnvironment(coord(i), coord(j), b) ? 1 : 0;
        env_b_[j * m + i] = b;
      }
    }
    env_key_ = key;
  }

  // Grid pass: δ per cell, and the best cells as seeds for the refinement.
  struct Seed {
    double d;
    double s, t;
  };
  std::vector<Seed> seeds;
  const int k = options_.refine_seeds;
  seeds.reserve(static_cast<std::size_t>(k) + 1);
  GroundTruthDepth out;
  out.depth_m = kNone;
  out.samples_per_side = m;
  for (int j = 0; j < m; ++j) {
    for (int i = 0; i < m; ++i) {
      if (!env_hit_[j * m + i]) continue;
      double a = 0.0;
      if (!ProbeTool(coord(i), coord(j), a)) continue;
      const double d = env_b_[j * m + i] - a;
      if (d > out.depth_m) {
        out.depth_m = d;
        out.at_uv_m = {coord(i), coord(j)};
      }
      if (k > 0 && (static_cast<int>(seeds.size()) < k || d > seeds.back().d)) {
        Seed sd{d, coord(i), coord(j)};
        auto it = std::upper_bound(seeds.begin(), seeds.end(), sd,
                                   [](const Seed& x, const Seed& y) { return x.d > y.d; });
        seeds.insert(it, sd);
        if (static_cast<int>(seeds.size()) > k) seeds.pop_back();
      }
    }
  }

  // Local refinement: compass search from each seed, halving the step down to refine_step_m.
  const auto eval = [&](double s, double t) {
    if (std::abs(s) > half || std::abs(t) > half) return kNone;
    const Sample p = Probe(s, t);
    return p.hit_a && p.hit_b ? p.b - p.a : kNone;
  };
  for (const Seed& seed : seeds) {
    double s = seed.s, t = seed.t, best = seed.d, h = 0.5 * cell;
    for (int iter = 0; iter < 400 && h >= options_.refine_step_m; ++iter) {
      static constexpr std::array<std::array<int, 2>, 8> kDirs{
          {{1, 0}, {-1, 0}, {0, 1}, {0, -1}, {1, 1}, {1, -1}, {-1, 1}, {-1, -1}}};
      bool moved = false;
      for (const auto& d : kDirs) {
        const double ns = s + d[0] * h, nt = t + d[1] * h;
        const double v = eval(ns, nt);
        if (v > best) {
          best = v;
          s = ns;
          t = nt;
          moved = true;
        }
      }
      if (!moved) h *= 0.5;
    }
    if (best > out.depth_m) {
      out.depth_m = best;
      out.at_uv_m = {s, t};
    }
  }
  out.rays = rays_ - rays_before;
  return out;
}

GroundTruthDepth GroundTruthDepthSolver::ConvergedDepth(const RigidTransform& X_WFt,
                                                        const RigidTransform& X_WFe,
                                                        const ContactWindow& w) {
  int m = options_.initial_samples;
  GroundTruthDepth prev = DepthAt(X_WFt, X_WFe, w, m);
  long long rays = prev.rays;
  while (true) {
    const int next = std::min(2 * m, options_.max_samples);
    if (next == m) {  // no finer grid allowed: not converged (unless nothing overlaps)
      prev.converged = std::isinf(prev.depth_m) && prev.depth_m < 0.0;
      prev.rays = rays;
      return prev;
    }
    m = next;
    GroundTruthDepth cur = DepthAt(X_WFt, X_WFe, w, m);
    rays += cur.rays;
    const bool both_empty = std::isinf(cur.depth_m) && std::isinf(prev.depth_m);
    cur.change_m = both_empty ? 0.0 : std::abs(cur.depth_m - prev.depth_m);
    if (std::isnan(cur.change_m)) cur.change_m = std::numeric_limits<double>::infinity();
    if (both_empty || cur.change_m < options_.tolerance_m) {
      cur.converged = true;
      cur.rays = rays;
      return cur;
    }
    prev = cur;
  }
}

GroundTruthContact GroundTruthDepthSolver::Linearize(const RigidTransform& X_WT,
                                                     const RigidTransform& X_TFt,
                                                     const RigidTransform& X_WFe,
                                                     const ContactWindow& window,
                                                     double stiffness_n_per_m, int step_resolution,
                                                     double tilt_step_rad) {
  ContactWindow w = window;
  // The seed's grid fixes the step table for every method compared, unless the caller sets it.
  w.resolution = step_resolution > 0 ? step_resolution : 50;
  const GradientSteps table = GradientSteps::For(w);
  const double h_tilt = tilt_step_rad > 0.0 ? tilt_step_rad : table.h_theta;
  // The tilts (samples 5-8) at h_tilt, the yaw (9, 10) at the table's h_θ.
  std::array<RigidTransform, kGradientSamples> poses =
      GradientSamplePoses(X_WT, w, {table.h_x, h_tilt});
  const std::array<RigidTransform, kGradientSamples> table_poses = GradientSamplePoses(X_WT, w);
  poses[9] = table_poses[9];
  poses[10] = table_poses[10];
  GroundTruthContact out;
  out.base = ConvergedDepth(poses[0] * X_TFt, X_WFe, w);
  long long rays = out.base.rays;
  std::array<DepthSample, kGradientSamples> samples;
  samples[0] = {out.base.depth_m, std::isfinite(out.base.depth_m) ? 0 : -1};
  for (int i = 1; i < kGradientSamples; ++i) {
    const GroundTruthDepth d = DepthAt(poses[i] * X_TFt, X_WFe, w, out.base.samples_per_side);
    rays += d.rays;
    samples[i] = {d.depth_m, std::isfinite(d.depth_m) ? 0 : -1};
  }
  LinearizationFaults faults;
  out.linearization = AssembleLinearization(w, samples, table.h_x, h_tilt, table.h_theta,
                                            stiffness_n_per_m, faults);
  out.linearization.point_W =
      w.center_W + out.base.at_uv_m.x * w.axis_u_W + out.base.at_uv_m.y * w.axis_v_W;
  out.F_T_W =
      PenaltyWrench(out.linearization.depth_m, out.linearization.gradient, stiffness_n_per_m);
  out.rays = rays;
  return out;
}

}  // namespace ht
