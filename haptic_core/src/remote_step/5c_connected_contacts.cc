#include <algorithm>
#include <array>
#include <cmath>
#include <glm/geometric.hpp>
#include <glm/trigonometric.hpp>
#include <limits>

#include "haptic_core/connected_contacts.h"

namespace ht {
namespace {

bool Valid(const OverlapFootprint& f) noexcept {
  return f.blocks_per_side > 0 && f.block_cells > 0 &&
         f.occupancy.size() >= static_cast<std::size_t>(f.blocks_per_side) * f.blocks_per_side;
}

/// Centre (m, W) of block (bi, bj) of footprint f.
glm::dvec3 BlockCenter(const OverlapFootprint& f, int bi, int bj) noexcept {
  const ContactWindow& w = f.window;
  const double block_m = f.block_cells * w.cell_size_m();
  // The last block may be cut by the window's edge: its centre is that of its cells.
  const auto centre = [&](int b) {
    const double lo = b * block_m;
    const double hi = std::min(w.extent_m, lo + block_m);
    return 0.5 * (lo + hi) - 0.5 * w.extent_m;
  };
  return w.center_W + centre(bi) * w.axis_u_W + centre(bj) * w.axis_v_W;
}

/// Axis-aligned box (W) of the occupied blocks' centres; false when none is occupied.
bool OccupiedBox(const OverlapFootprint& f, glm::dvec3& lo, glm::dvec3& hi) noexcept {
  lo = glm::dvec3(std::numeric_limits<double>::infinity());
  hi = -lo;
  bool any = false;
  const int nb = f.blocks_per_side;
  for (int bj = 0; bj < nb; ++bj) {
    for (int bi = 0; bi < nb; ++bi) {
      if (f.occupancy[static_cast<std::size_t>(bj) * nb + bi] == 0) continue;
      const glm::dvec3 p = BlockCenter(f, bi, bj);
      lo = glm::min(lo, p);
      hi = glm::max(hi, p);
      any = true;
    }
  }
  return any;
}

}  // namespace

double FootprintGap(const OverlapFootprint& a, const OverlapFootprint& b,
                    double enough_m) noexcept {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  if (!Valid(a) || !Valid(b)) return kInf;
  glm::dvec3 lo_b, hi_b, lo_a, hi_a;
  if (!OccupiedBox(a, lo_a, hi_a) || !OccupiedBox(b, lo_b, hi_b)) return kInf;
  double best2 = kInf;
  const double enough2 = enough_m > 0.0 ? enough_m * enough_m : -1.0;
  const int na = a.blocks_per_side, nb = b.blocks_per_side;
  for (int aj = 0; aj < na; ++aj) {
    for (int ai = 0; ai < na; ++ai) {
      if (a.occupancy[static_cast<std::size_t>(aj) * na + ai] == 0) continue;
      const glm::dvec3 p = BlockCenter(a, ai, aj);
      // b's box bounds every distance from p: skip p when the box is no nearer than the best.
      const glm::dvec3 out = glm::max(glm::dvec3(0.0), glm::max(lo_b - p, p - hi_b));
      if (glm::dot(out, out) >= best2) continue;
      for (int bj = 0; bj < nb; ++bj) {
        for (int bi = 0; bi < nb; ++bi) {
          if (b.occupancy[static_cast<std::size_t>(bj) * nb + bi] == 0) continue;
          const glm::dvec3 d = BlockCenter(b, bi, bj) - p;
          best2 = std::min(best2, glm::dot(d, d));
          if (best2 < enough2) return std::sqrt(best2);
        }
      }
    }
  }
  return std::sqrt(best2);
}

double OverlapLink(double gap_m, double link_m, double fade_m) noexcept {
  if (std::isnan(gap_m)) return 0.0;
  if (gap_m <= link_m) return 1.0;
  if (!(fade_m > 0.0)) return 0.0;
  return std::clamp(1.0 - (gap_m - link_m) / fade_m, 0.0, 1.0);
}

void LinkedPenaltyShares(std::span<const double> depths_m, std::span<const double> links,
                         double temperature_m, std::span<double> shares) noexcept {
  const std::size_t n = depths_m.size();
  if (shares.size() < n || links.size() < n * n) return;
  const double tau = temperature_m > 0.0 && std::isfinite(temperature_m) ? temperature_m : 1e-6;
  double deepest = -std::numeric_limits<double>::infinity();
  for (double d : depths_m) {
    if (std::isfinite(d)) deepest = std::max(deepest, d);
  }
  const auto e = [&](std::size_t i) { return std::exp((depths_m[i] - deepest) / tau); };
  for (std::size_t i = 0; i < n; ++i) {
    if (!std::isfinite(depths_m[i])) {
      shares[i] = 0.0;
      continue;
    }
    double rivals = 0.0;
    for (std::size_t j = 0; j < n; ++j) {
      if (j == i || !std::isfinite(depths_m[j])) continue;
      const double l = std::clamp(links[i * n + j], 0.0, 1.0);
      rivals += l * e(j);
    }
    if (e(i) > 0.0) {
      shares[i] = e(i) / (e(i) + rivals);
      continue;
    }
    // Its own weight underflowed (a contact far below the deepest, exp((δ − δ_max)/τ) = 0): the
    // same share relative to its own depth, 1 / (1 + Σ_j l_ij e^((δ_j − δ_i)/τ)), not 0/0.
    double relative = 0.0;
    for (std::size_t j = 0; j < n; ++j) {
      const double l = std::clamp(links[i * n + j], 0.0, 1.0);
      if (j == i || !std::isfinite(depths_m[j]) || !(l > 0.0)) continue;  // 0 · e^(+large): none
      relative += l * std::exp((depths_m[j] - depths_m[i]) / tau);
    }
    shares[i] = 1.0 / (1.0 + relative);
  }
}

void StrongestPathLinks(std::span<double> links, int n) noexcept {
  if (n <= 0 || links.size() < static_cast<std::size_t>(n) * static_cast<std::size_t>(n)) return;
  const auto at = [&](int i, int j) -> double& {
    return links[static_cast<std::size_t>(i) * static_cast<std::size_t>(n) +
                 static_cast<std::size_t>(j)];
  };
  for (int k = 0; k < n; ++k) {
    for (int i = 0; i < n; ++i) {
      if (i == k) continue;
      for (int j = 0; j < n; ++j) {
        if (j == i || j == k) continue;
        at(i, j) = std::max(at(i, j), std::min(at(i, k), at(k, j)));
      }
    }
  }
}

int ShareConnectedContacts(const HapticModel& tool, const RigidTransform& X_WT,
                           std::span<const ContactQuery> queries,
                           std::span<ContactLinearization> results,
                           const ContactSharingOptions& options, TexturePenetrationSolver& solver,
                           std::span<std::uint8_t> scratch, std::span<const int> family,
                           std::span<const std::span<const float>> base_overlaps) noexcept {
  const int n = static_cast<int>(
      std::min({queries.size(), results.size(), static_cast<std::size_t>(kMaxContacts)}));
  const auto per_contact = static_cast<std::size_t>(kMaxSharingBlocks) * kMaxSharingBlocks;
  if (n < 2 || !(options.link_m > 0.0) || scratch.size() < per_contact * n) return 0;
  const double reach_m = options.link_m + std::max(0.0, options.fade_m);
  const double cos_angle = std::cos(glm::radians(options.max_normal_angle_deg));
  const auto positive = [&](int i) {
    const double d = results[static_cast<std::size_t>(i)].depth_m;
    return std::isfinite(d) && d > 0.0;
  };
  // Two contacts may be one region: one object, normals within the clustering angle.
  const bool families = family.size() >= queries.size();
  const auto may_link = [&](int i, int j) {
    const ContactQuery& a = queries[static_cast<std::size_t>(i)];
    const ContactQuery& b = queries[static_cast<std::size_t>(j)];
    if (families && family[static_cast<std::size_t>(i)] >= 0 &&
        family[static_cast<std::size_t>(i)] == family[static_cast<std::size_t>(j)]) {
      return false;
    }
    return a.environment == b.environment && a.X_WO.translation == b.X_WO.translation &&
           a.X_WO.rotation == b.X_WO.rotation &&
           glm::dot(a.window.normal_W, b.window.normal_W) >= cos_angle;
  };
  // Only contacts with a candidate within reach of their windows are rendered again.
  std::array<bool, kMaxContacts> needed{};
  bool any = false;
  for (int i = 0; i < n; ++i) {
    for (int j = i + 1; j < n; ++j) {
      if (!positive(i) || !positive(j) || !may_link(i, j)) continue;
      const ContactWindow& a = queries[static_cast<std::size_t>(i)].window;
      const ContactWindow& b = queries[static_cast<std::size_t>(j)].window;
      const double reach = 0.5 * std::sqrt(2.0) * (a.extent_m + b.extent_m) + reach_m;
      if (glm::length(a.center_W - b.center_W) > reach) continue;
      needed[static_cast<std::size_t>(i)] = needed[static_cast<std::size_t>(j)] = true;
      any = true;
    }
  }
  if (!any) return 0;
  std::array<OverlapFootprint, kMaxContacts> footprints{};
  std::array<bool, kMaxContacts> occupied{};
  for (int i = 0; i < n; ++i) {
    if (!needed[static_cast<std::size_t>(i)]) continue;
    const ContactQuery& q = queries[static_cast<std::size_t>(i)];
    // Blocks of about a quarter of the link, at most kMaxSharingBlocks a side.
    const int n_cells = q.window.resolution;
    int block =
        std::max(1, static_cast<int>(std::ceil(0.25 * options.link_m / q.window.cell_size_m())));
    block = std::max(block, (n_cells + kMaxSharingBlocks - 1) / kMaxSharingBlocks);
    const int nb = (n_cells + block - 1) / block;
    const std::span<std::uint8_t> occupancy(
        scratch.data() + static_cast<std::size_t>(i) * per_contact,
        static_cast<std::size_t>(nb) * nb);
    const bool kept = base_overlaps.size() >= queries.size() &&
                      !base_overlaps[static_cast<std::size_t>(i)].empty();
    const int count =
        kept ? solver.OverlapOccupancy(base_overlaps[static_cast<std::size_t>(i)], q.window, block,
                                       occupancy)
             : solver.OverlapOccupancy(tool, X_WT, *q.environment, q.X_WO, q.window, block,
                                       occupancy, q.environment_triangles, q.tool_triangles);
    if (count <= 0) continue;
    footprints[static_cast<std::size_t>(i)] = {q.window, block, nb, occupancy};
    occupied[static_cast<std::size_t>(i)] = true;
  }
  // The links of the rendered contacts, then their shares.
  std::array<int, kMaxContacts> index{};
  int m = 0;
  for (int i = 0; i < n; ++i) {
    if (occupied[static_cast<std::size_t>(i)]) index[static_cast<std::size_t>(m++)] = i;
  }
  if (m < 2) return 0;
  std::array<double, kMaxContacts * kMaxContacts> links{};
  std::array<double, kMaxContacts> depths{}, shares{};
  bool linked = false;
  for (int a = 0; a < m; ++a) {
    const int i = index[static_cast<std::size_t>(a)];
    depths[static_cast<std::size_t>(a)] = results[static_cast<std::size_t>(i)].depth_m;
    for (int b = a + 1; b < m; ++b) {
      const int j = index[static_cast<std::size_t>(b)];
      double l = 0.0;
      if (may_link(i, j)) {
        l = OverlapLink(FootprintGap(footprints[static_cast<std::size_t>(i)],
                                     footprints[static_cast<std::size_t>(j)], options.link_m),
                        options.link_m, options.fade_m);
      }
      links[static_cast<std::size_t>(a * m + b)] = links[static_cast<std::size_t>(b * m + a)] = l;
      linked = linked || l > 0.0;
    }
  }
  if (!linked) return 0;
  const auto count = static_cast<std::size_t>(m);
  StrongestPathLinks({links.data(), count * count}, m);
  LinkedPenaltyShares({depths.data(), count}, {links.data(), count * count}, options.temperature_m,
                      {shares.data(), count});
  int changed = 0;
  for (int a = 0; a < m; ++a) {
    const double s = shares[static_cast<std::size_t>(a)];
    if (s >= 1.0) continue;
    results[static_cast<std::size_t>(index[static_cast<std::size_t>(a)])].stiffness_n_per_m *= s;
    ++changed;
  }
  return changed;
}

}  // namespace ht
