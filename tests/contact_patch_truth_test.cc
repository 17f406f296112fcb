// The pipeline truth (haptic_core/accuracy/contact_patch_truth.h, issue 31): closed forms (flat on
// flat, a tilted box on its edge, a sphere on a plane), the volume gradient against a finite
// difference of the intersection volume computed another way (column integration of convex
// intervals), a pose where a borrowed window sees nothing but the truth's own patch is right, and
// the property that every pose whose full-resolution meshes intersect gets a non-zero truth.

#include "haptic_core/accuracy/contact_patch_truth.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <glm/gtc/quaternion.hpp>
#include <numbers>
#include <random>

#include "accuracy_test_meshes.h"
#include "haptic_core/accuracy/mesh_contact_baseline.h"
#include "haptic_core/demo/procedural_models.h"

namespace ht {
namespace {

constexpr double kK = 8000.0;  // N/m

using test::At;
using test::Box;

// UV sphere of radius r about the origin with a pole vertex at −z (the lowest point is exact).
TriangleMesh Sphere(double r, int rings, int segments) {
  TriangleMesh m;
  m.vertices.push_back({0, 0, -r});
  for (int i = 1; i < rings; ++i) {
    const double phi = std::numbers::pi * i / rings;  // from −z
    for (int j = 0; j < segments; ++j) {
      const double th = 2.0 * std::numbers::pi * j / segments;
      m.vertices.push_back(
          {r * std::sin(phi) * std::cos(th), r * std::sin(phi) * std::sin(th), -r * std::cos(phi)});
    }
  }
  m.vertices.push_back({0, 0, r});
  const int top = static_cast<int>(m.vertices.size()) - 1;
  const auto ring = [&](int i, int j) { return 1 + (i - 1) * segments + (j % segments); };
  for (int j = 0; j < segments; ++j) m.triangles.push_back({0, ring(1, j + 1), ring(1, j)});
  for (int i = 1; i + 1 < rings; ++i) {
    for (int j = 0; j < segments; ++j) {
      m.triangles.push_back({ring(i, j), ring(i, j + 1), ring(i + 1, j + 1)});
      m.triangles.push_back({ring(i, j), ring(i + 1, j + 1), ring(i + 1, j)});
    }
  }
  for (int j = 0; j < segments; ++j) {
    m.triangles.push_back({top, ring(rings - 1, j), ring(rings - 1, j + 1)});
  }
  return m;
}

glm::dquat AboutY(double a) { return glm::angleAxis(a, glm::dvec3(0, 1, 0)); }

double AngleDeg(const glm::dvec3& a, const glm::dvec3& b) {
  const double c = glm::dot(a, b) / (glm::length(a) * glm::length(b));
  return std::acos(std::clamp(c, -1.0, 1.0)) * 180.0 / std::numbers::pi;
}

// A slab whose top face is z = 0.
const TriangleMesh kSlab = Box({-0.06, -0.06, -0.02}, {0.06, 0.06, 0.0});

struct Rig {
  Rig(const TriangleMesh& tool, const TriangleMesh& env, const ContactPatchTruthOptions& o = {})
      : tool_rays(tool), env_rays(env), truth(tool, env, tool_rays, env_rays, o) {}
  RayCastSurface tool_rays, env_rays;
  ContactPatchTruth truth;
};

TEST(RayCastSurface, TellsInsideFromOutsideWhateverTheDirection) {
  const RayCastSurface box(Box({-1, -1, -1}, {1, 1, 1}));
  for (const glm::dvec3 d : {glm::dvec3(0, 0, 1), glm::dvec3(0, 0, -1), glm::dvec3(0.6, 0, 0.8)}) {
    EXPECT_TRUE(box.IsInside({0.2, 0.3, -0.9}, d));
    EXPECT_FALSE(box.IsInside({0.2, 0.3, 1.5}, d));
    EXPECT_FALSE(box.IsInside({3, 0, 0}, d));
  }
}

// Flat on flat: a 2×2 cm face δ into a slab. One patch along +z, δ_gt = δ, F = k δ ẑ, no torque
// about the box's centre above the face; ∇_x V = −A ẑ by both routes (V = A·δ).
TEST(ContactPatchTruth, FlatOnFlatIsKDeltaAlongTheNormal) {
  const double delta = 0.3e-3;
  Rig rig(Box({-0.01, -0.01, -0.005}, {0.01, 0.01, 0.005}), kSlab);
  const RigidTransform X_WT = At({0.002, -0.003, 0.005 - delta});
  const PoseTruth t = rig.truth.At(X_WT, RigidTransform{}, RigidTransform{}, kK);
  ASSERT_EQ(t.patches.size(), 1u);
  const TruthPatch& p = t.patches[0];
  EXPECT_LT(AngleDeg(p.window.normal_W, {0, 0, 1}), 0.1);
  EXPECT_NEAR(p.contact.linearization.depth_m, delta, 1e-7);
  EXPECT_NEAR(t.F_T_W.force.z, kK * delta, 0.01 * kK * delta);
  EXPECT_NEAR(glm::length(glm::dvec2(t.F_T_W.force)), 0.0, 1e-3 * kK * delta);
  EXPECT_LT(glm::length(t.F_T_W.torque), 1e-3 * kK * delta * 0.01);
  // The window sits on the face and holds it.
  EXPECT_LT(glm::length(glm::dvec2(p.window.center_W) - glm::dvec2(0.002, -0.003)), 1e-4);
  EXPECT_GE(p.window.extent_m, 0.02);
  const double area = 4e-4;
  for (const glm::dvec3& g : {p.dV_dx_tool_W, p.dV_dx_environment_W}) {
    EXPECT_NEAR(g.z, -area, 0.01 * area);
    EXPECT_LT(glm::length(glm::dvec2(g)), 0.01 * area);
  }
  EXPECT_NEAR(p.tool_inside_area_m2, area + 4 * 0.02 * delta, 0.01 * area);
  EXPECT_NEAR(p.environment_inside_area_m2, area, 0.01 * area);
}

// A sphere of radius R pressed h into a plane: δ = h at the pole, F = k h ẑ through the centre;
// ∇_x V = −π a² ẑ with a² = 2Rh − h² (the cap's base), on a tessellated sphere within 3 %.
TEST(ContactPatchTruth, SphereOnAPlaneMatchesTheCap) {
  const double r = 5e-3, h = 0.2e-3;
  Rig rig(Sphere(r, 96, 192), kSlab);
  const RigidTransform X_WT = At({0.01, 0.0, r - h});
  const PoseTruth t = rig.truth.At(X_WT, RigidTransform{}, RigidTransform{}, kK);
  ASSERT_EQ(t.patches.size(), 1u);
  EXPECT_NEAR(t.patches[0].contact.linearization.depth_m, h, 1e-7);
  EXPECT_NEAR(t.F_T_W.force.z, kK * h, 0.01 * kK * h);
  EXPECT_LT(glm::length(t.F_T_W.torque), 0.01 * kK * h * r);
  const double cap = std::numbers::pi * (2 * r * h - h * h);
  EXPECT_NEAR(t.dV_dx_W.z, -cap, 0.03 * cap);
  EXPECT_LT(glm::length(glm::dvec2(t.dV_dx_W)), 0.01 * cap);
  EXPECT_LT(glm::length(t.dV_dtheta_W), 0.01 * cap * r);
}

// Intersection volume of a box (half sizes `half`, posed at X) with the half-space z ≤ 0 by
// column integration: per column the box's z interval (clipping a vertical line against its six
// faces) overlapped with z ≤ 0, midpoint rule over a grid covering its footprint.
double BoxHalfSpaceVolume(const glm::dvec3& half, const RigidTransform& X, int cells) {
  const glm::dmat3 R = glm::mat3_cast(X.rotation);
  const double reach = glm::length(half);
  const double x0 = X.translation.x - reach, y0 = X.translation.y - reach;
  const double step = 2.0 * reach / cells;
  double v = 0.0;
  for (int i = 0; i < cells; ++i) {
    for (int j = 0; j < cells; ++j) {
      const glm::dvec3 q(x0 + (i + 0.5) * step, y0 + (j + 0.5) * step, 0.0);
      double lo = -1e9, hi = 1e9;
      bool empty = false;
      for (int a = 0; a < 3 && !empty; ++a) {
        const glm::dvec3 axis = R[a];  // column a: the box's axis in W
        // |axis·(q + z ẑ − c)| ≤ half[a]  →  an interval in z (or all / nothing when axis.z = 0).
        const double base = glm::dot(axis, q - X.translation);
        if (std::abs(axis.z) < 1e-15) {
          if (std::abs(base) > half[a]) empty = true;
          continue;
        }
        double z1 = (-half[a] - base) / axis.z, z2 = (half[a] - base) / axis.z;
        if (z1 > z2) std::swap(z1, z2);
        lo = std::max(lo, z1);
        hi = std::min(hi, z2);
      }
      if (empty) continue;
      hi = std::min(hi, 0.0);
      if (hi > lo) v += (hi - lo) * step * step;
    }
  }
  return v;
}

// A box tilted 10° about y rests on one edge, δ below the plane. T1: δ_gt = δ, F = k δ ẑ and the
// torque of that force at the edge. T2: ∇V against central differences of the volume computed by
// column integration (two routes to one number), along z and about y.
TEST(ContactPatchTruth, TiltedBoxOnItsEdgeAgreesWithTheVolumeComputedAnotherWay) {
  const glm::dvec3 half(0.01, 0.01, 0.005);
  const double alpha = 10.0 * std::numbers::pi / 180.0, delta = 0.5e-3;
  Rig rig(Box(-half, half), kSlab);
  // The lowest edge (x = −hx, z = −hz in the box) after the tilt: lift the box so it is at −δ.
  const glm::dquat R = AboutY(alpha);
  const glm::dvec3 edge_T = R * glm::dvec3(-half.x, 0, -half.z);
  const glm::dvec3 edge_T2 = R * glm::dvec3(half.x, 0, -half.z);
  const glm::dvec3 low = edge_T.z < edge_T2.z ? edge_T : edge_T2;
  const RigidTransform X_WT = At({0, 0, -delta - low.z}, R);
  const PoseTruth t = rig.truth.At(X_WT, RigidTransform{}, RigidTransform{}, kK);
  ASSERT_EQ(t.patches.size(), 1u);
  EXPECT_NEAR(t.patches[0].contact.linearization.depth_m, delta, 1e-7);
  EXPECT_LT(AngleDeg(t.patches[0].window.normal_W, {0, 0, 1}), 0.1);
  const glm::dvec3 F(0, 0, kK * delta);
  EXPECT_NEAR(t.F_T_W.force.z, F.z, 0.01 * F.z);
  const glm::dvec3 torque = glm::cross(low, F);  // the force at the edge line's middle
  EXPECT_NEAR(t.F_T_W.torque.y, torque.y, 0.02 * std::abs(torque.y));
  EXPECT_NEAR(t.F_T_W.torque.x, 0.0, 0.02 * std::abs(torque.y));

  const int cells = 1600;
  const double hz = 20e-6, ht = 2e-3;
  const auto volume = [&](const RigidTransform& X) { return BoxHalfSpaceVolume(half, X, cells); };
  RigidTransform up = X_WT, down = X_WT;
  up.translation.z += hz;
  down.translation.z -= hz;
  const double dV_dz = (volume(up) - volume(down)) / (2 * hz);
  RigidTransform plus = X_WT, minus = X_WT;
  plus.rotation = AboutY(ht) * X_WT.rotation;  // world axes, about the centre of mass
  minus.rotation = AboutY(-ht) * X_WT.rotation;
  const double dV_dthy = (volume(plus) - volume(minus)) / (2 * ht);
  std::printf(
      "[pipeline truth] tilted box: dV/dz %.5g (columns) %.5g / %.5g (tool / environment);"
      " dV/dθy %.5g (columns) %.5g / %.5g\n",
      dV_dz, t.patches[0].dV_dx_tool_W.z, t.patches[0].dV_dx_environment_W.z, dV_dthy,
      t.patches[0].dV_dtheta_tool_W.y, t.patches[0].dV_dtheta_environment_W.y);
  for (const TruthPatch& p : t.patches) {
    EXPECT_NEAR(p.dV_dx_tool_W.z, dV_dz, 0.02 * std::abs(dV_dz));
    EXPECT_NEAR(p.dV_dx_environment_W.z, dV_dz, 0.02 * std::abs(dV_dz));
    EXPECT_NEAR(p.dV_dtheta_tool_W.y, dV_dthy, 0.03 * std::abs(dV_dthy));
    EXPECT_NEAR(p.dV_dtheta_environment_W.y, dV_dthy, 0.03 * std::abs(dV_dthy));
  }
}

// The pressure law's truth (step 4b) on a box tilted 10° about y, its lowest edge δ into a slab:
// the overlap's cross-section is a triangle with legs δ cot α along the bottom face and δ tan α
// along the side, V = b δ² / sin 2α, pushed along +z through the triangle's centroid,
// (δ cot α − δ tan α) / 3 from the edge towards the bottom face. Refined to 0.5 %.
TEST(ContactPatchTruth, ThePressureTruthOfATiltedBoxIsItsWedgesVolumeThroughItsCentroid) {
  const glm::dvec3 half(0.01, 0.01, 0.005);
  const double alpha = 10.0 * std::numbers::pi / 180.0, delta = 0.5e-3;
  ContactPatchTruthOptions o;
  o.pressure_tolerance = 0.005;
  Rig rig(Box(-half, half), kSlab, o);
  const glm::dquat R = AboutY(alpha);
  const glm::dvec3 edge_a = R * glm::dvec3(-half.x, 0, -half.z);
  const glm::dvec3 edge_b = R * glm::dvec3(half.x, 0, -half.z);
  const glm::dvec3 low = edge_a.z < edge_b.z ? edge_a : edge_b;
  const glm::dvec3 other = edge_a.z < edge_b.z ? edge_b : edge_a;  // along the bottom face
  const RigidTransform X_WT = At({0, 0, -delta - low.z}, R);
  const PoseTruth t = rig.truth.At(X_WT, RigidTransform{}, RigidTransform{}, kK);
  ASSERT_EQ(t.patches.size(), 1u);
  const GroundTruthPressure& p = t.patches[0].pressure;
  EXPECT_TRUE(p.converged) << p.samples_per_side << " " << p.change;
  const double volume = 2.0 * half.y * delta * delta / std::sin(2.0 * alpha);
  EXPECT_NEAR(p.volume_m3, volume, 0.01 * volume);
  EXPECT_NEAR(t.pressure_per_kp.force.z, volume, 0.01 * volume);
  EXPECT_LT(glm::length(glm::dvec2(t.pressure_per_kp.force)), 0.01 * volume);
  // The line of action: x where τ_y = (x − c_x)·(−F_z)... as r × F with F along +z.
  const double x_line = -t.pressure_per_kp.torque.y / t.pressure_per_kp.force.z;
  const double toward_face = other.x > low.x ? 1.0 : -1.0;
  const double expected =
      low.x + toward_face * (delta / std::tan(alpha) - delta * std::tan(alpha)) / 3.0;
  EXPECT_NEAR(x_line, expected, 0.01 * std::abs(expected - low.x));
  EXPECT_NEAR(t.pressure_volume_m3, p.volume_m3, 1e-15);
}

// A box on a slab tilted by 1 mrad about y bears on its lower edge: δ(θ) is a V whose arm is the
// edge's lever, so τ_y = (edge × k δ ẑ)_y, the 10° case's closed form. A tilt step of a 1 µm lift
// at the window's edge (about 0.09 mrad here) reads the arm; the default, a texel's lift (0.1 mm
// over half the window, about 9 mrad), reads the secant across the V's vertex, |θ|/h of it.
TEST(ContactPatchTruth, TiltedAMilliradianABoxBearsOnItsEdgeWithTheWholeLever) {
  const glm::dvec3 half(0.01, 0.01, 0.005);
  const double theta = 1e-3, delta = 0.1e-3;
  const glm::dquat R = AboutY(theta);
  const glm::dvec3 edge_T = R * glm::dvec3(-half.x, 0, -half.z);
  const glm::dvec3 edge_T2 = R * glm::dvec3(half.x, 0, -half.z);
  const glm::dvec3 low = edge_T.z < edge_T2.z ? edge_T : edge_T2;
  const RigidTransform X_WT = At({0, 0, -delta - low.z}, R);
  const glm::dvec3 F(0, 0, kK * delta);
  const double closed_form = glm::cross(low, F).y;
  double secant_torque = 0.0;
  EXPECT_EQ(ContactPatchTruthOptions{}.tilt_lift_m, 0.0);
  for (const double lift : {1e-6, 0.0}) {
    ContactPatchTruthOptions o;
    o.tilt_lift_m = lift;
    Rig rig(Box(-half, half), kSlab, o);
    const PoseTruth t = rig.truth.At(X_WT, RigidTransform{}, RigidTransform{}, kK);
    ASSERT_EQ(t.patches.size(), 1u);
    const TruthPatch& p = t.patches[0];
    EXPECT_NEAR(p.contact.linearization.depth_m, delta, 1e-7);
    EXPECT_NEAR(t.F_T_W.force.z, F.z, 0.01 * F.z);
    if (lift > 0.0) {
      EXPECT_NEAR(p.tilt_step_rad, lift / (0.5 * p.window.extent_m), 1e-12);
      EXPECT_LT(p.tilt_step_rad, 0.2 * theta);
      EXPECT_NEAR(t.F_T_W.torque.y, closed_form, 0.02 * std::abs(closed_form));
      EXPECT_NEAR(t.F_T_W.torque.x, 0.0, 0.02 * std::abs(closed_form));
    } else {
      EXPECT_NEAR(p.tilt_step_rad, p.gradient_step_m / (0.5 * p.window.extent_m), 1e-12);
      secant_torque = t.F_T_W.torque.y;
      // The secant across the vertex: θ/h of the arm.
      EXPECT_NEAR(secant_torque, closed_form * theta / p.tilt_step_rad,
                  0.05 * std::abs(closed_form));
    }
  }
  std::printf(
      "[pipeline truth] box tilted 1 mrad: τ_y %.4g N·m closed form (and a 1 µm tilt "
      "step), %.4g with the default texel tilt step\n",
      closed_form, secant_torque);
}

// A long bar tilted 2° touches the plane at one end only. A 2 cm window borrowed from the bar's
// middle (where a centroid of witness points on its long face may put it) sees no overlap, so a
// truth on that window is zero; the pipeline truth finds the end and gives k δ ẑ there.
TEST(ContactPatchTruth, OwnsItsContactWhereABorrowedWindowSeesNothing) {
  const glm::dvec3 half(0.04, 0.005, 0.005);
  const double alpha = 2.0 * std::numbers::pi / 180.0, delta = 0.3e-3;
  const TriangleMesh bar = Box(-half, half);
  Rig rig(bar, kSlab);
  const glm::dquat R = AboutY(alpha);
  const glm::dvec3 low = R * glm::dvec3(half.x, 0, -half.z);  // the +x end goes down
  ASSERT_LT(low.z, (R * glm::dvec3(-half.x, 0, -half.z)).z);
  const RigidTransform X_WT = At({0, 0, -delta - low.z}, R);
  GroundTruthDepthSolver borrowed(rig.tool_rays, rig.env_rays);
  const ContactWindow middle = ContactWindow::Make({0, 0, 0}, {0, 0, 1}, 0.02, 50);
  const GroundTruthContact on_middle =
      borrowed.Linearize(X_WT, RigidTransform{}, RigidTransform{}, middle, kK);
  EXPECT_EQ(glm::length(on_middle.F_T_W.force), 0.0);
  const PoseTruth t = rig.truth.At(X_WT, RigidTransform{}, RigidTransform{}, kK);
  ASSERT_EQ(t.patches.size(), 1u);
  // The inside surfaces are a strip L = δ / tan α long ending at the low end: the window is
  // centred on it and holds it.
  const double strip = delta / std::tan(alpha);
  EXPECT_NEAR(t.patches[0].window.center_W.x, low.x - 0.5 * strip, 1e-3);
  EXPECT_GE(t.patches[0].window.extent_m, strip);
  EXPECT_NEAR(t.patches[0].contact.linearization.depth_m, delta, 1e-7);
  EXPECT_NEAR(t.F_T_W.force.z, kK * delta, 0.01 * kK * delta);
}

TEST(ContactPatchTruth, SeparatedMeshesAndNonFinitePosesGiveNoTruth) {
  Rig rig(Box({-0.01, -0.01, -0.005}, {0.01, 0.01, 0.005}), kSlab);
  const PoseTruth apart = rig.truth.At(At({0, 0, 0.006}), RigidTransform{}, RigidTransform{}, kK);
  EXPECT_EQ(apart.pairs, 0);
  EXPECT_TRUE(apart.patches.empty());
  EXPECT_EQ(glm::length(apart.F_T_W.force), 0.0);
  const PoseTruth bad =
      rig.truth.At(At({std::nan(""), 0, 0}), RigidTransform{}, RigidTransform{}, kK);
  EXPECT_EQ(bad.pairs, 0);
}

// A flat face pressed δ into the crests of a ridged face (the fig75 block's ridges, 3 mm period,
// 0.4 mm high, turned to face up): the ridges are texture on one face, so the truth is one contact
// along the face's normal with F = k δ ẑ (the crests' overlap along ẑ is δ wherever the flat face
// covers them). Without the merges (issue 32, third stop) the ridge flanks' fine normals split
// the overlap into patches whose windows overlap, and the truth summed the same penetration
// more than once.
TEST(ContactPatchTruth, AFlatFaceOnRidgesIsOneContactNotOnePerFlank) {
  RidgedBlockParams params;
  params.full_resolution_grid = 120;
  const TriangleMesh ridged = MakeRidgedBlockFullResolution(params);
  const double crest_z = params.half_extents_m.z + params.ridges.amplitude_m;
  // The ridged block turned upside down: its ridged face is the top, crests at z = crest_z.
  const RigidTransform X_WFe = At({0, 0, 0}, glm::angleAxis(std::numbers::pi, glm::dvec3(1, 0, 0)));
  const TriangleMesh tool = Box({-0.01, -0.01, 0.0}, {0.01, 0.01, 0.01});
  const RayCastSurface tool_rays(tool), env_rays(ridged);
  ContactPatchTruth merged(tool, ridged, tool_rays, env_rays);
  ContactPatchTruthOptions old_options;
  old_options.macro_normal_radius_m = 0.0;
  old_options.overlap_merge_angle_deg = 0.0;
  old_options.minor_patch_fraction = 0.0;
  old_options.share_fade_m = 0.0;
  ContactPatchTruth unmerged(tool, ridged, tool_rays, env_rays, old_options);
  for (const double delta : {0.05e-3, 0.15e-3, 0.3e-3}) {
    const RigidTransform X_WT = At({0.0013, -0.0007, crest_z - delta});
    const PoseTruth t = merged.At(X_WT, RigidTransform{}, X_WFe, kK);
    const PoseTruth t0 = unmerged.At(X_WT, RigidTransform{}, X_WFe, kK);
    std::printf("δ %.2f mm: %zu patch(es), Fz %.3f N (k δ %.3f N); unmerged %zu, Fz %.3f N\n",
                delta * 1e3, t.patches.size(), t.F_T_W.force.z, kK * delta, t0.patches.size(),
                t0.F_T_W.force.z);
    ASSERT_EQ(t.patches.size(), 1u) << "δ " << delta;
    EXPECT_LT(AngleDeg(t.patches[0].window.normal_W, {0, 0, 1}), 2.0);
    EXPECT_NEAR(t.patches[0].contact.linearization.depth_m, delta, 0.02 * delta + 2e-6);
    EXPECT_NEAR(t.F_T_W.force.z, kK * delta, 0.05 * kK * delta);
    EXPECT_LT(glm::length(glm::dvec2(t.F_T_W.force)), 0.05 * kK * delta);
    EXPECT_GT(t.patches_merged, 0);
    // The old truth: more patches, and a larger force from the same penetration.
    EXPECT_GT(t0.patches.size(), 1u);
    EXPECT_GT(t0.F_T_W.force.z, 1.3 * kK * delta);
  }
}

// Two ridged faces interlocked a quarter period off (the fig76 pair: ridges along x, 3 mm period,
// 0.4 mm high): each tool crest leans on one flank of an environment groove, so the patch's −∇V
// points along the flanks. Lowered until the meshes touch and then δ further, the depth along
// the face's normal is δ exactly (lifting by δ separates them); along the flanks' direction it
// runs into the neighbouring ridges. The truth takes the face's normal (the environment's
// normals averaged over 5 mm), as the method does, and gives k δ upwards, not many times that.
TEST(ContactPatchTruth, InterlockedRidgesPushAlongTheFaceNotAlongAFlank) {
  RidgedBlockParams params;
  params.full_resolution_grid = 120;
  const TriangleMesh ridged = MakeRidgedBlockFullResolution(params);
  const RigidTransform X_WFe = At({0, 0, 0}, glm::angleAxis(std::numbers::pi, glm::dvec3(1, 0, 0)));
  const RayCastSurface rays(ridged);
  ContactPatchTruth truth(ridged, ridged, rays, rays);
  ContactPatchTruthOptions old_options;
  old_options.macro_normal_radius_m = 0.0;
  old_options.depth_along_macro_normal = false;
  old_options.overlap_merge_angle_deg = 0.0;
  old_options.minor_patch_fraction = 0.0;
  old_options.share_fade_m = 0.0;
  ContactPatchTruth old_truth(ridged, ridged, rays, rays, old_options);
  // The tool: the same block, ridges down, 10 mm smaller in x so that its ends stay on the
  // environment's face; shifted a quarter period in y.
  const double y_shift = 0.25 * params.ridges.period_m;
  const auto pose = [&](double z) { return At({0.0, y_shift, z}); };
  // Where the two first touch: near 2·top + max over y of the two profiles' sum (the tessellation
  // moves it by tens of µm), then bisected on the pair count within ±0.1 mm of that.
  const double top = params.half_extents_m.z;  // the faces' mean surfaces
  double touch = -1.0;
  for (int i = 0; i <= 20000; ++i) {
    const double y = -0.5 * params.ridges.period_m + i * 1e-4 * params.ridges.period_m;
    touch = std::max(touch, params.ridges.Height(-y) + params.ridges.Height(y - y_shift));
  }
  double lo = 2.0 * top + touch - 1e-4, hi = 2.0 * top + touch + 1e-4;
  ASSERT_EQ(truth.At(pose(hi), RigidTransform{}, X_WFe, kK).pairs, 0);
  ASSERT_GT(truth.At(pose(lo), RigidTransform{}, X_WFe, kK).pairs, 0);
  for (int i = 0; i < 14; ++i) {  // to 12 nm
    const double mid = 0.5 * (lo + hi);
    (truth.At(pose(mid), RigidTransform{}, X_WFe, kK).pairs > 0 ? lo : hi) = mid;
  }
  const double delta = 0.1e-3;
  const PoseTruth t = truth.At(pose(hi - delta), RigidTransform{}, X_WFe, kK);
  const PoseTruth t0 = old_truth.At(pose(hi - delta), RigidTransform{}, X_WFe, kK);
  double old_depth = 0.0;
  for (const TruthPatch& p : t0.patches) {
    old_depth = std::max(old_depth, p.contact.linearization.depth_m);
  }
  std::printf(
      "interlocked: %zu patch(es), Fz %.3f N, |Fxy| %.3f N (k δ %.3f N); old truth %zu "
      "patch(es), Fz %.3f N, deepest %.0f µm\n",
      t.patches.size(), t.F_T_W.force.z, glm::length(glm::dvec2(t.F_T_W.force)), kK * delta,
      t0.patches.size(), t0.F_T_W.force.z, old_depth * 1e6);
  ASSERT_FALSE(t.patches.empty());
  for (const TruthPatch& p : t.patches) {
    EXPECT_LT(AngleDeg(p.window.normal_W, {0, 0, 1}), 3.0);
    EXPECT_NEAR(p.contact.linearization.depth_m, delta, 0.05 * delta + 2e-6);
  }
  // The volume's gradient still leans along the flanks (T2 keeps it).
  EXPECT_GT(AngleDeg(-t.dV_dx_W, {0, 0, 1}), 10.0);
  EXPECT_LT(t.F_T_W.force.z, 1.5 * kK * delta * static_cast<double>(t.patches.size()));
  // The old truth cut the overlap into flank patches and summed them.
  EXPECT_GT(t0.patches.size(), t.patches.size());
  EXPECT_GT(t0.F_T_W.force.z, 1.5 * kK * delta);
}

// A box pressed into an L corner (a floor and a wall): two contacts 90° apart, which no merge
// may join.
TEST(ContactPatchTruth, AnLCornerStaysTwoContacts) {
  // The floor (z ≤ 0) and the wall (x ≥ 0.02) as two closed boxes in one mesh; the wall stands
  // 1 mm above the floor so that the two solids do not share a face.
  TriangleMesh env = Box({-0.06, -0.06, -0.02}, {0.02, 0.06, 0.0});
  const TriangleMesh wall = Box({0.02, -0.06, 0.001}, {0.04, 0.06, 0.04});
  const int offset = static_cast<int>(env.vertices.size());
  env.vertices.insert(env.vertices.end(), wall.vertices.begin(), wall.vertices.end());
  for (const glm::ivec3& t : wall.triangles) env.triangles.push_back(t + offset);
  const TriangleMesh tool = Box({-0.01, -0.01, -0.01}, {0.01, 0.01, 0.01});
  const RayCastSurface tool_rays(tool), env_rays(env);
  ContactPatchTruth truth(tool, env, tool_rays, env_rays);
  const double delta = 0.2e-3;
  // Centre 10 mm − δ above the floor and 10 mm − δ from the wall: pressed δ into both.
  const RigidTransform X_WT = At({0.02 - 0.01 + delta, 0.0, 0.01 - delta});
  const PoseTruth t = truth.At(X_WT, RigidTransform{}, RigidTransform{}, kK);
  ASSERT_EQ(t.patches.size(), 2u);
  const glm::dvec3 a = t.patches[0].window.normal_W, b = t.patches[1].window.normal_W;
  EXPECT_NEAR(AngleDeg(a, b), 90.0, 3.0);
  EXPECT_NEAR(t.F_T_W.force.z, kK * delta, 0.05 * kK * delta);
  EXPECT_NEAR(t.F_T_W.force.x, -kK * delta, 0.05 * kK * delta);
}

// Two feet (6 × 6 mm, one mesh) pressed δ into the slab, their inner faces g apart. Below the
// merge distance (5 mm) their overlaps are one patch pushing k δ; far apart, two pushing 2 k δ.
// Step 4a: in between, each of the two equally deep patches takes s = 1/(1 + λ), λ = 1 at 5 mm
// falling to 0 at 5 + 5 mm of the gap between their intersection curves, so F = 2 k δ / (1 + λ),
// which has no step where the feet's patches part. With the fade off (the truth before) it steps
// from k δ to 2 k δ there.
TEST(ContactPatchTruth, NeighbouringPatchesShareOnePenaltyThatFadesAsTheyPart) {
  const double w = 6e-3, delta = 0.2e-3;
  const auto feet = [&](double g) {
    TriangleMesh m = Box({-0.5 * g - w, -0.5 * w, 0.0}, {-0.5 * g, 0.5 * w, 0.01});
    const TriangleMesh b = Box({0.5 * g, -0.5 * w, 0.0}, {0.5 * g + w, 0.5 * w, 0.01});
    const int offset = static_cast<int>(m.vertices.size());
    m.vertices.insert(m.vertices.end(), b.vertices.begin(), b.vertices.end());
    for (const glm::ivec3& t : b.triangles) m.triangles.push_back(t + offset);
    return m;
  };
  // The slab as two halves 0.1 mm apart at x = 0, so that no slab triangle lies under both feet
  // (pairs that share a triangle are one patch however far apart: a whole-face triangle under
  // both feet would link them at any distance).
  TriangleMesh slab = Box({-0.06, -0.06, -0.02}, {-0.5e-4, 0.06, 0.0});
  {
    const TriangleMesh right = Box({0.5e-4, -0.06, -0.02}, {0.06, 0.06, 0.0});
    const int offset = static_cast<int>(slab.vertices.size());
    slab.vertices.insert(slab.vertices.end(), right.vertices.begin(), right.vertices.end());
    for (const glm::ivec3& t : right.triangles) slab.triangles.push_back(t + offset);
  }
  const RayCastSurface env_rays(slab);
  const auto force_at = [&](double g, double fade_m, PoseTruth* out = nullptr) {
    const TriangleMesh tool = feet(g);
    const RayCastSurface tool_rays(tool);
    ContactPatchTruthOptions o;
    o.share_fade_m = fade_m;
    ContactPatchTruth truth(tool, slab, tool_rays, env_rays, o);
    const PoseTruth t = truth.At(At({0.0, 0.0, -delta}), RigidTransform{}, RigidTransform{}, kK);
    if (out != nullptr) *out = t;
    return t.F_T_W.force.z;
  };
  const double kd = kK * delta;
  // Apart by far more than the fade: two patches, nothing shared.
  PoseTruth far;
  EXPECT_NEAR(force_at(30e-3, 5e-3, &far), 2.0 * kd, 0.02 * kd);
  ASSERT_EQ(far.patches.size(), 2u);
  EXPECT_EQ(far.patches_shared, 0);
  // Close: one patch.
  PoseTruth close;
  EXPECT_NEAR(force_at(3e-3, 5e-3, &close), kd, 0.02 * kd);
  ASSERT_EQ(close.patches.size(), 1u);
  // Swept across the parting: F = 2kδ/(1 + λ(gap)) on the gap each patch reports, and no step.
  double previous = std::nan(""), largest_step = 0.0;
  int shared = 0;
  for (double g = 3e-3; g <= 12.01e-3; g += 0.5e-3) {
    PoseTruth t;
    const double f = force_at(g, 5e-3, &t);
    if (t.patches.size() == 2) {
      const double gap = t.patches[0].gap_to_neighbour_m;
      EXPECT_NEAR(gap, t.patches[1].gap_to_neighbour_m, 1e-12);
      EXPECT_GE(gap, 5e-3 - 1e-9) << "two patches closer than the merge distance, g " << g;
      const double lambda = std::clamp(1.0 - (gap - 5e-3) / 5e-3, 0.0, 1.0);
      EXPECT_NEAR(f, 2.0 * kd / (1.0 + lambda), 0.02 * kd) << "g " << g << " gap " << gap;
      shared += t.patches_shared > 0;
    }
    if (std::isfinite(previous)) largest_step = std::max(largest_step, std::abs(f - previous));
    previous = f;
  }
  EXPECT_GE(shared, 3) << "the sweep should cross the fade";
  // A 0.5 mm step of the gap moves λ by 0.1, and 2/(1 + λ) has its steepest slope, 2, at λ = 0:
  // the force moves by at most 0.2 k δ a step (it moved by k δ at once before the fade).
  EXPECT_LT(largest_step, 0.21 * kd);
  // Without the fade: the step of k δ where the patches part.
  double step_off = 0.0;
  previous = std::nan("");
  for (double g = 3e-3; g <= 8.01e-3; g += 0.5e-3) {
    const double f = force_at(g, 0.0);
    if (std::isfinite(previous)) step_off = std::max(step_off, std::abs(f - previous));
    previous = f;
  }
  EXPECT_GT(step_off, 0.8 * kd);
}

TEST(ContactPatchTruthOptions, RefusesValuesOutOfRange) {
  ContactPatchTruthOptions o;
  o.merge_distance_m = 0.0;
  EXPECT_THROW(o.Validate(), std::invalid_argument);
  o = {};
  o.boundary_cell_m = 1.0;
  EXPECT_THROW(o.Validate(), std::invalid_argument);
  o = {};
  o.gradient_step_m = std::nan("");
  EXPECT_THROW(o.Validate(), std::invalid_argument);
  o = {};
  o.share_fade_m = -1e-3;
  EXPECT_THROW(o.Validate(), std::invalid_argument);
  o = {};
  o.share_temperature_m = 0.0;
  EXPECT_THROW(o.Validate(), std::invalid_argument);
}

// The seed's Fig. 75 pair at full resolution (the ridged block on the ridged gear): at random
// slides and tilts, lowered until the meshes touch and pressed 0.05–0.4 mm further, every pose
// gets a non-zero truth, every patch a positive δ, and the two routes to ∇V agree.
TEST(ContactPatchTruth, EveryIntersectingPoseOfTheBlockOnTheGearHasForce) {
  const TriangleMesh block = MakeRidgedBlockFullResolution();
  const TriangleMesh gear = MakeRidgedGearFullResolution();
  Rig rig(block, gear);
  const MeshContactBaseline fcl(block, gear);
  std::mt19937 rng(31);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const double top = RidgedGearParams{}.radius_m + RidgedGearParams{}.amplitude_m;
  for (int k = 0; k < 8; ++k) {
    const glm::dquat R = glm::angleAxis(0.03 * u(rng), glm::dvec3(1, 0, 0)) *
                         glm::angleAxis(0.03 * u(rng), glm::dvec3(0, 1, 0)) *
                         glm::angleAxis(0.3 * u(rng), glm::dvec3(0, 0, 1));
    const double x = 0.01 * u(rng), y = 0.003 * u(rng);
    double lo = top - 0.01, hi = top + 0.03;  // lo intersects, hi does not
    for (int i = 0; i < 40; ++i) {
      const double mid = 0.5 * (lo + hi);
      (fcl.Intersects(At({x, y, mid}, R), RigidTransform{}) ? lo : hi) = mid;
    }
    const double press = 0.05e-3 + 0.35e-3 * (k / 7.0);
    const RigidTransform X_WT = At({x, y, hi - press}, R);
    ASSERT_TRUE(fcl.Intersects(X_WT, RigidTransform{}));
    const PoseTruth t = rig.truth.At(X_WT, RigidTransform{}, RigidTransform{}, kK);
    ASSERT_FALSE(t.patches.empty()) << "pose " << k;
    EXPECT_GT(glm::length(t.F_T_W.force), 0.0) << "pose " << k;
    // Per patch the two routes agree to 5 % plus the sampling's floor (0.05 mm²: patches of a
    // fraction of a mm² are sampled by a few sub-triangles); over the pose to 3 % plus that floor.
    glm::dvec3 tool_route(0.0), environment_route(0.0);
    for (const TruthPatch& p : t.patches) {
      EXPECT_GT(p.contact.linearization.depth_m, 0.0) << "pose " << k;
      EXPECT_LT(glm::length(p.dV_dx_tool_W - p.dV_dx_environment_W),
                0.05 * glm::length(p.dV_dx_environment_W) + 5e-8)
          << "pose " << k;
      tool_route += p.dV_dx_tool_W;
      environment_route += p.dV_dx_environment_W;
    }
    EXPECT_LT(glm::length(tool_route - environment_route),
              0.03 * glm::length(environment_route) + 5e-8)
        << "pose " << k;
    EXPECT_LT(AngleDeg(-t.dV_dx_W, t.F_T_W.force), 10.0) << "pose " << k;
  }
}

}  // namespace
}  // namespace ht
