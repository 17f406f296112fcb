// OverlapCellLinks (haptic_core/overlap_links.h) against the cell-by-cell passes it replaced in
// TexturePenetrationSolver::OverlapRegions: every pair of cells within the reach tested, one by
// one. Two routes to the same components and bridge levels, compared bit for bit on random grids.

#include "haptic_core/overlap_links.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

namespace ht {
namespace {

int ReferenceFind(std::vector<int>& parent, int c) {
  while (parent[static_cast<std::size_t>(c)] != c) {
    parent[static_cast<std::size_t>(c)] = parent[static_cast<std::size_t>(parent[c])];
    c = parent[static_cast<std::size_t>(c)];
  }
  return c;
}

// Each cell with depth > 0 against every cell after it within the reach (a half disc).
std::vector<int> ReferenceComponents(const std::vector<float>& depth, int n, double reach) {
  std::vector<int> parent(depth.size(), -1);
  for (std::size_t c = 0; c < depth.size(); ++c) {
    if (depth[c] > 0.0f) parent[c] = static_cast<int>(c);
  }
  const int r = static_cast<int>(std::floor(reach));
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      const int c = j * n + i;
      if (parent[static_cast<std::size_t>(c)] < 0) continue;
      for (int dj = 0; dj <= r && j + dj < n; ++dj) {
        for (int di = (dj == 0 ? 1 : -r); di <= r; ++di) {
          if (i + di < 0 || i + di >= n || di * di + dj * dj > reach * reach) continue;
          const int d = (j + dj) * n + (i + di);
          if (parent[static_cast<std::size_t>(d)] < 0) continue;
          const int a = ReferenceFind(parent, c), b = ReferenceFind(parent, d);
          if (a != b) parent[static_cast<std::size_t>(std::max(a, b))] = std::min(a, b);
        }
      }
    }
  }
  for (std::size_t c = 0; c < depth.size(); ++c) {
    if (parent[c] >= 0) parent[c] = ReferenceFind(parent, static_cast<int>(c));
  }
  return parent;
}

// Kruskal over the superlevel sets with every reached cell tested (the form of issue 32's
// thirtieth stop).
std::vector<float> ReferenceBridgeLevels(const std::vector<float>& depth, int n, double reach,
                                         float floor) {
  std::vector<int> order;
  for (std::size_t c = 0; c < depth.size(); ++c) {
    if (depth[c] > floor) order.push_back(static_cast<int>(c));
  }
  std::sort(order.begin(), order.end(), [&](int a, int b) {
    const float da = depth[static_cast<std::size_t>(a)], db = depth[static_cast<std::size_t>(b)];
    return da > db || (da == db && a < b);
  });
  std::vector<int> parent(depth.size(), -1), peak(depth.size(), -1);
  std::vector<float> level(depth.size(), -std::numeric_limits<float>::infinity());
  const auto d = [&](int c) { return depth[static_cast<std::size_t>(c)]; };
  const int r = static_cast<int>(std::floor(reach));
  for (const int c : order) {
    parent[static_cast<std::size_t>(c)] = c;
    peak[static_cast<std::size_t>(c)] = c;
    const int i = c % n, j = c / n;
    for (int dj = -r; dj <= r; ++dj) {
      if (j + dj < 0 || j + dj >= n) continue;
      for (int di = -r; di <= r; ++di) {
        if (i + di < 0 || i + di >= n || di * di + dj * dj > reach * reach) continue;
        const int o = (j + dj) * n + (i + di);
        if (parent[static_cast<std::size_t>(o)] < 0) continue;
        int a = ReferenceFind(parent, c), b = ReferenceFind(parent, o);
        if (a == b) continue;
        int pa = peak[static_cast<std::size_t>(a)], pb = peak[static_cast<std::size_t>(b)];
        if (d(pa) < d(pb) || (d(pa) == d(pb) && pa > pb)) {
          std::swap(a, b);
          std::swap(pa, pb);
        }
        if (d(c) <= 0.0f && d(pb) > 0.0f) level[static_cast<std::size_t>(pb)] = d(c);
        parent[static_cast<std::size_t>(b)] = a;
      }
    }
  }
  return level;
}

// A random field of a few Gaussian bumps less a level, with noise and sometimes quantized (ties)
// or NaN cells: overlaps of several regions at every reach.
std::vector<float> RandomField(std::mt19937& rng, int n) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const int bumps = 1 + static_cast<int>(u(rng) * 8.0);
  std::vector<double> cx(bumps), cy(bumps), s(bumps), a(bumps);
  for (int b = 0; b < bumps; ++b) {
    cx[b] = u(rng) * n;
    cy[b] = u(rng) * n;
    s[b] = 1.0 + u(rng) * n * 0.2;
    a[b] = 20e-6 + u(rng) * 80e-6;
  }
  const double offset = 10e-6 + u(rng) * 60e-6;
  const double noise = u(rng) < 0.5 ? 0.0 : 5e-6 * u(rng);
  const bool quantize = u(rng) < 0.3;
  std::vector<float> f(static_cast<std::size_t>(n) * n);
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      double h = -offset + noise * (u(rng) - 0.5);
      for (int b = 0; b < bumps; ++b) {
        const double dx = i - cx[b], dy = j - cy[b];
        h += a[b] * std::exp(-(dx * dx + dy * dy) / (2.0 * s[b] * s[b]));
      }
      if (quantize) h = std::round(h / 4e-6) * 4e-6;
      f[static_cast<std::size_t>(j) * n + i] = static_cast<float>(h);
    }
  }
  if (u(rng) < 0.2) f[static_cast<std::size_t>(u(rng) * (n * n - 1))] = std::nanf("");
  return f;
}

