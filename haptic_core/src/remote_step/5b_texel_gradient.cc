// Stage 5b's gradient at texel scale and its translation patches (depth_refinement.h):
// DepthRefiner::TexelScaleGradient, the kink planes of the translation arms, and the patches
// (cell-spaced and texel-spaced) the operator's local model reads.

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <span>
#include <stdexcept>
#include <string>

#include "5b_patch_envelope.h"
#include "haptic_core/depth_refinement.h"

namespace ht {

using namespace patch_envelope;  // NOLINT(google-build-using-namespace): this stage's own helpers

PenetrationGradient DepthRefiner::TexelScaleGradient(const RigidTransform& X_WT,
                                                     std::span<const Seed> base, int num_seeds,
                                                     const Seed& deepest,
                                                     const glm::dvec3& point_W) noexcept {
  const ContactWindow& w = window_;
  const double cell = w.cell_size_m();
  const glm::dvec3& u = w.axis_u_W;
  const glm::dvec3& v = w.axis_v_W;
  const glm::dvec3& n = w.normal_W;
  GatherEnvironment(deepest.s - cell, deepest.s + cell, deepest.t - cell, deepest.t + cell);
  GatherTool(tool_all_, deepest.s - cell, deepest.s + cell, deepest.t - cell, deepest.t + cell);
  const double texel = TexelOfGathered(tool_local_);
  const double h_x = options_.gradient_step_texels * texel;
  const double h_theta = h_x / (0.5 * w.gradient_lever_extent_m());
  const double reach = h_x + h_theta * glm::length(point_W - X_WT.translation);
  const double floor_m = options_.search_floor_texels * texel;
  // The base seeds within reach of the deepest (a small step cannot bring a far, lower peak
  // above it), deepest first, at most four.
  std::array<int, kBaseSeedSamples> order{};
  const int num_near = SeedsNear(base, num_seeds, deepest, reach, order);
  const auto poses = GradientSamplePoses(X_WT, w, {h_x, h_theta});
  std::array<double, 10> displaced{};
  displaced.fill(-kInf);
  for (int m = 0; m < num_near; ++m) {
    const Seed& sd = base[static_cast<std::size_t>(order[static_cast<std::size_t>(m)])];
    const double margin = reach + 4.0 * texel;
    const Box box{sd.s - margin, sd.s + margin, sd.t - margin, sd.t + margin};
    GatherEnvironment(box.s0, box.s1, box.t0, box.t1);
    GatherTool(tool_all_, box.s0 - reach, box.s1 + reach, box.t0 - reach, box.t1 + reach);
    // Sample k + 1 of the table: ±u, ±v, ±θu, ±θv, ±θn (the translations alone where the rotation
    // part is the secant's: DepthRefinementOptions::texel_scale_rotation).
    const int displacements = options_.texel_scale_rotation ? 10 : 4;
    for (int k = 0; k < displacements; ++k) {
      const int axis = k / 2;
      const double sign = (k % 2 == 0) ? 1.0 : -1.0;
      double shift_s = 0.0, shift_t = 0.0;
      std::span<const Projected> tool_tris = tool_local_;
      // The maximum may stay with the environment's feature (the seed's point) or move with the
      // tool's (the seed's point carried by the displacement: where a tool edge bounds it, the
      // seed's own point may have left the tool's support): both starts are climbed.
      double moved_s = sd.s, moved_t = sd.t;
      if (axis == 0) {
        shift_s = sign * h_x;
        moved_s += shift_s;
      } else if (axis == 1) {
        shift_t = sign * h_x;
        moved_t += shift_t;
      } else {
        const RigidTransform& X = poses[static_cast<std::size_t>(k + 1)];
        MoveTool(X);
        tool_tris = tool_moved_;
        const glm::dvec3 p_W = w.center_W + sd.s * u + sd.t * v;
        const glm::dvec3 moved_W = X * (X_WT.Inverse() * p_W) - w.center_W;
        moved_s = glm::dot(moved_W, u);
        moved_t = glm::dot(moved_W, v);
      }
      double& d = displaced[static_cast<std::size_t>(k)];
      d = std::max(d, ClimbBoth(tool_tris, box, sd.s, sd.t, moved_s, moved_t, texel, floor_m,
                                shift_s, shift_t));
    }
  }
  // Central differences, one-sided where a displaced pose found no overlap.
  const auto central = [&](int axis, double step) {
    const double plus = displaced[static_cast<std::size_t>(2 * axis)];
    const double minus = displaced[static_cast<std::size_t>(2 * axis + 1)];
    if (plus > -kInf && minus > -kInf) return (plus - minus) / (2.0 * step);
    if (plus > -kInf) return (plus - deepest.depth_m) / step;
    if (minus > -kInf) return (deepest.depth_m - minus) / step;
    return 0.0;
  };
  PenetrationGradient g;
  g.d_translation_W = central(0, h_x) * u + central(1, h_x) * v - n;
  g.d_rotation_W = central(2, h_theta) * u + central(3, h_theta) * v + central(4, h_theta) * n;
  return g;
}

int DepthRefiner::TranslationKinkPlanes(std::span<const Seed> found, const Seed& deepest,
                                        double h_x, ContactLinearization& lin) noexcept {
  const ContactWindow& w = window_;
  const glm::dvec3 axes[2] = {w.axis_u_W, w.axis_v_W};
  int added = 0;
  for (int a = 0; a < 2; ++a) {
    const double slope = glm::dot(lin.gradient.d_translation_W, axes[a]);
    for (int side = 0; side < 2 && lin.num_kink_planes < kMaxKinkPlanes; ++side) {
      const Seed& f = found[static_cast<std::size_t>(2 * a + side)];
      const double sign = side == 0 ? 1.0 : -1.0;
      if (!(f.depth_m > -kInf)) continue;
      const double above = f.depth_m - (deepest.depth_m + sign * slope * h_x);
      if (!(above > options_.translation_kink_tolerance_m)) continue;
      // The arm's slope: the refined maximum's central difference at ±h_x ± h_t, climbed from the
      // sample's refined point and from that point carried by the extra shift.
      const double shift = sign * h_x;
      GatherEnvironment(f.s - h_x, f.s + h_x, f.t - h_x, f.t + h_x);
      GatherTool(tool_all_, f.s - 2.0 * h_x, f.s + 2.0 * h_x, f.t - 2.0 * h_x, f.t + 2.0 * h_x);
      const double texel = TexelOfGathered(tool_local_);
      const double h_t = options_.gradient_step_texels * texel;
      const double margin = h_t + 4.0 * texel;
      const Box box{f.s - margin, f.s + margin, f.t - margin, f.t + margin};
      GatherEnvironment(box.s0, box.s1, box.t0, box.t1);
      const double reach = std::abs(shift) + h_t;
      GatherTool(tool_all_, box.s0 - reach, box.s1 + reach, box.t0 - reach, box.t1 + reach);
      const double floor_m = options_.search_floor_texels * texel;
      double at[2] = {-kInf, -kInf};  // at shift + h_t, shift − h_t
      for (int e = 0; e < 2; ++e) {
        const double extra = e == 0 ? h_t : -h_t;
        const double shift_s = a == 0 ? shift + extra : 0.0;
        const double shift_t = a == 1 ? shift + extra : 0.0;
        const double moved_s = f.s + (a == 0 ? extra : 0.0);
        const double moved_t = f.t + (a == 1 ? extra : 0.0);
        const Seed at_point =
            Search(tool_local_, box, f.s, f.t, 0.0, 1, texel, floor_m, shift_s, shift_t);
        const Seed at_moved =
            Search(tool_local_, box, moved_s, moved_t, 0.0, 1, texel, floor_m, shift_s, shift_t);
        at[e] = std::max(at_point.depth_m, at_moved.depth_m);
      }
      double arm = 0.0;
      if (at[0] > -kInf && at[1] > -kInf) {
        arm = (at[0] - at[1]) / (2.0 * h_t);
      } else if (at[0] > -kInf) {
        arm = (at[0] - f.depth_m) / h_t;
      } else if (at[1] > -kInf) {
        arm = (f.depth_m - at[1]) / h_t;
      } else {
        continue;
      }
      // Convex across the cell: the arm on the + side rises faster than the contact's plane, the
      // arm on the − side falls faster (seen going +a).
      if (!(sign * (arm - slope) > 0.0) || !std::isfinite(arm)) continue;
      KinkPlane p;
      p.depth_m = std::min(f.depth_m - shift * arm, lin.depth_m);
      p.d_rotation_W = lin.gradient.d_rotation_W;
      p.d_translation_offset_W = (arm - slope) * axes[a];
      if (!std::isfinite(p.depth_m)) continue;
      lin.kink_planes[static_cast<std::size_t>(lin.num_kink_planes++)] = p;
      ++added;
    }
  }
  counters_.translation_kink_planes += static_cast<std::uint64_t>(added);
  return added;
}

void DepthRefiner::FillTranslationPatch(const RigidTransform& X_WT, const Seed& deepest,
                                        std::span<const Seed> found, double cell_step,
                                        ContactLinearization& lin) noexcept {
  constexpr int R = kTranslationPatchRadius;
  constexpr int S = kTranslationPatchSide;
  const int m = options_.translation_patch_spacing_cells;
  const double h = m * cell_step;  // the nodes' spacing
  const int grow = R * m;          // cells the tool's render is grown by
  const ContactWindow& w = window_;
  TranslationPatch& patch = lin.patch;
  patch = TranslationPatch{};
  patch.step_m = h;
  patch.axis_u_W = w.axis_u_W;
  patch.axis_v_W = w.axis_v_W;
  const double slope_u = glm::dot(lin.gradient.d_translation_W, w.axis_u_W);
  const double slope_v = glm::dot(lin.gradient.d_translation_W, w.axis_v_W);
  // The window's grid at the base pose, the tool's grown by R·m cells: node (i, j), the tool moved
  // by (i·m, j·m) cells, is the tool's render read (−i·m, −j·m) cells over (as the four rendered
  // translation samples are), so each node's deepest cell is found over the whole window.
  const int n = w.resolution, nt = n + 2 * grow;
  patch_env_heights_.assign(static_cast<std::size_t>(n) * n, -kInf32);
  patch_tool_heights_.assign(static_cast<std::size_t>(nt) * nt, kInf32);
  RenderPatchHeightsFast(*env_, X_WO_, env_list_, w, PatchSide::kEnvironment, 0,
                         patch_env_heights_);
  RenderPatchHeightsFast(*tool_, X_WT, tool_list_, w, PatchSide::kTool, grow, patch_tool_heights_);
  std::array<Seed, static_cast<std::size_t>(S * S)> at{};
  at.fill(Seed{-kInf, 0.0, 0.0});
  const auto index = [](int i, int j) { return static_cast<std::size_t>((j + R) * S + (i + R)); };
  at[index(0, 0)] = deepest;
  // The rendered samples one cell away (1: +u, 2: −u, 3: +v, 4: −v), already refined: the nodes
  // one step away when the spacing is one cell.
  const std::array<std::array<int, 2>, 4> rendered{{{1, 0}, {-1, 0}, {0, 1}, {0, -1}}};
  if (m == 1) {
    for (std::size_t k = 0; k < rendered.size() && k < found.size(); ++k) {
      at[index(rendered[k][0], rendered[k][1])] = found[k];
    }
  }
  const double cell = w.cell_size_m();
  // Ring by ring, so that each node's neighbour towards q0 is done first.
  for (int ring = 1; ring <= R; ++ring) {
    for (int j = -ring; j <= ring; ++j) {
      for (int i = -ring; i <= ring; ++i) {
        if (std::max(std::abs(i), std::abs(j)) != ring) continue;
        Seed& node = at[index(i, j)];
        if (node.depth_m > -kInf) continue;  // a refined rendered sample
        const double shift_s = i * h, shift_t = j * h;
        // A pattern search from (s, t) over a square of half side `half` (sub-sampled on the
        // grid's cell when `subgrid`).
        const auto climb = [&](double s, double t, double half, bool subgrid) {
          const Box box{s - half - cell, s + half + cell, t - half - cell, t + half + cell};
          GatherEnvironment(box.s0, box.s1, box.t0, box.t1);
          GatherTool(tool_all_, box.s0 - shift_s, box.s1 - shift_s, box.t0 - shift_t,
                     box.t1 - shift_t);
          if (env_local_.empty() || tool_local_.empty()) return;
          const double texel = TexelOfGathered(tool_local_);
          const double floor_m = (options_.translation_patch_floor_texels > 0.0
                                      ? options_.translation_patch_floor_texels
                                      : options_.search_floor_texels) *
                                 texel;
          const int g =
              subgrid
                  ? std::clamp(static_cast<int>(std::ceil(2.0 * half / (kSubsampleTexels * texel))),
                               1, options_.max_subsamples)
                  : 1;
          const Seed r = Search(tool_local_, box, s, t, half, g, 0.5 * (2.0 * half / g), floor_m,
                                shift_s, shift_t);
          if (r.depth_m > node.depth_m) node = r;
        };
        const DepthSample grid = DirectionalPenetrationDepthShifted(
            patch_env_heights_, n, patch_tool_heights_, grow, -i * m, -j * m);
        if (grid.cell >= 0) {
          double s = 0.0, t = 0.0;
          CellCoordinates(w, grid.cell, s, t);
          climb(s, t, 0.75 * cell, options_.subgrid_translations);
        }
        // The neighbour one step nearer q0: its maximum carried by that step (a tool feature).
        const int ni = i - (i > 0) + (i < 0), nj = j - (j > 0) + (j < 0);
        const Seed& near = at[index(ni, nj)];
        if (options_.translation_patch_neighbour_climbs && near.depth_m > -kInf) {
          climb(near.s + (i - ni) * h, near.t + (j - nj) * h, 0.25 * h, false);
          climb(near.s, near.t, 0.25 * h, false);
        }
      }
    }
  }
  for (int j = -R; j <= R; ++j) {
    for (int i = -R; i <= R; ++i) {
      const Seed& node = at[index(i, j)];
      const double value = (node.depth_m > -kInf && std::isfinite(node.depth_m))
                               ? node.depth_m - deepest.depth_m
                               : (slope_u * i + slope_v * j) * h;
      patch.depth_m[index(i, j)] = static_cast<float>(value);
    }
  }
  patch.depth_m[index(0, 0)] = 0.0f;
  if (options_.translation_patch_follows_rotation) {
    patch.lever_W = w.center_W + deepest.s * w.axis_u_W + deepest.t * w.axis_v_W - X_WT.translation;
  }
}

void DepthRefiner::FillTexelTranslationPatch(std::span<const Seed> base, int num_seeds,
                                             std::span<const Seed> found, const Seed& deepest,
                                             ContactLinearization& lin) noexcept {
  constexpr int R = kTranslationPatchRadius;
  constexpr int S = kTranslationPatchSide;
  const ContactWindow& w = window_;
  const double cell = w.cell_size_m();
  GatherEnvironment(deepest.s - cell, deepest.s + cell, deepest.t - cell, deepest.t + cell);
  GatherTool(tool_all_, deepest.s - cell, deepest.s + cell, deepest.t - cell, deepest.t + cell);
  const double texel = TexelOfGathered(tool_local_);
  const double h = options_.translation_patch_step_texels * texel;
  const double reach = R * h;
  const double floor_m = options_.search_floor_texels * texel;
  TranslationPatch& patch = lin.patch;
  patch = TranslationPatch{};
  patch.step_m = h;
  patch.axis_u_W = w.axis_u_W;
  patch.axis_v_W = w.axis_v_W;
  // The base seeds within reach of the deepest, deepest first, at most four (as
  // TexelScaleGradient).
  std::array<int, kBaseSeedSamples> order{};
  const int num_near = SeedsNear(base, num_seeds, deepest, reach, order);
  std::array<double, static_cast<std::size_t>(S * S)> node{};
  node.fill(-kInf);
  const auto index = [](int i, int j) { return static_cast<std::size_t>((j + R) * S + (i + R)); };
  // Every node climbed from a start `f` (ClimbBoth: from its point and from its point carried by
  // the node's shift).
  const auto climb_from = [&](const Seed& f) {
    if (!(f.depth_m > -kInf)) return;
    const double margin = reach + 4.0 * texel;
    const Box box{f.s - margin, f.s + margin, f.t - margin, f.t + margin};
    GatherEnvironment(box.s0, box.s1, box.t0, box.t1);
    GatherTool(tool_all_, box.s0 - reach, box.s1 + reach, box.t0 - reach, box.t1 + reach);
    for (int j = -R; j <= R; ++j) {
      for (int i = -R; i <= R; ++i) {
        if (i == 0 && j == 0) continue;
        const double shift_s = i * h, shift_t = j * h;
        double& d = node[index(i, j)];
        d = std::max(d, ClimbBoth(tool_local_, box, f.s, f.t, f.s + shift_s, f.t + shift_t, texel,
                                  floor_m, shift_s, shift_t));
      }
    }
  };
  // The starts: the base seeds within reach, and, since a peak that a shift brings above the
  // deepest one (the other flank across a trough, whose V the patch is for) need not be among
  // them (their cells lie next to the deepest's or on it), the neighbouring peaks
  // (neighbour_peak_seeds) and the refined rendered translation samples' maxima (±1 cell along u
  // and v).
  for (int m = 0; m < num_near; ++m) {
    climb_from(base[static_cast<std::size_t>(order[static_cast<std::size_t>(m)])]);
  }
  for (int k = 0; k < num_neighbour_peaks_; ++k) {
    climb_from(neighbour_peaks_[static_cast<std::size_t>(k)]);
  }
  for (const Seed& f : found) climb_from(f);
  const double slope_u = glm::dot(lin.gradient.d_translation_W, w.axis_u_W);
  const double slope_v = glm::dot(lin.gradient.d_translation_W, w.axis_v_W);
  for (int j = -R; j <= R; ++j) {
    for (int i = -R; i <= R; ++i) {
      const double d = node[index(i, j)];
      const double value =
          (d > -kInf && std::isfinite(d)) ? d - deepest.depth_m : (slope_u * i + slope_v * j) * h;
      patch.depth_m[index(i, j)] = static_cast<float>(value);
    }
  }
  patch.depth_m[index(0, 0)] = 0.0f;
}

double DepthRefiner::TexelOfGathered(std::span<const Projected> tool_tris) const noexcept {
  double texel = kInf;
  for (const Projected& P : env_local_) {
    if (P.textured && P.texel_m > 0.0) texel = std::min(texel, P.texel_m);
  }
  for (const Projected& P : tool_tris) {
    if (P.textured && P.texel_m > 0.0) texel = std::min(texel, P.texel_m);
  }
  return std::isfinite(texel) ? texel : 0.25 * window_.cell_size_m();
}

}  // namespace ht
