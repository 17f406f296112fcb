#include "haptic_core/model_build/surface_error.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <limits>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "haptic_core/statistics.h"

namespace ht {
namespace {

// Barycentric coordinates (b0, b1, b2) of the point of triangle (a, b, c) closest to p (Ericson,
// Real-Time Collision Detection §5.1.5, by Voronoi regions).
glm::dvec3 ClosestBarycentric(const glm::dvec3& p, const glm::dvec3& a, const glm::dvec3& b,
                              const glm::dvec3& c) {
  const glm::dvec3 ab = b - a, ac = c - a, ap = p - a;
  const double d1 = glm::dot(ab, ap), d2 = glm::dot(ac, ap);
  if (d1 <= 0.0 && d2 <= 0.0) return {1.0, 0.0, 0.0};
  const glm::dvec3 bp = p - b;
  const double d3 = glm::dot(ab, bp), d4 = glm::dot(ac, bp);
  if (d3 >= 0.0 && d4 <= d3) return {0.0, 1.0, 0.0};
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) {
    const double v = d1 / (d1 - d3);
    return {1.0 - v, v, 0.0};
  }
  const glm::dvec3 cp = p - c;
  const double d5 = glm::dot(ab, cp), d6 = glm::dot(ac, cp);
  if (d6 >= 0.0 && d5 <= d6) return {0.0, 0.0, 1.0};
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) {
    const double w = d2 / (d2 - d6);
    return {1.0 - w, 0.0, w};
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0) {
    const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    return {0.0, 1.0 - w, w};
  }
  const double denom = va + vb + vc;
  if (!(std::abs(denom) > 0.0)) return {1.0 / 3.0, 1.0 / 3.0, 1.0 / 3.0};  // degenerate
  const double v = vb / denom, w = vc / denom;
  return {1.0 - v - w, v, w};
}

}  // namespace

