// Stage 5b: the penetration depth refined to the finest texture level; see
// depth_refinement.h for the method. The seeds' searches and the refinement of a contact; the
// screen over the window in 5b_depth_screening.cc, the envelope's evaluation in
// 5b_patch_envelope.h.

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

double PatchHeightAt(const HapticModel& model, const RigidTransform& X_WO,
                     std::span<const int> triangles, const ContactWindow& window, PatchSide side,
                     double s_m, double t_m, int level, bool parallax) noexcept {
  Envelope envelope(side == PatchSide::kEnvironment, window.depth_range_m());
  ParallaxEdge edge{};
  Projected P;
  for (const int f : triangles) {
    if (f < 0 || static_cast<std::size_t>(f) >= model.triangles.size()) continue;
    if (!ProjectTriangle(model, X_WO, window, f, side, P, parallax && level == 0)) continue;
    envelope.Add(ValueAt(P, model.texture, s_m, t_m, level, window.cell_size_m(),
                         DepthRefinementOptions{}.parallax_iterations, &edge));
    envelope.AddEdge(edge);
  }
  return envelope.Finish();
}

void DepthRefinementOptions::Validate() const {
  if (max_subsamples < 1 || max_subsamples > 16) {
    throw std::invalid_argument("depth refinement: max_subsamples must be in [1, 16], got " +
                                std::to_string(max_subsamples));
  }
  if (!(search_floor_texels > 0.0) || !std::isfinite(search_floor_texels)) {
    throw std::invalid_argument("depth refinement: search_floor_texels must be > 0, got " +
                                std::to_string(search_floor_texels));
  }
  if (!(screen_tolerance_m >= 0.0) || !std::isfinite(screen_tolerance_m)) {
    throw std::invalid_argument("depth refinement: screen_tolerance_m must be >= 0, got " +
                                std::to_string(screen_tolerance_m));
  }
  if (!std::isfinite(screen_floor_m)) {
    throw std::invalid_argument("depth refinement: screen_floor_m must be finite, got " +
                                std::to_string(screen_floor_m));
  }
  if (parallax && conservative_screen) {
    throw std::invalid_argument(
        "depth refinement: parallax and conservative_screen cannot be on together (the screen's "
        "bounds are the render's form)");
  }
  if (parallax_iterations < 1 || parallax_iterations > 64) {
    throw std::invalid_argument("depth refinement: parallax_iterations must be in [1, 64], got " +
                                std::to_string(parallax_iterations));
  }
  if (max_screen_leaves < 1) {
    throw std::invalid_argument("depth refinement: max_screen_leaves must be >= 1, got " +
                                std::to_string(max_screen_leaves));
  }
}

DepthRefiner::DepthRefiner(const DepthRefinementOptions& options, std::size_t max_triangles)
    : options_(options) {
  options_.Validate();
  env_list_.reserve(max_triangles);
  tool_list_.reserve(max_triangles);
  vertex_scratch_.reserve(max_triangles);
  env_local_.reserve(max_triangles);
  tool_local_.reserve(max_triangles);
  env_all_.reserve(max_triangles);
  tool_all_.reserve(max_triangles);
  tool_pose_all_.reserve(max_triangles);
  if (options_.conservative_screen) {
    for (auto& v : env_screen_) v.reserve(max_triangles);
    for (auto& v : tool_screen_) v.reserve(max_triangles);
  }
}

void DepthRefiner::BeginStep() noexcept {
  last_ = next_;
  num_last_ = num_next_;
  num_next_ = 0;
}

void DepthRefiner::ProjectAll(const HapticModel& model, const RigidTransform& X, PatchSide side,
                              std::span<const int> list, std::vector<Projected>& out) noexcept {
  out.clear();
  Projected P;
  for (const int f : list) {
    if (!ProjectTriangle(model, X, window_, f, side, P, options_.parallax)) continue;
    P.face = f;
    out.push_back(P);
  }
}

void DepthRefiner::GatherEnvironment(double s0, double s1, double t0, double t1) noexcept {
  env_local_.clear();
  for (const Projected& P : env_all_) {
    if (P.x1 < s0 || P.x0 > s1 || P.y1 < t0 || P.y0 > t1) continue;
    env_local_.push_back(P);
  }
}

