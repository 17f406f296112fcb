#include "haptic_core/model_build/texture_bake.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <glm/common.hpp>
#include <glm/geometric.hpp>
#include <glm/mat2x2.hpp>
#include <glm/matrix.hpp>
#include <limits>
#include <map>
#include <numbers>
#include <numeric>
#include <random>
#include <stdexcept>
#include <string>
#include <thread>
#include <utility>

#include "haptic_core/ray_cast_surface.h"

namespace ht {
namespace {
// Smallest chart leg the atlas accepts (texels).
constexpr int kMinChartTexels = 4;

// Atlas: n×n square cells, two charts per cell, for `triangles` charts.
int AtlasCellsPerSide(int triangles) noexcept {
  const int cells_needed = (triangles + 1) / 2;
  int n = static_cast<int>(std::ceil(std::sqrt(static_cast<double>(cells_needed))));
  while (n * n < cells_needed) ++n;
  return std::max(n, 1);
}
// Gutter heights are extrapolated this far from the triangle (texels) and held constant beyond:
// level-0 bilinear samples inside a chart read texels up to √2 texels away from it.
constexpr double kMaxExtrapolationTexels = 1.5;

bool Finite(const glm::dvec3& v) {
  return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}

void ValidateMesh(const TriangleMesh& mesh, const char* which) {
  const std::string name(which);
  if (mesh.vertices.empty() || mesh.triangles.empty()) {
    throw std::invalid_argument("BakeHapticTexture: " + name + " mesh is empty (" +
                                std::to_string(mesh.vertices.size()) + " vertices, " +
                                std::to_string(mesh.triangles.size()) + " triangles)");
  }
  if (mesh.vertices.size() > static_cast<size_t>(std::numeric_limits<int>::max()) ||
      mesh.triangles.size() > static_cast<size_t>(std::numeric_limits<int>::max())) {
    throw std::invalid_argument("BakeHapticTexture: " + name + " mesh is too large");
  }
  for (size_t i = 0; i < mesh.vertices.size(); ++i) {
    if (!Finite(mesh.vertices[i])) {
      throw std::invalid_argument("BakeHapticTexture: " + name + " vertex " + std::to_string(i) +
                                  " is not finite");
    }
  }
  const int nv = static_cast<int>(mesh.vertices.size());
  for (size_t f = 0; f < mesh.triangles.size(); ++f) {
    for (int c = 0; c < 3; ++c) {
      const int vi = mesh.triangles[f][c];
      if (vi < 0 || vi >= nv) {
        throw std::invalid_argument("BakeHapticTexture: " + name + " triangle " +
                                    std::to_string(f) + " indexes vertex " + std::to_string(vi) +
                                    " out of range [0, " + std::to_string(nv) + ")");
      }
    }
  }
}

void ValidateParams(const TextureBakeParams& p) {
  const int s = p.texture_size;
  if (s < 16 || s > 16384 || (s & (s - 1)) != 0) {
    throw std::invalid_argument(
        "BakeHapticTexture: texture_size must be a power of two in [16, 16384], got " +
        std::to_string(s));
  }
  if (p.gutter_texels < 1 || p.gutter_texels > 16) {
    throw std::invalid_argument("BakeHapticTexture: gutter_texels must be in [1, 16], got " +
                                std::to_string(p.gutter_texels));
  }
  if (!(p.crease_angle_deg >= 0.0 && p.crease_angle_deg <= 180.0)) {
    throw std::invalid_argument("BakeHapticTexture: crease_angle_deg must be in [0, 180], got " +
                                std::to_string(p.crease_angle_deg));
  }
  if (!(p.max_ray_distance_m >= 0.0) || !std::isfinite(p.max_ray_distance_m)) {
    throw std::invalid_argument(
        "BakeHapticTexture: max_ray_distance_m must be finite and >= 0, got " +
        std::to_string(p.max_ray_distance_m));
  }
  if (p.validation_samples < 0) {
    throw std::invalid_argument("BakeHapticTexture: validation_samples must be >= 0, got " +
                                std::to_string(p.validation_samples));
  }
  if (p.threads < 0) {
    throw std::invalid_argument("BakeHapticTexture: threads must be >= 0, got " +
                                std::to_string(p.threads));
  }
}

// Angle-weighted corner normals, split at crease edges (see TextureBakeParams::crease_angle_deg).
// Vertices at exactly the same position are treated as one, so that seams of split vertices
// (glTF) do not split the normals.
std::vector<glm::dvec3> CornerNormals(const TriangleMesh& m, double crease_angle_deg) {
  const int nf = static_cast<int>(m.triangles.size());
  const int nv = static_cast<int>(m.vertices.size());
  // Weld by exact position.
  std::vector<int> canon(nv);
  {
    std::map<std::array<double, 3>, int> first;
    for (int i = 0; i < nv; ++i) {
      const glm::dvec3& v = m.vertices[i];
      canon[i] = first.emplace(std::array<double, 3>{v.x, v.y, v.z}, i).first->second;
    }
  }
  std::vector<glm::dvec3> face_n(nf, glm::dvec3(0.0));
  std::vector<std::array<double, 3>> corner_angle(nf, {0.0, 0.0, 0.0});
  std::vector<std::vector<std::pair<int, int>>> incident(nv);  // (face, corner) per canon vertex
  for (int f = 0; f < nf; ++f) {
    const glm::ivec3 t = m.triangles[f];
    const glm::dvec3 cr =
        glm::cross(m.vertices[t[1]] - m.vertices[t[0]], m.vertices[t[2]] - m.vertices[t[0]]);
    const double len = glm::length(cr);
    if (!(len > 0.0)) continue;  // degenerate: no normal, no weight
    face_n[f] = cr / len;
    for (int c = 0; c < 3; ++c) {
      const glm::dvec3 a = m.vertices[t[(c + 1) % 3]] - m.vertices[t[c]];
      const glm::dvec3 b = m.vertices[t[(c + 2) % 3]] - m.vertices[t[c]];
      corner_angle[f][c] = std::atan2(glm::length(glm::cross(a, b)), glm::dot(a, b));
      incident[canon[t[c]]].push_back({f, c});
    }
  }
  const double cos_crease = std::cos(crease_angle_deg * std::numbers::pi / 180.0);
  std::vector<glm::dvec3> out(3 * static_cast<size_t>(nf), glm::dvec3(0.0));
  std::vector<int> parent;
  for (int v = 0; v < nv; ++v) {
    const auto& inc = incident[v];
    const int k = static_cast<int>(inc.size());
    if (k == 0) continue;
    parent.resize(k);
    std::iota(parent.begin(), parent.end(), 0);
    const auto find = [&](int i) {
      while (parent[i] != i) i = parent[i] = parent[parent[i]];
      return i;
    };
    // Two faces of the fan join when they share an edge at v that is not a crease.
    for (int i = 0; i < k; ++i) {
      const glm::ivec3 ti = m.triangles[inc[i].first];
      for (int j = i + 1; j < k; ++j) {
        const glm::ivec3 tj = m.triangles[inc[j].first];
        bool share = false;
        for (int a = 1; a < 3 && !share; ++a) {
          const int wa = canon[ti[(inc[i].second + a) % 3]];
          for (int b = 1; b < 3; ++b) share |= wa == canon[tj[(inc[j].second + b) % 3]];
        }
        if (share && glm::dot(face_n[inc[i].first], face_n[inc[j].first]) >= cos_crease) {
          parent[find(i)] = find(j);
        }
      }
    }
    std::vector<glm::dvec3> sum(k, glm::dvec3(0.0));
    for (int i = 0; i < k; ++i) {
      sum[find(i)] += corner_angle[inc[i].first][inc[i].second] * face_n[inc[i].first];
    }
    for (int i = 0; i < k; ++i) {
      const glm::dvec3 s = sum[find(i)];
      const double len = glm::length(s);
      out[3 * static_cast<size_t>(inc[i].first) + inc[i].second] =
          len > 1e-12 ? s / len : face_n[inc[i].first];
    }
  }
  // Corners of degenerate triangles: the angle-weighted normal of all faces at the vertex, else +z.
  for (int f = 0; f < nf; ++f) {
    if (glm::length(face_n[f]) > 0.0) continue;
    for (int c = 0; c < 3; ++c) {
      glm::dvec3 s(0.0);
      for (const auto& [g, e] : incident[canon[m.triangles[f][c]]]) {
        s += corner_angle[g][e] * face_n[g];
      }
      const double len = glm::length(s);
      out[3 * static_cast<size_t>(f) + c] = len > 1e-12 ? s / len : glm::dvec3(0, 0, 1);
    }
  }
  return out;
}

// Signed distance h (m) from `p_S` along unit `n` to the nearer of the first surfaces of
// `rays` above (+n) and below (−n) within `range`. Both rays start `range`·1e-6 behind p so that
// a surface through p itself is found. Returns false when neither ray hits.
bool NearestAlongNormal(const RayCastSurface& rays, const glm::dvec3& p, const glm::dvec3& n,
                        double range, double& h) noexcept {
  const double eps = 1e-6 * range;
  const double up = rays.FirstHit(p - eps * n, n, range + eps);
  const double down = rays.FirstHit(p + eps * n, -n, range + eps);
  const bool hit_up = up >= 0.0, hit_down = down >= 0.0;
  if (!hit_up && !hit_down) return false;
  const double h_up = up - eps, h_down = -(down - eps);
  if (hit_up && hit_down) {
    h = std::abs(h_up) <= std::abs(h_down) ? h_up : h_down;
  } else {
    h = hit_up ? h_up : h_down;
  }
  return true;
}

// One chart: the affine map from atlas texel coordinates (texel centres at i + 0.5) to barycentric
// coordinates of its triangle.
struct Chart {
  std::array<glm::dvec2, 3> t{};  // texel positions of the corners
  glm::dmat2 inv{1.0};            // texel offset from t[0] → (b1, b2)
  bool usable = false;            // non-degenerate triangle
};

// Closest point of the 2-D triangle t to q (Ericson, Real-Time Collision Detection, 5.1.5).
glm::dvec2 ClosestOnTriangle(const glm::dvec2& q, const std::array<glm::dvec2, 3>& t) {
  const glm::dvec2 ab = t[1] - t[0], ac = t[2] - t[0], ap = q - t[0];
  const double d1 = glm::dot(ab, ap), d2 = glm::dot(ac, ap);
  if (d1 <= 0.0 && d2 <= 0.0) return t[0];
  const glm::dvec2 bp = q - t[1];
  const double d3 = glm::dot(ab, bp), d4 = glm::dot(ac, bp);
  if (d3 >= 0.0 && d4 <= d3) return t[1];
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) return t[0] + d1 / (d1 - d3) * ab;
  const glm::dvec2 cp = q - t[2];
  const double d5 = glm::dot(ab, cp), d6 = glm::dot(ac, cp);
  if (d6 >= 0.0 && d5 <= d6) return t[2];
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) return t[0] + d2 / (d2 - d6) * ac;
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0) {
    return t[1] + (d4 - d3) / ((d4 - d3) + (d5 - d6)) * (t[2] - t[1]);
  }
  return q;  // inside
}

