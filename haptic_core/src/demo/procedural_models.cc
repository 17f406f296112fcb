#include "haptic_core/demo/procedural_models.h"

#include <cmath>
#include <glm/geometric.hpp>
#include <numbers>
#include <stdexcept>
#include <string>

namespace ht {
namespace {

constexpr double kTwoPi = 2.0 * std::numbers::pi;

void AddTriangle(HapticModel& m, glm::ivec3 t, const glm::dvec3 normals[3], const glm::vec2 uvs[3],
                 bool is_textured, double texel_size) {
  m.triangles.push_back(t);
  for (int c = 0; c < 3; ++c) {
    m.corner_normals_O.push_back(normals[c]);
    m.corner_uvs.push_back(uvs[c]);
  }
  m.textured.push_back(is_textured ? 1 : 0);
  m.texel_size_m.push_back(texel_size);
}

glm::dvec3 FaceNormal(const HapticModel& m, glm::ivec3 t) {
  const glm::dvec3 a = m.vertices_O[t[0]], b = m.vertices_O[t[1]], c = m.vertices_O[t[2]];
  return glm::normalize(glm::cross(b - a, c - a));
}

void AddFlatTriangle(HapticModel& m, glm::ivec3 t, const glm::vec2 uvs[3], bool is_textured,
                     double texel_size) {
  const glm::dvec3 n = FaceNormal(m, t);
  const glm::dvec3 normals[3] = {n, n, n};
  AddTriangle(m, t, normals, uvs, is_textured, texel_size);
}

void RequirePositive(double v, const char* what) {
  if (!(v > 0.0)) throw std::invalid_argument(std::string(what) + " must be positive");
}

}  // namespace

double RidgeProfile::Height(double s_m) const noexcept {
  const double c = std::cos(kTwoPi * s_m / period_m);
  if (sharpness < 1e-6) return amplitude_m * c;
  return amplitude_m * std::tanh(sharpness * c) / std::tanh(sharpness);
}

double RidgeProfile::MaxSlope() const noexcept {
  const double k = kTwoPi / period_m;
  if (sharpness < 1e-6) return amplitude_m * k;
  // d/ds tanh(β cos(ks)) = −β k sin(ks) sech²(β cos(ks)); largest near cos(ks) = 0.
  double best = 0.0;
  for (int i = 0; i <= 2000; ++i) {
    const double x = std::numbers::pi * i / 2000.0;
    const double sech = 1.0 / std::cosh(sharpness * std::cos(x));
    best = std::max(best, sharpness * k * std::sin(x) * sech * sech);
  }
  return amplitude_m * best / std::tanh(sharpness);
}

RidgeProfile RidgedGearParams::Profile() const noexcept {
  return {amplitude_m, kTwoPi * radius_m / teeth, sharpness};
}

HapticModel MakeTexturedBox(const glm::dvec3& h,
                            const std::function<double(double, double)>& bottom_height,
                            int texture_size, double mass_kg, std::string name) {
  RequirePositive(h.x, "box half extent x");
  RequirePositive(h.y, "box half extent y");
  RequirePositive(h.z, "box half extent z");
  RequirePositive(mass_kg, "box mass");
  if (texture_size < 2) throw std::invalid_argument("box texture_size must be >= 2");

  HapticModel m;
  m.name = std::move(name);
  // 0-3 bottom corners (counter-clockwise seen from +z), 4 bottom centre, 5-8 top, 9 top centre.
  const double sx[4] = {-1, 1, 1, -1}, sy[4] = {-1, -1, 1, 1};
  for (int i = 0; i < 4; ++i) m.vertices_O.push_back({sx[i] * h.x, sy[i] * h.y, -h.z});
  m.vertices_O.push_back({0, 0, -h.z});
  for (int i = 0; i < 4; ++i) m.vertices_O.push_back({sx[i] * h.x, sy[i] * h.y, h.z});
  m.vertices_O.push_back({0, 0, h.z});

  const double texel = 2.0 * std::max(h.x, h.y) / texture_size;
  const auto uv_bottom = [&](int vi) {
    const glm::dvec3 v = m.vertices_O[vi];
    return glm::vec2(static_cast<float>((v.x + h.x) / (2 * h.x)),
                     static_cast<float>((v.y + h.y) / (2 * h.y)));
  };
  const glm::vec2 zero_uv[3] = {};
  for (int i = 0; i < 4; ++i) {  // bottom fan, outward −z: textured
    const int j = (i + 1) % 4;
    const glm::vec2 uvs[3] = {uv_bottom(4), uv_bottom(j), uv_bottom(i)};
    AddFlatTriangle(m, {4, j, i}, uvs, true, texel);
  }
  for (int i = 0; i < 4; ++i) {  // top fan, outward +z
    AddFlatTriangle(m, {9, 5 + i, 5 + (i + 1) % 4}, zero_uv, false, texel);
  }
  for (int i = 0; i < 4; ++i) {  // sides
    const int j = (i + 1) % 4;
    AddFlatTriangle(m, {i, j, 5 + j}, zero_uv, false, texel);
    AddFlatTriangle(m, {i, 5 + j, 5 + i}, zero_uv, false, texel);
  }

  const int n = texture_size;
  std::vector<float> texels(static_cast<size_t>(n) * n);
  for (int y = 0; y < n; ++y) {
    const double yo = -h.y + (y + 0.5) / n * 2 * h.y;
    for (int x = 0; x < n; ++x) {
      const double xo = -h.x + (x + 0.5) / n * 2 * h.x;
      texels[static_cast<size_t>(y) * n + x] = static_cast<float>(bottom_height(xo, yo));
    }
  }
  m.texture = HeightField(n, n, std::move(texels), false, false);
  m.hull_vertices_O = m.vertices_O;
  m.center_of_mass_O = glm::dvec3(0.0);
  m.mass_kg = mass_kg;
  const double a = 2 * h.x, b = 2 * h.y, c = 2 * h.z;
  m.inertia_diagonal_O = {mass_kg / 12 * (b * b + c * c), mass_kg / 12 * (a * a + c * c),
                          mass_kg / 12 * (a * a + b * b)};
  m.full_resolution_triangles = 16;
  m.Validate();
  return m;
}

HapticModel MakeRidgedBlock(const RidgedBlockParams& p) {
  RequirePositive(p.ridges.period_m, "ridge period");
  const RidgeProfile ridges = p.ridges;
  HapticModel m = MakeTexturedBox(
      p.half_extents_m, [ridges](double, double y) { return ridges.Height(y); }, p.texture_size,
      p.mass_kg, "ridged_block");
  const std::int64_t g = p.full_resolution_grid;
  m.full_resolution_triangles = 2 * g * g + 12 * g;
  return m;
}

TriangleMesh MakeRidgedBlockFullResolution(const RidgedBlockParams& p) {
  const glm::dvec3 h = p.half_extents_m;
  const int n = p.full_resolution_grid;
  if (n < 1) throw std::invalid_argument("full_resolution_grid must be >= 1");
  TriangleMesh mesh;
  const auto grid_index = [n](int i, int j) { return j * (n + 1) + i; };
  for (int j = 0; j <= n; ++j) {
    const double y = -h.y + 2 * h.y * j / n;
    const double z = -h.z - p.ridges.Height(y);  // displaced along the outward normal −z
    for (int i = 0; i <= n; ++i) mesh.vertices.push_back({-h.x + 2 * h.x * i / n, y, z});
  }
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      mesh.triangles.push_back({grid_index(i, j), grid_index(i, j + 1), grid_index(i + 1, j + 1)});
      mesh.triangles.push_back({grid_index(i, j), grid_index(i + 1, j + 1), grid_index(i + 1, j)});
    }
  }
  // Boundary ring of the bottom grid, counter-clockwise seen from +z.
  std::vector<int> ring;
  for (int i = 0; i < n; ++i) ring.push_back(grid_index(i, 0));
  for (int j = 0; j < n; ++j) ring.push_back(grid_index(n, j));
  for (int i = n; i > 0; --i) ring.push_back(grid_index(i, n));
  for (int j = n; j > 0; --j) ring.push_back(grid_index(0, j));
  const int top0 = static_cast<int>(mesh.vertices.size());
  for (int r : ring) {
    const glm::dvec3 v = mesh.vertices[r];
    mesh.vertices.push_back({v.x, v.y, h.z});
  }
  const int top_centre = static_cast<int>(mesh.vertices.size());
  mesh.vertices.push_back({0, 0, h.z});
  const int rn = static_cast<int>(ring.size());
  for (int k = 0; k < rn; ++k) {
    const int k1 = (k + 1) % rn;
    mesh.triangles.push_back({ring[k], ring[k1], top0 + k1});
    mesh.triangles.push_back({ring[k], top0 + k1, top0 + k});
    mesh.triangles.push_back({top_centre, top0 + k, top0 + k1});
  }
  return mesh;
}

