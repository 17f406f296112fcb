#include "haptic_core/connected_contacts.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <glm/geometric.hpp>
#include <glm/trigonometric.hpp>
#include <limits>

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

bool FootprintsWithin(const OverlapFootprint& a, const OverlapFootprint& b,
                      double link_m) noexcept {
  if (!(link_m > 0.0) || !Valid(a) || !Valid(b)) return false;
  glm::dvec3 lo_a, hi_a, lo_b, hi_b;
  if (!OccupiedBox(a, lo_a, hi_a) || !OccupiedBox(b, lo_b, hi_b)) return false;
  const glm::dvec3 gap = glm::max(glm::dvec3(0.0), glm::max(lo_a - hi_b, lo_b - hi_a));
  if (glm::dot(gap, gap) >= link_m * link_m) return false;
  const int na = a.blocks_per_side, nb = b.blocks_per_side;
  for (int aj = 0; aj < na; ++aj) {
    for (int ai = 0; ai < na; ++ai) {
      if (a.occupancy[static_cast<std::size_t>(aj) * na + ai] == 0) continue;
      const glm::dvec3 p = BlockCenter(a, ai, aj);
      // Blocks of b whose centre lies outside p's box by a link cannot be linked to it.
      if (glm::any(glm::lessThan(p + link_m, lo_b)) || glm::any(glm::greaterThan(p - link_m, hi_b)))
        continue;
      for (int bj = 0; bj < nb; ++bj) {
        for (int bi = 0; bi < nb; ++bi) {
          if (b.occupancy[static_cast<std::size_t>(bj) * nb + bi] == 0) continue;
          const glm::dvec3 d = BlockCenter(b, bi, bj) - p;
          if (glm::dot(d, d) < link_m * link_m) return true;
        }
      }
    }
  }
  return false;
}

bool FootprintCentroidInside(const OverlapFootprint& a, const OverlapFootprint& b,
                             double margin_m) noexcept {
  if (!Valid(a) || !Valid(b) || !(margin_m >= 0.0)) return false;
  const ContactWindow& w = a.window;
  double u0 = std::numeric_limits<double>::infinity(), u1 = -u0, v0 = u0, v1 = -u0;
  const int na = a.blocks_per_side;
  for (int bj = 0; bj < na; ++bj) {
    for (int bi = 0; bi < na; ++bi) {
      if (a.occupancy[static_cast<std::size_t>(bj) * na + bi] == 0) continue;
      const glm::dvec3 d = BlockCenter(a, bi, bj) - w.center_W;
      u0 = std::min(u0, glm::dot(d, w.axis_u_W));
      u1 = std::max(u1, glm::dot(d, w.axis_u_W));
      v0 = std::min(v0, glm::dot(d, w.axis_v_W));
      v1 = std::max(v1, glm::dot(d, w.axis_v_W));
    }
  }
  if (!(u1 >= u0)) return false;
  const double block_m = a.block_cells * w.cell_size_m();
  const double half = 0.5 * (std::max(u1 - u0, v1 - v0) + block_m) + margin_m;
  glm::dvec3 sum(0.0);
  int count = 0;
  const int nb = b.blocks_per_side;
  for (int bj = 0; bj < nb; ++bj) {
    for (int bi = 0; bi < nb; ++bi) {
      if (b.occupancy[static_cast<std::size_t>(bj) * nb + bi] == 0) continue;
      sum += BlockCenter(b, bi, bj);
      ++count;
    }
  }
  if (count == 0) return false;
  const glm::dvec3 d = sum / static_cast<double>(count) - w.center_W;
  return std::abs(glm::dot(d, w.axis_u_W) - 0.5 * (u0 + u1)) <= half &&
         std::abs(glm::dot(d, w.axis_v_W) - 0.5 * (v0 + v1)) <= half &&
         std::abs(glm::dot(d, w.normal_W)) <= half;
}

void PenaltySharesByDepth(std::span<const double> depths_m, double temperature_m,
                          std::span<double> shares) noexcept {
  const std::size_t n = std::min(depths_m.size(), shares.size());
  double deepest = -std::numeric_limits<double>::infinity();
  int finite = 0;
  for (std::size_t i = 0; i < n; ++i) {
    if (!std::isfinite(depths_m[i])) continue;
    deepest = std::max(deepest, depths_m[i]);
    ++finite;
  }
  const bool equal = !(temperature_m > 0.0) || !std::isfinite(temperature_m);
  double sum = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    shares[i] = !std::isfinite(depths_m[i]) ? 0.0
                : equal                     ? 1.0
                                            : std::exp((depths_m[i] - deepest) / temperature_m);
    sum += shares[i];
  }
  for (std::size_t i = 0; i < n; ++i) shares[i] = finite > 0 ? shares[i] / sum : 0.0;
}

