// Stage 5b's translation patches (depth_refinement.h): DepthRefiner::FillTranslationPatch, the
// contact's depth over in-plane translations that the operator's fallback model reads.

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