SurfaceErrorReport MeasureSurfaceError(const HapticModel& model, const TriangleMesh& full_O,
                                       const SurfaceErrorParams& params) {
  const auto start = std::chrono::steady_clock::now();
  if (params.samples < 1) {
    throw std::invalid_argument("MeasureSurfaceError: samples must be >= 1, got " +
                                std::to_string(params.samples));
  }
  if (!(params.outside_threshold_m > 0.0) || !std::isfinite(params.outside_threshold_m)) {
    throw std::invalid_argument("MeasureSurfaceError: outside_threshold_m must be finite and > 0");
  }
  if (!(params.region_radius_m >= 0.0) || !std::isfinite(params.region_radius_m) ||
      !std::isfinite(params.region_center_O.x) || !std::isfinite(params.region_center_O.y) ||
      !std::isfinite(params.region_center_O.z)) {
    throw std::invalid_argument(
        "MeasureSurfaceError: region_radius_m must be finite and >= 0, its centre finite");
  }
  const std::size_t nf = model.triangles.size();
  if (nf == 0 || full_O.triangles.empty()) {
    throw std::invalid_argument("MeasureSurfaceError: model '" + model.name +
                                "' or its full-resolution mesh has no triangles");
  }
  if (model.corner_normals_O.size() != 3 * nf || model.corner_uvs.size() != 3 * nf ||
      model.textured.size() != nf) {
    throw std::invalid_argument("MeasureSurfaceError: model '" + model.name +
                                "' lacks corner normals, uvs or textured flags per triangle");
  }
  for (const glm::ivec3& t : model.triangles) {
    for (int c = 0; c < 3; ++c) {
      if (t[c] < 0 || static_cast<std::size_t>(t[c]) >= model.vertices_O.size()) {
        throw std::invalid_argument("MeasureSurfaceError: model '" + model.name +
                                    "' has a triangle index out of range");
      }
    }
  }
  std::vector<double> cumulative;
  cumulative.reserve(full_O.triangles.size());
  double total = 0.0;
  for (const glm::ivec3& t : full_O.triangles) {
    for (int c = 0; c < 3; ++c) {
      if (t[c] < 0 || static_cast<std::size_t>(t[c]) >= full_O.vertices.size()) {
        throw std::invalid_argument(
            "MeasureSurfaceError: the full-resolution mesh has a triangle index out of range");
      }
    }
    const glm::dvec3 a = full_O.vertices[t[0]], b = full_O.vertices[t[1]],
                     c = full_O.vertices[t[2]];
    const bool inside =
        params.region_radius_m <= 0.0 ||
        glm::length((a + b + c) / 3.0 - params.region_center_O) <= params.region_radius_m;
    if (inside) total += 0.5 * glm::length(glm::cross(b - a, c - a));
    cumulative.push_back(total);
  }
  if (!(total > 0.0)) {
    throw std::invalid_argument(
        "MeasureSurfaceError: the full-resolution mesh has no area" +
        std::string(params.region_radius_m > 0.0 ? " within the region" : ""));
  }

  std::mt19937_64 rng(params.seed);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  std::vector<double> dist, outside;
  dist.reserve(static_cast<std::size_t>(params.samples));
  outside.reserve(static_cast<std::size_t>(params.samples));
  std::int64_t above = 0;
  constexpr int kCandidates = 3;
  for (int s = 0; s < params.samples; ++s) {
    const double pick = uni(rng) * total;
    const std::size_t fi = std::min<std::size_t>(
        static_cast<std::size_t>(std::upper_bound(cumulative.begin(), cumulative.end(), pick) -
                                 cumulative.begin()),
        cumulative.size() - 1);
    const glm::ivec3 ft = full_O.triangles[fi];
    const double sr = std::sqrt(uni(rng)), r2 = uni(rng);
    const glm::dvec3 p = (1.0 - sr) * full_O.vertices[ft[0]] +
                         sr * (1.0 - r2) * full_O.vertices[ft[1]] +
                         sr * r2 * full_O.vertices[ft[2]];

    // The kCandidates coarse triangles whose closest points are nearest p.
    std::array<std::pair<double, std::size_t>, kCandidates> best;
    best.fill({std::numeric_limits<double>::infinity(), 0});
    for (std::size_t f = 0; f < nf; ++f) {
      const glm::ivec3 t = model.triangles[f];
      const glm::dvec3 &a = model.vertices_O[t[0]], &b = model.vertices_O[t[1]],
                       &c = model.vertices_O[t[2]];
      const glm::dvec3 w = ClosestBarycentric(p, a, b, c);
      const glm::dvec3 q = w.x * a + w.y * b + w.z * c;
      const double d2 = glm::dot(p - q, p - q);
      if (d2 < best.back().first) {
        best.back() = {d2, f};
        std::sort(best.begin(), best.end());
      }
    }

    double best_dist = std::numeric_limits<double>::infinity(), best_signed = 0.0;
    for (const auto& [d2, f] : best) {
      if (!std::isfinite(d2)) continue;
      const glm::ivec3 t = model.triangles[f];
      const glm::dvec3 &a = model.vertices_O[t[0]], &b = model.vertices_O[t[1]],
                       &c = model.vertices_O[t[2]];
      const glm::dvec3 face = glm::cross(b - a, c - a);
      const double face_len = glm::length(face);
      if (!(face_len > 0.0)) continue;
      const glm::dvec3 n_f = face / face_len;
      // Fixed-point steps towards the q whose interpolated normal's line passes through p (the
      // bake's ray), kept inside the triangle.
      glm::dvec3 w = ClosestBarycentric(p, a, b, c);
      glm::dvec3 N{0.0};
      for (int it = 0; it < 4; ++it) {
        N = glm::normalize(w.x * model.corner_normals_O[3 * f] +
                           w.y * model.corner_normals_O[3 * f + 1] +
                           w.z * model.corner_normals_O[3 * f + 2]);
        const double along = glm::dot(N, n_f);
        if (!(along > 1e-3)) break;
        const double t_plane = glm::dot(p - a, n_f) / along;
        w = ClosestBarycentric(p - t_plane * N, a, b, c);
      }
      N = glm::normalize(w.x * model.corner_normals_O[3 * f] +
                         w.y * model.corner_normals_O[3 * f + 1] +
                         w.z * model.corner_normals_O[3 * f + 2]);
      if (!std::isfinite(N.x)) continue;
      const glm::dvec3 q = w.x * a + w.y * b + w.z * c;
      double h = 0.0;
      if (model.textured[f]) {
        const glm::vec2 uv = static_cast<float>(w.x) * model.corner_uvs[3 * f] +
                             static_cast<float>(w.y) * model.corner_uvs[3 * f + 1] +
                             static_cast<float>(w.z) * model.corner_uvs[3 * f + 2];
        h = model.texture.Sample(0, uv.x, uv.y);
      }
      const glm::dvec3 r = q + h * N;
      const double d = glm::length(p - r);
      if (d < best_dist) {
        best_dist = d;
        best_signed = glm::dot(p - r, N);
      }
    }
    if (!std::isfinite(best_dist)) continue;
    dist.push_back(best_dist);
    outside.push_back(std::max(0.0, best_signed));
    if (best_signed > params.outside_threshold_m) ++above;
  }

  SurfaceErrorReport rep;
  rep.samples = static_cast<int>(dist.size());
  rep.share_outside =
      dist.empty() ? 0.0 : static_cast<double>(above) / static_cast<double>(dist.size());
  rep.p50_m = Percentile(dist, 0.50);
  rep.p95_m = Percentile(dist, 0.95);
  rep.p99_m = Percentile(dist, 0.99);
  rep.max_m = Percentile(dist, 1.0);
  rep.outside_p99_m = Percentile(outside, 0.99);
  rep.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return rep;
}

}  // namespace ht
