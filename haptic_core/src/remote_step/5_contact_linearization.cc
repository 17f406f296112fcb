#include <oneapi/tbb/parallel_for.h>
#include <oneapi/tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "haptic_core/contact_linearization.h"

namespace ht {

int AddKinkPlanes(const ContactWindow& w, std::span<const DepthSample> samples,
                  const glm::dvec3& p_WT, ContactLinearization& lin, bool own_slope,
                  bool hang_other_arm) noexcept {
  lin.num_kink_planes = std::clamp(lin.num_kink_planes, 0, kMaxKinkPlanes);
  if (samples.size() < static_cast<std::size_t>(kGradientSamples) || !std::isfinite(lin.depth_m) ||
      samples[0].cell < 0) {
    return lin.num_kink_planes;
  }
  const double h = GradientSteps::For(w).h_theta;
  const glm::dvec3& J_x = lin.gradient.d_translation_W;
  // The slope about axis a of the depth of cell c: its lever r_c × ∂δ/∂x along a.
  const auto slope = [&](int cell, const glm::dvec3& a) {
    return glm::dot(glm::cross(w.CellCenter(cell) - p_WT, J_x), a);
  };
  const glm::dvec3 axes[2] = {w.axis_u_W, w.axis_v_W};
  bool kinked[2] = {false, false};
  double arm_slope[2][2] = {{0.0, 0.0}, {0.0, 0.0}};  // [axis][plus, minus]
  for (int a = 0; a < 2; ++a) {
    // Samples 5, 6: ±h_θ about u; 7, 8: about v (GradientSamplePoses).
    const DepthSample& plus = samples[static_cast<std::size_t>(5 + 2 * a)];
    const DepthSample& minus = samples[static_cast<std::size_t>(6 + 2 * a)];
    if (plus.cell < 0 || minus.cell < 0 || plus.cell == minus.cell) continue;
    arm_slope[a][0] = slope(plus.cell, axes[a]);
    arm_slope[a][1] = slope(minus.cell, axes[a]);
    // A V: tilted either way, the deepest cell is one that rises with that tilt (a resting face
    // whose two edges bear in turn). Elsewhere the secant of the samples stays.
    kinked[a] = arm_slope[a][0] > 0.0 && arm_slope[a][1] < 0.0;
  }
  // At q0 the deepest cell's own slope is the gradient along a kinked axis: the secant across the
  // V's vertex reads the two arms' mean. Only where the deepest cell bears like one of the arms
  // (its slope within 10 % of that arm's: a sharp V, tilted by h_θ the face still bears on the
  // same edge); on a rounded contact the deepest cell moves with any tilt, and its single cell's
  // slope is the noisier estimate. bearing[a]: the arm it bears like (0: plus, 1: minus), or −1.
  glm::dvec3 d_rotation = lin.gradient.d_rotation_W;
  int bearing[2] = {-1, -1};
  for (int a = 0; a < 2 && own_slope; ++a) {
    if (!kinked[a]) continue;
    const double s0 = slope(samples[0].cell, axes[a]);
    if (!std::isfinite(s0)) continue;
    const double off_plus = std::abs(s0 - arm_slope[a][0]) / std::abs(arm_slope[a][0]);
    const double off_minus = std::abs(s0 - arm_slope[a][1]) / std::abs(arm_slope[a][1]);
    if (!(std::min(off_plus, off_minus) <= 0.1)) continue;
    bearing[a] = off_plus <= off_minus ? 0 : 1;
    d_rotation += (s0 - glm::dot(d_rotation, axes[a])) * axes[a];
  }
  // The planes already held (translation arms) share the contact's rotation slope.
  for (int m = 0; m < lin.num_kink_planes; ++m) {
    lin.kink_planes[static_cast<std::size_t>(m)].d_rotation_W +=
        d_rotation - lin.gradient.d_rotation_W;
  }
  lin.gradient.d_rotation_W = d_rotation;
  for (int a = 0; a < 2; ++a) {
    if (!kinked[a]) continue;
    // Each arm at q0: A± = δ(±h_θ) ∓ h_θ·s±, its plane through its sample (m).
    const double arm_at_q0[2] = {
        samples[static_cast<std::size_t>(5 + 2 * a)].depth_m - h * arm_slope[a][0],
        samples[static_cast<std::size_t>(6 + 2 * a)].depth_m + h * arm_slope[a][1]};
    for (int side = 0; side < 2 && lin.num_kink_planes < kMaxKinkPlanes; ++side) {
      KinkPlane p;
      p.d_rotation_W = d_rotation + (arm_slope[a][side] - glm::dot(d_rotation, axes[a])) * axes[a];
      if (hang_other_arm && bearing[a] >= 0) {
        if (side == bearing[a]) continue;  // the contact's own plane
        // The other arm below δ0 by the arms' gap at q0 (none where it reads deeper: a tie): the
        // V's shape from its two samples, hung from δ0, so that the arms tie where the samples'
        // arms cross. Each A alone is off by its lever's error times h_θ.
        p.depth_m = lin.depth_m - std::max(arm_at_q0[bearing[a]] - arm_at_q0[side], 0.0);
      } else {
        // The contact's own plane already.
        if (samples[static_cast<std::size_t>(5 + 2 * a + side)].cell == samples[0].cell) continue;
        // Through the sample: δ_m(q0 ⊕ ±h_θ·a) = δ(±h_θ); never above δ0 at q0.
        p.depth_m = std::min(arm_at_q0[side], lin.depth_m);
      }
      if (!std::isfinite(p.depth_m) || !std::isfinite(p.d_rotation_W.x) ||
          !std::isfinite(p.d_rotation_W.y) || !std::isfinite(p.d_rotation_W.z)) {
        continue;
      }
      lin.kink_planes[static_cast<std::size_t>(lin.num_kink_planes++)] = p;
    }
  }
  return lin.num_kink_planes;
}

const char* ToString(RotationGradient r) noexcept {
  switch (r) {
    case RotationGradient::kRenderedSamples:
      return "rendered";
    case RotationGradient::kContactLever:
      return "lever";
    case RotationGradient::kWarpedBaseRender:
      return "warp";
  }
  return "?";
}

RotationGradient ParseRotationGradient(const std::string& text) {
  for (const RotationGradient r :
       {RotationGradient::kRenderedSamples, RotationGradient::kContactLever,
        RotationGradient::kWarpedBaseRender}) {
    if (text == ToString(r)) return r;
  }
  throw std::invalid_argument("rotation gradient must be rendered, lever or warp, got '" + text +
                              "'");
}

void WarpedRotationSamples(std::span<const float> env, std::span<const float> tool_ext,
                           const ContactWindow& w, const glm::dvec3& p_WTcm,
                           std::span<DepthSample> out) noexcept {
  for (DepthSample& s : out) s = {-std::numeric_limits<double>::infinity(), -1};
  const int n = w.resolution, nt = n + 2;
  if (n <= 0 || out.size() < 6 || env.size() < static_cast<size_t>(n) * n ||
      tool_ext.size() < static_cast<size_t>(nt) * nt) {
    return;
  }
  const double cell = w.cell_size_m(), h = GradientSteps::For(w).h_theta;
  const double inv_2cell = 0.5 / cell, inv_cell = 1.0 / cell;
  // The window centre less the centre of mass, in the window's frame (u, v, n).
  const glm::dvec3 c = w.center_W - p_WTcm;
  const double cu = glm::dot(c, w.axis_u_W), cv = glm::dot(c, w.axis_v_W),
               cn = glm::dot(c, w.normal_W);
  // The tool's slope along one axis at a cell from its two neighbours (one-sided where one is
  // off the tool's patch, 0 where both are).
  const auto slope = [&](float lo, float mid, float hi) {
    const bool fl = std::isfinite(lo), fh = std::isfinite(hi);
    if (fl && fh) return (static_cast<double>(hi) - lo) * inv_2cell;
    if (fh) return (static_cast<double>(hi) - mid) * inv_cell;
    if (fl) return (static_cast<double>(mid) - lo) * inv_cell;
    return 0.0;
  };
  double best[6];
  int best_cell[6];
  for (int k = 0; k < 6; ++k) {
    best[k] = -std::numeric_limits<double>::infinity();
    best_cell[k] = -1;
  }
  for (int j = 0; j < n; ++j) {
    const float* row = &tool_ext[static_cast<size_t>(j + 1) * nt + 1];
    const float* below = row - nt;
    const float* above = row + nt;
    const float* env_row = &env[static_cast<size_t>(j) * n];
    const double r_v = cv + ((j + 0.5) / n - 0.5) * w.extent_m;
    for (int i = 0; i < n; ++i) {
      const float t = row[i], e = env_row[i];
      if (!(std::isfinite(t) && std::isfinite(e))) continue;
      const double delta = static_cast<double>(e - t);
      const double g_u = slope(row[i - 1], t, row[i + 1]);
      const double g_v = slope(below[i], t, above[i]);
      const double r_u = cu + ((i + 0.5) / n - 0.5) * w.extent_m;
      const double r_n = cn + t;
      // ∂t/∂θ about u, v, n: r × (n − ∇t) in the window's frame, ∇t = (g_u, g_v, 0).
      const double b[3] = {r_v + r_n * g_v, -r_n * g_u - r_u, r_v * g_u - r_u * g_v};
      const int cell_index = j * n + i;
      for (int k = 0; k < 3; ++k) {
        const double plus = delta - h * b[k], minus = delta + h * b[k];
        if (plus > best[2 * k]) {
          best[2 * k] = plus;
          best_cell[2 * k] = cell_index;
        }
        if (minus > best[2 * k + 1]) {
          best[2 * k + 1] = minus;
          best_cell[2 * k + 1] = cell_index;
        }
      }
    }
  }
  for (int k = 0; k < 6; ++k) {
    if (best_cell[k] >= 0) out[static_cast<size_t>(k)] = {best[k], best_cell[k]};
  }
}

TexturePenetrationSolver::TexturePenetrationSolver(int max_resolution, int max_triangles,
                                                   TextureStagePath path)
    : path_(path), links_(max_resolution) {
  const size_t cells = static_cast<size_t>(max_resolution) * max_resolution;
  env_heights_.reserve(cells);
  tool_heights_.reserve(cells);
  tool_ext_heights_.reserve(static_cast<size_t>(max_resolution + 2) * (max_resolution + 2));
  max_resolution_ = max_resolution;
  env_triangles_.reserve(static_cast<size_t>(max_triangles));
  tool_triangles_.reserve(static_cast<size_t>(max_triangles));
  vertex_scratch_.reserve(static_cast<size_t>(max_triangles));  // a closed mesh: V ≈ F/2
  first_triangles_.reserve(64);
  env_max_.Reserve(max_resolution);
  env_row_max_.Reserve(max_resolution);
  tool_bounds_.Reserve(static_cast<size_t>(max_triangles));
  region_parent_.reserve(cells);
  overlap_depth_.reserve(cells);
  bridge_level_.reserve(cells);
}

void TexturePenetrationSolver::RenderEnvironment(const HapticModel& environment,
                                                 const RigidTransform& X_WO, const ContactWindow& w,
                                                 TriangleSubset subset) noexcept {
  const size_t cells = static_cast<size_t>(w.resolution) * w.resolution;
  env_heights_.assign(cells, -std::numeric_limits<float>::infinity());
  SelectPatchTrianglesIn(subset, environment, X_WO, w, PatchSide::kEnvironment, w.cell_size_m(),
                         env_triangles_, 0.0, &vertex_scratch_, nullptr);
  if (path_ == TextureStagePath::kFast) {
    RenderPatchHeightsFast(environment, X_WO, env_triangles_, w, PatchSide::kEnvironment, 0,
                           env_heights_);
  } else {
    RenderPatchHeights(environment, X_WO, env_triangles_, w, PatchSide::kEnvironment, env_heights_);
  }
}

DepthSample TexturePenetrationSolver::EvaluateTool(const HapticModel& tool,
                                                   const RigidTransform& X_WT,
                                                   const ContactWindow& w) noexcept {
  const size_t cells = static_cast<size_t>(w.resolution) * w.resolution;
  tool_heights_.assign(cells, std::numeric_limits<float>::infinity());
  if (path_ == TextureStagePath::kFast) {
    RenderPatchHeightsFast(tool, X_WT, tool_triangles_, w, PatchSide::kTool, 0, tool_heights_);
  } else {
    RenderPatchHeights(tool, X_WT, tool_triangles_, w, PatchSide::kTool, tool_heights_);
  }
  return DirectionalPenetrationDepth(env_heights_, tool_heights_);
}

DepthSample TexturePenetrationSolver::Depth(const HapticModel& tool, const RigidTransform& X_WT,
                                            const HapticModel& environment,
                                            const RigidTransform& X_WO, const ContactWindow& w,
                                            TriangleSubset environment_triangles,
                                            TriangleSubset tool_triangles) noexcept {
  RenderEnvironment(environment, X_WO, w, environment_triangles);
  SelectPatchTrianglesIn(tool_triangles, tool, X_WT, w, PatchSide::kTool, w.cell_size_m(),
                         tool_triangles_, 0.0, &vertex_scratch_, nullptr);
  return EvaluateTool(tool, X_WT, w);
}

int TexturePenetrationSolver::OverlapRegions(const HapticModel& tool, const RigidTransform& X_WT,
                                             const HapticModel& environment,
                                             const RigidTransform& X_WO, const ContactWindow& w,
                                             double link_m, std::span<OverlapRegion> out,
                                             TriangleSubset environment_triangles,
                                             TriangleSubset tool_triangles,
                                             double bridge_floor_m) noexcept {
  const int n = w.resolution;
  const auto cells = static_cast<std::size_t>(n) * static_cast<std::size_t>(n);
  if (n > max_resolution_ || !(link_m >= 0.0)) return 0;
  Depth(tool, X_WT, environment, X_WO, w, environment_triangles, tool_triangles);
  overlap_depth_.resize(cells);
  for (std::size_t c = 0; c < cells; ++c) overlap_depth_[c] = env_heights_[c] - tool_heights_[c];
  return OverlapRegions(overlap_depth_, w, link_m, out, bridge_floor_m);
}

int TexturePenetrationSolver::OverlapRegions(std::span<const float> overlap, const ContactWindow& w,
                                             double link_m, std::span<OverlapRegion> out,
                                             double bridge_floor_m) noexcept {
  const int n = w.resolution;
  const auto cells = static_cast<std::size_t>(n) * static_cast<std::size_t>(n);
  if (n > max_resolution_ || !(link_m >= 0.0) || overlap.size() < cells) return 0;
  overlap = overlap.first(cells);
  // Single linkage over the overlapping cells (overlap_links.h): region_parent_[c] is the first
  // cell of c's region, −1 where b − a ≤ 0.
  region_parent_.resize(cells);
  const double reach = link_m / w.cell_size_m();
  if (links_.Components(overlap, n, reach, region_parent_) < 0) return 0;
  // Regions in order of their roots (the first cell of each), then the kept ones sorted deepest
  // first.
  int count = 0;
  const auto keep = out.size();
  for (std::size_t k = 0; k < keep; ++k) out[k] = OverlapRegion{};
  // A root's slot is found by a scan of the roots met so far (few regions; at most 64 counted).
  std::array<int, 64> roots{};
  for (std::size_t c = 0; c < cells; ++c) {
    if (region_parent_[c] < 0) continue;
    const int root = region_parent_[c];
    int slot = -1;
    for (int k = 0; k < count; ++k) {
      if (roots[static_cast<std::size_t>(k)] == root) slot = k;
    }
    if (slot < 0) {
      if (count == static_cast<int>(roots.size())) continue;  // past 64: not counted further
      roots[static_cast<std::size_t>(count)] = root;
      slot = count++;
    }
    const int i = static_cast<int>(c % static_cast<std::size_t>(n));
    const int j = static_cast<int>(c / static_cast<std::size_t>(n));
    const double depth = overlap[c];
    // Collected in slot order into `out` while it has room; the rest are only counted.
    if (static_cast<std::size_t>(slot) >= keep) continue;
    OverlapRegion& g = out[static_cast<std::size_t>(slot)];
    if (g.cells == 0) {
      g = {i, i, j, j, 0, depth, static_cast<int>(c)};
    }
    g.i0 = std::min(g.i0, i);
    g.i1 = std::max(g.i1, i);
    g.j0 = std::min(g.j0, j);
    g.j1 = std::max(g.j1, j);
    g.cells += 1;
    if (depth > g.depth_m) {
      g.depth_m = depth;
      g.peak_cell = static_cast<int>(c);
    }
  }
  const auto kept = std::min<std::size_t>(keep, static_cast<std::size_t>(count));
  if (bridge_floor_m > 0.0 && count >= 2) {
    bridge_level_.resize(cells);
    // Only the kept regions' peaks are read: the pass stops once each has its level.
    std::array<int, 64> peaks{};
    for (std::size_t k = 0; k < kept; ++k) peaks[k] = out[k].peak_cell;
    links_.BridgeLevels(overlap, n, reach, static_cast<float>(-bridge_floor_m), bridge_level_,
                        std::span<const int>(peaks.data(), kept));
    for (std::size_t k = 0; k < kept; ++k) {
      OverlapRegion& g = out[k];
      const float level = bridge_level_[static_cast<std::size_t>(g.peak_cell)];
      g.bridge_m = std::isfinite(level) ? static_cast<double>(level)
                                        : -std::numeric_limits<double>::infinity();
    }
  }
  std::sort(out.begin(), out.begin() + static_cast<std::ptrdiff_t>(kept),
            [](const OverlapRegion& a, const OverlapRegion& b) { return a.depth_m > b.depth_m; });
  return count;
}

int TexturePenetrationSolver::OverlapOccupancy(const HapticModel& tool, const RigidTransform& X_WT,
                                               const HapticModel& environment,
                                               const RigidTransform& X_WO, const ContactWindow& w,
                                               int block_cells, std::span<std::uint8_t> occupancy,
                                               TriangleSubset environment_triangles,
                                               TriangleSubset tool_triangles) noexcept {
  const int n = w.resolution;
  if (block_cells < 1 || n > max_resolution_) return -1;
  const int nb = (n + block_cells - 1) / block_cells;
  if (occupancy.size() < static_cast<std::size_t>(nb) * static_cast<std::size_t>(nb)) return -1;
  Depth(tool, X_WT, environment, X_WO, w, environment_triangles, tool_triangles);
  const auto cells = static_cast<std::size_t>(n) * static_cast<std::size_t>(n);
  overlap_depth_.resize(cells);
  for (std::size_t c = 0; c < cells; ++c) overlap_depth_[c] = env_heights_[c] - tool_heights_[c];
  return OverlapOccupancy(overlap_depth_, w, block_cells, occupancy);
}

int TexturePenetrationSolver::OverlapOccupancy(std::span<const float> overlap,
                                               const ContactWindow& w, int block_cells,
                                               std::span<std::uint8_t> occupancy) const noexcept {
  const int n = w.resolution;
  if (block_cells < 1 || n > max_resolution_) return -1;
  const int nb = (n + block_cells - 1) / block_cells;
  const auto blocks = static_cast<std::size_t>(nb) * static_cast<std::size_t>(nb);
  if (occupancy.size() < blocks ||
      overlap.size() < static_cast<std::size_t>(n) * static_cast<std::size_t>(n)) {
    return -1;
  }
  std::fill_n(occupancy.begin(), blocks, std::uint8_t{0});
  int occupied = 0;
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      const auto c =
          static_cast<std::size_t>(j) * static_cast<std::size_t>(n) + static_cast<std::size_t>(i);
      if (!(overlap[c] > 0.0f)) continue;
      std::uint8_t& b = occupancy[static_cast<std::size_t>(j / block_cells) * nb +
                                  static_cast<std::size_t>(i / block_cells)];
      occupied += b == 0 ? 1 : 0;
      b = 1;
    }
  }
  return occupied;
}

