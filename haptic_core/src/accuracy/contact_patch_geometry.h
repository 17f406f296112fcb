// The pipeline truth's geometry on full-resolution meshes (contact_patch_truth.h): a mesh's
// welded topology, where one triangle's edges pierce another, hash grids, the closest point on a
// triangle, the macroscopic surface normal, and union-find. Internal to src/accuracy/
// (contact_patch_truth.cc).
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <glm/geometric.hpp>
#include <glm/gtc/type_precision.hpp>
#include <unordered_map>
#include <vector>

#include "haptic_core/mesh.h"

namespace ht::patch_truth {

// A mesh's per-triangle data for the inside surfaces: unit face normals and areas in its frame,
// and its edge neighbours (−1 where an edge has no single other triangle), over vertices welded
// by position so that split vertices do not cut the flood fill.
struct MeshTopology {
  std::vector<glm::dvec3> normal_F;
  std::vector<double> area_m2;
  std::vector<std::array<int, 3>> neighbours;

  explicit MeshTopology(const TriangleMesh& mesh) {
    const std::size_t nf = mesh.triangles.size();
    normal_F.resize(nf);
    area_m2.resize(nf);
    neighbours.assign(nf, {-1, -1, -1});
    // Weld by exact position.
    struct Hash {
      std::size_t operator()(const glm::dvec3& p) const noexcept {
        const std::hash<double> h;
        return h(p.x) ^ (h(p.y) * 0x9e3779b97f4a7c15ull) ^ (h(p.z) * 0xc2b2ae3d27d4eb4full);
      }
    };
    std::unordered_map<glm::dvec3, int, Hash> weld;
    weld.reserve(mesh.vertices.size());
    std::vector<int> id(mesh.vertices.size());
    for (std::size_t v = 0; v < mesh.vertices.size(); ++v) {
      id[v] = weld.try_emplace(mesh.vertices[v], static_cast<int>(weld.size())).first->second;
    }
    std::unordered_map<std::uint64_t, std::array<int, 2>> edges;  // (a < b) → up to two faces
    edges.reserve(nf * 2);
    const auto key = [&](int a, int b) {
      const auto lo = static_cast<std::uint64_t>(std::min(a, b));
      const auto hi = static_cast<std::uint64_t>(std::max(a, b));
      return (lo << 32) | hi;
    };
    for (std::size_t f = 0; f < nf; ++f) {
      const glm::ivec3 t = mesh.triangles[f];
      const glm::dvec3 c = glm::cross(mesh.vertices[t[1]] - mesh.vertices[t[0]],
                                      mesh.vertices[t[2]] - mesh.vertices[t[0]]);
      const double len = glm::length(c);
      normal_F[f] = len > 0.0 ? c / len : glm::dvec3(0.0);
      area_m2[f] = 0.5 * len;
      for (int e = 0; e < 3; ++e) {
        auto [it, fresh] = edges.try_emplace(key(id[t[e]], id[t[(e + 1) % 3]]),
                                             std::array<int, 2>{static_cast<int>(f), -1});
        if (!fresh) it->second[1] = it->second[1] == -1 ? static_cast<int>(f) : -2;
      }
    }
    for (std::size_t f = 0; f < nf; ++f) {
      const glm::ivec3 t = mesh.triangles[f];
      for (int e = 0; e < 3; ++e) {
        const auto& pair = edges.at(key(id[t[e]], id[t[(e + 1) % 3]]));
        if (pair[1] < 0) continue;  // boundary or non-manifold edge
        neighbours[f][e] = pair[0] == static_cast<int>(f) ? pair[1] : pair[0];
      }
    }
  }
};

// Where the edges of triangle (a0, a1, a2) pierce triangle (b0, b1, b2): adds each crossing
// point to `sum` and counts it (Möller–Trumbore on each edge as a segment).
inline void EdgePiercings(const glm::dvec3& a0, const glm::dvec3& a1, const glm::dvec3& a2,
                          const glm::dvec3& b0, const glm::dvec3& b1, const glm::dvec3& b2,
                          glm::dvec3& sum, int& count) {
  const glm::dvec3 e1 = b1 - b0, e2 = b2 - b0;
  const glm::dvec3* corners[3] = {&a0, &a1, &a2};
  for (int e = 0; e < 3; ++e) {
    const glm::dvec3& o = *corners[e];
    const glm::dvec3 d = *corners[(e + 1) % 3] - o;
    const glm::dvec3 p = glm::cross(d, e2);
    const double det = glm::dot(e1, p);
    if (std::abs(det) < 1e-30) continue;
    const double inv = 1.0 / det;
    const glm::dvec3 t = o - b0;
    const double u = glm::dot(t, p) * inv;
    if (u < 0.0 || u > 1.0) continue;
    const glm::dvec3 q = glm::cross(t, e1);
    const double v = glm::dot(d, q) * inv;
    if (v < 0.0 || u + v > 1.0) continue;
    const double s = glm::dot(e2, q) * inv;
    if (s < 0.0 || s > 1.0) continue;
    sum += o + s * d;
    ++count;
  }
}

// The cell of a hash grid of cube side `cell` (m) that holds p, and the cell's hash key.
inline glm::i64vec3 GridCell(const glm::dvec3& p, double cell) {
  return glm::i64vec3(std::floor(p.x / cell), std::floor(p.y / cell), std::floor(p.z / cell));
}
inline std::uint64_t GridHash(const glm::i64vec3& c) {
  return static_cast<std::uint64_t>(c.x * 73856093LL) ^
         static_cast<std::uint64_t>(c.y * 19349663LL) ^
         static_cast<std::uint64_t>(c.z * 83492791LL);
}

// Indices in a hash grid of cube side `cell` (m): whatever lies within `cell` of a point is among
// the entries of the 27 cells about the point's own (ForEachNear; farther ones too, and those of
// cells whose keys collide). Used by the pairs' single linkage, the patches' gaps (step 4a) and
// SurfaceNormalGrid.
class CellGrid {
 public:
  explicit CellGrid(double cell) : cell_(cell) {}
  void Add(const glm::dvec3& p, int index) { AddToCell(GridCell(p, cell_), index); }
  void AddToCell(const glm::i64vec3& c, int index) { cells_[GridHash(c)].push_back(index); }
  // Calls f(index) for each entry of the 27 cells about the one holding p.
  template <class F>
  void ForEachNear(const glm::dvec3& p, F&& f) const {
    const glm::i64vec3 c = GridCell(p, cell_);
    for (int dx = -1; dx <= 1; ++dx) {
      for (int dy = -1; dy <= 1; ++dy) {
        for (int dz = -1; dz <= 1; ++dz) {
          const auto it = cells_.find(GridHash(c + glm::i64vec3(dx, dy, dz)));
          if (it == cells_.end()) continue;
          for (const int j : it->second) f(j);
        }
      }
    }
  }

