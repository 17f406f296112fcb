// The hard cases of DESIGN.md §8 / docs/hard-cases.md, each a named test through the parts of the
// product it touches (the remote step, the penetration depth, the contact model, the tool step,
// the safety stage): every one gives finite, bounded forces and no crash, and the property each
// case is about. Each prints one "[hard case]" line with what it gave (the docs table quotes them).

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <functional>
#include <glm/gtc/quaternion.hpp>
#include <limits>
#include <memory>
#include <numbers>
#include <stdexcept>
#include <string>

#include "haptic_core/contact_model.h"
#include "haptic_core/contact_windows.h"
#include "haptic_core/demo/demo_scenes.h"
#include "haptic_core/demo/procedural_models.h"
#include "haptic_core/haptic_scene.h"
#include "haptic_core/model_build/hull_hierarchy_build.h"
#include "haptic_core/penetration_depth.h"
#include "haptic_core/remote_step.h"
#include "haptic_core/stability_map.h"
#include "haptic_core/tool_simulation.h"
#include "haptic_core/wrench_safety.h"

namespace ht {
namespace {

constexpr double kK = 8000.0;  // N/m
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

bool Finite(const Wrench& F) {
  return std::isfinite(F.force.x + F.force.y + F.force.z + F.torque.x + F.torque.y + F.torque.z);
}

// The largest force one contact can give on a window: k·δ·|J| with δ ≤ 2R = 2W (the box) and each
// finite-difference slope ≤ 2W / h_x = 2N.
double ForceBound(const ContactWindow& w, int contacts = 1) {
  return contacts * kK * 2.0 * w.extent_m * std::sqrt(1.0 + 2.0 * std::pow(2.0 * w.resolution, 2));
}

std::shared_ptr<const HapticModel> FlatBox(glm::dvec3 half, double mass = 0.1) {
  return std::make_shared<const HapticModel>(MakeTexturedBox(
      half, [](double, double) { return 0.0; }, 16, mass, "flat_box"));
}

// A tool box (bottom face textured, frame at its centre) over a big flat object whose top is z = 0.
HapticScene BoxOnSlab(std::shared_ptr<const HapticModel> tool) {
  HapticScene s;
  s.name = "box_on_slab";
  s.tool = std::move(tool);
  TouchableObject slab;
  // MakeTexturedBox's textured face is its bottom: turned over, it is the top, at z = 0.
  slab.model = FlatBox({0.06, 0.06, 0.01}, 2.0);
  slab.X_WO.rotation = glm::angleAxis(std::numbers::pi, glm::dvec3(1, 0, 0));
  slab.X_WO.translation = {0, 0, -0.01};
  slab.stiffness_n_per_m = kK;
  s.touchables.push_back(slab);
  return s;
}

// BoxOnSlab with a tool box of half extents `half_extents_m` (m) whose bottom carries two 40 µm
// Gaussian bumps of width `sigma_m` (m) at x = ±10 mm in its frame.
HapticScene TwoBumpsOnSlab(const glm::dvec3& half_extents_m, double sigma_m, const char* name) {
  const auto bumps = [sigma_m](double x, double y) {
    const auto g = [&](double cx) {
      return 40e-6 * std::exp(-((x - cx) * (x - cx) + y * y) / (2.0 * sigma_m * sigma_m));
    };
    return g(-10e-3) + g(10e-3);
  };
  return BoxOnSlab(
      std::make_shared<const HapticModel>(MakeTexturedBox(half_extents_m, bumps, 512, 0.1, name)));
}

RigidTransform At(glm::dvec3 p, glm::dquat R = glm::dquat(1, 0, 0, 0)) {
  RigidTransform X;
  X.translation = p;
  X.rotation = R;
  return X;
}

ContactModel StepAt(const HapticScene& scene, const RigidTransform& X_WT,
                    StepTimings* timings = nullptr) {
  HapticTexturePipeline pipeline(scene, PipelineOptions{});
  StepTimings t;
  ContactModel m = pipeline.Step(X_WT, 1, t);
  if (timings) *timings = t;
  return m;
}

// The block's home pose on the gear (BlockOnGearHomePose) moved dz (m) along W's z.
RigidTransform BlockAboveHome(double dz) {
  const RigidTransform home = BlockOnGearHomePose();
  return At(home.translation + glm::dvec3(0, 0, dz), home.rotation);
}

// Where the block touches the gear: the highest dz (m; BlockAboveHome) at which a step of
// `pipeline` (no twist) has a contact of δ0 ≥ 0, by bisection over [−2, 3] mm.
double BlockTouchDz(HapticTexturePipeline& pipeline) {
  StepTimings t;
  double lo = -2e-3, hi = 3e-3;
  for (int i = 0; i < 30; ++i) {
    const double mid = 0.5 * (lo + hi);
    const ContactModel m = pipeline.Step(BlockAboveHome(mid), 1, t);
    (m.num_contacts > 0 && m.contacts[0].depth_m >= 0.0 ? lo : hi) = mid;
  }
  return lo;
}

void Report(const char* name, const std::string& what) {
  std::printf("[hard case] %s: %s\n", name, what.c_str());
}

std::string Fmt(const char* fmt, double a, double b = 0, double c = 0, double d = 0) {
  char buf[256];
  std::snprintf(buf, sizeof buf, fmt, a, b, c, d);
  return buf;
}

// Stage 5a (its birth ramp and bridge fade, PipelineOptions): a box whose bottom carries two
// 40 µm bumps (σ 3 mm) 20 mm apart is lowered onto a flat slab in 1 µm steps. High up, the two
// overlaps are far apart, two regions; as the box sinks the overlaps widen, and at a gap of 10 mm
// (the link: r = σ·sqrt(2 ln(40 µm / h)) = 5 mm at h ≈ 10 µm) they become one region. The second
// region's weight fades in with its depth and out as its bridge level goes to 0, so the force
// changes between consecutive heights by no more than a few k·Δz: no step where the supports
// join.
TEST(HardCases, AContinuousSplitJoinsTwoSupportsWithoutAStep) {
  const HapticScene scene = TwoBumpsOnSlab({0.03, 0.02, 0.01}, 3e-3, "two_wide_bumps");
  HapticTexturePipeline split(scene, PipelineOptions{});
  StepTimings t;
  double largest_step = 0.0, previous = -1.0;
  for (int h_um = 30; h_um >= 2; --h_um) {
    const RigidTransform X_WT = At({0.0, 0.0, 0.01 + h_um * 1e-6});
    const ContactModel b = split.Step(X_WT, 1, t);
    ASSERT_GE(b.num_contacts, 1) << h_um;
    const double fz = b.F_T_W_at_q0.force.z;
    if (previous >= 0.0) largest_step = std::max(largest_step, std::abs(fz - previous));
    previous = fz;
  }
  EXPECT_LT(largest_step, 4.0 * kK * 1e-6);  // no step where the supports join
  Report("a continuous split", Fmt("largest step while two supports join: %.4f N (k dz = %.4f N)",
                                   largest_step, kK * 1e-6));
}

// Stage 5c (PipelineOptions): a flat box face pressed on the end cap
// of a smooth cylinder (the gear model without ridges) overlaps it over the whole 50 mm disc. The
// cylinder's hull hierarchy has small leaves, and windows may not exceed 20 mm, so the coarse
// clustering leaves the disc in several windows, each reading the whole δ. Shared, the windows
// over one connected overlap push k·δ once, as the pipeline
// truth's one patch does. A 30 mm groove across the box's face leaves two overlaps 30 mm apart
// (the link is 5 mm): the windows over each share its penalty, and the two push 2·k·δ.
TEST(HardCases, OneOverlapInSeveralWindowsPushesOnce) {
  RidgedGearParams gp;
  gp.amplitude_m = 0.0;  // a smooth cylinder
  gp.texture_size = 64;
  gp.coarse_segments = 120;
  auto gear_model = MakeRidgedGear(gp);
  HullHierarchyParams hp;
  hp.max_leaf_triangles = 8;
  gear_model.hull_hierarchy =
      BuildConvexHullHierarchy(gear_model.vertices_O, gear_model.triangles, hp);
  ASSERT_GT(gear_model.hull_hierarchy.nodes.size(), 8u);
  const auto scene_with = [&](std::function<double(double, double)> bottom) {
    HapticScene s;
    s.name = "box_on_cap";
    s.tool = std::make_shared<const HapticModel>(
        MakeTexturedBox({0.03, 0.03, 0.005}, std::move(bottom), 512, 0.1, "box"));
    TouchableObject gear;
    gear.model = std::make_shared<const HapticModel>(gear_model);
    gear.stiffness_n_per_m = kK;
    s.touchables.push_back(gear);
    return s;
  };
  // The box's bottom (−z in its frame) against the cap at x = +L/2 (facing +x).
  const double press = 50e-6;
  const RigidTransform X_WT = At({0.5 * gp.length_m + 0.005 - press, 0.0, 0.0},
                                 glm::angleAxis(0.5 * std::numbers::pi, glm::dvec3(0, 1, 0)));
  const auto step = [&](const HapticScene& scene) {
    PipelineOptions options;
    options.max_window_extent_m = options.window_extent_m;
    HapticTexturePipeline pipeline(scene, options);
    StepTimings t;
    ContactModel m = pipeline.Step(X_WT, 1, t);
    return std::make_pair(m, pipeline.step_faults().shared_contacts);
  };
  const HapticScene flat = scene_with([](double, double) { return 0.0; });
  const auto [shared, num_shared] = step(flat);
  ASSERT_GE(shared.num_contacts, 2);
  EXPECT_EQ(num_shared, shared.num_contacts);  // every contact shares one penalty
  double delta = 0.0;
  for (int i = 0; i < shared.num_contacts; ++i) {
    delta = std::max(delta, shared.contacts[static_cast<std::size_t>(i)].depth_m);
    EXPECT_NEAR(shared.contacts[static_cast<std::size_t>(i)].depth_m, press, 5e-6) << i;
  }
  const double F_shared = shared.F_T_W_at_q0.force.x;
  EXPECT_NEAR(F_shared, kK * delta, 0.02 * kK * delta);
  // Grooved: two overlaps 30 mm apart, each a region of its own. Each window renders only its
  // cluster's triangles (sectors of the cap) clipped to its 20 mm square, so the overlap between
  // two windows over one part can go unrendered (a 5 mm link without fade read the 40 mm chord of
  // one part as two regions, 1.2 N); the default 10 mm link bridges that and still parts the two
  // overlaps (λ = 0 past 15 mm).
  const HapticScene grooved =
      scene_with([](double x, double) { return std::abs(x) < 15e-3 ? -1e-3 : 0.0; });
  const auto [g_shared, g_num] = step(grooved);
  ASSERT_GE(g_shared.num_contacts, 3);
  double g_delta = 0.0;
  for (int i = 0; i < g_shared.num_contacts; ++i) {
    g_delta = std::max(g_delta, g_shared.contacts[static_cast<std::size_t>(i)].depth_m);
  }
  EXPECT_NEAR(g_delta, press, 5e-6);
  EXPECT_NEAR(g_shared.F_T_W_at_q0.force.x, 2.0 * kK * g_delta, 0.04 * kK * g_delta);
  Report("one overlap in several windows",
         Fmt("%.0f windows over one disc: %.3f N shared (k delta = %.3f N); two overlaps: %.3f N",
             static_cast<double>(shared.num_contacts), F_shared, kK * delta,
             g_shared.F_T_W_at_q0.force.x) +
             Fmt(" (%.0f windows)", static_cast<double>(g_shared.num_contacts)));
}

TEST(HardCases, CoplanarRestingContact) {
  // Every cell of the window has the same δ: many equal maxima.
  const HapticScene scene = BoxOnSlab(FlatBox({0.02, 0.02, 0.01}));
  const ContactModel m = StepAt(scene, At({0, 0, 0.01 - 0.1e-3}));
  ASSERT_GE(m.num_contacts, 1);
  const Wrench& F = m.F_T_W_at_q0;
  ASSERT_TRUE(Finite(F));
  EXPECT_NEAR(F.force.z, kK * 0.1e-3 * m.num_contacts, 1e-6);
  EXPECT_NEAR(std::hypot(F.force.x, F.force.y), 0.0, 1e-9);
  Report("coplanar resting contact",
         Fmt("%.0f contact(s), F = (%.2g, %.2g, %.4f) N for δ = 0.1 mm: k·δ along n, no "
             "tangential force",
             static_cast<double>(m.num_contacts), F.force.x, F.force.y, F.force.z));
}

TEST(HardCases, GrazingContactDirection) {
  // n 85° away from the faces' normal: the faces barely face the window (cos 85° = 0.087 > the
  // 0.05 facing threshold) and heights along n vary by tan 85° per metre across the window.
  const auto tool = FlatBox({0.02, 0.02, 0.01});
  const auto object = FlatBox({0.06, 0.06, 0.01}, 2.0);
  const RigidTransform X_WO =
      At({0, 0, -0.01}, glm::angleAxis(std::numbers::pi, glm::dvec3(1, 0, 0)));
  TexturePenetrationSolver solver;
  double worst = 0.0;
  for (double deg : {80.0, 85.0, 87.0, 89.0}) {
    const double a = deg * std::numbers::pi / 180.0;
    const ContactWindow w =
        ContactWindow::Make({0, 0, 0}, {std::sin(a), 0.0, std::cos(a)}, 0.02, 50);
    const ContactLinearization lin =
        solver.Linearize(*tool, At({0, 0, 0.01 - 0.2e-3}), *object, X_WO, w, kK);
    const Wrench F = PenaltyWrench(lin.depth_m, lin.gradient, kK);
    ASSERT_TRUE(Finite(F)) << deg;
    EXPECT_LE(glm::length(F.force), ForceBound(w)) << deg;
    worst = std::max(worst, glm::length(F.force));
  }
  Report("grazing contact direction",
         Fmt("n at 80-89° from the face normal: finite; largest |F| %.3g N (bound k·2W·|J|max = "
             "%.3g N): δ along a grazing n is large, the seed's 'not a height field' limit",
             worst, ForceBound(ContactWindow::Make({0, 0, 0}, {0, 0, 1}, 0.02, 50))));
}

TEST(HardCases, ZeroAndNearZeroPenetration) {
  const HapticScene scene = BoxOnSlab(FlatBox({0.02, 0.02, 0.01}));
  const ContactModel touching = StepAt(scene, At({0, 0, 0.01}));
  EXPECT_TRUE(Finite(touching.F_T_W_at_q0));
  // Touching: nothing but the depth's rounding (a window centred on the region puts its cells at
  // coordinates that are not round: δ0 = 2e-18 m here, 1.8e-14 N).
  EXPECT_LE(glm::length(touching.F_T_W_at_q0.force), kK * 1e-15);
  const ContactModel barely = StepAt(scene, At({0, 0, 0.01 - 1e-9}));
  EXPECT_TRUE(Finite(barely.F_T_W_at_q0));
  EXPECT_LE(glm::length(barely.F_T_W_at_q0.force), kK * 2e-9 * std::max(1, barely.num_contacts));
  // And the contact model switches the contact on and off continuously around δ = 0.
  const ContactModelEvaluation out = EvaluateContactModel(barely, At({0, 0, 0.01 + 1e-6}));
  EXPECT_EQ(out.active_contacts, 0);
  Report("zero and near-zero penetration",
         Fmt("δ = 0: |F| = %.2g N (the depth's rounding); δ = 1 nm: |F| = %.2g N; 1 µm out: "
             "contact off",
             glm::length(touching.F_T_W_at_q0.force), glm::length(barely.F_T_W_at_q0.force)));
}

TEST(HardCases, PenetrationDeeperThanTheTextureAmplitude) {
  const HapticScene scene = MakeBlockOnGearScene();
  const double amplitude = RidgedBlockParams{}.ridges.amplitude_m;  // 0.4 mm
  double last_fz = 0.0;
  std::string what;
  for (double depth : {1e-3, 5e-3, 15e-3}) {
    RigidTransform X = BlockOnGearHomePose();
    X.translation.z -= 0.5e-3 + depth;
    const ContactModel m = StepAt(scene, X);
    ASSERT_GE(m.num_contacts, 1) << depth;
    const Wrench& F = m.F_T_W_at_q0;
    ASSERT_TRUE(Finite(F)) << depth;
    EXPECT_GT(F.force.z, 0.0) << "pushes the tool out at " << depth;
    EXPECT_LE(m.contacts[0].depth_m, 2.0 * 0.02 + 1e-9) << "δ saturates at 2R";
    EXPECT_GE(F.force.z, last_fz) << "deeper never pushes less";
    last_fz = F.force.z;
    what += Fmt("%.0f mm (%.0f× A): δ %.2f mm, Fz %.1f N; ", depth * 1e3, depth / amplitude,
                m.contacts[0].depth_m * 1e3, F.force.z);
  }
  Report("penetration deeper than the texture amplitude", what + "monotonic, finite");
}

TEST(HardCases, DeepestPointOnTheWindowBorder) {
  // A tilted tool face: δ is largest on the window's edge.
  const auto tool = FlatBox({0.03, 0.03, 0.005});
  const auto object = FlatBox({0.06, 0.06, 0.01}, 2.0);
  const RigidTransform X_WO =
      At({0, 0, -0.01}, glm::angleAxis(std::numbers::pi, glm::dvec3(1, 0, 0)));
  const ContactWindow w = ContactWindow::Make({0, 0, 0}, {0, 0, 1}, 0.02, 50);
  TexturePenetrationSolver solver;
  const double theta = 0.05;
  const auto X_WT = At({0, 0, 0.005 + 0.1e-3}, glm::angleAxis(theta, glm::dvec3(0, 1, 0)));
  const ContactLinearization lin = solver.Linearize(*tool, X_WT, *object, X_WO, w, kK);
  const Wrench F = PenaltyWrench(lin.depth_m, lin.gradient, kK);
  ASSERT_TRUE(Finite(F));
  EXPECT_GT(lin.depth_m, 0.0);
  // The deepest cell is in the border column; the slope along u is the face's tilt.
  EXPECT_NEAR(std::abs(lin.point_W.x), 0.5 * w.extent_m - 0.5 * w.cell_size_m(), 1e-9);
  EXPECT_NEAR(std::abs(lin.gradient.d_translation_W.x), std::tan(theta), 2e-3);
  Report("deepest point on the window border",
         Fmt("deepest cell at x = %.4f m (border column), ∂δ/∂x = %.4f (tan θ = %.4f), |F| = %.3f "
             "N; the truth at the border itself is half a cell deeper",
             lin.point_W.x, lin.gradient.d_translation_W.x, std::tan(theta), glm::length(F.force)));
}

// Two ridged blocks (seed Fig. 76): the lower one upside down under the tool.
HapticScene InterlockedRidgedBlocks() {
  HapticScene scene;
  scene.tool = std::make_shared<const HapticModel>(MakeRidgedBlock());
  TouchableObject lower;
  lower.model = std::make_shared<const HapticModel>(MakeRidgedBlock());
  lower.X_WO = At({0, 0, -0.01}, glm::angleAxis(std::numbers::pi, glm::dvec3(1, 0, 0)));
  lower.stiffness_n_per_m = kK;
  scene.touchables.push_back(lower);
  return scene;
}

TEST(HardCases, InterlockingRidges) {
  // Two ridged blocks interlocked (seed Fig. 76), the upper one turned about n: the torque about
  // n opposes the turn.
  const HapticScene scene = InterlockedRidgedBlocks();
  std::string what;
  for (double deg : {-2.0, 2.0}) {
    const double a = deg * std::numbers::pi / 180.0;
    const ContactModel m =
        StepAt(scene, At({0, 1.5e-3, 0.01 + 0.1e-3}, glm::angleAxis(a, glm::dvec3(0, 0, 1))));
    ASSERT_GE(m.num_contacts, 1);
    ASSERT_TRUE(Finite(m.F_T_W_at_q0));
    EXPECT_LT(m.F_T_W_at_q0.torque.z * a, 0.0) << deg << "°: the torque about n opposes the turn";
    EXPECT_GT(m.F_T_W_at_q0.force.z, 0.0);
    what += Fmt("%+.0f°: τz %+.2e N·m, Fz %.2f N; ", deg, m.F_T_W_at_q0.torque.z,
                m.F_T_W_at_q0.force.z);
  }
  Report("interlocking ridges", what + "torque opposes the rotation");
}

// Largest tangential/normal force ratio over 8 shifts across a period of interlocked saw teeth
// of slope `slope` and period `period` on both faces, each pressed until δ = 0.1 mm.
double SawToothRatio(double slope, double period) {
  const double amplitude = slope * period / 2.0;
  const auto saw = [=](double, double y) {
    const double s = std::fmod(std::fmod(y, period) + period, period) / period;  // 0..1
    return amplitude * (s < 0.5 ? 2.0 * s : 2.0 - 2.0 * s) - 0.5 * amplitude;
  };
  const HapticModel tool = MakeTexturedBox({0.02, 0.02, 0.01}, saw, 1024, 0.1, "saw");
  const HapticModel object = MakeTexturedBox({0.03, 0.03, 0.01}, saw, 1024, 1.0, "saw_slab");
  const RigidTransform X_WO =
      At({0, 0, -0.01}, glm::angleAxis(std::numbers::pi, glm::dvec3(1, 0, 0)));
  const ContactWindow w = ContactWindow::Make({0, 0, 0}, {0, 0, 1}, 0.02, 50);
  TexturePenetrationSolver solver;
  double worst = 0.0;
  for (int i = 0; i < 8; ++i) {
    const double y = (i + 0.5) * period / 8.0;
    double lo = 0.01 - 2.0 * amplitude, hi = 0.01 + 2.0 * amplitude;  // z of the tool's centre
    for (int it = 0; it < 40; ++it) {
      const double mid = 0.5 * (lo + hi);
      (solver.Depth(tool, At({0, y, mid}), object, X_WO, w).depth_m > 0.1e-3 ? lo : hi) = mid;
    }
    const ContactLinearization lin = solver.Linearize(tool, At({0, y, hi}), object, X_WO, w, kK);
    const Wrench F = PenaltyWrench(lin.depth_m, lin.gradient, kK);
    EXPECT_TRUE(Finite(F)) << y;
    EXPECT_GT(F.force.z, 0.0) << y;
    if (F.force.z > 0.0) worst = std::max(worst, std::hypot(F.force.x, F.force.y) / F.force.z);
  }
  return worst;
}

TEST(HardCases, TextureSlopesAbove60Degrees) {
  // Teeth of slope tan 70° = 2.75, interlocked: where the grid resolves them (4 mm period, ten
  // cells) the flanks push the tool sideways with a tangential/normal ratio up to the slope and no
  // more; where it does not (0.8 mm, two cells) the mip level the grid's cell selects has
  // averaged them away (seed §19.6.2): a bounded, smaller force, not aliasing.
  const double slope = std::tan(70.0 * std::numbers::pi / 180.0);
  const double resolved = SawToothRatio(slope, 4e-3);
  const double filtered = SawToothRatio(slope, 0.8e-3);
  EXPECT_LE(resolved, 1.2 * slope);
  EXPECT_GT(resolved, 0.3 * slope) << "the flanks should push sideways";
  EXPECT_LE(filtered, resolved);
  Report("texture slopes above 60°",
         Fmt("interlocked teeth of slope %.2f (70°) at δ = 0.1 mm: tangential/normal up to %.2f "
             "with a 4 mm period; %.2f with 0.8 mm (two cells: the mip level averages the teeth "
             "away); finite",
             slope, resolved, filtered));
}

TEST(HardCases, DegenerateAndSliverCoarseTriangles) {
  HapticModel m = MakeTexturedBox(
      {0.02, 0.02, 0.01}, [](double, double) { return 0.0; }, 16, 0.1, "box_with_slivers");
  // A zero-area triangle (three collinear points on the bottom) and a 1e-9 m sliver, both facing
  // down like the bottom face, with the bottom's corner normals and uvs.
  const int base = static_cast<int>(m.vertices_O.size());
  m.vertices_O.push_back({-0.01, 0.0, -0.01});
  m.vertices_O.push_back({0.0, 0.0, -0.01});
  m.vertices_O.push_back({0.01, 0.0, -0.01});
  m.vertices_O.push_back({0.0, 1e-9, -0.01});
  for (glm::ivec3 t :
       {glm::ivec3(base, base + 2, base + 1), glm::ivec3(base, base + 3, base + 2)}) {
    m.triangles.push_back(t);
    for (int c = 0; c < 3; ++c) {
      m.corner_normals_O.push_back({0, 0, -1});
      m.corner_uvs.push_back({0.5f, 0.5f});
    }
    m.textured.push_back(0);
    m.texel_size_m.push_back(1e-4);
  }
  const auto tool = std::make_shared<const HapticModel>(m);
  const HapticScene with = BoxOnSlab(tool);
  const HapticScene without = BoxOnSlab(FlatBox({0.02, 0.02, 0.01}));
  const RigidTransform X = At({0, 0, 0.01 - 0.1e-3});
  const ContactModel a = StepAt(with, X), b = StepAt(without, X);
  ASSERT_TRUE(Finite(a.F_T_W_at_q0));
  EXPECT_NEAR(a.F_T_W_at_q0.force.z, b.F_T_W_at_q0.force.z, 1e-9);
  Report("degenerate and sliver coarse triangles",
         Fmt("a zero-area and a 1 nm sliver triangle on the pressed face: Fz %.4f N, the same as "
             "without them (%.4f N)",
             a.F_T_W_at_q0.force.z, b.F_T_W_at_q0.force.z));
}

TEST(HardCases, ContactDirectionFlippingBetweenFrames) {
  // Models whose n flips every tick (a thin wall seen from both sides): the tool step and the
  // safety stage keep the force finite, within the device's limits and its rate limit.
  ContactModel up, down;
  up.num_contacts = down.num_contacts = 1;
  up.contacts[0].depth_m = down.contacts[0].depth_m = 1e-3;
  up.contacts[0].stiffness_n_per_m = down.contacts[0].stiffness_n_per_m = kK;
  up.contacts[0].gradient.d_translation_W = {0, 0, -1};
  down.contacts[0].gradient.d_translation_W = {0, 0, 1};
  const ToolSimulator sim(BlockOnGearToolInertia(), VirtualCoupling{});
  const SafetyLimits limits;
  WrenchSafetyFilter safety(limits);
  ToolState s;
  const double h = 1e-3;
  double max_f = 0.0, max_step = 0.0;
  glm::dvec3 last(0.0);
  for (int i = 0; i < 2000; ++i) {
    const bool odd = i % 2;
    const ToolStepResult r =
        sim.StepBlended(s, RigidTransform{}, Twist{}, odd ? up : down, odd ? down : up, 0.25, h);
    ASSERT_TRUE(r.ok);
    std::uint32_t flags = 0;
    const Wrench out = safety.Filter(-r.F_coupling_T_W, Twist{}, 0.001, true, h, flags);
    ASSERT_TRUE(Finite(out));
    max_f = std::max(max_f, glm::length(out.force));
    if (i > 0) max_step = std::max(max_step, glm::length(out.force - last));
    last = out.force;
  }
  EXPECT_LE(max_f, limits.max_force_n + 1e-9);
  EXPECT_LE(max_step, limits.max_force_rate_n_per_s * h + 1e-9);
  Report("contact direction flipping between frames",
         Fmt("n flipping every tick for 2 s: device |F| ≤ %.3f N, step ≤ %.3f N per tick (limits "
             "%.0f N, %.0f N/s)",
             max_f, max_step, limits.max_force_n, limits.max_force_rate_n_per_s));
}

TEST(HardCases, VeryStiffContactOnALightTool) {
  StabilityProbe p;
  p.stiffness_n_per_m = 1e6;
  p.mass_kg = 0.01;
  p.rate_hz = 1000.0;
  const StabilityResult imp = ProbeStability(p, ToolIntegrator::kImplicitEuler);
  const StabilityResult exp = ProbeStability(p, ToolIntegrator::kExplicitEuler);
  EXPECT_TRUE(imp.stable);
  EXPECT_FALSE(exp.stable);
  Report("very stiff contact on a light tool",
         Fmt("k = 1e6 N/m, m = 10 g, 1 kHz (h·ω = %.1f): implicit stable (late amplitude %.2g m), "
             "explicit diverges; the whole map: build/benchmarks/stability_map",
             imp.h_omega, imp.late_amplitude_m));
}

TEST(HardCases, StaleModelAfterADelaySpike) {
  // A model linearized 5 cm from where the tool now is (a 500 ms delay spike): the linear model
  // extrapolates a huge δ; the safety stage clamps it and fades it out once the model is stale.
  ContactModel m;
  m.num_contacts = 1;
  m.contacts[0].depth_m = 0.2e-3;
  m.contacts[0].stiffness_n_per_m = kK;
  m.contacts[0].gradient.d_translation_W = {0, 0, -1};
  const ContactModelEvaluation e = EvaluateContactModel(m, At({0, 0, -0.05}));
  ASSERT_TRUE(Finite(e.F_T_W));
  const SafetyLimits limits;
  WrenchSafetyFilter safety(limits);
  std::uint32_t flags = 0;
  Wrench out;
  double first = -1.0;
  for (int i = 0; i < 400; ++i) {
    out = safety.Filter(e.F_T_W, Twist{}, 0.5, true, 1e-3, flags);
    ASSERT_TRUE(Finite(out));
    EXPECT_LE(glm::length(out.force), limits.max_force_n + 1e-9);
    if (i == 0) first = glm::length(out.force);
  }
  EXPECT_EQ(glm::length(out.force), 0.0);
  Report("stale model after a delay spike",
         Fmt("model 5 cm off: Φ = %.0f N extrapolated; device gets %.3f N on the first tick "
             "(rate limit), never above %.0f N, and 0 once older than the model timeout",
             glm::length(e.F_T_W.force), first, limits.max_force_n));
}

TEST(HardCases, ImpactFasterThanTheModelsCome) {
  // The block over the gear, 0.9 mm above touching, falling at 50 mm/s: a model made now is used
  // for as long as the next takes to come (10–150 ms over a network, or a slow GPU step), by
  // which time the block is in the gear. With speculative contacts (PipelineOptions::
  // speculative_lead_s) the model already holds the gear's surface, separated (δ0 < 0, no force
  // yet), and the operator's local model puts it where a fresh step finds it; at rest, rising
  // or sliding sideways the model has no contact, as before.
  const HapticScene scene = MakeBlockOnGearScene();
  PipelineOptions options;
  HapticTexturePipeline pipeline(scene, options);
  const auto above = BlockAboveHome;
  StepTimings t;
  const double touch_dz = BlockTouchDz(pipeline);
  const RigidTransform X0 = above(touch_dz + 0.9e-3);
  const Twist falling{{0.0, 0.0, -0.05}, {}};
  EXPECT_EQ(pipeline.Step(X0, 2, t).num_contacts, 0);
  EXPECT_EQ(pipeline.Step(X0, 3, t, Twist{{0.0, 0.0, 0.05}, {}}).num_contacts, 0);
  EXPECT_EQ(pipeline.Step(X0, 4, t, Twist{{0.05, 0.0, 0.0}, {}}).num_contacts, 0);
  EXPECT_EQ(pipeline.Step(X0, 5, t, Twist{{0.0, 0.0, kNaN}, {}}).num_contacts, 0);
  const std::int64_t speculative_before = pipeline.step_faults().speculative_pairs;
  const ContactModel m = pipeline.Step(X0, 6, t, falling);
  ASSERT_GE(m.num_contacts, 1);
  EXPECT_GT(pipeline.step_faults().speculative_pairs, speculative_before);
  EXPECT_NEAR(m.contacts[0].depth_m, -0.9e-3, 30e-6);  // the gap, to the grid's accuracy
  EXPECT_EQ(glm::length(m.F_T_W_at_q0.force), 0.0);
  // 20 ms later the block is 1 mm lower, 0.1 mm into the gear: its local model against a fresh
  // step there.
  const RigidTransform X1 = above(touch_dz - 0.1e-3);
  const ContactModelEvaluation local = EvaluateContactModel(m, X1);
  PipelineOptions plain;
  plain.speculative_lead_s = 0.0;
  HapticTexturePipeline fresh_pipeline(scene, plain);
  const ContactModel fresh = fresh_pipeline.Step(X1, 7, t);
  ASSERT_GE(fresh.num_contacts, 1);
  const double fresh_fz = fresh.F_T_W_at_q0.force.z;
  EXPECT_GT(fresh_fz, 0.1);
  EXPECT_NEAR(local.F_T_W.force.z, fresh_fz, 0.1 * fresh_fz);
  Report("impact faster than the models come",
         Fmt("block 0.9 mm above the gear falling at 50 mm/s: model δ0 = %.0f µm (separated); "
             "0.1 mm into the gear its local model pushes %.2f N, a fresh step %.2f N; at rest, "
             "rising or sliding: no contact",
             m.contacts[0].depth_m * 1e6, local.F_T_W.force.z, fresh_fz));
  PipelineOptions bad;
  bad.speculative_lead_s = -1.0;
  EXPECT_THROW(bad.Validate(), std::invalid_argument);
  bad = PipelineOptions{};
  bad.max_speculative_margin_m = kNaN;
  EXPECT_THROW(bad.Validate(), std::invalid_argument);
}

TEST(HardCases, ASurfaceARoundTripAwayIsInTheModelOfAToolAtRest) {
  // Under a long delay a model answers a tool pose a round trip old: the hand may since have
  // pressed down onto a surface the pose was clear of (the seed's z phase lifts and presses at
  // up to 22 mm/s; at 150 ms one way the model comes 300 ms after its pose). With the speculative
  // floor (PipelineOptions::speculative_floor_m, set by the remote node from the round trip) the
  // model of a tool at rest 2 mm above the gear already holds the gear, separated (δ0 < 0, no
  // force), and 0.1 mm inside the gear its local model pushes as a fresh step there does;
  // without the floor it holds nothing. Beside a touching pair the floor adds nothing.
  const HapticScene scene = MakeBlockOnGearScene();
  PipelineOptions plain;
  plain.speculative_lead_s = 0.0;
  HapticTexturePipeline without(scene, plain);
  PipelineOptions floored = plain;
  floored.speculative_floor_m = 3e-3;
  HapticTexturePipeline with(scene, floored);
  EXPECT_DOUBLE_EQ(with.speculative_floor_m(), 3e-3);
  const auto above = BlockAboveHome;
  StepTimings t;
  const double touch_dz = BlockTouchDz(without);
  const RigidTransform X0 = above(touch_dz + 2e-3);
  EXPECT_EQ(without.Step(X0, 2, t).num_contacts, 0);
  const std::int64_t speculative_before = with.step_faults().speculative_pairs;
  const ContactModel m = with.Step(X0, 2, t);  // at rest: no twist
  ASSERT_GE(m.num_contacts, 1);
  EXPECT_GT(with.step_faults().speculative_pairs, speculative_before);
  EXPECT_NEAR(m.contacts[0].depth_m, -2e-3, 30e-6);  // the gap, to the grid's accuracy
  EXPECT_EQ(glm::length(m.F_T_W_at_q0.force), 0.0);
  const RigidTransform X1 = above(touch_dz - 0.1e-3);
  const ContactModelEvaluation local = EvaluateContactModel(m, X1);
  HapticTexturePipeline fresh_pipeline(scene, plain);
  const ContactModel fresh = fresh_pipeline.Step(X1, 3, t);
  ASSERT_GE(fresh.num_contacts, 1);
  const double fresh_fz = fresh.F_T_W_at_q0.force.z;
  EXPECT_GT(fresh_fz, 0.1);
  EXPECT_NEAR(local.F_T_W.force.z, fresh_fz, 0.1 * fresh_fz);
  // Beyond the floor: nothing.
  EXPECT_EQ(with.Step(above(touch_dz + 4e-3), 4, t).num_contacts, 0);
  // Touching, the floored step's model is the plain one's.
  const ContactModel touching_plain = without.Step(X1, 5, t);
  const ContactModel touching_floored = with.Step(X1, 5, t);
  ASSERT_EQ(touching_floored.num_contacts, touching_plain.num_contacts);
  EXPECT_EQ(touching_floored.F_T_W_at_q0.force.z, touching_plain.F_T_W_at_q0.force.z);
  // The setter: a negative or non-finite floor is none.
  with.SetSpeculativeFloor(-1.0);
  EXPECT_EQ(with.speculative_floor_m(), 0.0);
  with.SetSpeculativeFloor(kNaN);
  EXPECT_EQ(with.speculative_floor_m(), 0.0);
  EXPECT_EQ(with.Step(X0, 6, t).num_contacts, 0);
  PipelineOptions bad;
  bad.speculative_floor_m = -1e-3;
  EXPECT_THROW(bad.Validate(), std::invalid_argument);
  Report("a surface a round trip away",
         Fmt("block at rest 2 mm above the gear, floor 3 mm: model δ0 = %.0f µm (separated, no "
             "force; none without the floor); 0.1 mm into the gear its local model pushes %.2f N, "
             "a fresh step %.2f N",
             m.contacts[0].depth_m * 1e6, local.F_T_W.force.z, fresh_fz));
}

TEST(HardCases, ASurfaceARoundTripAwayNeverTakesATouchingObjectsContactSlot) {
  // A wall 2 mm beside the block, first among the touchables, and the gear under the block, which
  // presses 0.1 mm into it: with room for one contact only, the floor's separated contact on the
  // untouched wall must not take the slot of the gear's, which pushes.
  HapticScene scene = MakeBlockOnGearScene();
  PipelineOptions plain;
  plain.speculative_lead_s = 0.0;
  StepTimings t;
  double touch_dz = 0.0;
  {  // before the wall joins the scene (a pipeline holds its scene)
    HapticTexturePipeline gear_only(scene, plain);
    touch_dz = BlockTouchDz(gear_only);
  }
  const RigidTransform X = BlockAboveHome(touch_dz - 0.1e-3);
  double min_x = std::numeric_limits<double>::infinity();
  for (const glm::dvec3& v : scene.tool->vertices_O) min_x = std::min(min_x, (X * v).x);
  const glm::dvec3 half{0.01, 0.03, 0.03};
  TouchableObject wall;
  wall.model = std::make_shared<const HapticModel>(MakeTexturedBox(
      half, [](double, double) { return 0.0; }, 16, 2.0, "side_wall"));
  wall.X_WO.translation = {min_x - 2e-3 - half.x, X.translation.y, X.translation.z};
  wall.stiffness_n_per_m = 8000.0;
  scene.touchables.insert(scene.touchables.begin(), wall);
  PipelineOptions floored = plain;
  floored.speculative_floor_m = 3e-3;
  HapticTexturePipeline room(scene, floored);
  const ContactModel both = room.Step(X, 2, t);
  ASSERT_EQ(both.num_contacts, 2);  // the wall, separated, and the gear
  int separated = 0;
  for (int i = 0; i < both.num_contacts; ++i) separated += both.contacts[i].depth_m < 0.0 ? 1 : 0;
  EXPECT_EQ(separated, 1);
  PipelineOptions one = floored;
  one.max_contacts = 1;
  HapticTexturePipeline tight(scene, one);
  const ContactModel m = tight.Step(X, 3, t);
  ASSERT_EQ(m.num_contacts, 1);
  EXPECT_GT(m.contacts[0].depth_m, 0.0);
  EXPECT_GT(m.F_T_W_at_q0.force.z, 0.1);
  Report("a surface a round trip away beside a touching one",
         Fmt("a wall 2 mm beside the block, first in the scene, floor 3 mm: two contacts (one "
             "separated); with room for one, the gear's (δ0 = %.0f µm, %.2f N up)",
             m.contacts[0].depth_m * 1e6, m.F_T_W_at_q0.force.z));
}

TEST(HardCases, NonFinitePosesFromTheNetwork) {
  const HapticScene scene = MakeBlockOnGearScene();
  RigidTransform bad = BlockOnGearHomePose();
  bad.translation.x = kNaN;
  const ContactModel m = StepAt(scene, bad);
  EXPECT_EQ(m.num_contacts, 0);
  RigidTransform inf = BlockOnGearHomePose();
  inf.rotation.w = std::numeric_limits<double>::infinity();
  EXPECT_EQ(StepAt(scene, inf).num_contacts, 0);
  ContactModel one;
  one.num_contacts = 1;
  one.contacts[0].depth_m = 1e-3;
  one.contacts[0].stiffness_n_per_m = kK;
  one.contacts[0].gradient.d_translation_W = {0, 0, -1};
  EXPECT_TRUE(Finite(EvaluateContactModel(one, bad).F_T_W));
  const ToolSimulator sim(BlockOnGearToolInertia(), VirtualCoupling{});
  ToolState s;
  const ToolStepResult r = sim.Step(s, bad, Twist{}, one, 1.0, 1e-3);
  EXPECT_FALSE(r.ok);
  EXPECT_TRUE(IsFiniteRigidTransform(s.X_WT));
  WrenchSafetyFilter safety{SafetyLimits{}};
  std::uint32_t flags = 0;
  const Wrench out = safety.Filter(Wrench{{kNaN, 0, 0}, {}}, Twist{}, 0.001, true, 1e-3, flags);
  EXPECT_TRUE(Finite(out));
  Report("NaN or infinite poses from the network",
         "remote step: empty model; contact model: finite (zero) wrench; tool step: holds the "
         "tool, ok = false; safety: non-finite wrench becomes zero");
}

// Issue 31's grazing guard: a δ beyond what the coarse geometry allows is dropped and counted;
// what it allows is kept (a genuinely deep press is: PenetrationDeeperThanTheTextureAmplitude).
TEST(HardCases, GrazingGuardDropsDepthsTheCoarseGeometryCannotHold) {
  std::array<ContactQuery, 3> queries{};
  std::array<ContactLinearization, 3> results{};
  queries[0].depth_bound_m = 1.2e-3;  // e.g. 0.4 mm coarse + 0.8 mm reach
  results[0].depth_m = 18e-3;         // the sideways overlap along a grazing n (fig77: 18-34 mm)
  queries[1].depth_bound_m = 1.2e-3;
  results[1].depth_m = 1.1e-3;  // within the bound: kept
  results[2].depth_m = 30e-3;   // no bound (+∞): kept
  EXPECT_EQ(DropGrazingContacts(queries, results), 1);
  EXPECT_TRUE(std::isinf(results[0].depth_m) && results[0].depth_m < 0.0);
  EXPECT_EQ(results[1].depth_m, 1.1e-3);
  EXPECT_EQ(results[2].depth_m, 30e-3);
  // The remote step sets the bound from the cluster: a deep press keeps its contact and counts
  // no drop.
  const HapticScene scene = MakeBlockOnGearScene();
  RigidTransform X = BlockOnGearHomePose();
  X.translation.z -= 0.5e-3 + 5e-3;
  HapticTexturePipeline a(scene, PipelineOptions{});
  StepTimings t;
  const ContactModel ma = a.Step(X, 1, t);
  ASSERT_GE(ma.num_contacts, 1);
  EXPECT_EQ(a.step_faults().grazing_dropped, 0);
  ASSERT_EQ(a.last_contact_queries().size(), 1u);
  const double bound = a.last_contact_queries()[0].depth_bound_m;
  EXPECT_TRUE(std::isfinite(bound));
  EXPECT_GT(bound, ma.contacts[0].depth_m);
}

// Issue 31: separated leaf pairs beyond their leaves' own texture reach start no contact (the
// coarse query's tolerance adds a margin beyond the reach, so it finds them).
TEST(HardCases, SeparatedPairsBeyondTheirTextureReachStartNoContact) {
  const HapticScene scene = MakeBlockOnGearScene();
  const double reach = scene.tool->OutwardReach() + scene.touchables[0].model->OutwardReach();
  RigidTransform X = BlockOnGearHomePose();  // 0.5 mm above the gear's mean top line
  X.translation.z += reach + 0.25e-3 - 0.5e-3;
  HapticTexturePipeline a(scene, PipelineOptions{});
  StepTimings ta;
  a.Step(X, 1, ta);
  EXPECT_EQ(ta.leaf_pairs, 1);
  EXPECT_EQ(a.last_contact_queries().size(), 0u);
  EXPECT_EQ(a.step_faults().unreachable_pairs, 1);
  // Within the reach the pair is kept.
  X.translation.z -= 0.5e-3;
  a.Step(X, 1, ta);
  EXPECT_EQ(a.last_contact_queries().size(), 1u);
}

// Issue 31: a window sized from its cluster keeps the cell W/N of the smallest window.
TEST(HardCases, WindowsSizedFromTheClusterKeepTheCell) {
  const HapticScene scene = MakeBlockOnGearScene();
  std::array<ContactCandidate, 3> c{};
  for (auto& x : c) x.object = &scene.touchables[0];
  c[0].extent_m = 0.0;    // the smallest window
  c[1].extent_m = 0.031;  // between
  c[2].extent_m = 0.09;   // beyond the largest
  c[1].depth_bound_m = 2e-3;
  std::array<ContactQuery, 3> out{};
  std::int64_t bad = 0;
  ASSERT_EQ(MakeContactQueries(c, 0.02, 0.04, 50, out, bad), 3);
  EXPECT_EQ(out[0].window.extent_m, 0.02);
  EXPECT_EQ(out[0].window.resolution, 50);
  EXPECT_EQ(out[1].window.extent_m, 0.031);
  EXPECT_EQ(out[1].window.resolution, 78);  // ceil(50 · 0.031 / 0.02)
  EXPECT_LE(out[1].window.cell_size_m(), 0.02 / 50);
  EXPECT_EQ(out[2].window.extent_m, 0.04);
  EXPECT_EQ(out[2].window.resolution, 100);
  EXPECT_EQ(out[1].depth_bound_m, 2e-3);
  EXPECT_EQ(bad, 0);
  PipelineOptions o;
  o.max_window_extent_m = 0.04;
  EXPECT_EQ(o.max_window_resolution(), 100);
  o.max_window_extent_m = 0.01;
  EXPECT_THROW(o.Validate(), std::invalid_argument);
}

}  // namespace
}  // namespace ht