std::array<RigidTransform, kGradientSamples> GradientSamplePoses(const RigidTransform& X_WT,
                                                                 const ContactWindow& w) noexcept {
  return GradientSamplePoses(X_WT, w, GradientSteps::For(w));
}

std::array<RigidTransform, kGradientSamples> GradientSamplePoses(const RigidTransform& X_WT,
                                                                 const ContactWindow& w,
                                                                 const GradientSteps& h) noexcept {
  const glm::dvec3 u = w.axis_u_W, v = w.axis_v_W, n = w.normal_W, zero(0.0);
  const Twist steps[5] = {{h.h_x * u, zero},
                          {h.h_x * v, zero},
                          {zero, h.h_theta * u},
                          {zero, h.h_theta * v},
                          {zero, h.h_theta * n}};
  std::array<RigidTransform, kGradientSamples> poses;
  poses[0] = X_WT;
  for (int i = 0; i < 5; ++i) {
    poses[1 + 2 * i] = Displace(X_WT, steps[i]);
    poses[2 + 2 * i] = Displace(X_WT, {-steps[i].linear, -steps[i].angular});
  }
  return poses;
}

namespace {

// The central difference of samples 1 + 2i and 2 + 2i (one-sided, and counted in `faults`, where
// one of them has no overlap), and ∂δ/∂x from the first two: what the rendered and the lever
// linearizations share.
struct Differences {
  const ContactWindow& w;
  std::span<const DepthSample> samples;
  LinearizationFaults& faults;
  double Central(int i, double step) const noexcept {
    const DepthSample& base = samples[0];
    const DepthSample& plus = samples[1 + 2 * i];
    const DepthSample& minus = samples[2 + 2 * i];
    if (plus.cell >= 0 && minus.cell >= 0) return (plus.depth_m - minus.depth_m) / (2.0 * step);
    ++faults.missing_overlap;
    if (plus.cell >= 0) return (plus.depth_m - base.depth_m) / step;
    if (minus.cell >= 0) return (base.depth_m - minus.depth_m) / step;
    return 0.0;
  }
  // ∂δ/∂x: central differences along u and v; moving the tool along +n lifts every tool height
  // by the same amount, so ∂δ/∂x_n = −1 exactly.
  glm::dvec3 Translation(double h_x) const noexcept {
    return Central(0, h_x) * w.axis_u_W + Central(1, h_x) * w.axis_v_W - w.normal_W;
  }
};

// δ0, the point and the normal of a linearization from the base sample; false (depth_m = −∞ or
// the base's depth, no gradient) when `samples` is shorter than `needed` or the base has no
// overlap.
bool StartLinearization(const ContactWindow& w, std::span<const DepthSample> samples,
                        std::size_t needed, double stiffness_n_per_m,
                        ContactLinearization& out) noexcept {
  out.stiffness_n_per_m = stiffness_n_per_m;
  out.normal_W = w.normal_W;
  out.point_W = w.center_W;
  out.depth_m = -std::numeric_limits<double>::infinity();
  if (samples.size() < needed) return false;
  out.depth_m = samples[0].depth_m;
  if (samples[0].cell < 0) return false;
  out.point_W = w.CellCenter(samples[0].cell);
  return true;
}

}  // namespace

