#include "haptic_core/demo/seed_models.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <glm/geometric.hpp>
#include <numbers>
#include <stdexcept>
#include <string>

#include "haptic_core/demo/procedural_models.h"
#include "seed_shapes.h"

namespace ht {
using seed_shapes::Angle;
using seed_shapes::AxisBox;
using seed_shapes::BlurredInterval;
using seed_shapes::BlurredSolid;
using seed_shapes::BuildPolycube;
using seed_shapes::Cdf;
using seed_shapes::Cylinder;
using seed_shapes::Fract;
using seed_shapes::GridAxis;
using seed_shapes::Interval;
using seed_shapes::kTwoPi;
using seed_shapes::MakeGridAxis;
using seed_shapes::Pdf;
using seed_shapes::PlaneWaveNoise;
using seed_shapes::QuadMesh;
using seed_shapes::Require;
using seed_shapes::RequireFinite;
using seed_shapes::RequirePositive;
using seed_shapes::SawTooth;
using seed_shapes::ShapeFromPolycube;
using seed_shapes::Smoothstep;
using seed_shapes::ValidateDetail;

// ---------------------------------------------------------------------------------------------

TriangleMesh MakeTexturedHammerFullResolution(const TexturedHammerParams& p) {
  RequirePositive(p.head_half_extents_m.x, "hammer head half extent x");
  RequirePositive(p.head_half_extents_m.y, "hammer head half extent y");
  RequirePositive(p.head_half_extents_m.z, "hammer head half extent z");
  RequirePositive(p.length_m, "hammer length");
  RequirePositive(p.handle_radius_m, "hammer handle radius");
  RequirePositive(p.edge_blur_m, "hammer edge blur");
  RequirePositive(p.knurl_period_m, "hammer knurl period");
  RequirePositive(p.peen_min_period_m, "hammer peen min period");
  RequirePositive(p.peen_max_period_m, "hammer peen max period");
  RequirePositive(p.cell_size_m.x, "hammer cell size x");
  RequirePositive(p.cell_size_m.y, "hammer cell size y");
  RequirePositive(p.cell_size_m.z, "hammer cell size z");
  RequireFinite(p.knurl_amplitude_m, "hammer knurl amplitude");
  RequireFinite(p.peen_amplitude_m, "hammer peen amplitude");
  ValidateDetail(p.detail_scale);
  const glm::dvec3 hh = p.head_half_extents_m;
  const double R = p.handle_radius_m;
  const double outer_blend = 3.0e-3;
  Require(R + outer_blend + 2.0 * p.edge_blur_m <= std::min(hh.x, hh.y),
          "hammer handle radius must leave a ledge under the head (radius + 3 mm + 2σ <= head "
          "half extents x and y)");
  const double z_top = 0.5 * p.length_m, z_bottom = -0.5 * p.length_m;
  const double z_head = z_top - 2.0 * hh.z;
  Require(z_head - z_bottom > 4.0 * R, "hammer handle must be longer than 4 radii");

  BlurredSolid solid(p.edge_blur_m);
  solid.AddBox({-hh.x, -hh.y, z_head}, {hh.x, hh.y, z_top});
  solid.AddCylinder({2, {0.0, 0.0}, R, z_bottom, z_head, 0.0, outer_blend});

  const int starts = std::max(1, static_cast<int>(std::lround(kTwoPi * R / p.knurl_period_m)));
  const double grip0 = z_bottom + p.grip_start_m, grip1 = grip0 + p.grip_length_m;
  const double fade = 3.0e-3;
  const PlaneWaveNoise peen(8, p.peen_min_period_m, p.peen_max_period_m, 1.0);
  const auto detail = [&](const glm::dvec3& q, const glm::dvec3& n) {
    const double radial = std::sqrt(n.x * n.x + n.y * n.y);
    const double w_knurl = Smoothstep(grip0, grip0 + fade, q.z) *
                           (1.0 - Smoothstep(grip1 - fade, grip1, q.z)) *
                           Smoothstep(0.85, 0.97, radial);
    double h = 0.0;
    if (w_knurl > 0.0) {
      const double theta = std::atan2(q.y, q.x);
      h += w_knurl * p.knurl_amplitude_m * std::cos(starts * theta) *
           std::cos(kTwoPi * q.z / p.knurl_period_m);
    }
    const double w_head = Smoothstep(z_head - 4.0e-3, z_head, q.z);
    if (w_head > 0.0) h += w_head * p.peen_amplitude_m * std::tanh(0.5 * peen(q));
    return h;
  };
  return ShapeFromPolycube(
      solid, p.cell_size_m, p.detail_scale, [](glm::dvec3&, glm::dvec3&) {}, detail);
}

TriangleMesh MakeRoughCadPartFullResolution(const RoughCadPartParams& p) {
  RequirePositive(p.plate_half_extents_m.x, "CAD part plate half extent x");
  RequirePositive(p.plate_half_extents_m.y, "CAD part plate half extent y");
  RequirePositive(p.boss_radius_m, "CAD part boss radius");
  RequirePositive(p.pin_radius_m, "CAD part pin radius");
  RequirePositive(p.edge_blur_m, "CAD part edge blur");
  RequirePositive(p.mill_period_m, "CAD part mill period");
  RequirePositive(p.wall_period_m, "CAD part wall period");
  RequirePositive(p.rough_min_period_m, "CAD part roughness min period");
  RequirePositive(p.rough_max_period_m, "CAD part roughness max period");
  RequirePositive(p.cell_size_m.x, "CAD part cell size x");
  RequirePositive(p.cell_size_m.y, "CAD part cell size y");
  RequirePositive(p.cell_size_m.z, "CAD part cell size z");
  RequireFinite(p.mill_amplitude_m, "CAD part mill amplitude");
  RequireFinite(p.wall_amplitude_m, "CAD part wall amplitude");
  RequireFinite(p.rough_amplitude_m, "CAD part roughness amplitude");
  ValidateDetail(p.detail_scale);
  const double hx = p.plate_half_extents_m.x, hy = p.plate_half_extents_m.y;
  const double boss_blend = 5.0e-3, pin_blend = 3.0e-3;
  Require(p.bottom_z_m < p.plate_top_z_m && p.plate_top_z_m < p.slot_floor_z_m &&
              p.slot_floor_z_m < p.step_top_z_m && p.step_top_z_m < p.pin_top_z_m &&
              p.plate_top_z_m < p.boss_top_z_m,
          "CAD part heights must increase: bottom < plate top < slot floor < step top < pin top, "
          "plate top < boss top");
  Require(
      -hx < p.step_start_x_m && p.step_start_x_m < p.slot_start_x_m && p.slot_start_x_m < hx &&
          0.0 < p.slot_half_width_m && p.slot_half_width_m < hy,
      "CAD part layout along x/y: -hx < step start < slot start < hx, 0 < slot half width < hy");
  Require(p.boss_centre_m.x + p.boss_radius_m + boss_blend < p.step_start_x_m &&
              p.boss_centre_m.x - p.boss_radius_m - boss_blend > -hx &&
              p.boss_centre_m.y - p.boss_radius_m - boss_blend > 0.0 &&
              p.boss_centre_m.y + p.boss_radius_m + boss_blend < hy,
          "CAD part bosses must stand on the low plate, 5 mm clear of its edges and the x axis");
  Require(p.pin_centre_m.x - p.pin_radius_m - pin_blend > p.step_start_x_m &&
              p.pin_centre_m.x + p.pin_radius_m + pin_blend < hx &&
              p.pin_centre_m.y - p.pin_radius_m - pin_blend > p.slot_half_width_m &&
              p.pin_centre_m.y + p.pin_radius_m + pin_blend < hy,
          "CAD part pins must stand on the step, 3 mm clear of its edges and the slot");

  BlurredSolid solid(p.edge_blur_m);
  const double sw = p.slot_half_width_m;
  solid.AddBox({-hx, -hy, p.bottom_z_m}, {hx, hy, p.plate_top_z_m});
  solid.AddBox({p.step_start_x_m, -hy, p.plate_top_z_m}, {hx, -sw, p.step_top_z_m});
  solid.AddBox({p.step_start_x_m, sw, p.plate_top_z_m}, {hx, hy, p.step_top_z_m});
  solid.AddBox({p.step_start_x_m, -sw, p.plate_top_z_m}, {p.slot_start_x_m, sw, p.step_top_z_m});
  solid.AddBox({p.slot_start_x_m, -sw, p.plate_top_z_m}, {hx, sw, p.slot_floor_z_m});
  for (double sy : {-1.0, 1.0}) {
    solid.AddCylinder({2,
                       {p.boss_centre_m.x, sy * p.boss_centre_m.y},
                       p.boss_radius_m,
                       p.plate_top_z_m,
                       p.boss_top_z_m,
                       0.0,
                       boss_blend});
    solid.AddCylinder({2,
                       {p.pin_centre_m.x, sy * p.pin_centre_m.y},
                       p.pin_radius_m,
                       p.step_top_z_m,
                       p.pin_top_z_m,
                       0.0,
                       pin_blend});
  }

  const glm::dvec2 cutter_centre(-3.0 * hx, 0.4 * hy);
  const PlaneWaveNoise rough(8, p.rough_min_period_m, p.rough_max_period_m, 2.0);
  const auto detail = [&](const glm::dvec3& q, const glm::dvec3& n) {
    const double w_flat = Smoothstep(0.5, 0.9, std::abs(n.z));
    const double mill =
        p.mill_amplitude_m *
        std::cos(kTwoPi * glm::length(glm::dvec2(q.x, q.y) - cutter_centre) / p.mill_period_m);
    const double wall = p.wall_amplitude_m * std::cos(kTwoPi * q.z / p.wall_period_m);
    return w_flat * mill + (1.0 - w_flat) * wall + p.rough_amplitude_m * std::tanh(0.5 * rough(q));
  };
  return ShapeFromPolycube(
      solid, p.cell_size_m, p.detail_scale, [](glm::dvec3&, glm::dvec3&) {}, detail);
}

TriangleMesh MakeToothedFileFullResolution(const ToothedFileParams& p) {
  RequirePositive(p.handle_length_m, "file handle length");
  RequirePositive(p.handle_radius_m, "file handle radius");
  RequirePositive(p.neck_length_m, "file neck length");
  RequirePositive(p.neck_half_width_m, "file neck half width");
  RequirePositive(p.neck_half_thickness_m, "file neck half thickness");
  RequirePositive(p.blade_length_m, "file blade length");
  RequirePositive(p.blade_half_width_m, "file blade half width");
  RequirePositive(p.blade_half_thickness_m, "file blade half thickness");
  RequirePositive(p.taper_length_m, "file taper length");
  RequirePositive(p.tip_width_scale, "file tip width scale");
  RequirePositive(p.tip_thickness_scale, "file tip thickness scale");
  RequirePositive(p.edge_blur_m, "file edge blur");
  RequirePositive(p.overcut_period_m, "file overcut period");
  RequirePositive(p.upcut_period_m, "file upcut period");
  RequirePositive(p.edge_tooth_period_m, "file edge tooth period");
  RequirePositive(p.grip_period_m, "file grip period");
  RequirePositive(p.cell_size_m.x, "file cell size x");
  RequirePositive(p.cell_size_m.y, "file cell size y");
  RequirePositive(p.cell_size_m.z, "file cell size z");
  RequireFinite(p.tooth_amplitude_m, "file tooth amplitude");
  RequireFinite(p.edge_tooth_amplitude_m, "file edge tooth amplitude");
  RequireFinite(p.grip_amplitude_m, "file grip amplitude");
  ValidateDetail(p.detail_scale);
  const double neck_extent = std::max(p.neck_half_width_m, p.neck_half_thickness_m);
  Require(p.taper_length_m <= p.blade_length_m, "file taper must not be longer than the blade");
  Require(p.tip_width_scale <= 1.0 && p.tip_thickness_scale <= 1.0,
          "file tip scales must be in (0, 1]");
  // The handle's radial map is blended in from neck_extent + 0.5 mm; it stays monotone along
  // each ray (no folds on the end faces) while that is at most half the radius.
  Require(neck_extent + 0.5e-3 <= 0.5 * p.handle_radius_m,
          "file neck must fit well inside the handle (max neck half size + 0.5 mm <= handle "
          "radius / 2)");
  Require(p.neck_half_width_m < p.blade_half_width_m &&
              p.neck_half_thickness_m < p.blade_half_thickness_m,
          "file neck must be narrower and thinner than the blade");
  const double x_handle = -0.5 * p.TotalLength();
  const double x_neck = x_handle + p.handle_length_m;
  const double x_blade = x_neck + p.neck_length_m;
  const double x_tip = x_blade + p.blade_length_m;
  const double x_taper = x_tip - p.taper_length_m;

  BlurredSolid solid(p.edge_blur_m);
  solid.AddCylinder(
      {0, {0.0, 0.0}, p.handle_radius_m, x_handle, x_neck, neck_extent + 0.5e-3, 0.0});
  solid.AddBox({x_neck, -p.neck_half_width_m, -p.neck_half_thickness_m},
               {x_blade, p.neck_half_width_m, p.neck_half_thickness_m});
  solid.AddBox({x_blade, -p.blade_half_width_m, -p.blade_half_thickness_m},
               {x_tip, p.blade_half_width_m, p.blade_half_thickness_m});

  // Taper D(x, y, z) = (x, y·a(x), z·b(x)); normals map by the inverse transpose of its Jacobian.
  const auto taper = [&](glm::dvec3& q, glm::dvec3& n) {
    if (q.x <= x_taper) return;
    const double t = std::min(1.0, (q.x - x_taper) / p.taper_length_m);
    const double a = 1.0 - (1.0 - p.tip_width_scale) * t * t;
    const double b = 1.0 - (1.0 - p.tip_thickness_scale) * t * t;
    const double da = t < 1.0 ? -(1.0 - p.tip_width_scale) * 2.0 * t / p.taper_length_m : 0.0;
    const double db = t < 1.0 ? -(1.0 - p.tip_thickness_scale) * 2.0 * t / p.taper_length_m : 0.0;
    n = glm::normalize(glm::dvec3(n.x - q.y * da / a * n.y - q.z * db / b * n.z, n.y / a, n.z / b));
    q.y *= a;
    q.z *= b;
  };
  const double c1 = std::cos(65.0 * std::numbers::pi / 180.0),
               s1 = std::sin(65.0 * std::numbers::pi / 180.0);
  const double c2 = std::cos(-45.0 * std::numbers::pi / 180.0),
               s2 = std::sin(-45.0 * std::numbers::pi / 180.0);
  const double fade = 2.0e-3;
  const auto detail = [&](const glm::dvec3& q, const glm::dvec3& n) {
    const double w_blade = Smoothstep(x_blade + 4.0e-3, x_blade + 4.0e-3 + fade, q.x) *
                           (1.0 - Smoothstep(x_tip - 3.0e-3 - fade, x_tip - 3.0e-3, q.x));
    double h = 0.0;
    if (w_blade > 0.0) {
      const double w_face = Smoothstep(0.85, 0.97, std::abs(n.z));
      const double w_edge = Smoothstep(0.85, 0.97, n.y);
      // Coordinates across the cuts (crest lines at +65° and −45° to the axis).
      const double u1 = -q.x * s1 + q.y * c1, u2 = -q.x * s2 + q.y * c2;
      const double teeth = p.tooth_amplitude_m * std::min(SawTooth(u1 / p.overcut_period_m),
                                                          SawTooth(u2 / p.upcut_period_m));
      const double edge = p.edge_tooth_amplitude_m * SawTooth(q.x / p.edge_tooth_period_m);
      h += w_blade * (w_face * teeth + w_edge * edge);
    }
    const double w_grip = Smoothstep(x_handle + 5.0e-3, x_handle + 5.0e-3 + fade, q.x) *
                          (1.0 - Smoothstep(x_neck - 5.0e-3 - fade, x_neck - 5.0e-3, q.x)) *
                          Smoothstep(0.85, 0.97, std::sqrt(n.y * n.y + n.z * n.z));
    h += w_grip * p.grip_amplitude_m * std::cos(kTwoPi * q.x / p.grip_period_m);
    return h;
  };
  return ShapeFromPolycube(solid, p.cell_size_m, p.detail_scale, taper, detail);
}

TriangleMesh MakeWrinkledTorusFullResolution(const WrinkledTorusParams& p) {
  RequirePositive(p.major_radius_m, "torus major radius");
  RequirePositive(p.minor_radius_m, "torus minor radius");
  RequireFinite(p.wrinkle_amplitude_m, "torus wrinkle amplitude");
  ValidateDetail(p.detail_scale);
  Require(p.minor_radius_m + std::abs(p.wrinkle_amplitude_m) < p.major_radius_m,
          "torus minor radius plus wrinkle amplitude must be below the major radius");
  Require(std::abs(p.wrinkle_amplitude_m) < 0.5 * p.minor_radius_m,
          "torus wrinkle amplitude must be below half the minor radius");
  Require(p.major_segments >= 3 && p.tube_segments >= 3,
          "torus needs at least 3 major and 3 tube segments");
  const int nu = p.major_segments, nv = p.tube_segments;
  const double R = p.major_radius_m, r = p.minor_radius_m;
  const double A = p.detail_scale * p.wrinkle_amplitude_m;
  TriangleMesh mesh;
  mesh.vertices.reserve(static_cast<size_t>(nu) * nv);
  for (int i = 0; i < nu; ++i) {
    const double theta = kTwoPi * i / nu;
    for (int j = 0; j < nv; ++j) {
      const double phi = kTwoPi * j / nv;
      const glm::dvec3 n(std::cos(phi) * std::cos(theta), std::cos(phi) * std::sin(theta),
                         std::sin(phi));
      const double rho = r + A * std::sin(p.major_waves * theta + p.tube_waves * phi);
      mesh.vertices.push_back(R * glm::dvec3(std::cos(theta), std::sin(theta), 0.0) + rho * n);
    }
  }
  // (i along θ, j along φ): ∂p/∂θ × ∂p/∂φ points out of the tube.
  const auto idx = [nu, nv](int i, int j) { return (i % nu) * nv + (j % nv); };
  mesh.triangles.reserve(2 * static_cast<size_t>(nu) * nv);
  for (int i = 0; i < nu; ++i) {
    for (int j = 0; j < nv; ++j) {
      mesh.triangles.push_back({idx(i, j), idx(i + 1, j), idx(i + 1, j + 1)});
      mesh.triangles.push_back({idx(i, j), idx(i + 1, j + 1), idx(i, j + 1)});
    }
  }
  return mesh;
}

// ---------------------------------------------------------------------------------------------

const std::vector<SeedModelSpec>& SeedModelSpecs() {
  static const std::vector<SeedModelSpec> kSpecs = {
      {SeedModel::kBlock, "block", 65536, 16, 1},
      {SeedModel::kGear, "gear", 25600, 1600, 1},
      {SeedModel::kHammer, "hammer", 433152, 518, 210},
      {SeedModel::kCadPart, "cad_part", 658432, 720, 390},
      {SeedModel::kFile, "file", 285824, 632, 113},
      {SeedModel::kTorus, "torus", 128000, 532, 114},
  };
  return kSpecs;
}

const SeedModelSpec& SeedModelSpecOf(SeedModel model) {
  for (const SeedModelSpec& s : SeedModelSpecs()) {
    if (s.model == model) return s;
  }
  throw std::invalid_argument("unknown SeedModel value " + std::to_string(static_cast<int>(model)));
}

const char* SeedModelName(SeedModel model) { return SeedModelSpecOf(model).name; }

SeedModel ParseSeedModelName(const std::string& name) {
  std::string valid;
  for (const SeedModelSpec& s : SeedModelSpecs()) {
    if (name == s.name) return s.model;
    valid += valid.empty() ? "" : ", ";
    valid += s.name;
  }
  throw std::invalid_argument("unknown seed model '" + name + "'; valid names: " + valid);
}

TriangleMesh MakeSeedModelFullResolution(SeedModel model) {
  switch (model) {
    case SeedModel::kBlock:
      return MakeRidgedBlockFullResolution();
    case SeedModel::kGear:
      return MakeRidgedGearFullResolution();
    case SeedModel::kHammer:
      return MakeTexturedHammerFullResolution();
    case SeedModel::kCadPart:
      return MakeRoughCadPartFullResolution();
    case SeedModel::kFile:
      return MakeToothedFileFullResolution();
    case SeedModel::kTorus:
      return MakeWrinkledTorusFullResolution();
  }
  throw std::invalid_argument("unknown SeedModel value " + std::to_string(static_cast<int>(model)));
}

}  // namespace ht