int ShareConnectedContacts(const HapticModel& tool, const RigidTransform& X_WT,
                           std::span<const ContactQuery> queries,
                           std::span<ContactLinearization> results,
                           const ContactSharingOptions& options, TexturePenetrationSolver& solver,
                           std::span<std::uint8_t> scratch) noexcept {
  const int n = static_cast<int>(
      std::min({queries.size(), results.size(), static_cast<std::size_t>(kMaxContacts)}));
  const auto per_contact = static_cast<std::size_t>(kMaxSharingBlocks) * kMaxSharingBlocks;
  if (n < 2 || !(options.link_m > 0.0) || scratch.size() < per_contact * n) return 0;
  const double link = options.link_m;
  // The margin of an overlap's window (the pipeline truth's window_margin_m).
  constexpr double kShareMargin = 1e-3;
  const double cos_angle = std::cos(glm::radians(options.max_normal_angle_deg));
  const auto positive = [&](int i) {
    const double d = results[static_cast<std::size_t>(i)].depth_m;
    return std::isfinite(d) && d > 0.0;
  };
  // Two contacts may be one region: one object, normals within the clustering angle.
  const auto may_link = [&](int i, int j) {
    const ContactQuery& a = queries[static_cast<std::size_t>(i)];
    const ContactQuery& b = queries[static_cast<std::size_t>(j)];
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
      const double reach = 0.5 * std::sqrt(2.0) * (a.extent_m + b.extent_m) + link;
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
    int block = std::max(1, static_cast<int>(std::ceil(0.25 * link / q.window.cell_size_m())));
    block = std::max(block, (n_cells + kMaxSharingBlocks - 1) / kMaxSharingBlocks);
    const int nb = (n_cells + block - 1) / block;
    const std::span<std::uint8_t> occupancy(
        scratch.data() + static_cast<std::size_t>(i) * per_contact,
        static_cast<std::size_t>(nb) * nb);
    const int count = solver.OverlapOccupancy(tool, X_WT, *q.environment, q.X_WO, q.window, block,
                                              occupancy, q.environment_triangles, q.tool_triangles);
    if (count <= 0) continue;
    footprints[static_cast<std::size_t>(i)] = {q.window, block, nb, occupancy};
    occupied[static_cast<std::size_t>(i)] = true;
  }
  // Single linkage over the contacts (union-find), then one penalty per group.
  std::array<int, kMaxContacts> parent{};
  for (int i = 0; i < n; ++i) parent[static_cast<std::size_t>(i)] = i;
  const auto find = [&](int i) {
    while (parent[static_cast<std::size_t>(i)] != i) i = parent[static_cast<std::size_t>(i)];
    return i;
  };
  for (int i = 0; i < n; ++i) {
    for (int j = i + 1; j < n; ++j) {
      if (!occupied[static_cast<std::size_t>(i)] || !occupied[static_cast<std::size_t>(j)] ||
          !may_link(i, j) || find(i) == find(j)) {
        continue;
      }
      const OverlapFootprint& a = footprints[static_cast<std::size_t>(i)];
      const OverlapFootprint& b = footprints[static_cast<std::size_t>(j)];
      if (FootprintsWithin(a, b, link) ||
          (options.centroid_in_window && (FootprintCentroidInside(a, b, kShareMargin) ||
                                          FootprintCentroidInside(b, a, kShareMargin)))) {
        parent[static_cast<std::size_t>(std::max(find(i), find(j)))] = std::min(find(i), find(j));
      }
    }
  }
  int shared = 0;
  std::array<double, kMaxContacts> depths{}, shares{};
  std::array<int, kMaxContacts> members{};
  for (int root = 0; root < n; ++root) {
    int m = 0;
    for (int i = 0; i < n; ++i) {
      if (!occupied[static_cast<std::size_t>(i)] || find(i) != root) continue;
      members[static_cast<std::size_t>(m)] = i;
      depths[static_cast<std::size_t>(m++)] = results[static_cast<std::size_t>(i)].depth_m;
    }
    if (m < 2) continue;
    PenaltySharesByDepth({depths.data(), static_cast<std::size_t>(m)}, options.temperature_m,
                         {shares.data(), static_cast<std::size_t>(m)});
    for (int k = 0; k < m; ++k) {
      results[static_cast<std::size_t>(members[static_cast<std::size_t>(k)])].stiffness_n_per_m *=
          shares[static_cast<std::size_t>(k)];
    }
    shared += m;
  }
  return shared;
}

}  // namespace ht