ContactLinearization AssembleLinearization(const ContactWindow& w,
                                           std::span<const DepthSample> samples,
                                           double stiffness_n_per_m,
                                           LinearizationFaults& faults) noexcept {
  const GradientSteps h = GradientSteps::For(w);
  return AssembleLinearization(w, samples, h.h_x, h.h_theta, h.h_theta, stiffness_n_per_m, faults);
}

ContactLinearization AssembleLinearization(const ContactWindow& w,
                                           std::span<const DepthSample> samples, double h_x,
                                           double h_tilt, double h_yaw, double stiffness_n_per_m,
                                           LinearizationFaults& faults) noexcept {
  ContactLinearization out;
  if (!StartLinearization(w, samples, kGradientSamples, stiffness_n_per_m, out)) return out;
  const Differences d{w, samples, faults};
  out.gradient.d_translation_W = d.Translation(h_x);
  out.gradient.d_rotation_W = d.Central(2, h_tilt) * w.axis_u_W +
                              d.Central(3, h_tilt) * w.axis_v_W + d.Central(4, h_yaw) * w.normal_W;
  return out;
}

ContactLinearization AssembleLeverLinearization(const ContactWindow& w,
                                                std::span<const DepthSample> samples,
                                                const glm::dvec3& r_W, double stiffness_n_per_m,
                                                LinearizationFaults& faults) noexcept {
  ContactLinearization out;
  if (!StartLinearization(w, samples, 5, stiffness_n_per_m, out)) return out;
  const Differences d{w, samples, faults};
  out.gradient.d_translation_W = d.Translation(GradientSteps::For(w).h_x);
  // The tool point p moves by Δx + Δθ × r: δ changes by ∂δ/∂x·(Δθ × r) = (r × ∂δ/∂x)·Δθ.
  out.gradient.d_rotation_W = glm::cross(r_W, out.gradient.d_translation_W);
  return out;
}

