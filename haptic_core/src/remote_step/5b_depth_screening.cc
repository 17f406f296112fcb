// Stage 5b's screen (depth_refinement.h): the window's squares whose bound on b − a can still beat
// the deepest point found, searched down to leaves (DepthRefiner::Screen), and the seeds near the
// deepest.

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

double DepthRefiner::SideBound(std::span<const Projected> all, std::span<const int> list,
                               const HeightField& texture, bool environment,
                               const Box& square) const noexcept {
  const double range = window_.depth_range_m();
  double bound = environment ? -kInf : kInf;
  for (const int i : list) {
    const Projected& P = all[static_cast<std::size_t>(i)];
    // The part of the square the triangle's box covers (ValueAt's 1e-12 margin).
    const double s0 = std::max(square.s0, P.x0 - 1e-12), s1 = std::min(square.s1, P.x1 + 1e-12);
    const double t0 = std::max(square.t0, P.y0 - 1e-12), t1 = std::min(square.t1, P.y1 + 1e-12);
    if (s0 > s1 || t0 > t1) continue;
    // The coarse height and the texture coordinates are linear on the triangle: over its part
    // inside the rectangle (the triangle clipped by the rectangle's four sides, at most seven
    // corners) their extremes are at that polygon's corners.
    std::array<double, 2 * 9> poly{}, next{};
    int count = 3;
    for (int c = 0; c < 3; ++c) {
      poly[static_cast<std::size_t>(2 * c)] = P.x[c];
      poly[static_cast<std::size_t>(2 * c + 1)] = P.y[c];
    }
    // Keep the side of axis `axis` (0: s, 1: t) where sign·(coordinate − limit) ≤ 0.
    const auto clip = [&](int axis, double limit, double sign) {
      int out = 0;
      for (int k = 0; k < count; ++k) {
        const double* a = &poly[static_cast<std::size_t>(2 * k)];
        const double* b = &poly[static_cast<std::size_t>(2 * ((k + 1) % count))];
        const double fa = sign * (a[axis] - limit), fb = sign * (b[axis] - limit);
        if (fa <= 0.0) {
          next[static_cast<std::size_t>(2 * out)] = a[0];
          next[static_cast<std::size_t>(2 * out + 1)] = a[1];
          ++out;
        }
        if ((fa < 0.0 && fb > 0.0) || (fa > 0.0 && fb < 0.0)) {
          const double r = fa / (fa - fb);
          next[static_cast<std::size_t>(2 * out)] = a[0] + r * (b[0] - a[0]);
          next[static_cast<std::size_t>(2 * out + 1)] = a[1] + r * (b[1] - a[1]);
          // The crossing lies on the limit exactly (not a rounding away from it).
          next[static_cast<std::size_t>(2 * out + axis)] = limit;
          ++out;
        }
      }
      count = out;
      poly = next;
    };
    clip(0, s1, 1.0);
    if (count > 0) clip(0, s0, -1.0);
    if (count > 0) clip(1, t1, 1.0);
    if (count > 0) clip(1, t0, -1.0);
    if (count == 0) continue;
    double d_lo = kInf, d_hi = -kInf, u_lo = kInf, u_hi = -kInf, v_lo = kInf, v_hi = -kInf;
    for (int c = 0; c < count; ++c) {
      double b0, b1, b2;
      Barycentric(P, poly[static_cast<std::size_t>(2 * c)],
                  poly[static_cast<std::size_t>(2 * c + 1)], b0, b1, b2);
      const double d = b0 * P.d[0] + b1 * P.d[1] + b2 * P.d[2];
      d_lo = std::min(d_lo, d);
      d_hi = std::max(d_hi, d);
      if (P.textured) {
        const double u = b0 * P.tu[0] + b1 * P.tu[1] + b2 * P.tu[2];
        const double v = b0 * P.tv[0] + b1 * P.tv[1] + b2 * P.tv[2];
        u_lo = std::min(u_lo, u);
        u_hi = std::max(u_hi, u);
        v_lo = std::min(v_lo, v);
        v_hi = std::max(v_hi, v);
      }
    }
    // Rounding of the clipped corners: a relative allowance on the heights.
    const double slack = 1e-9 * (std::abs(d_lo) + std::abs(d_hi)) + 1e-12;
    d_lo -= slack;
    d_hi += slack;
    double lo = d_lo, hi = d_hi;
    if (P.textured) {
      // Inside the triangle the coordinates stay within its corners' box.
      u_lo = std::max(u_lo, static_cast<double>(std::min({P.tu[0], P.tu[1], P.tu[2]})));
      u_hi = std::min(u_hi, static_cast<double>(std::max({P.tu[0], P.tu[1], P.tu[2]})));
      v_lo = std::max(v_lo, static_cast<double>(std::min({P.tv[0], P.tv[1], P.tv[2]})));
      v_hi = std::min(v_hi, static_cast<double>(std::max({P.tv[0], P.tv[1], P.tv[2]})));
      float h_lo = 0.0f, h_hi = 0.0f;
      texture.RangeOver(static_cast<float>(std::min(u_lo, u_hi)),
                        static_cast<float>(std::min(v_lo, v_hi)),
                        static_cast<float>(std::max(u_lo, u_hi)),
                        static_cast<float>(std::max(v_lo, v_hi)), h_lo, h_hi);
      double f_lo, f_hi;
      NormalFactorRange(P, f_lo, f_hi);
      const double products[4] = {h_lo * f_lo, h_lo * f_hi, h_hi * f_lo, h_hi * f_hi};
      lo += *std::min_element(products, products + 4);
      hi += *std::max_element(products, products + 4);
    }
    // Values outside the window's box are ignored (HeightOver).
    if (hi < -range || lo > range) continue;
    bound =
        environment ? std::max(bound, std::min(hi, range)) : std::min(bound, std::max(lo, -range));
  }
  return bound;
}