// Texel state during the bake.
enum : std::uint8_t { kUnowned = 0, kHit = 1, kMiss = 2, kFilled = 3 };

// Fills texels of state kMiss (when `within_chart`, from neighbours of the same chart) or kUnowned
// (otherwise, from any neighbour) by breadth-first dilation: each texel of a layer gets the mean
// of its 8-neighbours settled in earlier layers. Texels never reached are set to 0.
void Dilate(int size, std::vector<float>& h, std::vector<std::uint8_t>& state,
            const std::vector<int>& chart, bool within_chart) {
  const std::uint8_t target = within_chart ? kMiss : kUnowned;
  const auto settled = [&](size_t k) { return state[k] == kHit || state[k] == kFilled; };
  std::vector<int> frontier, next;
  std::vector<std::uint8_t> queued(h.size(), 0);
  const auto visit_neighbours = [&](int x, int y, auto&& fn) {
    for (int dy = -1; dy <= 1; ++dy) {
      for (int dx = -1; dx <= 1; ++dx) {
        if (dx == 0 && dy == 0) continue;
        const int nx = x + dx, ny = y + dy;
        if (nx < 0 || ny < 0 || nx >= size || ny >= size) continue;
        const size_t k = static_cast<size_t>(ny) * size + nx;
        const size_t k0 = static_cast<size_t>(y) * size + x;
        if (within_chart && chart[k] != chart[k0]) continue;
        fn(k);
      }
    }
  };
  for (int y = 0; y < size; ++y) {
    for (int x = 0; x < size; ++x) {
      const size_t k = static_cast<size_t>(y) * size + x;
      if (state[k] != target) continue;
      bool near = false;
      visit_neighbours(x, y, [&](size_t n) { near |= settled(n); });
      if (near) {
        frontier.push_back(static_cast<int>(k));
        queued[k] = 1;
      }
    }
  }
  std::vector<float> values;
  while (!frontier.empty()) {
    values.assign(frontier.size(), 0.0f);
    for (size_t i = 0; i < frontier.size(); ++i) {
      const int k = frontier[i];
      double sum = 0.0;
      int count = 0;
      visit_neighbours(k % size, k / size, [&](size_t n) {
        if (settled(n)) {
          sum += h[n];
          ++count;
        }
      });
      values[i] = count > 0 ? static_cast<float>(sum / count) : 0.0f;
    }
    for (size_t i = 0; i < frontier.size(); ++i) {
      h[frontier[i]] = values[i];
      state[frontier[i]] = kFilled;
    }
    next.clear();
    for (const int k : frontier) {
      visit_neighbours(k % size, k / size, [&](size_t n) {
        if (state[n] == target && !queued[n]) {
          queued[n] = 1;
          next.push_back(static_cast<int>(n));
        }
      });
    }
    std::swap(frontier, next);
  }
  for (size_t k = 0; k < h.size(); ++k) {
    if (state[k] == target) {
      h[k] = 0.0f;
      state[k] = kFilled;
    }
  }
}

}  // namespace