ContactLinearization TexturePenetrationSolver::Linearize(
    const HapticModel& tool, const RigidTransform& X_WT, const HapticModel& environment,
    const RigidTransform& X_WO, const ContactWindow& w, double stiffness_n_per_m,
    std::span<DepthSample> samples_out, TriangleSubset environment_triangles,
    TriangleSubset tool_triangles, std::span<float> base_overlap_out) noexcept {
  const GradientSteps h = GradientSteps::For(w);
  // The base pose's b − a (base_overlap_out), from the tool heights `t` (stride, border cells).
  const auto keep_base_overlap = [&](const std::vector<float>& t, int stride, int border) {
    const int n = w.resolution;
    if (base_overlap_out.size() < static_cast<std::size_t>(n) * n) return;
    for (int j = 0; j < n; ++j) {
      const float* a = t.data() + static_cast<std::size_t>(j + border) * stride + border;
      const float* b = env_heights_.data() + static_cast<std::size_t>(j) * n;
      float* o = base_overlap_out.data() + static_cast<std::size_t>(j) * n;
      for (int i = 0; i < n; ++i) o[i] = b[i] - a[i];
    }
  };

  const bool from_base = rotation_gradient_ != RotationGradient::kRenderedSamples;
  RenderEnvironment(environment, X_WO, w, environment_triangles);
  // Tool triangles are chosen once, with margins that cover every perturbed pose (the render
  // re-checks facing at each pose); without rendered rotations only the base pose is drawn, on
  // the window grown by a cell.
  SelectPatchTrianglesIn(tool_triangles, tool, X_WT, w, PatchSide::kTool, 2.0 * h.h_x,
                         tool_triangles_, from_base ? 1e-9 : h.h_theta + 1e-9, &vertex_scratch_,
                         nullptr, from_base ? 0.0 : h.h_theta);
  std::array<DepthSample, kGradientSamples> samples;
  for (DepthSample& s : samples) s = {-std::numeric_limits<double>::infinity(), -1};
  glm::dvec3 lever_W(0.0);  // RotationGradient::kContactLever
  if (from_base) {
    // The base pose on the window grown by one cell; the rotations come from it.
    const int n = w.resolution, nt = n + 2;
    if (path_ == TextureStagePath::kFast) {
      RenderGrownBase(tool, X_WT, w, samples);
      if (samples[0].cell >= 0) keep_base_overlap(tool_ext_heights_, nt, 1);
    } else {
      // The reference: the grown window (the same centre, axes and cell centres, one more cell
      // on each side, and the window's own box along n) and the translations at their poses.
      tool_ext_heights_.assign(static_cast<size_t>(nt) * nt,
                               std::numeric_limits<float>::infinity());
      ContactWindow grown = w;
      grown.resolution = nt;
      grown.extent_m = w.extent_m * nt / n;
      RenderPatchHeights(tool, X_WT, tool_triangles_, grown, PatchSide::kTool, tool_ext_heights_,
                         w.depth_range_m());
      samples[0] = EvaluateTool(tool, X_WT, w);
      if (samples[0].cell >= 0) {
        keep_base_overlap(tool_heights_, n, 0);
        const auto poses = GradientSamplePoses(X_WT, w);
        for (int i = 1; i < 5; ++i) samples[i] = EvaluateTool(tool, poses[i], w);
      }
    }
    if (samples[0].cell >= 0) {
      if (rotation_gradient_ == RotationGradient::kWarpedBaseRender) {
        WarpedRotationSamples(env_heights_, tool_ext_heights_, w, X_WT.translation,
                              std::span<DepthSample>(samples).subspan(5));
      } else {
        // The deepest cell's tool point (its height along n from the window plane) less the
        // centre of mass.
        const int i = samples[0].cell % n, j = samples[0].cell / n;
        const double t = tool_ext_heights_[static_cast<size_t>(j + 1) * nt + (i + 1)];
        lever_W = w.CellCenter(samples[0].cell) + t * w.normal_W - X_WT.translation;
      }
    }
  } else if (path_ == TextureStagePath::kFast) {
    // The base pose on the window grown by one cell gives the four translations (RenderGrownBase);
    // the six rotations are rendered.
    const size_t cells = static_cast<size_t>(w.resolution) * w.resolution;
    const auto poses = GradientSamplePoses(X_WT, w);
    bool done = false;
    if (parallel_renders_) {
      // The seven renders at once, each into its own buffer. The rotations start with the base
      // (measured faster on two threads than the base first: 211 against 259 µs on fig75), so
      // when the base finds no overlap they are computed and discarded below, renders the
      // serial path never makes.
      try {
        // Isolated: while this thread waits for the seven, it must not pick up another contact
        // of the batch, which would run on this same solver (one solver per thread).
        oneapi::tbb::this_task_arena::isolate([&] {
          oneapi::tbb::parallel_for(0, 7, [&](int task) {
            if (task == 0) {
              RenderGrownBase(tool, X_WT, w, samples);
              return;
            }
            std::vector<float>& heights = rotation_heights_[static_cast<size_t>(task - 1)];
            const RigidTransform& pose = poses[static_cast<size_t>(task + 4)];
            if (cull_rotations_ == CullRotations::kAlways) {
              // No first cell: the base is rendered at the same time.
              heights.resize(cells);
              ToolDepthCull hints;
              samples[static_cast<size_t>(task + 4)] =
                  RenderToolDepth(tool, pose, tool_triangles_, w, env_heights_, heights, hints);
              return;
            }
            heights.assign(cells, std::numeric_limits<float>::infinity());
            RenderPatchHeightsFast(tool, pose, tool_triangles_, w, PatchSide::kTool, 0, heights);
            samples[static_cast<size_t>(task + 4)] =
                DirectionalPenetrationDepth(env_heights_, heights);
          });
        });
        done = true;
      } catch (...) {
        done = false;  // could not spawn the tasks: the serial path below
      }
    }
    if (!done) {
      RenderGrownBase(tool, X_WT, w, samples);
      if (samples[0].cell >= 0) {
        // Each rotation's depth alone, its render culled to the cells that can matter
        // (RenderToolDepth), from the cells around the unrotated pose's deepest cell; under
        // kWhenItPays, only while the first rotation drew few enough cells for it to pay.
        tool_heights_.resize(cells);
        bool cull = cull_rotations_ != CullRotations::kNever;
        // The environment's max pyramid skips whole tool triangles; building it (about a
        // microsecond) pays where the tool brings many (fig77's file: 131-142 against 146-151 µs
        // per contact), not for a few large ones (the block on the gear).
        const bool pyramid = cull && tool_triangles_.size() > kPyramidTriangles;
        if (pyramid) env_max_.Build(env_heights_, w.resolution);
        if (cull) env_row_max_.Build(env_heights_, w.resolution);
        tool_bounds_.Reset(tool, w.cell_size_m());
        for (int i = 5; i < kGradientSamples; ++i) {
          if (!cull) {
            samples[i] = EvaluateTool(tool, poses[i], w);
            continue;
          }
          // The first rotation's first pass finds the triangles around the deepest cell; the
          // other five start from those.
          ToolDepthCull hints;
          hints.first_cell = samples[0].cell;
          hints.env_max = pyramid ? &env_max_ : nullptr;
          hints.env_row_max = &env_row_max_;
          hints.bounds = &tool_bounds_;
          if (i == 5) {
            hints.first_triangles_out = &first_triangles_;
          } else {
            hints.first_triangles = first_triangles_;
          }
          samples[i] = RenderToolDepth(tool, poses[i], tool_triangles_, w, env_heights_,
                                       tool_heights_, hints);
          if (i == 5 && cull_rotations_ == CullRotations::kWhenItPays &&
              hints.cells_drawn > kCullPaysFraction * static_cast<double>(cells)) {
            cull = false;
          }
        }
        if (cull) ++culled_contacts_;
      }
    }
    if (samples[0].cell >= 0) keep_base_overlap(tool_ext_heights_, w.resolution + 2, 1);
  } else {
    samples[0] = EvaluateTool(tool, X_WT, w);
    if (samples[0].cell >= 0) {
      keep_base_overlap(tool_heights_, w.resolution, 0);
      const auto poses = GradientSamplePoses(X_WT, w);
      for (int i = 1; i < kGradientSamples; ++i) samples[i] = EvaluateTool(tool, poses[i], w);
    }
  }
  if (samples[0].cell < 0) {
    for (int i = 1; i < kGradientSamples; ++i) samples[i] = samples[0];
  }
  if (samples_out.size() >= samples.size())
    std::copy(samples.begin(), samples.end(), samples_out.begin());
  if (rotation_gradient_ == RotationGradient::kContactLever) {
    return AssembleLeverLinearization(w, samples, lever_W, stiffness_n_per_m, faults_);
  }
  return AssembleLinearization(w, samples, stiffness_n_per_m, faults_);
}

