#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>

#include "haptic_core/overlap_links.h"

namespace ht {
namespace {

// The first set bit of a row in [from, to], or −1.
int NextSet(const std::uint64_t* row, int from, int to) noexcept {
  if (from > to) return -1;
  int w = from >> 6;
  const int last = to >> 6;
  std::uint64_t word = row[w] & (~std::uint64_t{0} << (from & 63));
  for (;;) {
    if (word != 0) {
      const int b = (w << 6) + std::countr_zero(word);
      return b <= to ? b : -1;
    }
    if (++w > last) return -1;
    word = row[w];
  }
}

// The first clear bit of a row in [from, to], or to + 1.
int NextClear(const std::uint64_t* row, int from, int to) noexcept {
  if (from > to) return to + 1;
  int w = from >> 6;
  const int last = to >> 6;
  std::uint64_t word = ~row[w] & (~std::uint64_t{0} << (from & 63));
  for (;;) {
    if (word != 0) return std::min((w << 6) + std::countr_zero(word), to + 1);
    if (++w > last) return to + 1;
    word = ~row[w];
  }
}

// Calls f(cell) for the first set cell of each run of set cells of row `row_j` within [lo, hi].
template <typename F>
void ForEachRun(const std::uint64_t* row, int row_j, int n, int lo, int hi, F&& f) {
  lo = std::max(lo, 0);
  hi = std::min(hi, n - 1);
  for (int p = NextSet(row, lo, hi); p >= 0;) {
    f(row_j * n + p);
    const int q = NextClear(row, p, hi);
    p = q > hi ? -1 : NextSet(row, q, hi);
  }
}

}  // namespace

OverlapCellLinks::OverlapCellLinks(int max_resolution) {
  const int n = std::max(max_resolution, 0);
  const auto cells = static_cast<std::size_t>(n) * static_cast<std::size_t>(n);
  rows_.reserve(static_cast<std::size_t>(n) * static_cast<std::size_t>((n + 63) / 64));
  half_width_.reserve(static_cast<std::size_t>(n) + 1);
  order_.reserve(cells);
  parent_.reserve(cells);
  peak_.reserve(cells);
}

bool OverlapCellLinks::Prepare(int n, double reach, std::size_t cells) noexcept {
  if (n < 1 || !(reach >= 0.0)) return false;
  if (cells != static_cast<std::size_t>(n) * static_cast<std::size_t>(n)) return false;
  words_ = (n + 63) / 64;
  rows_.assign(static_cast<std::size_t>(n) * static_cast<std::size_t>(words_), 0);
  // Links reach at most the grid's side: a larger reach links what n − 1 does.
  r_ = static_cast<int>(std::min(std::floor(reach), static_cast<double>(n - 1)));
  half_width_.assign(static_cast<std::size_t>(r_) + 1, 0);
  for (int dj = 0; dj <= r_; ++dj) {
    int w = r_;
    while (w > 0 && w * w + dj * dj > reach * reach) --w;
    half_width_[static_cast<std::size_t>(dj)] = w;
  }
  return true;
}

int OverlapCellLinks::Find(std::span<int> parent, int c) const noexcept {
  while (parent[static_cast<std::size_t>(c)] != c) {
    const int up = parent[static_cast<std::size_t>(c)];
    parent[static_cast<std::size_t>(c)] = parent[static_cast<std::size_t>(up)];  // path halving
    c = up;
  }
  return c;
}

int OverlapCellLinks::Components(std::span<const float> depth, int n, double reach,
                                 std::span<int> parent) noexcept {
  if (parent.size() != depth.size() || !Prepare(n, reach, depth.size())) return -1;
  const auto cells = depth.size();
  // With a reach of a cell or more, each run of set cells starts as one component, a star about
  // its first cell (its smallest index, so roots stay first cells).
  for (std::size_t c = 0; c < cells; ++c) {
    const bool set = depth[c] > 0.0f;
    const bool run_goes_on = set && r_ >= 1 && c % n != 0 && parent[c - 1] >= 0;
    parent[c] = !set ? -1 : run_goes_on ? parent[c - 1] : static_cast<int>(c);
    if (set) rows_[c / n * words_ + (c % n) / 64] |= std::uint64_t{1} << (c % n % 64);
  }
  const auto link = [&](int c, int d) {
    const int a = Find(parent, c), b = Find(parent, d);
    if (a != b) parent[static_cast<std::size_t>(std::max(a, b))] = std::min(a, b);
  };
  if (r_ >= 1) {
    // Each run of set cells [i0, i1] is one component already (above), and a cell dj rows below is
    // within reach of one of its cells exactly when it lies in [i0 − w, i1 + w], w the half width
    // at dj: so each run links its first cell to one cell of every run in that range of the r rows
    // below, and of its own row after it.
    for (int j = 0; j < n; ++j) {
      const std::uint64_t* row = rows_.data() + static_cast<std::size_t>(j) * words_;
      for (int i0 = NextSet(row, 0, n - 1); i0 >= 0;) {
        const int i1 = NextClear(row, i0, n - 1) - 1;
        const int c = j * n + i0;
        for (int dj = 0; dj <= r_ && j + dj < n; ++dj) {
          const int w = half_width_[static_cast<std::size_t>(dj)];
          ForEachRun(rows_.data() + static_cast<std::size_t>(j + dj) * words_, j + dj, n,
                     dj == 0 ? i1 + 1 : i0 - w, i1 + w, [&](int d) { link(c, d); });
        }
        i0 = i1 + 1 < n ? NextSet(row, i1 + 1, n - 1) : -1;
      }
    }
  }
  int count = 0;
  for (std::size_t c = 0; c < cells; ++c) {
    if (parent[c] < 0) continue;
    parent[c] = Find(parent, static_cast<int>(c));  // roots are first cells: parent[root] = root
    count += parent[c] == static_cast<int>(c) ? 1 : 0;
  }
  return count;
}

bool OverlapCellLinks::BridgeLevels(std::span<const float> depth, int n, double reach, float floor,
                                    std::span<float> level, std::span<const int> peaks) noexcept {
  if (level.size() != depth.size() || !Prepare(n, reach, depth.size())) return false;
  const auto cells = depth.size();
  order_.clear();
  for (std::size_t c = 0; c < cells; ++c) {
    if (depth[c] > floor) order_.push_back(static_cast<int>(c));  // NaN and −∞ drop out
  }
  std::sort(order_.begin(), order_.end(), [&](int a, int b) {
    const float da = depth[static_cast<std::size_t>(a)], db = depth[static_cast<std::size_t>(b)];
    return da > db || (da == db && a < b);
  });
  parent_.assign(cells, -1);
  peak_.assign(cells, -1);
  std::fill(level.begin(), level.end(), -std::numeric_limits<float>::infinity());
  const auto d = [&](int c) { return depth[static_cast<std::size_t>(c)]; };
  // The wanted peaks still without a level (the deepest cell never gets one); −1: all wanted.
  const auto wanted = [&](int c) {
    return std::find(peaks.begin(), peaks.end(), c) != peaks.end();
  };
  int open = -1;
  if (!peaks.empty() && !order_.empty()) {
    open = 0;
    for (std::size_t k = 0; k < peaks.size(); ++k) {
      const int p = peaks[k];
      if (p < 0 || static_cast<std::size_t>(p) >= cells || p == order_[0]) continue;
      if (std::find(peaks.begin(), peaks.begin() + static_cast<std::ptrdiff_t>(k), p) !=
          peaks.begin() + static_cast<std::ptrdiff_t>(k)) {
        continue;  // listed twice
      }
      ++open;
    }
  }
  // Kruskal over the superlevel sets. A cell's links are made before its bit is set, so that
  // every run of set bits in a row is one component when it is read (a cell's row neighbours
  // joined it when the later of them was added).
  for (const int c : order_) {
    if (open == 0) break;  // every wanted peak has its level
    const auto uc = static_cast<std::size_t>(c);
    parent_[uc] = c;
    peak_[uc] = c;
    const float t = d(c);
    const int i = c % n, j = c / n;
    const auto join = [&](int other) {
      int a = Find(parent_, c), b = Find(parent_, other);
      if (a == b) return;
      int pa = peak_[static_cast<std::size_t>(a)], pb = peak_[static_cast<std::size_t>(b)];
      if (d(pa) < d(pb) || (d(pa) == d(pb) && pa > pb)) {
        std::swap(a, b);
        std::swap(pa, pb);
      }
      // a holds the elder (deeper) peak; b's component ends here.
      if (t <= 0.0f && d(pb) > 0.0f) {
        level[static_cast<std::size_t>(pb)] = t;
        if (open > 0 && wanted(pb)) --open;
      }
      parent_[static_cast<std::size_t>(b)] = a;
    };
    if (r_ >= 1) {
      for (int dj = -r_; dj <= r_; ++dj) {
        if (j + dj < 0 || j + dj >= n) continue;
        const int w = half_width_[static_cast<std::size_t>(std::abs(dj))];
        ForEachRun(rows_.data() + static_cast<std::size_t>(j + dj) * words_, j + dj, n, i - w,
                   i + w, join);
      }
    }
    rows_[static_cast<std::size_t>(j) * words_ + static_cast<std::size_t>(i / 64)] |=
        std::uint64_t{1} << (i % 64);
  }
  return true;
}

}  // namespace ht