int SmallestAtlasSize(int triangles, int gutter_texels) noexcept {
  const int n = AtlasCellsPerSide(std::max(triangles, 1));
  for (int size = 16; size <= 16384; size *= 2) {
    if (size / n - 4 * gutter_texels >= kMinChartTexels) return size;
  }
  return 0;
}

BakedTexture BakeHapticTexture(const TriangleMesh& coarse_O, const TriangleMesh& full_O,
                               const TextureBakeParams& params) {
  const auto start = std::chrono::steady_clock::now();
  ValidateParams(params);
  ValidateMesh(coarse_O, "coarse");
  ValidateMesh(full_O, "full-resolution");

  const int nf = static_cast<int>(coarse_O.triangles.size());
  const int size = params.texture_size;
  const int gutter = params.gutter_texels;
  const int n = AtlasCellsPerSide(nf);
  const int c = size / n;
  const int leg = c - 4 * gutter;
  if (leg < kMinChartTexels) {
    throw std::invalid_argument("BakeHapticTexture: " + std::to_string(nf) +
                                " triangles do not fit a " + std::to_string(size) +
                                "² atlas with gutter " + std::to_string(gutter) +
                                " (chart legs of " + std::to_string(leg) +
                                " texels, need >= " + std::to_string(kMinChartTexels) +
                                "); use a larger texture_size or a coarser mesh");
  }

  // Frame for Embree: centred on the coarse bounding box so that float rays keep their precision.
  glm::dvec3 lo(std::numeric_limits<double>::infinity()), hi(-lo);
  for (const auto& v : coarse_O.vertices) {
    lo = glm::min(lo, v);
    hi = glm::max(hi, v);
  }
  const glm::dvec3 origin_O = 0.5 * (lo + hi);
  double range = params.max_ray_distance_m;
  if (range == 0.0) range = kAutoRayDistanceFraction * glm::length(hi - lo);
  if (!(range > 0.0)) {
    throw std::invalid_argument(
        "BakeHapticTexture: the coarse mesh has a zero-size bounding box; give max_ray_distance_m");
  }

  BakedTexture out;
  TextureBakeReport& rep = out.report;
  rep.max_ray_distance_m = range;
  rep.cell_texels = c;
  rep.cells_per_side = n;
  out.corner_normals_O = CornerNormals(coarse_O, params.crease_angle_deg);
  out.corner_uvs.assign(3 * static_cast<size_t>(nf), glm::vec2(0.0f));
  out.textured.assign(nf, 0);
  out.texel_size_m.assign(nf, 0.0);

  // Charts.
  std::vector<Chart> charts(nf);
  const double g = gutter, cd = c;
  for (int f = 0; f < nf; ++f) {
    const int cell = f / 2, half = f % 2;
    const glm::dvec2 cell_origin((cell % n) * cd, (cell / n) * cd);
    // Right-angle corner first, then the two others (local texel coordinates of the cell).
    const std::array<glm::dvec2, 3> slots =
        half == 0 ? std::array<glm::dvec2, 3>{glm::dvec2(g, g), glm::dvec2(cd - 3 * g, g),
                                              glm::dvec2(g, cd - 3 * g)}
                  : std::array<glm::dvec2, 3>{glm::dvec2(cd - g, cd - g), glm::dvec2(3 * g, cd - g),
                                              glm::dvec2(cd - g, 3 * g)};
    const glm::ivec3 t = coarse_O.triangles[f];
    const glm::dvec3 P[3] = {coarse_O.vertices[t[0]], coarse_O.vertices[t[1]],
                             coarse_O.vertices[t[2]]};
    // The corner opposite the longest edge takes the right angle.
    int r = 0;
    double longest = -1.0;
    for (int k = 0; k < 3; ++k) {
      const double len = glm::length(P[(k + 2) % 3] - P[(k + 1) % 3]);
      if (len > longest) {
        longest = len;
        r = k;
      }
    }
    glm::dvec2 T[3];
    for (int k = 0; k < 3; ++k) T[(r + k) % 3] = cell_origin + slots[k];
    for (int k = 0; k < 3; ++k) {
      out.corner_uvs[3 * static_cast<size_t>(f) + k] =
          glm::vec2(static_cast<float>(T[k].x / size), static_cast<float>(T[k].y / size));
    }
    Chart& ch = charts[f];
    ch.t = {T[0], T[1], T[2]};
    const glm::dmat2 E(T[1] - T[0], T[2] - T[0]);  // columns e1, e2
    ch.inv = glm::inverse(E);
    // Jacobian surface ← texels: J = [P1-P0, P2-P0]·E⁻¹ (3×2); its largest singular value.
    const glm::dvec3 d1 = P[1] - P[0], d2 = P[2] - P[0];
    const glm::dvec3 j1 = ch.inv[0][0] * d1 + ch.inv[0][1] * d2;  // ∂p/∂x
    const glm::dvec3 j2 = ch.inv[1][0] * d1 + ch.inv[1][1] * d2;  // ∂p/∂y
    const double a = glm::dot(j1, j1), b = glm::dot(j1, j2), d = glm::dot(j2, j2);
    const double tr = a + d, disc = std::sqrt(std::max(0.0, 0.25 * tr * tr - (a * d - b * b)));
    ch.usable = glm::length(glm::cross(d1, d2)) > 1e-12 * longest * longest && longest > 0.0;
    out.texel_size_m[f] = ch.usable ? std::sqrt(0.5 * tr + disc) : 0.0;
  }

  const auto chart_of = [&](int x, int y) -> int {
    const int cx = x / c, cy = y / c;
    if (cx >= n || cy >= n) return -1;
    const int s = (x - cx * c) + (y - cy * c);
    int half;
    if (s <= c - 2) {
      half = 0;
    } else if (s >= c) {
      half = 1;
    } else {
      return -1;  // diagonal texel between the two charts
    }
    const int f = 2 * (cy * n + cx) + half;
    return f < nf ? f : -1;
  };

  const RayCastSurface rays(full_O, origin_O);
  // Coarse surface point (frame of the Embree scene) and unit normal at barycentric b.
  const auto surface = [&](int f, double b1, double b2, glm::dvec3& p, glm::dvec3& nrm) {
    const glm::ivec3 t = coarse_O.triangles[f];
    const double b0 = 1.0 - b1 - b2;
    p = b0 * coarse_O.vertices[t[0]] + b1 * coarse_O.vertices[t[1]] + b2 * coarse_O.vertices[t[2]] -
        origin_O;
    const size_t k = 3 * static_cast<size_t>(f);
    nrm = b0 * out.corner_normals_O[k] + b1 * out.corner_normals_O[k + 1] +
          b2 * out.corner_normals_O[k + 2];
    const double len = glm::length(nrm);
    if (!(len > 1e-9)) return false;
    nrm /= len;
    return true;
  };

  const size_t texel_count = static_cast<size_t>(size) * size;
  std::vector<float> h(texel_count, 0.0f);
  std::vector<std::uint8_t> state(texel_count, kUnowned);
  std::vector<int> chart(texel_count, -1);
  int threads =
      params.threads > 0 ? params.threads : static_cast<int>(std::thread::hardware_concurrency());
  threads = std::clamp(threads, 1, 64);
  struct Counts {
    std::int64_t baked = 0, rays = 0, misses = 0, clamped = 0;
  };
  std::vector<Counts> counts(threads);
  const auto work = [&](int id) {
    Counts& cnt = counts[id];
    for (int y = id; y < size; y += threads) {
      for (int x = 0; x < size; ++x) {
        const size_t k = static_cast<size_t>(y) * size + x;
        const int f = chart_of(x, y);
        chart[k] = f;
        if (f < 0 || !charts[f].usable) continue;
        ++cnt.baked;
        const Chart& ch = charts[f];
        // Height at texel position qq of chart f (barycentric map extended beyond the triangle).
        const auto height_at = [&](const glm::dvec2& qq, double& out_h) {
          const glm::dvec2 b = ch.inv * (qq - ch.t[0]);
          glm::dvec3 p, nrm;
          if (!surface(f, b.x, b.y, p, nrm)) return false;
          cnt.rays += 2;
          return NearestAlongNormal(rays, p, nrm, range, out_h);
        };
        const glm::dvec2 q(x + 0.5, y + 0.5);
        const glm::dvec2 q_edge = ClosestOnTriangle(q, ch.t);
        const double out_dist = glm::length(q - q_edge);
        double hv = 0.0;
        bool hit = false;
        if (out_dist == 0.0) {
          hit = height_at(q, hv);
        } else {
          // Gutter texel: the linear function through the heights at the corners of a copy of
          // the triangle shrunk about q_edge to legs of max(1, out_dist) texels, extrapolated
          // towards q by at most kMaxExtrapolationTexels (held constant beyond): a smooth
          // continuation of the chart's own heights where bilinear samples read them.
          const double lambda = std::min(1.0, std::max(1.0, out_dist) / leg);
          const double reach = std::min(out_dist, kMaxExtrapolationTexels) / out_dist;
          double hp[3];
          hit = true;
          for (int i = 0; i < 3 && hit; ++i) {
            hit = height_at(q_edge + lambda * (ch.t[i] - q_edge), hp[i]);
          }
          if (hit) {
            const glm::dvec2 beta = ch.inv * (q_edge + reach * (q - q_edge) / lambda - ch.t[0]);
            hv = (1.0 - beta.x - beta.y) * hp[0] + beta.x * hp[1] + beta.y * hp[2];
          }
        }
        if (!hit) {
          ++cnt.misses;
          state[k] = kMiss;
          continue;
        }
        if (std::abs(hv) > range) {  // only extrapolated gutter heights can exceed the range
          hv = std::clamp(hv, -range, range);
          ++cnt.clamped;
        }
        h[k] = static_cast<float>(hv);
        state[k] = kHit;
      }
    }
  };
  {
    std::vector<std::thread> pool;
    for (int id = 1; id < threads; ++id) pool.emplace_back(work, id);
    work(0);
    for (auto& th : pool) th.join();
  }
  for (const Counts& cnt : counts) {
    rep.texels_baked += cnt.baked;
    rep.rays += cnt.rays;
    rep.misses += cnt.misses;
    rep.clamped += cnt.clamped;
  }
  // A chart is textured when at least one of its rays hit.
  for (size_t k = 0; k < texel_count; ++k) {
    if (state[k] == kHit) out.textured[chart[k]] = 1;
  }
  Dilate(size, h, state, chart, /*within_chart=*/true);
  for (size_t k = 0; k < texel_count; ++k) {
    if (chart[k] >= 0 && !out.textured[chart[k]]) h[k] = 0.0f;  // charts without any hit
  }
  Dilate(size, h, state, chart, /*within_chart=*/false);
  for (const float v : h) {
    rep.max_abs_height_m = std::max(rep.max_abs_height_m, std::abs(static_cast<double>(v)));
  }
  out.texture = HeightField(size, size, std::move(h), false, false);

  // Validation: bilinear level-0 samples against rays cast at the same points.
  std::vector<double> cumulative_area;
  std::vector<int> faces;
  double total = 0.0;
  for (int f = 0; f < nf; ++f) {
    if (!out.textured[f]) continue;
    const glm::ivec3 t = coarse_O.triangles[f];
    total += 0.5 * glm::length(glm::cross(coarse_O.vertices[t[1]] - coarse_O.vertices[t[0]],
                                          coarse_O.vertices[t[2]] - coarse_O.vertices[t[0]]));
    cumulative_area.push_back(total);
    faces.push_back(f);
  }
  if (!faces.empty() && total > 0.0 && params.validation_samples > 0) {
    std::mt19937_64 rng(params.seed);
    std::uniform_real_distribution<double> uni(0.0, 1.0);
    double sum_sq = 0.0;
    std::int64_t used = 0;
    for (int s = 0; s < params.validation_samples; ++s) {
      const double pick = uni(rng) * total;
      const size_t i =
          std::min<size_t>(std::upper_bound(cumulative_area.begin(), cumulative_area.end(), pick) -
                               cumulative_area.begin(),
                           faces.size() - 1);
      const int f = faces[i];
      const double sr = std::sqrt(uni(rng)), r2 = uni(rng);
      const double b1 = sr * (1.0 - r2), b2 = sr * r2, b0 = 1.0 - b1 - b2;
      const size_t k = 3 * static_cast<size_t>(f);
      const glm::vec2 uv = static_cast<float>(b0) * out.corner_uvs[k] +
                           static_cast<float>(b1) * out.corner_uvs[k + 1] +
                           static_cast<float>(b2) * out.corner_uvs[k + 2];
      const double sampled = out.texture.Sample(0, uv.x, uv.y);
      glm::dvec3 p, nrm;
      double cast = 0.0;
      rep.rays += 2;
      if (!surface(f, b1, b2, p, nrm) || !NearestAlongNormal(rays, p, nrm, range, cast)) {
        ++rep.validation_misses;
        continue;
      }
      const double err = std::abs(sampled - cast);
      rep.max_bake_error_m = std::max(rep.max_bake_error_m, err);
      sum_sq += err * err;
      ++used;
    }
    if (used > 0) rep.rms_bake_error_m = std::sqrt(sum_sq / static_cast<double>(used));
  }
  rep.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return out;
}

void ApplyBakedTexture(BakedTexture baked, HapticModel& model) {
  const size_t nf = model.triangles.size();
  if (baked.corner_normals_O.size() != 3 * nf || baked.corner_uvs.size() != 3 * nf ||
      baked.textured.size() != nf || baked.texel_size_m.size() != nf) {
    throw std::invalid_argument("ApplyBakedTexture: baked texture is for " +
                                std::to_string(baked.textured.size()) + " triangles, model '" +
                                model.name + "' has " + std::to_string(nf));
  }
  model.corner_normals_O = std::move(baked.corner_normals_O);
  model.corner_uvs = std::move(baked.corner_uvs);
  model.textured = std::move(baked.textured);
  model.texel_size_m = std::move(baked.texel_size_m);
  model.texture = std::move(baked.texture);
}

}  // namespace ht