void DepthRefiner::ScreenSquare(const Box& square, int depth, Seed& best, int& leaves) noexcept {
  const std::vector<int>& env = env_screen_[static_cast<std::size_t>(depth)];
  const std::vector<int>& tool = tool_screen_[static_cast<std::size_t>(depth)];
  const double side = square.s1 - square.s0;
  // The finer level-0 texel over the square's triangles (TexelOfGathered's rule).
  double texel = kInf;
  for (const auto& [all, list] : {std::pair{&env_all_, &env}, std::pair{&tool_all_, &tool}}) {
    for (const int i : *list) {
      const Projected& P = (*all)[static_cast<std::size_t>(i)];
      if (P.textured && P.texel_m > 0.0) texel = std::min(texel, P.texel_m);
    }
  }
  if (!std::isfinite(texel)) texel = 0.25 * window_.cell_size_m();
  if (side <= 2.0 * texel || depth == kMaxScreenDepth) {
    // A leaf: the local search from a 2×2 sub-grid of the square, free to climb half a square
    // beyond it.
    if (leaves >= options_.max_screen_leaves) {
      truncated_ = true;
      return;
    }
    ++leaves;
    const double half = 0.5 * side;
    const Box box{square.s0 - half, square.s1 + half, square.t0 - half, square.t1 + half};
    const auto gather = [&](const std::vector<Projected>& all, const std::vector<int>& list,
                            std::vector<Projected>& out) {
      out.clear();
      for (const int i : list) {
        const Projected& P = all[static_cast<std::size_t>(i)];
        if (Overlaps(P, box.s0, box.s1, box.t0, box.t1)) out.push_back(P);
      }
    };
    gather(env_all_, env, env_local_);
    gather(tool_all_, tool, tool_local_);
    const Seed found =
        Search(tool_local_, box, 0.5 * (square.s0 + square.s1), 0.5 * (square.t0 + square.t1), half,
               2, 0.25 * side, options_.search_floor_texels * texel, 0.0, 0.0);
    if (found.depth_m > best.depth_m) best = found;
    return;
  }
  // Four children, the most promising first.
  const double sm = 0.5 * (square.s0 + square.s1), tm = 0.5 * (square.t0 + square.t1);
  std::array<Box, 4> child{Box{square.s0, sm, square.t0, tm}, Box{sm, square.s1, square.t0, tm},
                           Box{square.s0, sm, tm, square.t1}, Box{sm, square.s1, tm, square.t1}};
  std::array<double, 4> bound{};
  std::array<int, 4> order{0, 1, 2, 3};
  for (int c = 0; c < 4; ++c) {
    ++squares_;
    bound[static_cast<std::size_t>(c)] =
        SideBound(env_all_, env, env_->texture, true, child[static_cast<std::size_t>(c)]) -
        SideBound(tool_all_, tool, tool_->texture, false, child[static_cast<std::size_t>(c)]);
  }
  std::sort(order.begin(), order.end(), [&](int a, int b) {
    return bound[static_cast<std::size_t>(a)] > bound[static_cast<std::size_t>(b)];
  });
  for (const int c : order) {
    // NaN and −∞ (a side missing) never pass.
    if (!(bound[static_cast<std::size_t>(c)] > ScreenThreshold(best.depth_m))) continue;
    const Box& b = child[static_cast<std::size_t>(c)];
    const auto keep = [&](const std::vector<Projected>& all, const std::vector<int>& list,
                          std::vector<int>& out) {
      out.clear();
      for (const int i : list) {
        if (Overlaps(all[static_cast<std::size_t>(i)], b.s0, b.s1, b.t0, b.t1)) out.push_back(i);
      }
    };
    keep(env_all_, env, env_screen_[static_cast<std::size_t>(depth + 1)]);
    keep(tool_all_, tool, tool_screen_[static_cast<std::size_t>(depth + 1)]);
    ScreenSquare(b, depth + 1, best, leaves);
    if (truncated_) return;
  }
}

void DepthRefiner::Screen(Seed& best) noexcept {
  squares_ = 0;
  truncated_ = false;
  const double half = 0.5 * window_.extent_m;
  const Box root{-half, half, -half, half};
  std::vector<int>& env = env_screen_[0];
  std::vector<int>& tool = tool_screen_[0];
  env.clear();
  tool.clear();
  for (std::size_t i = 0; i < env_all_.size(); ++i) env.push_back(static_cast<int>(i));
  for (std::size_t i = 0; i < tool_all_.size(); ++i) tool.push_back(static_cast<int>(i));
  ++squares_;
  const double bound = SideBound(env_all_, env, env_->texture, true, root) -
                       SideBound(tool_all_, tool, tool_->texture, false, root);
  int leaves = 0;
  if (bound > ScreenThreshold(best.depth_m)) ScreenSquare(root, 0, best, leaves);
  counters_.screen_squares += squares_;
  counters_.screen_leaves += static_cast<std::uint64_t>(leaves);
  if (truncated_) counters_.screen_truncated += 1;
}

}  // namespace ht