HapticModel MakeRidgedGear(const RidgedGearParams& p) {
  RequirePositive(p.radius_m, "gear radius");
  RequirePositive(p.length_m, "gear length");
  RequirePositive(p.mass_kg, "gear mass");
  if (p.coarse_segments < 3) throw std::invalid_argument("gear needs at least 3 segments");
  if (p.teeth < 1) throw std::invalid_argument("gear needs at least 1 tooth");
  if (p.texture_size < 2) throw std::invalid_argument("gear texture_size must be >= 2");
  const int S = p.coarse_segments;
  const double R = p.radius_m, L = p.length_m;

  HapticModel m;
  m.name = "ridged_gear";
  for (int ring = 0; ring < 2; ++ring) {
    const double x = ring == 0 ? -0.5 * L : 0.5 * L;
    for (int j = 0; j < S; ++j) {
      const double phi = kTwoPi * j / S;
      m.vertices_O.push_back({x, R * std::cos(phi), R * std::sin(phi)});
    }
  }
  const int c0 = 2 * S, c1 = 2 * S + 1;
  m.vertices_O.push_back({-0.5 * L, 0, 0});
  m.vertices_O.push_back({0.5 * L, 0, 0});

  // The ridges vary along the circumference only: texel size is the arc per texel.
  const double texel = std::max(kTwoPi * R, L) / p.texture_size;
  const glm::vec2 zero_uv[3] = {};
  for (int j = 0; j < S; ++j) {
    const int b = (j + 1) % S;
    const double phi_a = kTwoPi * j / S, phi_b = kTwoPi * (j + 1) / S;
    const glm::dvec3 na(0, std::cos(phi_a), std::sin(phi_a)),
        nb(0, std::cos(phi_b), std::sin(phi_b));
    const auto va = static_cast<float>(static_cast<double>(j) / S);
    const auto vb = static_cast<float>(static_cast<double>(j + 1) / S);  // 1.0 at the seam
    {
      const glm::dvec3 normals[3] = {na, nb, nb};
      const glm::vec2 uvs[3] = {{0.0f, va}, {0.0f, vb}, {1.0f, vb}};
      AddTriangle(m, {j, b, S + b}, normals, uvs, true, texel);
    }
    {
      const glm::dvec3 normals[3] = {na, nb, na};
      const glm::vec2 uvs[3] = {{0.0f, va}, {1.0f, vb}, {1.0f, va}};
      AddTriangle(m, {j, S + b, S + j}, normals, uvs, true, texel);
    }
    AddFlatTriangle(m, {c0, b, j}, zero_uv, false, texel);
    AddFlatTriangle(m, {c1, S + j, S + b}, zero_uv, false, texel);
  }

  const int n = p.texture_size;
  const RidgeProfile profile = p.Profile();
  std::vector<float> texels(static_cast<size_t>(n) * n);
  for (int y = 0; y < n; ++y) {
    const double v = (y + 0.5) / n;
    const auto height = static_cast<float>(profile.Height(kTwoPi * R * v));
    for (int x = 0; x < n; ++x) texels[static_cast<size_t>(y) * n + x] = height;
  }
  m.texture = HeightField(n, n, std::move(texels), false, true);
  m.hull_vertices_O.assign(m.vertices_O.begin(), m.vertices_O.begin() + 2 * S);
  m.mass_kg = p.mass_kg;
  const double ixx = 0.5 * p.mass_kg * R * R;
  const double iyy = p.mass_kg / 12.0 * (3 * R * R + L * L);
  m.inertia_diagonal_O = {ixx, iyy, iyy};
  m.full_resolution_triangles = 2LL * p.full_resolution_segments * (p.full_resolution_rows + 1);
  m.Validate();
  return m;
}