void DepthRefiner::GatherTool(std::span<const Projected> from, double s0, double s1, double t0,
                              double t1) noexcept {
  tool_local_.clear();
  for (const Projected& P : from) {
    if (P.x1 < s0 || P.x0 > s1 || P.y1 < t0 || P.y0 > t1) continue;
    tool_local_.push_back(P);
  }
}

double DepthRefiner::Difference(std::span<const Projected> tool, double s, double t, double shift_s,
                                double shift_t) noexcept {
  ++evaluations_;
  const double range = window_.depth_range_m();
  const int it = options_.parallax_iterations;
  const double b = HeightOver(env_local_, env_->texture, true, range, s, t, 0, 0.0, it);
  if (!(b > -kInf)) return -kInf;
  const double a =
      HeightOver(tool, tool_->texture, false, range, s - shift_s, t - shift_t, 0, 0.0, it);
  if (!(a < kInf)) return -kInf;
  return b - a;
}

DepthRefiner::Seed DepthRefiner::Search(std::span<const Projected> tool, const Box& box, double s,
                                        double t, double half_side, int subsamples, double step,
                                        double floor_m, double shift_s, double shift_t) noexcept {
  Seed best{-kInf, s, t};
  const auto inside = [&](double ss, double tt) {
    return ss >= box.s0 && ss <= box.s1 && tt >= box.t0 && tt <= box.t1;
  };
  const auto consider = [&](double ss, double tt) {
    if (!inside(ss, tt)) return false;
    const double d = Difference(tool, ss, tt, shift_s, shift_t);
    if (d > best.depth_m) {
      best = {d, ss, tt};
      return true;
    }
    return false;
  };
  // The four neighbours along u and v.
  static constexpr std::array<std::array<int, 2>, 4> kDirections{
      {{1, 0}, {-1, 0}, {0, 1}, {0, -1}}};
  if (subsamples <= 1) {
    // A start just off the surface (a rendered cell's centre a few micrometres past the edge of
    // a face whose displaced surface, with parallax, ends inside it) reads nothing: its four
    // neighbours at the pattern's steps are tried, nearest first, until one reads a depth.
    if (!consider(s, t)) {
      for (double probe = std::max(floor_m, step / 64.0);
           probe > 0.0 && probe <= step && !(best.depth_m > -kInf); probe *= 2.0) {
        for (const auto& d : kDirections) {
          consider(s + d[0] * probe, t + d[1] * probe);
        }
      }
    }
  } else {
    const double spacing = 2.0 * half_side / subsamples;
    for (int j = 0; j < subsamples; ++j) {
      for (int i = 0; i < subsamples; ++i) {
        consider(s - half_side + (i + 0.5) * spacing, t - half_side + (j + 0.5) * spacing);
      }
    }
  }
  if (!(best.depth_m > -kInf)) return best;
  // Pattern search over the four neighbours along u and v at `step`, halved when none is
  // better.
  // First improvement: the direction that last improved is tried first, and the search moves
  // as soon as a neighbour is better.
  int moves = 0, last = 0;
  while (step >= floor_m && moves < 64) {
    const Seed from = best;
    bool moved = false;
    for (int k = 0; k < 4 && !moved; ++k) {
      const int d = (last + k) % 4;
      if (consider(from.s + kDirections[d][0] * step, from.t + kDirections[d][1] * step)) {
        moved = true;
        last = d;
      }
    }
    if (moved) {
      ++moves;
    } else {
      step *= 0.5;
    }
  }
  return best;
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

double DepthRefiner::ScreenThreshold(double best_m) const noexcept {
  return std::max(best_m, options_.screen_floor_m) + options_.screen_tolerance_m;
}

bool DepthRefiner::Refine(const HapticModel& tool, const RigidTransform& X_WT,
                          const ContactQuery& query, std::span<DepthSample> samples,
                          ContactLinearization& lin) noexcept {
  if (samples.size() < static_cast<std::size_t>(kGradientSamples) || samples[0].cell < 0 ||
      query.environment == nullptr) {
    return false;
  }
  env_ = query.environment;
  tool_ = &tool;
  X_WO_ = query.X_WO;
  window_ = query.window;
  const ContactWindow& w = window_;
  const double cell = w.cell_size_m();
  const GradientSteps big = GradientSteps::For(w);
  evaluations_ = 0;
  SelectPatchTrianglesIn(query.environment_triangles, *env_, X_WO_, w, PatchSide::kEnvironment,
                         cell, env_list_, 0.0, &vertex_scratch_);
  SelectPatchTrianglesIn(query.tool_triangles, tool, X_WT, w, PatchSide::kTool, 2.0 * big.h_x,
                         tool_list_, big.h_theta + 1e-9, &vertex_scratch_, nullptr, big.h_theta);
  ProjectAll(*env_, X_WO_, PatchSide::kEnvironment, env_list_, env_all_);
  ProjectAll(tool, X_WT, PatchSide::kTool, tool_list_, tool_all_);

  // A search from the window point (s, t) (m) within the 1.75-cell square around it, the tool at
  // X (shifted in-plane by (shift_s, shift_t) where X is the base pose): a sub-grid over its
  // 1.5-cell square first with `subgrid`, else a pattern search from the point alone.
  const auto refine_at = [&](double s, double t, std::span<const Projected> tool_at, double shift_s,
                             double shift_t, bool subgrid) -> Seed {
    const double half = 0.75 * cell;
    const Box box{s - half - cell, s + half + cell, t - half - cell, t + half + cell};
    GatherEnvironment(box.s0, box.s1, box.t0, box.t1);
    GatherTool(tool_at, box.s0 - shift_s, box.s1 - shift_s, box.t0 - shift_t, box.t1 - shift_t);
    const double texel = TexelOfGathered(tool_local_);
    const double floor_m = options_.search_floor_texels * texel;
    if (!subgrid)
      return Search(tool_local_, box, s, t, half, 1, 0.5 * half, floor_m, shift_s, shift_t);
    const int g = std::clamp(static_cast<int>(std::ceil(2.0 * half / (kSubsampleTexels * texel))),
                             1, options_.max_subsamples);
    return Search(tool_local_, box, s, t, half, g, 0.5 * (2.0 * half / g), floor_m, shift_s,
                  shift_t);
  };
  // One rendered sample's deepest cell refined at a pose.
  const auto refine_cell = [&](int cell_index, std::span<const Projected> tool_at, double shift_s,
                               double shift_t, bool subgrid) -> Seed {
    double s = 0.0, t = 0.0;
    CellCoordinates(w, cell_index, s, t);
    return refine_at(s, t, tool_at, shift_s, shift_t, subgrid);
  };

  // The base: every distinct deepest cell of the samples is a seed.
  std::array<int, kBaseSeedSamples> seed_cells{};
  int num_seeds = 0;
  for (int k = 0; k < kBaseSeedSamples; ++k) {
    const int c = samples[static_cast<std::size_t>(k)].cell;
    if (c < 0 || c >= w.resolution * w.resolution) continue;
    // A cell next to a seed is mostly within that seed's square (1.5 cells) and its climb.
    const int n = w.resolution;
    if (std::any_of(seed_cells.begin(), seed_cells.begin() + num_seeds, [&](int o) {
          return std::abs(o % n - c % n) <= 1 && std::abs(o / n - c / n) <= 1;
        })) {
      continue;
    }
    seed_cells[static_cast<std::size_t>(num_seeds++)] = c;
  }
  std::array<Seed, kBaseSeedSamples> base{};
  int best = -1;
  for (int k = 0; k < num_seeds; ++k) {
    base[static_cast<std::size_t>(k)] = refine_cell(seed_cells[k], tool_all_, 0.0, 0.0, true);
    if (best < 0 || base[k].depth_m > base[static_cast<std::size_t>(best)].depth_m) best = k;
  }
  Seed deepest = best >= 0 ? base[static_cast<std::size_t>(best)] : Seed{-kInf, 0.0, 0.0};
  // A deeper point found away from the grid's seeds (the screen, the last step) becomes deepest
  // and one of the base seeds, and the displaced samples are searched from it too. Returns how much
  // deeper (µm, rounded; 0 when the seeds found nothing).
  bool deeper_away_from_seeds = false;
  const auto take_deeper = [&](const Seed& found) -> std::uint64_t {
    const std::uint64_t raised =
        deepest.depth_m > -kInf
            ? static_cast<std::uint64_t>(std::llround((found.depth_m - deepest.depth_m) * 1e6))
            : 0;
    deepest = found;
    deeper_away_from_seeds = true;
    if (num_seeds < kBaseSeedSamples) {
      base[static_cast<std::size_t>(num_seeds++)] = deepest;
    } else {
      base[static_cast<std::size_t>(best)] = deepest;
    }
    return raised;
  };
  // The grid's seeds carried by parallax: where each side's envelope reads its surface point,
  // more than half a cell away.
  if (options_.parallax) {
    const double half_extent = 0.5 * w.extent_m, range = w.depth_range_m();
    const int grid_seeds = num_seeds;
    for (int k = 0; k < grid_seeds; ++k) {
      double s = 0.0, t = 0.0;
      CellCoordinates(w, seed_cells[static_cast<std::size_t>(k)], s, t);
      for (const bool environment : {true, false}) {
        double ds = 0.0, dt = 0.0;
        if (!ParallaxOffset(environment ? std::span<const Projected>(env_all_)
                                        : std::span<const Projected>(tool_all_),
                            environment ? env_->texture : tool.texture, environment, range, s, t,
                            ds, dt)) {
          continue;
        }
        if (ds * ds + dt * dt < 0.25 * cell * cell) continue;
        const double cs = std::clamp(s + ds, -half_extent, half_extent),
                     ct = std::clamp(t + dt, -half_extent, half_extent);
        ++counters_.parallax_offset_seeds;
        const Seed found = refine_at(cs, ct, tool_all_, 0.0, 0.0, true);
        if (!(found.depth_m > deepest.depth_m)) continue;
        ++counters_.parallax_offset_found;
        counters_.parallax_offset_raised_um += take_deeper(found);
      }
    }
  }
  // The conservative screen: wherever b − a can still beat the seeds' best.
  if (options_.conservative_screen) {
    Seed screened = deepest;
    Screen(screened);
    if (screened.depth_m > deepest.depth_m) {
      counters_.screen_found += 1;
      counters_.screen_raised_um += take_deeper(screened);
    }
  }
  // The last step's deepest points within this window, each searched by a pattern search from
  // the point (it was a refined maximum one step ago: no sub-grid).
  {
    const double half_extent = 0.5 * w.extent_m;
    for (int k = 0; k < num_last_; ++k) {
      const LastStepPoint& last = last_[static_cast<std::size_t>(k)];
      if (last.environment != env_) continue;
      const glm::dvec3 r = X_WT * last.p_T - w.center_W;
      const double s = glm::dot(r, w.axis_u_W), t = glm::dot(r, w.axis_v_W);
      if (!(std::abs(s) <= half_extent && std::abs(t) <= half_extent)) continue;
      ++counters_.last_step_seeds;
      const Seed found = refine_at(s, t, tool_all_, 0.0, 0.0, false);
      if (!(found.depth_m > deepest.depth_m)) continue;
      ++counters_.last_step_found;
      counters_.last_step_raised_um += take_deeper(found);
    }
  }
  // The neighbouring peaks: climbs from half a cell and a cell from the
  // deepest along ±u and ±v, where the other flank across a trough lies (its cell is next to
  // the deepest's, and so never a seed of its own).
  num_neighbour_peaks_ = 0;
  if (deepest.depth_m > -kInf) {
    const double half_extent = 0.5 * w.extent_m;
    const Seed from = deepest;
    static constexpr std::array<std::array<int, 2>, 4> kAxes{{{1, 0}, {-1, 0}, {0, 1}, {0, -1}}};
    for (const auto& a : kAxes) {
      for (const double along : {0.5 * cell, cell}) {
        const double s = std::clamp(from.s + a[0] * along, -half_extent, half_extent);
        const double t = std::clamp(from.t + a[1] * along, -half_extent, half_extent);
        const Box box{s - cell, s + cell, t - cell, t + cell};
        GatherEnvironment(box.s0, box.s1, box.t0, box.t1);
        GatherTool(tool_all_, box.s0, box.s1, box.t0, box.t1);
        const double texel = TexelOfGathered(tool_local_);
        const Seed found = Search(tool_local_, box, s, t, 0.0, 1, 2.0 * texel,
                                  options_.search_floor_texels * texel, 0.0, 0.0);
        ++counters_.neighbour_peak_seeds;
        if (!(found.depth_m > -kInf)) continue;
        // Distinct from the deepest and from the peaks kept (two texels apart).
        const auto near = [&](const Seed& o) {
          return std::hypot(o.s - found.s, o.t - found.t) < 2.0 * texel;
        };
        bool seen = near(from);
        for (int k = 0; k < num_neighbour_peaks_ && !seen; ++k) {
          seen = near(neighbour_peaks_[static_cast<std::size_t>(k)]);
        }
        if (seen) continue;
        if (num_neighbour_peaks_ < kMaxNeighbourPeaks) {
          neighbour_peaks_[static_cast<std::size_t>(num_neighbour_peaks_++)] = found;
        }
        if (found.depth_m > deepest.depth_m) {
          ++counters_.neighbour_peak_found;
          counters_.neighbour_peak_raised_um += take_deeper(found);
        }
      }
    }
  }
  if (!(deepest.depth_m > -kInf)) {
    counters_.evaluations += evaluations_;
    return false;
  }

  const glm::dvec3 point_W = w.center_W + deepest.s * w.axis_u_W + deepest.t * w.axis_v_W;

  // The rendered displaced samples, each from its own deepest cell at its own pose.
  {
    const auto poses = GradientSamplePoses(X_WT, w);
    for (int k = 1; k < kGradientSamples; ++k) {
      DepthSample& sample = samples[static_cast<std::size_t>(k)];
      if (sample.cell < 0) continue;
      if (k > 4) {
        ProjectAll(tool, poses[static_cast<std::size_t>(k)], PatchSide::kTool, tool_list_,
                   tool_pose_all_);
      }
      // The sample refined from one cell: ±h_x along u (1, 2) and v (3, 4) are the base pose
      // shifted, the rotations (5…10) the tool at their pose.
      const auto refine_from = [&](int cell_index) {
        if (k > 4) {
          return refine_cell(cell_index, tool_pose_all_, 0.0, 0.0, false);
        }
        const double sign = (k % 2 == 1) ? 1.0 : -1.0;
        return refine_cell(cell_index, tool_all_, k <= 2 ? sign * big.h_x : 0.0,
                           k <= 2 ? 0.0 : sign * big.h_x, false);
      };
      Seed found = refine_from(sample.cell);
      if (deeper_away_from_seeds) {
        // The screen or the last step found the maximum away from the seeds: the displaced
        // sample is searched from there too (its own deepest cell may hold the seeds' lower
        // peak).
        const Seed also = refine_from(CellAt(w, deepest.s, deepest.t));
        if (also.depth_m > found.depth_m) found = also;
      }
      if (found.depth_m > -kInf) sample.depth_m = found.depth_m;
    }
  }

  counters_.contacts += 1;
  counters_.seeds += static_cast<std::uint64_t>(num_seeds);
  counters_.evaluations += evaluations_;
  const double raised = deepest.depth_m - samples[0].depth_m;
  if (raised > 0.0) counters_.raised_um += static_cast<std::uint64_t>(std::llround(raised * 1e6));
  samples[0] = {deepest.depth_m, CellAt(w, deepest.s, deepest.t)};
  lin.depth_m = deepest.depth_m;
  lin.point_W = point_W;
  if (num_next_ < kMaxLastStepSeeds) {
    // p_T = R_WTᵀ (p_W − p_WT): the point in the tool's frame.
    next_[static_cast<std::size_t>(num_next_++)] = {
        env_, glm::conjugate(X_WT.rotation) * (point_W - X_WT.translation)};
  }
  {
    // The refined rendered samples' one-cell secants.
    LinearizationFaults faults;
    lin.gradient = AssembleLinearization(w, samples, lin.stiffness_n_per_m, faults).gradient;
    // Where a rotated sample has no cell (the rotated tool leaves the environment's patch), the
    // rotation part is the lever's at the refined deepest point: (r × ∂δ/∂x).
    bool rotations_drawn = true;
    for (int k = 5; k < kGradientSamples; ++k) {
      rotations_drawn &= samples[static_cast<std::size_t>(k)].cell >= 0;
    }
    if (!rotations_drawn) {
      lin.gradient.d_rotation_W =
          glm::cross(point_W - X_WT.translation, lin.gradient.d_translation_W);
    }
  }
  return true;
}

}  // namespace ht