void TexturePenetrationSolver::RenderGrownBase(const HapticModel& tool, const RigidTransform& X_WT,
                                               const ContactWindow& w,
                                               std::span<DepthSample> samples) noexcept {
  // The translations by ±h_x = ±one cell along u and v are this render read one cell over (the
  // tool moved +u is, at window cell i, what the unmoved tool has at cell i − 1).
  const int n = w.resolution, nt = n + 2;
  tool_ext_heights_.assign(static_cast<size_t>(nt) * nt, std::numeric_limits<float>::infinity());
  RenderPatchHeightsFast(tool, X_WT, tool_triangles_, w, PatchSide::kTool, 1, tool_ext_heights_);
  samples[0] = DirectionalPenetrationDepthShifted(env_heights_, n, tool_ext_heights_, 1, 0, 0);
  samples[1] = DirectionalPenetrationDepthShifted(env_heights_, n, tool_ext_heights_, 1, -1, 0);
  samples[2] = DirectionalPenetrationDepthShifted(env_heights_, n, tool_ext_heights_, 1, 1, 0);
  samples[3] = DirectionalPenetrationDepthShifted(env_heights_, n, tool_ext_heights_, 1, 0, -1);
  samples[4] = DirectionalPenetrationDepthShifted(env_heights_, n, tool_ext_heights_, 1, 0, 1);
}

}  // namespace ht
