// Haptic texture bake (DESIGN.md §2): heights found by rays from the coarse surface along its
// interpolated normal reproduce the full-resolution surface.

#include "haptic_core/model_build/texture_bake.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <glm/geometric.hpp>
#include <limits>
#include <map>
#include <numbers>
#include <random>
#include <set>
#include <stdexcept>
#include <utility>
#include <vector>

namespace ht {
namespace {

// Grid of nx×ny quads over [x0,x1]×[y0,y1] at height z(x, y), counter-clockwise seen from +z.
TriangleMesh MakeGrid(double x0, double x1, double y0, double y1, int nx, int ny,
                      const std::function<double(double, double)>& z) {
  TriangleMesh m;
  for (int j = 0; j <= ny; ++j) {
    for (int i = 0; i <= nx; ++i) {
      const double x = x0 + (x1 - x0) * i / nx, y = y0 + (y1 - y0) * j / ny;
      m.vertices.push_back({x, y, z(x, y)});
    }
  }
  const auto id = [&](int i, int j) { return j * (nx + 1) + i; };
  for (int j = 0; j < ny; ++j) {
    for (int i = 0; i < nx; ++i) {
      m.triangles.push_back({id(i, j), id(i + 1, j), id(i + 1, j + 1)});
      m.triangles.push_back({id(i, j), id(i + 1, j + 1), id(i, j + 1)});
    }
  }
  return m;
}

// Square [x0, x0+side]×[0, side] at z = 0 as two triangles, normal +z.
void AddSquare(TriangleMesh& m, double x0, double side) {
  const int b = static_cast<int>(m.vertices.size());
  m.vertices.push_back({x0, 0, 0});
  m.vertices.push_back({x0 + side, 0, 0});
  m.vertices.push_back({x0 + side, side, 0});
  m.vertices.push_back({x0, side, 0});
  m.triangles.push_back({b, b + 1, b + 2});
  m.triangles.push_back({b, b + 2, b + 3});
}

// Octahedron subdivided `level` times, vertices on the sphere of radius `radius` (outward winding).
TriangleMesh MakeOctasphere(int level, double radius) {
  TriangleMesh m;
  m.vertices = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
  m.triangles = {{0, 2, 4}, {2, 1, 4}, {1, 3, 4}, {3, 0, 4},
                 {2, 0, 5}, {1, 2, 5}, {3, 1, 5}, {0, 3, 5}};
  for (int l = 0; l < level; ++l) {
    std::map<std::pair<int, int>, int> mid;
    const auto midpoint = [&](int a, int b) {
      const auto key = std::minmax(a, b);
      auto it = mid.find(key);
      if (it != mid.end()) return it->second;
      m.vertices.push_back(glm::normalize(m.vertices[a] + m.vertices[b]));
      const int id = static_cast<int>(m.vertices.size()) - 1;
      mid.emplace(key, id);
      return id;
    };
    std::vector<glm::ivec3> next;
    for (const glm::ivec3 t : m.triangles) {
      const int ab = midpoint(t[0], t[1]), bc = midpoint(t[1], t[2]), ca = midpoint(t[2], t[0]);
      next.push_back({t[0], ab, ca});
      next.push_back({ab, t[1], bc});
      next.push_back({ca, bc, t[2]});
      next.push_back({ab, bc, ca});
    }
    m.triangles = std::move(next);
  }
  for (auto& v : m.vertices) v *= radius;
  return m;
}

// Closest point of triangle abc to p (Ericson, Real-Time Collision Detection, 5.1.5).
glm::dvec3 ClosestOnTriangle(const glm::dvec3& p, const glm::dvec3& a, const glm::dvec3& b,
                             const glm::dvec3& c) {
  const glm::dvec3 ab = b - a, ac = c - a, ap = p - a;
  const double d1 = glm::dot(ab, ap), d2 = glm::dot(ac, ap);
  if (d1 <= 0 && d2 <= 0) return a;
  const glm::dvec3 bp = p - b;
  const double d3 = glm::dot(ab, bp), d4 = glm::dot(ac, bp);
  if (d3 >= 0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return a + d1 / (d1 - d3) * ab;
  const glm::dvec3 cp = p - c;
  const double d5 = glm::dot(ab, cp), d6 = glm::dot(ac, cp);
  if (d6 >= 0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return a + d2 / (d2 - d6) * ac;
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    return b + (d4 - d3) / ((d4 - d3) + (d5 - d6)) * (c - b);
  }
  const double denom = 1.0 / (va + vb + vc);
  return a + ab * (vb * denom) + ac * (vc * denom);
}

double DistanceToMesh(const glm::dvec3& p, const TriangleMesh& m) {
  double best = std::numeric_limits<double>::infinity();
  for (const glm::ivec3 t : m.triangles) {
    const glm::dvec3 q = ClosestOnTriangle(p, m.vertices[t[0]], m.vertices[t[1]], m.vertices[t[2]]);
    best = std::min(best, glm::length(p - q));
  }
  return best;
}

// A point of coarse triangle f at barycentric (b0, b1, b2), reconstructed from the baked data the
// way the penetration-depth code reads it: uv interpolated in float, level-0 bilinear sample.
struct SurfacePoint {
  glm::dvec3 p_coarse, normal;  // unit interpolated normal
  double h;
};
SurfacePoint Reconstruct(const TriangleMesh& coarse, const BakedTexture& baked, int f, double b1,
                         double b2) {
  const double b0 = 1.0 - b1 - b2;
  const glm::ivec3 t = coarse.triangles[f];
  SurfacePoint s;
  s.p_coarse = b0 * coarse.vertices[t[0]] + b1 * coarse.vertices[t[1]] + b2 * coarse.vertices[t[2]];
  const size_t k = 3 * static_cast<size_t>(f);
  s.normal = glm::normalize(b0 * baked.corner_normals_O[k] + b1 * baked.corner_normals_O[k + 1] +
                            b2 * baked.corner_normals_O[k + 2]);
  const float u = static_cast<float>(b0 * baked.corner_uvs[k].x + b1 * baked.corner_uvs[k + 1].x +
                                     b2 * baked.corner_uvs[k + 2].x);
  const float v = static_cast<float>(b0 * baked.corner_uvs[k].y + b1 * baked.corner_uvs[k + 1].y +
                                     b2 * baked.corner_uvs[k + 2].y);
  s.h = baked.texture.Sample(0, u, v);
  return s;
}

// Uniform random barycentric coordinates (b1, b2).
std::pair<double, double> RandomBarycentric(std::mt19937_64& rng) {
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  const double s = std::sqrt(uni(rng)), r = uni(rng);
  return {s * (1.0 - r), s * r};
}

TEST(TextureBake, FlatSquareOverSinusoidReproducesTheSinusoid) {
  const double amplitude = 0.5e-3, period = 5e-3, side = 20e-3;
  const double k = 2 * std::numbers::pi / period;
  // The full surface extends 1 mm beyond the coarse square, as a closed object's surface would
  // continue past a face: the gutters' extended charts then find it too. 220 quads over 22 mm.
  const double margin = 1e-3, spacing = 0.1e-3;
  const TriangleMesh full = MakeGrid(-margin, side + margin, -margin, side + margin, 220, 220,
                                     [&](double x, double) { return amplitude * std::sin(k * x); });
  TriangleMesh coarse;
  AddSquare(coarse, 0.0, side);
  TextureBakeParams params;
  params.texture_size = 256;
  const BakedTexture baked = BakeHapticTexture(coarse, full, params);
  const TextureBakeReport& r = baked.report;
  EXPECT_EQ(r.misses, 0);
  EXPECT_EQ(r.validation_misses, 0);
  EXPECT_EQ(r.clamped, 0);
  EXPECT_GT(r.texels_baked, 0);
  EXPECT_NEAR(r.max_ray_distance_m, kAutoRayDistanceFraction * side * std::sqrt(2.0), 1e-12);
  ASSERT_EQ(baked.textured, (std::vector<std::uint8_t>{1, 1}));
  for (const glm::dvec3& n : baked.corner_normals_O) EXPECT_NEAR(glm::dot(n, {0, 0, 1}), 1, 1e-12);
  // Each right triangle maps to an isosceles right chart: a similarity, texel = side / leg.
  const double texel = side / (r.cell_texels - 4 * params.gutter_texels);
  EXPECT_NEAR(baked.texel_size_m[0], texel, 1e-12);
  EXPECT_NEAR(baked.texel_size_m[1], texel, 1e-12);

  // Error budget against A sin(kx) at points at least 1.5 texels inside a chart, whose bilinear
  // samples read only texels inside it: interpolating a function of x alone along a texel axis
  // errs by at most max|h''|·τ²/8 = A k² τ²/8; the texels hold heights of the piecewise-linear
  // full mesh, whose chordal error is A k² δ²/8 (δ the grid spacing); float storage, float uv and
  // Embree's float rays add well under 0.02 µm. Nearer the edges the samples also read gutter
  // texels, linear extrapolations over up to √2 texels from a fit about a texel wide, whose error
  // is of the same O(h''τ²) kind with a larger constant (checked against 4× the bound).
  const double bilinear = amplitude * k * k * texel * texel / 8;
  const double chordal = amplitude * k * k * spacing * spacing / 8;
  const double bound = bilinear + chordal + 2e-8;
  std::mt19937_64 rng(7);
  double max_err = 0.0, max_err_edge = 0.0;
  int interior = 0;
  for (int i = 0; i < 10000; ++i) {
    const int f = i % 2;
    const auto [b1, b2] = RandomBarycentric(rng);
    const SurfacePoint s = Reconstruct(coarse, baked, f, b1, b2);
    const double err = std::abs(s.h - amplitude * std::sin(k * s.p_coarse.x));
    // Distance (texels) from the sample to the chart's edges.
    glm::dvec2 t[3];
    for (int c = 0; c < 3; ++c) t[c] = glm::dvec2(baked.corner_uvs[3 * f + c]) * 256.0;
    const glm::dvec2 q = (1 - b1 - b2) * t[0] + b1 * t[1] + b2 * t[2];
    double edge_dist = std::numeric_limits<double>::infinity();
    for (int c = 0; c < 3; ++c) {
      const glm::dvec2 e = t[(c + 1) % 3] - t[c], w = q - t[c];
      edge_dist = std::min(edge_dist, std::abs(e.x * w.y - e.y * w.x) / glm::length(e));
    }
    if (edge_dist >= 1.5) {
      max_err = std::max(max_err, err);
      ++interior;
    } else {
      max_err_edge = std::max(max_err_edge, err);
    }
  }
  std::printf(
      "sinusoid: max error %.3g um (interior), %.3g um (within 1.5 texels of an edge), "
      "bound %.3g um (bilinear %.3g, chordal %.3g); bake report max %.3g um rms %.3g um, "
      "max |h| %.4g mm\n",
      max_err * 1e6, max_err_edge * 1e6, bound * 1e6, bilinear * 1e6, chordal * 1e6,
      r.max_bake_error_m * 1e6, r.rms_bake_error_m * 1e6, r.max_abs_height_m * 1e3);
  EXPECT_GT(interior, 9000);
  EXPECT_LE(max_err, bound);
  EXPECT_GT(max_err, 0.0);
  EXPECT_LE(max_err_edge, 4 * bound);
  // The report compares the texture with the piecewise-linear mesh itself at random points: for
  // the interior, within the bilinear error plus twice the chordal error (texture vs sinusoid vs
  // mesh); the other way round, the error against the sinusoid is within the reported one plus
  // the chordal error (different random points, hence a little slack).
  EXPECT_LE(r.max_bake_error_m, 4 * bound);
  EXPECT_GT(r.max_bake_error_m, 0.0);
  EXPECT_LE(r.rms_bake_error_m, bilinear + 2 * chordal);
  EXPECT_LE(max_err, r.max_bake_error_m + chordal + 0.1 * bilinear);
  // Largest |h|: the sinusoid's amplitude, plus what the gutters' extrapolation adds (O(h''τ²)).
  EXPECT_GE(r.max_abs_height_m, amplitude - chordal);
  EXPECT_LE(r.max_abs_height_m, amplitude + 4 * bound);
}

TEST(TextureBake, ReconstructedPointsLieOnTheFullSphere) {
  const double radius = 10e-3;
  const TriangleMesh coarse = MakeOctasphere(1, radius);  // 32 triangles
  const TriangleMesh full = MakeOctasphere(6, radius);    // 32768 triangles
  TextureBakeParams params;
  params.texture_size = 256;
  // The middle faces of the once-subdivided octahedron lie 1.84 mm inside the sphere at their
  // centres, beyond the automatic range (5% of 34.6 mm).
  params.max_ray_distance_m = 3e-3;
  const BakedTexture baked = BakeHapticTexture(coarse, full, params);
  const TextureBakeReport& r = baked.report;
  EXPECT_EQ(r.misses, 0);
  EXPECT_EQ(r.validation_misses, 0);
  for (std::uint8_t t : baked.textured) EXPECT_EQ(t, 1);
  // Smooth surface: one normal per vertex, shared by all its corners, and nearly radial.
  for (size_t f = 0; f < coarse.triangles.size(); ++f) {
    for (int c = 0; c < 3; ++c) {
      const glm::dvec3 v = coarse.vertices[coarse.triangles[f][c]];
      EXPECT_GT(glm::dot(baked.corner_normals_O[3 * f + c], glm::normalize(v)), 0.99);
    }
  }

  // Error budget: the height along N over the coarse plane has curvature about 1/R; bilinear
  // interpolation with texels of at most τ in any direction errs by at most M·τ²/4 (M a bound on
  // the Hessian, taken as 2/R to cover the tilt of N), and the texels hold heights of the faceted
  // full mesh, whose gap to the sphere (sagitta e²/8R of its edges e) enters twice.
  double texel = 0.0;
  for (double t : baked.texel_size_m) texel = std::max(texel, t);
  double edge = 0.0;
  for (const glm::ivec3 t : full.triangles) {
    edge = std::max(edge, glm::length(full.vertices[t[1]] - full.vertices[t[0]]));
  }
  const double sagitta = edge * edge / (8 * radius);
  const double bilinear = (2 / radius) * texel * texel / 4;
  const double bound = bilinear + 2 * sagitta + 5e-8;
  std::mt19937_64 rng(11);
  double max_mesh = 0.0, max_sphere = 0.0, max_ray = 0.0;
  for (int i = 0; i < 300; ++i) {
    const int f = static_cast<int>(rng() % coarse.triangles.size());
    const auto [b1, b2] = RandomBarycentric(rng);
    const SurfacePoint s = Reconstruct(coarse, baked, f, b1, b2);
    const glm::dvec3 p = s.p_coarse + s.h * s.normal;
    // Route 1: distance to the nearest full-resolution triangle.
    max_mesh = std::max(max_mesh, DistanceToMesh(p, full));
    // Route 2: the analytic sphere, and the ray p_coarse + t·N meeting it.
    max_sphere = std::max(max_sphere, std::abs(glm::length(p) - radius));
    const double pn = glm::dot(s.p_coarse, s.normal);
    const double t = -pn + std::sqrt(pn * pn - glm::dot(s.p_coarse, s.p_coarse) + radius * radius);
    max_ray = std::max(max_ray, std::abs(s.h - t));
    EXPECT_GT(s.h, 0.0);  // the inscribed coarse mesh lies inside
  }
  std::printf(
      "sphere: texel %.3g mm; max distance to mesh %.3g um, to sphere %.3g um, "
      "|h - ray/sphere| %.3g um; bound %.3g um (bilinear %.3g, sagitta %.3g); "
      "report max %.3g um, max |h| %.3g mm\n",
      texel * 1e3, max_mesh * 1e6, max_sphere * 1e6, max_ray * 1e6, bound * 1e6, bilinear * 1e6,
      sagitta * 1e6, r.max_bake_error_m * 1e6, r.max_abs_height_m * 1e3);
  EXPECT_LE(max_mesh, bound);
  EXPECT_LE(max_sphere, bound + sagitta);
  EXPECT_LE(max_ray, 1.05 * (bound + sagitta));
  EXPECT_LE(r.max_bake_error_m, bound);
  // The deepest point of a coarse face, the centre of a middle face, lies R(1 - 1/√(3/2)·...)
  // = R - |(v1+v2+v3)/3| below the sphere, recovered to within the bound.
  const glm::dvec3 centre =
      (coarse.vertices[coarse.triangles[3][0]] + coarse.vertices[coarse.triangles[3][1]] +
       coarse.vertices[coarse.triangles[3][2]]) /
      3.0;
  EXPECT_NEAR(r.max_abs_height_m, radius - glm::length(centre), bound);
}

TEST(TextureBake, MissesAreCountedAndFilledFromNeighbours) {
  const double side = 10e-3, height = 0.2e-3;
  // The full surface covers only x < side/2 of the first square and nothing of the second one.
  const TriangleMesh full = MakeGrid(-1e-3, 0.5 * side, -1e-3, side + 1e-3, 30, 60,
                                     [&](double, double) { return height; });
  TriangleMesh coarse;
  AddSquare(coarse, 0.0, side);
  AddSquare(coarse, 5 * side, side);
  TextureBakeParams params;
  params.texture_size = 128;
  params.max_ray_distance_m = 1e-3;
  params.validation_samples = 4000;
  const BakedTexture baked = BakeHapticTexture(coarse, full, params);
  const TextureBakeReport& r = baked.report;
  ASSERT_EQ(baked.textured, (std::vector<std::uint8_t>{1, 1, 0, 0}));
  // Half of the first square's texels and all of the second's miss: 3/4 of all.
  const double miss_fraction = static_cast<double>(r.misses) / static_cast<double>(r.texels_baked);
  std::printf("misses %lld of %lld texels baked (%.3f); validation misses %lld\n",
              static_cast<long long>(r.misses), static_cast<long long>(r.texels_baked),
              miss_fraction, static_cast<long long>(r.validation_misses));
  EXPECT_NEAR(miss_fraction, 0.75, 0.05);
  // Validation samples fall only on textured triangles, half of whose area is uncovered.
  EXPECT_NEAR(static_cast<double>(r.validation_misses) / params.validation_samples, 0.5, 0.05);
  EXPECT_NEAR(r.max_bake_error_m, 0.0, 1e-9);
  const HeightFieldLevel& l0 = baked.texture.level(0);
  for (float t : l0.texels) ASSERT_TRUE(std::isfinite(t));
  // Missed texels of the first square's charts took their neighbours' height.
  std::mt19937_64 rng(3);
  for (int i = 0; i < 500; ++i) {
    const int f = i % 2;
    const auto [b1, b2] = RandomBarycentric(rng);
    EXPECT_NEAR(Reconstruct(coarse, baked, f, b1, b2).h, height, 1e-9);
    EXPECT_EQ(Reconstruct(coarse, baked, f + 2, b1, b2).h, 0.0);
  }
}

TEST(TextureBake, BadInputThrows) {
  TriangleMesh coarse;
  AddSquare(coarse, 0.0, 1e-2);
  const TriangleMesh full = coarse;
  TextureBakeParams small;
  small.texture_size = 64;
  small.validation_samples = 10;
  EXPECT_NO_THROW(BakeHapticTexture(coarse, full, small));

  TriangleMesh bad_index = coarse;
  bad_index.triangles[1][2] = 4;
  EXPECT_THROW(BakeHapticTexture(bad_index, full, small), std::invalid_argument);
  EXPECT_THROW(BakeHapticTexture(coarse, bad_index, small), std::invalid_argument);
  bad_index.triangles[1][2] = -1;
  EXPECT_THROW(BakeHapticTexture(bad_index, full, small), std::invalid_argument);

  TriangleMesh nan_vertex = coarse;
  nan_vertex.vertices[2].y = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(BakeHapticTexture(nan_vertex, full, small), std::invalid_argument);
  EXPECT_THROW(BakeHapticTexture(coarse, nan_vertex, small), std::invalid_argument);
  nan_vertex.vertices[2].y = std::numeric_limits<double>::infinity();
  EXPECT_THROW(BakeHapticTexture(nan_vertex, full, small), std::invalid_argument);

  EXPECT_THROW(BakeHapticTexture(TriangleMesh{}, full, small), std::invalid_argument);
  EXPECT_THROW(BakeHapticTexture(coarse, TriangleMesh{}, small), std::invalid_argument);

  for (int size : {100, 8, 0, -64, 32768}) {
    TextureBakeParams p = small;
    p.texture_size = size;
    EXPECT_THROW(BakeHapticTexture(coarse, full, p), std::invalid_argument) << size;
  }
  TextureBakeParams p = small;
  p.max_ray_distance_m = -1.0;
  EXPECT_THROW(BakeHapticTexture(coarse, full, p), std::invalid_argument);
  p.max_ray_distance_m = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(BakeHapticTexture(coarse, full, p), std::invalid_argument);
  p = small;
  p.gutter_texels = 0;
  EXPECT_THROW(BakeHapticTexture(coarse, full, p), std::invalid_argument);
  p = small;
  p.crease_angle_deg = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(BakeHapticTexture(coarse, full, p), std::invalid_argument);

  // 512 triangles in 16² texels leave charts far below 4 texels per side.
  const TriangleMesh sphere = MakeOctasphere(3, 1e-2);
  p = small;
  p.texture_size = 16;
  try {
    BakeHapticTexture(sphere, sphere, p);
    ADD_FAILURE() << "no throw";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("512 triangles"), std::string::npos) << e.what();
  }

  // A texture baked for 2 triangles does not apply to a model of 512.
  HapticModel model;
  model.vertices_O = sphere.vertices;
  model.triangles = sphere.triangles;
  EXPECT_THROW(ApplyBakedTexture(BakeHapticTexture(coarse, full, small), model),
               std::invalid_argument);
}

TEST(TextureBake, AtlasChartsAreDisjointAndInsideTheTexture) {
  const double radius = 10e-3;
  const TriangleMesh sphere = MakeOctasphere(3, radius);  // 512 triangles, full == coarse
  TextureBakeParams params;
  params.texture_size = 512;
  params.validation_samples = 2000;
  const BakedTexture baked = BakeHapticTexture(sphere, sphere, params);
  const int n = params.texture_size;
  const int nf = static_cast<int>(sphere.triangles.size());
  ASSERT_EQ(baked.corner_uvs.size(), 3 * static_cast<size_t>(nf));
  for (const glm::vec2 uv : baked.corner_uvs) {
    EXPECT_GE(uv.x, 0.0f);
    EXPECT_LE(uv.x, 1.0f);
    EXPECT_GE(uv.y, 0.0f);
    EXPECT_LE(uv.y, 1.0f);
  }
  // 1) No texel centre lies inside (or on the border of) two charts.
  // 2) The texels a bilinear sample reads anywhere in a chart (its footprint, traced by dense
  //    samples) belong to no other chart's footprint: charts never read each other's texels.
  std::vector<int> inside(static_cast<size_t>(n) * n, -1), footprint(inside);
  int overlaps = 0, shared_footprint = 0;
  for (int f = 0; f < nf; ++f) {
    glm::dvec2 t[3];
    for (int c = 0; c < 3; ++c) t[c] = glm::dvec2(baked.corner_uvs[3 * f + c]) * double(n);
    const double area =
        (t[1].x - t[0].x) * (t[2].y - t[0].y) - (t[2].x - t[0].x) * (t[1].y - t[0].y);
    ASSERT_GT(std::abs(area), 2.0 * 4 * 4 / 2) << "chart " << f << " smaller than 4 texels a side";
    const int x0 = std::max(0, static_cast<int>(std::min({t[0].x, t[1].x, t[2].x})) - 2);
    const int x1 = std::min(n - 1, static_cast<int>(std::max({t[0].x, t[1].x, t[2].x})) + 2);
    const int y0 = std::max(0, static_cast<int>(std::min({t[0].y, t[1].y, t[2].y})) - 2);
    const int y1 = std::min(n - 1, static_cast<int>(std::max({t[0].y, t[1].y, t[2].y})) + 2);
    for (int y = y0; y <= y1; ++y) {
      for (int x = x0; x <= x1; ++x) {
        const glm::dvec2 q(x + 0.5, y + 0.5);
        const auto edge = [&](int a, int b) {
          return ((t[b].x - t[a].x) * (q.y - t[a].y) - (t[b].y - t[a].y) * (q.x - t[a].x)) * area;
        };
        if (edge(0, 1) >= 0 && edge(1, 2) >= 0 && edge(2, 0) >= 0) {
          int& owner = inside[static_cast<size_t>(y) * n + x];
          if (owner >= 0 && owner != f) ++overlaps;
          owner = f;
        }
      }
    }
    constexpr int kSteps = 200;  // spacing well under a quarter texel for these charts
    for (int i = 0; i <= kSteps; ++i) {
      for (int j = 0; i + j <= kSteps; ++j) {
        const double b1 = double(i) / kSteps, b2 = double(j) / kSteps;
        const glm::dvec2 q = (1 - b1 - b2) * t[0] + b1 * t[1] + b2 * t[2];
        const int qx = static_cast<int>(std::floor(q.x - 0.5)),
                  qy = static_cast<int>(std::floor(q.y - 0.5));
        for (int dy = 0; dy <= 1; ++dy) {
          for (int dx = 0; dx <= 1; ++dx) {
            const int x = std::clamp(qx + dx, 0, n - 1), y = std::clamp(qy + dy, 0, n - 1);
            int& owner = footprint[static_cast<size_t>(y) * n + x];
            if (owner >= 0 && owner != f) ++shared_footprint;
            owner = f;
          }
        }
      }
    }
    // No direction of the chart is sampled more coarsely than texel_size_m (m per texel).
    for (int c = 0; c < 3; ++c) {
      const glm::ivec3 tri = sphere.triangles[f];
      const double metres =
          glm::length(sphere.vertices[tri[(c + 1) % 3]] - sphere.vertices[tri[c]]);
      const double texels = glm::length(t[(c + 1) % 3] - t[c]);
      EXPECT_LE(metres / texels, baked.texel_size_m[f] * (1 + 1e-9));
      EXPECT_GE(metres / texels, 0.3 * baked.texel_size_m[f]);
    }
  }
  EXPECT_EQ(overlaps, 0);
  EXPECT_EQ(shared_footprint, 0);
  // full == coarse: every height is (nearly) zero, gutters included: they extrapolate the chart's
  // own heights instead of measuring the surface against the triangle's plane extended across a
  // coarse edge (which would give d·tan(dihedral angle) there).
  EXPECT_EQ(baked.report.misses, 0);
  EXPECT_LT(baked.report.max_abs_height_m, 1e-6 * radius);
}

TEST(TextureBake, CreaseAngleSplitsNormalsOfABoxButNotOfASphere) {
  // Unit cube, 12 triangles, outward winding.
  TriangleMesh box;
  for (int i = 0; i < 8; ++i) box.vertices.push_back({i & 1, (i >> 1) & 1, (i >> 2) & 1});
  box.triangles = {{0, 2, 1}, {1, 2, 3}, {4, 5, 6}, {5, 7, 6}, {0, 1, 4}, {1, 5, 4},
                   {2, 6, 3}, {3, 6, 7}, {0, 4, 2}, {2, 4, 6}, {1, 3, 5}, {3, 7, 5}};
  TextureBakeParams params;
  params.texture_size = 64;
  params.validation_samples = 100;
  const BakedTexture boxed = BakeHapticTexture(box, box, params);
  for (size_t f = 0; f < box.triangles.size(); ++f) {
    const glm::ivec3 t = box.triangles[f];
    const glm::dvec3 face = glm::normalize(glm::cross(box.vertices[t[1]] - box.vertices[t[0]],
                                                      box.vertices[t[2]] - box.vertices[t[0]]));
    EXPECT_NEAR(glm::dot(face, glm::dvec3(0.5) - box.vertices[t[0]]), -0.5, 1e-12) << "winding";
    for (int c = 0; c < 3; ++c) {
      EXPECT_NEAR(glm::dot(boxed.corner_normals_O[3 * f + c], face), 1.0, 1e-12);
    }
  }
  // At 180° nothing is a crease: the cube's corners get one angle-weighted normal, (±1,±1,±1)/√3.
  params.crease_angle_deg = 180.0;
  const BakedTexture smooth = BakeHapticTexture(box, box, params);
  for (size_t f = 0; f < box.triangles.size(); ++f) {
    for (int c = 0; c < 3; ++c) {
      const glm::dvec3 expected = glm::normalize(box.vertices[box.triangles[f][c]] - 0.5);
      EXPECT_NEAR(glm::dot(smooth.corner_normals_O[3 * f + c], expected), 1.0, 1e-12);
    }
  }
  // Sphere: every corner at a vertex shares one normal.
  const TriangleMesh sphere = MakeOctasphere(2, 1.0);
  params.crease_angle_deg = 60.0;
  params.texture_size = 256;
  const BakedTexture round = BakeHapticTexture(sphere, sphere, params);
  std::map<int, glm::dvec3> at_vertex;
  for (size_t f = 0; f < sphere.triangles.size(); ++f) {
    for (int c = 0; c < 3; ++c) {
      const glm::dvec3 n = round.corner_normals_O[3 * f + c];
      EXPECT_NEAR(glm::length(n), 1.0, 1e-12);
      const auto [it, fresh] = at_vertex.emplace(sphere.triangles[f][c], n);
      if (!fresh) {
        EXPECT_LT(glm::length(it->second - n), 1e-12);
      }
    }
  }
}

TEST(TextureBake, ApplyFillsTheModel) {
  const TriangleMesh sphere = MakeOctasphere(2, 1e-2);
  const TriangleMesh full = MakeOctasphere(4, 1e-2);
  TextureBakeParams params;
  params.texture_size = 128;
  params.validation_samples = 100;
  BakedTexture baked = BakeHapticTexture(sphere, full, params);
  const double reach = baked.report.max_abs_height_m;
  HapticModel model;
  model.name = "sphere";
  model.vertices_O = sphere.vertices;
  model.triangles = sphere.triangles;
  ApplyBakedTexture(std::move(baked), model);
  EXPECT_EQ(model.corner_normals_O.size(), 3 * sphere.triangles.size());
  EXPECT_EQ(model.corner_uvs.size(), 3 * sphere.triangles.size());
  EXPECT_EQ(model.textured.size(), sphere.triangles.size());
  EXPECT_EQ(model.texel_size_m.size(), sphere.triangles.size());
  EXPECT_EQ(model.texture.level(0).width, 128);
  EXPECT_EQ(model.texture.num_levels(), 8);
  EXPECT_NEAR(model.TextureReach(), reach, 1e-9);
  model.hull_vertices_O = full.vertices;
  model.mass_kg = 1.0;
  model.inertia_diagonal_O = glm::dvec3(1.0);
  EXPECT_NO_THROW(model.Validate());
}

// Throwaway timing: HT_BAKE_TIMING=1 texture_bake_test --gtest_filter=*Timing*
TEST(TextureBake, TimingOf1024TextureOver512TrianglesAnd131kFull) {
  if (std::getenv("HT_BAKE_TIMING") == nullptr) GTEST_SKIP() << "set HT_BAKE_TIMING to run";
  const double radius = 50e-3;
  const TriangleMesh coarse = MakeOctasphere(3, radius);  // 512 triangles
  TriangleMesh full = MakeOctasphere(7, radius);          // 131072 triangles
  for (auto& v : full.vertices) {
    const glm::dvec3 d = glm::normalize(v);
    v = d * (radius + 0.3e-3 * std::sin(60 * d.x) * std::sin(60 * d.y));
  }
  const BakedTexture baked = BakeHapticTexture(coarse, full, {});
  const TextureBakeReport& r = baked.report;
  std::printf(
      "1024² over %zu coarse / %zu full triangles: %.3f s, %lld texels, %lld rays, "
      "%lld misses, max |h| %.3g mm, bake error max %.3g um rms %.3g um\n",
      coarse.triangles.size(), full.triangles.size(), r.seconds,
      static_cast<long long>(r.texels_baked), static_cast<long long>(r.rays),
      static_cast<long long>(r.misses), r.max_abs_height_m * 1e3, r.max_bake_error_m * 1e6,
      r.rms_bake_error_m * 1e6);
}

}  // namespace
}  // namespace ht