TriangleMesh MakeRidgedGearFullResolution(const RidgedGearParams& p) {
  const int S = p.full_resolution_segments, rows = p.full_resolution_rows;
  if (S < 3 || rows < 1) throw std::invalid_argument("gear full resolution needs S>=3, rows>=1");
  const RidgeProfile profile = p.Profile();
  TriangleMesh mesh;
  for (int r = 0; r <= rows; ++r) {
    const double x = -0.5 * p.length_m + p.length_m * r / rows;
    for (int j = 0; j < S; ++j) {
      const double phi = kTwoPi * j / S;
      const double rad = p.radius_m + profile.Height(p.radius_m * phi);
      mesh.vertices.push_back({x, rad * std::cos(phi), rad * std::sin(phi)});
    }
  }
  const auto idx = [S](int r, int j) { return r * S + (j % S); };
  for (int r = 0; r < rows; ++r) {
    for (int j = 0; j < S; ++j) {
      mesh.triangles.push_back({idx(r, j), idx(r, j + 1), idx(r + 1, j + 1)});
      mesh.triangles.push_back({idx(r, j), idx(r + 1, j + 1), idx(r + 1, j)});
    }
  }
  const int c0 = static_cast<int>(mesh.vertices.size());
  mesh.vertices.push_back({-0.5 * p.length_m, 0, 0});
  mesh.vertices.push_back({0.5 * p.length_m, 0, 0});
  for (int j = 0; j < S; ++j) {
    mesh.triangles.push_back({c0, idx(0, j + 1), idx(0, j)});
    mesh.triangles.push_back({c0 + 1, idx(rows, j), idx(rows, j + 1)});
  }
  return mesh;
}

}  // namespace ht