 private:
  double cell_;
  std::unordered_map<std::uint64_t, std::vector<int>> cells_;
};

// The point of triangle (a, b, c) closest to p (Ericson, Real-Time Collision Detection, 5.1.5:
// the Voronoi region of p among the triangle's vertices, edges and face).
inline glm::dvec3 ClosestPointOnTriangle(const glm::dvec3& p, const glm::dvec3& a,
                                         const glm::dvec3& b, const glm::dvec3& c) {
  const glm::dvec3 ab = b - a, ac = c - a, ap = p - a;
  const double d1 = glm::dot(ab, ap), d2 = glm::dot(ac, ap);
  if (d1 <= 0.0 && d2 <= 0.0) return a;
  const glm::dvec3 bp = p - b;
  const double d3 = glm::dot(ab, bp), d4 = glm::dot(ac, bp);
  if (d3 >= 0.0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) return a + (d1 / (d1 - d3)) * ab;
  const glm::dvec3 cp = p - c;
  const double d5 = glm::dot(ab, cp), d6 = glm::dot(ac, cp);
  if (d6 >= 0.0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) return a + (d2 / (d2 - d6)) * ac;
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0) {
    return b + ((d4 - d3) / ((d4 - d3) + (d5 - d6))) * (c - b);
  }
  const double denom = va + vb + vc;
  if (!(std::abs(denom) > 0.0)) return a;  // degenerate triangle
  const double v = vb / denom, w = vc / denom;
  return a + v * ab + w * ac;
}