TEST(OverlapCellLinks, ComponentsAndBridgeLevelsAreTheCellByCellPassesBitForBit) {
  std::mt19937 rng(20261127);
  const int sizes[] = {1, 7, 50, 64, 65, 90, 128};
  const double reaches[] = {0.0, 0.7, 1.0, 1.5, 2.0, 4.3, 12.0, 25.0, 200.0};
  OverlapCellLinks links(128);
  int regions_seen = 0, levels_seen = 0;
  for (const int n : sizes) {
    for (const double reach : reaches) {
      // The reference tests every pair within the reach: the largest grids at the smaller reaches.
      if (n > 64 && reach > 12.0) continue;
      for (int trial = 0; trial < 2; ++trial) {
        const std::vector<float> f = RandomField(rng, n);
        std::vector<int> parent(f.size(), 7);
        const int count = links.Components(f, n, reach, parent);
        const std::vector<int> expected = ReferenceComponents(f, n, reach);
        ASSERT_EQ(parent, expected) << "n " << n << " reach " << reach;
        int roots = 0;
        for (std::size_t c = 0; c < expected.size(); ++c) {
          roots += expected[c] == static_cast<int>(c) ? 1 : 0;
        }
        ASSERT_EQ(count, roots);
        regions_seen += count >= 2 ? 1 : 0;
        for (const float floor : {0.0f, -20e-6f, -1.0f}) {
          std::vector<float> level(f.size(), 3.0f);
          ASSERT_TRUE(links.BridgeLevels(f, n, reach, floor, level));
          const std::vector<float> expected_level = ReferenceBridgeLevels(f, n, reach, floor);
          // Asked for the components' peaks only, the pass may stop early: their levels are the
          // full pass's.
          std::vector<int> peaks;
          for (std::size_t c = 0; c < f.size(); ++c) {
            if (parent[c] != static_cast<int>(c)) continue;
            int peak = static_cast<int>(c);
            for (std::size_t e = 0; e < f.size(); ++e) {
              if (parent[e] == parent[c] && f[e] > f[static_cast<std::size_t>(peak)]) {
                peak = static_cast<int>(e);
              }
            }
            peaks.push_back(peak);
          }
          std::vector<float> peak_level(f.size(), 3.0f);
          ASSERT_TRUE(links.BridgeLevels(f, n, reach, floor, peak_level, peaks));
          for (const int p : peaks) {
            ASSERT_EQ(peak_level[static_cast<std::size_t>(p)],
                      expected_level[static_cast<std::size_t>(p)])
                << "n " << n << " reach " << reach << " peak " << p;
          }
          for (std::size_t c = 0; c < f.size(); ++c) {
            ASSERT_EQ(level[c], expected_level[c])
                << "n " << n << " reach " << reach << " cell " << c;
            levels_seen += std::isfinite(level[c]) ? 1 : 0;
          }
        }
      }
    }
  }
  // The grids exercised what they are for: several regions, and finite bridge levels (this seed:
  // 99 finite levels).
  EXPECT_GT(regions_seen, 20);
  EXPECT_GT(levels_seen, 50);
}

TEST(OverlapCellLinks, BadInputWritesNothing) {
  OverlapCellLinks links(8);
  std::vector<float> f(16, 1.0f);
  std::vector<int> parent(16, 5);
  std::vector<float> level(16, 2.0f);
  EXPECT_EQ(links.Components(f, 4, -1.0, parent), -1);
  EXPECT_EQ(links.Components(f, 4, std::nan(""), parent), -1);
  EXPECT_EQ(links.Components(f, 5, 1.0, parent), -1);  // 16 cells are not 5 × 5
  EXPECT_EQ(std::count(parent.begin(), parent.end(), 5), 16);
  EXPECT_FALSE(links.BridgeLevels(f, 4, -1.0, 0.0f, level));
  EXPECT_FALSE(links.BridgeLevels(f, 4, 1.0, 0.0f, std::span<float>(level).first(15)));
  EXPECT_EQ(std::count(level.begin(), level.end(), 2.0f), 16);
  // A grid larger than the reserve still works (allocating).
  std::vector<int> large(400);
  EXPECT_EQ(links.Components(std::vector<float>(400, 1.0f), 20, 1.0, large), 1);
}

}  // namespace
}  // namespace ht