// A mesh's surface normal averaged over a ball (its macroscopic normal): the triangles in a hash
// grid of cell r (each in every cell its bounding box meets), and per query the area of each
// triangle inside the ball of radius r, estimated by splitting triangles larger than (r/4)² until
// they are not and counting the pieces whose centroid lies in the ball.
class SurfaceNormalGrid {
 public:
  SurfaceNormalGrid(const TriangleMesh& mesh, const MeshTopology& topology, double r)
      : mesh_(mesh), topology_(topology), r_(r), grid_(r) {
    if (!(r > 0.0)) return;
    stamp_of_.assign(mesh.triangles.size(), 0);
    for (std::size_t f = 0; f < mesh.triangles.size(); ++f) {
      const glm::ivec3 t = mesh.triangles[f];
      const glm::dvec3 a = mesh.vertices[t[0]], b = mesh.vertices[t[1]], c = mesh.vertices[t[2]];
      const glm::i64vec3 lo = GridCell(glm::min(a, glm::min(b, c)), r),
                         hi = GridCell(glm::max(a, glm::max(b, c)), r);
      for (std::int64_t x = lo.x; x <= hi.x; ++x) {
        for (std::int64_t y = lo.y; y <= hi.y; ++y) {
          for (std::int64_t z = lo.z; z <= hi.z; ++z) {
            grid_.AddToCell({x, y, z}, static_cast<int>(f));
          }
        }
      }
    }
  }

  // The area-weighted mean of the outward normals within r of p_F (mesh frame): its length is
  // the surface's flatness there (1 on a plane, about 0.7 on a right-angled edge, 0 where no
  // surface is within r).
  glm::dvec3 MeanNormal(const glm::dvec3& p_F) const {
    if (!(r_ > 0.0)) return glm::dvec3(0.0);
    if (++stamp_ == 0) {
      std::fill(stamp_of_.begin(), stamp_of_.end(), 0);
      stamp_ = 1;
    }
    glm::dvec3 sum(0.0);
    double weight = 0.0;
    const double small2 = (0.25 * r_) * (0.25 * r_);
    grid_.ForEachNear(p_F, [&](int f) {
      if (stamp_of_[f] == stamp_) return;
      stamp_of_[f] = stamp_;
      const glm::ivec3 t = mesh_.triangles[f];
      const glm::dvec3 a = mesh_.vertices[t[0]], b = mesh_.vertices[t[1]],
                       cc = mesh_.vertices[t[2]];
      const glm::dvec3 q = ClosestPointOnTriangle(p_F, a, b, cc);
      if (glm::dot(q - p_F, q - p_F) > r_ * r_) return;
      const double inside = AreaInBall(p_F, a, b, cc, topology_.area_m2[f], small2);
      sum += inside * topology_.normal_F[f];
      weight += inside;
    });
    return weight > 0.0 ? sum / weight : glm::dvec3(0.0);
  }

 private:
  double AreaInBall(const glm::dvec3& p, const glm::dvec3& a, const glm::dvec3& b,
                    const glm::dvec3& c, double area, double small2) const {
    const double e2 =
        std::max({glm::dot(b - a, b - a), glm::dot(c - b, c - b), glm::dot(a - c, a - c)});
    if (e2 <= small2) {
      const glm::dvec3 g = (a + b + c) / 3.0 - p;
      return glm::dot(g, g) <= r_ * r_ ? area : 0.0;
    }
    const glm::dvec3 q = ClosestPointOnTriangle(p, a, b, c);
    if (glm::dot(q - p, q - p) > r_ * r_) return 0.0;
    const glm::dvec3 ab = 0.5 * (a + b), bc = 0.5 * (b + c), ca = 0.5 * (c + a);
    const double quarter = 0.25 * area;
    return AreaInBall(p, a, ab, ca, quarter, small2) + AreaInBall(p, ab, b, bc, quarter, small2) +
           AreaInBall(p, ca, bc, c, quarter, small2) + AreaInBall(p, ab, bc, ca, quarter, small2);
  }

  const TriangleMesh& mesh_;
  const MeshTopology& topology_;
  double r_;
  CellGrid grid_;
  mutable std::vector<std::uint32_t> stamp_of_;
  mutable std::uint32_t stamp_ = 0;
};

// Union-find with path halving.
inline int Find(std::vector<int>& parent, int i) {
  while (parent[i] != i) i = parent[i] = parent[parent[i]];
  return i;
}

}  // namespace ht::patch_truth
