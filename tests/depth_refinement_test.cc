// Stage 5b (issue 32): the penetration depth refined to the finest texture level.
//  - PatchHeightAt at the window's cell centres, at the render's mip level, is the reference
//    render's value (two routes to one number);
//  - closed forms: a sinusoid of known amplitude under a flat tool (δ = A − z0, no in-plane
//    slope) and under a curved tool (a paraboloid of radius R: δ(x0) = max_x A cos(kx) −
//    (x − x0)²/2R − z0 and dδ/dx0 = (x* − x0)/R), at several N: the refined δ is the closed
//    form's within the texture's own interpolation error at every N, where the grid's reads low
//    by the mip filter's averaging, and its gradient is the closed form's secant (cell secants);
//  - bad input: a contact without overlap is left unchanged.
#include "haptic_core/depth_refinement.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>
#include <random>
#include <vector>

#include "haptic_core/contact_linearization.h"
#include "haptic_core/contact_model.h"
#include "haptic_core/demo/procedural_models.h"
#include "haptic_core/height_field.h"
#include "haptic_core/penetration_depth.h"
#include "haptic_core/penetration_depth_backend.h"
#include "test_scenes.h"

namespace ht {
namespace {

using testing::EnvironmentBox;
using testing::EnvironmentPose;
using testing::ToolBox;
using testing::ToolPose;

constexpr double kA = 40e-6;        // sinusoid amplitude (m)
constexpr double kLambda = 2e-3;    // its period (m)
constexpr double kR = 4e-3;         // the curved tool's radius (m)
constexpr double kToolHalf = 3e-3;  // the curved tool's half side (m)
const double kK = 2.0 * std::numbers::pi / kLambda;

double Sinusoid(double x, double) { return kA * std::cos(kK * x); }

// The curved tool: a box of 6 mm side whose bottom bulges down as a paraboloid of radius kR
// through its centre (heights along its outward normal −z: h = −r²/2R).
HapticModel CurvedTool() {
  return MakeTexturedBox(
      {kToolHalf, kToolHalf, 0.01},
      [](double x, double y) { return -(x * x + y * y) / (2.0 * kR); }, 1024, 0.05,
      "paraboloid_tool");
}

RigidTransform CurvedToolPose(double x0, double z0) {
  RigidTransform X;
  X.translation = {x0, 0.0, z0 + 0.01};
  return X;
}

// max_x A cos(kx) − (x − x0)²/2R by a dense scan and golden-section refinement; x* in `at`.
double ClosedFormDepth(double x0, double z0, double& at) {
  const auto f = [&](double x) { return kA * std::cos(kK * x) - (x - x0) * (x - x0) / (2.0 * kR); };
  double best = -1.0, best_x = 0.0;
  for (int i = -20000; i <= 20000; ++i) {
    const double x = x0 + i * 1e-7;
    if (f(x) > best) {
      best = f(x);
      best_x = x;
    }
  }
  double a = best_x - 1e-7, b = best_x + 1e-7;
  const double g = 0.5 * (std::sqrt(5.0) - 1.0);
  for (int i = 0; i < 80; ++i) {
    const double c = b - g * (b - a), d = a + g * (b - a);
    if (f(c) > f(d)) {
      b = d;
    } else {
      a = c;
    }
  }
  at = 0.5 * (a + b);
  return f(at) - z0;
}

struct Refined {
  ContactLinearization grid, refined;
  std::vector<DepthSample> samples;
};

// `patch_switched_on`: the refiner is built with `options` and its translation patch turned on
// afterwards (DepthRefiner::SetTranslationPatch, as the remote node does by the round trip).
Refined LinearizeAndRefine(const HapticModel& tool, const RigidTransform& X_WT,
                           const HapticModel& env, int n, DepthRefinementOptions options = {},
                           bool patch_switched_on = false) {
  ContactQuery q;
  q.environment = &env;
  q.X_WO = EnvironmentPose();
  q.window = ContactWindow::Make({0.0, 0.0, 0.0}, {0.0, 0.0, 1.0}, 0.02, n);
  q.stiffness_n_per_m = 1000.0;
  CpuPenetrationDepthBackend backend(128);
  Refined r;
  r.samples.resize(kGradientSamples);
  std::vector<ContactLinearization> out(1);
  EXPECT_TRUE(backend.LinearizeBatch(tool, X_WT, {&q, 1}, out, r.samples));
  r.grid = out[0];
  r.refined = out[0];
  DepthRefiner refiner(options);
  if (patch_switched_on) refiner.SetTranslationPatch(true);
  EXPECT_TRUE(refiner.Refine(tool, X_WT, q, r.samples, r.refined));
  EXPECT_GT(refiner.counters().evaluations, 0u);
  return r;
}

TEST(DepthRefinement, PatchHeightAtCellCentresIsTheReferenceRender) {
  const HapticModel tool = CurvedTool();
  const HapticModel env = EnvironmentBox(Sinusoid, 1024);
  const RigidTransform X_WT = CurvedToolPose(0.3e-3, 20e-6);
  for (const int n : {16, 50}) {
    const ContactWindow w = ContactWindow::Make({0.0, 0.0, 0.0}, {0.0, 0.0, 1.0}, 0.02, n);
    for (const bool environment : {true, false}) {
      const HapticModel& m = environment ? env : tool;
      const RigidTransform X = environment ? EnvironmentPose() : X_WT;
      const PatchSide side = environment ? PatchSide::kEnvironment : PatchSide::kTool;
      std::vector<int> all(m.triangles.size());
      for (std::size_t f = 0; f < all.size(); ++f) all[f] = static_cast<int>(f);
      std::vector<float> heights(static_cast<std::size_t>(n) * n,
                                 environment ? -std::numeric_limits<float>::infinity()
                                             : std::numeric_limits<float>::infinity());
      RenderPatchHeights(m, X, all, w, side, heights);
      int covered = 0;
      for (int c = 0; c < n * n; ++c) {
        const glm::dvec3 p = w.CellCenter(c) - w.center_W;
        const double h =
            PatchHeightAt(m, X, all, w, side, glm::dot(p, w.axis_u_W), glm::dot(p, w.axis_v_W), -1);
        const float r = heights[static_cast<std::size_t>(c)];
        ASSERT_EQ(std::isfinite(h), std::isfinite(r)) << "cell " << c << " n " << n;
        if (!std::isfinite(r)) continue;
        ++covered;
        EXPECT_NEAR(h, r, 1e-6 * std::abs(r) + 1e-12) << "cell " << c << " n " << n;
      }
      EXPECT_GT(covered, environment ? n * n - 1 : 4) << n;
    }
  }
}

TEST(DepthRefinement, SinusoidUnderAFlatToolGivesItsAmplitudeAtEveryGrid) {
  const HapticModel tool = ToolBox([](double, double) { return 0.0; }, 512);
  const HapticModel env = EnvironmentBox(Sinusoid, 1024);
  const double z0 = kA - 25e-6;  // δ = A − z0 = 25 µm, on every crest
  double grid_error_at_16 = 0.0;
  for (const int n : {16, 25, 50, 100}) {
    const Refined r = LinearizeAndRefine(tool, ToolPose(0.0, 0.0, z0), env, n);
    // Bilinear interpolation of the 1024² texture (39 µm texels on 4 cm) reads a crest
    // A(k·texel)²/8 ≈ 0.08 µm low at most; the search stops within a quarter texel.
    EXPECT_NEAR(r.refined.depth_m, 25e-6, 0.3e-6) << "N " << n;
    EXPECT_GE(r.refined.depth_m, r.grid.depth_m - 1e-9) << "N " << n;
    // Crests run along y: moving a flat tool in its plane changes nothing.
    EXPECT_NEAR(glm::dot(r.refined.gradient.d_translation_W, glm::dvec3(1, 0, 0)), 0.0, 1e-3);
    EXPECT_NEAR(glm::dot(r.refined.gradient.d_translation_W, glm::dvec3(0, 1, 0)), 0.0, 1e-3);
    EXPECT_DOUBLE_EQ(r.refined.gradient.d_translation_W.z, -1.0);
    if (n == 16) grid_error_at_16 = 25e-6 - r.grid.depth_m;
  }
  // What the refinement removes: at N = 16 (1.25 mm cells, mip level 5 of a 2 mm period) the
  // grid's filtered samples lose most of the crest.
  EXPECT_GT(grid_error_at_16, 10e-6);
}

TEST(DepthRefinement, SinusoidUnderACurvedToolGivesTheClosedFormDepthAndSlope) {
  const HapticModel tool = CurvedTool();
  const HapticModel env = EnvironmentBox(Sinusoid, 1024);
  const double z0 = 10e-6;
  for (const double x0 : {0.15e-3, 0.3e-3, -0.4e-3}) {
    double x_star = 0.0;
    const double depth = ClosedFormDepth(x0, z0, x_star);
    const double slope = (x_star - x0) / kR;  // dδ/dx0 (envelope theorem)
    ASSERT_GT(depth, 5e-6);
    for (const int n : {16, 25, 50}) {
      const double h = 0.02 / n;  // the grid's translation step
      double unused = 0.0;
      const double secant =
          (ClosedFormDepth(x0 + h, z0, unused) - ClosedFormDepth(x0 - h, z0, unused)) / (2.0 * h);
      const Refined r = LinearizeAndRefine(tool, CurvedToolPose(x0, z0), env, n);
      EXPECT_NEAR(r.refined.depth_m, depth, 0.3e-6) << "x0 " << x0 << " N " << n;
      EXPECT_NEAR(r.refined.gradient.d_translation_W.x, secant, 0.02 * std::abs(secant) + 2e-3)
          << "x0 " << x0 << " N " << n;
      // The refined point is where the closed form's maximum is.
      EXPECT_NEAR(r.refined.point_W.x, x_star, 20e-6) << "x0 " << x0 << " N " << n;
      std::printf(
          "x0 %+.2f mm N %3d: δ %.2f µm; error refined %+.3f µm, grid %+.2f µm; dδ/dx %+.4f: "
          "cell secant %+.4f (closed form's %+.4f, grid's %+.4f)\n",
          x0 * 1e3, n, depth * 1e6, (r.refined.depth_m - depth) * 1e6,
          (r.grid.depth_m - depth) * 1e6, slope, r.refined.gradient.d_translation_W.x, secant,
          r.grid.gradient.d_translation_W.x);
    }
  }
}

// A broad low hump (kHump, σ 3 mm, at kHumpAt) and, 10 mm away, a narrow tall spike (kSpike,
// σ 150 µm, at kSpikeAt): heights (m) over world (x, y) (m), and the spike's top, max h, by a
// 1 µm scan around it (m).
constexpr double kHump = 20e-6, kSpike = 40e-6;
constexpr glm::dvec2 kHumpAt{-5e-3, 0.0}, kSpikeAt{5e-3, 3e-3};
double HumpAndSpike(double x, double y) {
  const auto g = [&](glm::dvec2 c, double sigma) {
    const double r2 = (x - c.x) * (x - c.x) + (y - c.y) * (y - c.y);
    return std::exp(-r2 / (2.0 * sigma * sigma));
  };
  return kHump * g(kHumpAt, 3e-3) + kSpike * g(kSpikeAt, 150e-6);
}
double SpikeTop() {
  double peak = 0.0;
  for (int i = -400; i <= 400; ++i) {
    for (int j = -400; j <= 400; ++j) {
      peak = std::max(peak, HumpAndSpike(kSpikeAt.x + i * 1e-6, kSpikeAt.y + j * 1e-6));
    }
  }
  return peak;
}

// The conservative screen (issue 32, sixth stop) against a closed form the seeds cannot find: a
// broad low hump (20 µm, σ 3 mm) and, 10 mm away, a narrow tall spike (40 µm, σ 150 µm) under a
// flat tool. At every N the grid's filtered cells read the hump deepest (at N = 16 a cell
// averages the spike to a few micrometres), so the seeds climb the hump; the screen's bounds
// (the texture's level-0 maxima) keep the spike's squares and its leaf search finds it. δ is
// max_x h(x) − z0 within the bilinear texture's error; the point is the spike's.
TEST(DepthRefinement, ScreenFindsTheNarrowPeakTheFilteredGridHides) {
  const auto surface = HumpAndSpike;
  const glm::dvec2 spike_at = kSpikeAt;
  const double peak = SpikeTop();
  const HapticModel tool = ToolBox([](double, double) { return 0.0; }, 256);
  const HapticModel env = EnvironmentBox(surface, 1024);
  const double z0 = 10e-6;
  for (const int n : {16, 25, 50}) {
    DepthRefinementOptions seeds_only, screened;
    seeds_only.conservative_screen = false;
    screened.conservative_screen = true;
    // The screen bounds the render's form: both without parallax (on by default).
    seeds_only.parallax = screened.parallax = false;
    const Refined before = LinearizeAndRefine(tool, ToolPose(0.0, 0.0, z0), env, n, seeds_only);
    const Refined r = LinearizeAndRefine(tool, ToolPose(0.0, 0.0, z0), env, n, screened);
    // The seeds stay on the hump (the test's premise) ...
    EXPECT_LT(before.refined.depth_m, kHump - z0 + 1e-6) << "N " << n;
    // ... the screen finds the spike: the closed form within the bilinear texture's error (a
    // peak of σ 150 µm between texel centres ~40 µm apart reads up to A·d²/2σ² ≈ 0.7 µm low).
    EXPECT_NEAR(r.refined.depth_m, peak - z0, 1.0e-6) << "N " << n;
    EXPECT_NEAR(r.refined.point_W.x, spike_at.x, 40e-6) << "N " << n;
    EXPECT_NEAR(r.refined.point_W.y, spike_at.y, 40e-6) << "N " << n;
    std::printf("N %3d: grid δ %.2f µm, seeds %.2f µm, screened %.2f µm (closed form %.2f µm)\n", n,
                r.grid.depth_m * 1e6, before.refined.depth_m * 1e6, r.refined.depth_m * 1e6,
                (peak - z0) * 1e6);
  }
}

// DepthRefinementOptions::seed_from_last_step: the narrow peak of the test above, hidden from the
// whole window's filtered grid, found on a step whose window holds it alone, is kept on the next
// step over the whole window; forgotten, the whole window's seeds stay on the hump as without the
// option, bit for bit.
TEST(DepthRefinement, ASeedFromTheLastStepKeepsTheNarrowPeakTheFilteredGridHides) {
  const auto surface = HumpAndSpike;
  const glm::dvec2 spike_at = kSpikeAt;
  const double peak = SpikeTop();
  const HapticModel tool = ToolBox([](double, double) { return 0.0; }, 256);
  const HapticModel env = EnvironmentBox(surface, 1024);
  const double z0 = 10e-6;
  const RigidTransform X_WT = ToolPose(0.0, 0.0, z0);
  CpuPenetrationDepthBackend backend(128);
  const auto refine = [&](DepthRefiner& refiner, glm::dvec3 centre, double extent, int n,
                          const HapticModel* environment = nullptr) {
    ContactQuery q;
    q.environment = environment != nullptr ? environment : &env;
    q.X_WO = EnvironmentPose();
    q.window = ContactWindow::Make(centre, {0.0, 0.0, 1.0}, extent, n);
    q.stiffness_n_per_m = 1000.0;
    std::vector<DepthSample> samples(kGradientSamples);
    std::vector<ContactLinearization> out(1);
    EXPECT_TRUE(backend.LinearizeBatch(tool, X_WT, {&q, 1}, out, samples));
    refiner.BeginStep();
    EXPECT_TRUE(refiner.Refine(tool, X_WT, q, samples, out[0]));
    return out[0];
  };
  DepthRefinementOptions with;
  with.seed_from_last_step = true;
  DepthRefiner seeded(with), alone{DepthRefinementOptions{}};
  const glm::dvec3 spike_W{spike_at.x, spike_at.y, 0.0}, origin{0.0, 0.0, 0.0};
  // Step 1: a 4 mm window around the spike; its own grid finds it.
  const ContactLinearization first = refine(seeded, spike_W, 4e-3, 16);
  EXPECT_NEAR(first.depth_m, peak - z0, 1.0e-6);
  EXPECT_EQ(seeded.counters().last_step_found, 0u);
  // Step 2: the whole 20 mm window, whose grid's seeds stay on the hump (the screen test's
  // premise, checked below): the last step's point finds the spike.
  const ContactLinearization kept = refine(seeded, origin, 0.02, 50);
  EXPECT_NEAR(kept.depth_m, peak - z0, 1.0e-6);
  EXPECT_NEAR(kept.point_W.x, spike_at.x, 40e-6);
  EXPECT_NEAR(kept.point_W.y, spike_at.y, 40e-6);
  EXPECT_EQ(seeded.counters().last_step_seeds, 1u);
  EXPECT_EQ(seeded.counters().last_step_found, 1u);
  // The displaced samples were searched from the spike too: the slope there is the spike's
  // (zero at its top, within the secant's one-cell step over a σ of 150 µm), not the hump's.
  const ContactLinearization hump = refine(alone, origin, 0.02, 50);
  EXPECT_LT(hump.depth_m, kHump - z0 + 1e-6);
  EXPECT_LT(std::abs(kept.gradient.d_translation_W.x), 0.05);
  EXPECT_LT(std::abs(kept.gradient.d_translation_W.y), 0.05);
  // Forgotten: the whole window again starts from its grid alone, as without the option.
  seeded.ForgetLastStep();
  const ContactLinearization forgotten = refine(seeded, origin, 0.02, 50);
  EXPECT_EQ(forgotten.depth_m, hump.depth_m);
  EXPECT_EQ(forgotten.point_W, hump.point_W);
  EXPECT_EQ(forgotten.gradient.d_translation_W, hump.gradient.d_translation_W);
  EXPECT_EQ(forgotten.gradient.d_rotation_W, hump.gradient.d_rotation_W);
  // A point found on another environment model is no seed: after the spike's step, the whole
  // window on a copy of the model (another object) starts from its grid alone.
  const HapticModel copy = env;
  refine(seeded, spike_W, 4e-3, 16);
  const ContactLinearization on_copy = refine(seeded, origin, 0.02, 50, &copy);
  EXPECT_EQ(on_copy.depth_m, hump.depth_m);
}

TEST(DepthRefinement, AContactWithoutOverlapIsLeftUnchanged) {
  const HapticModel tool = CurvedTool();
  const HapticModel env = EnvironmentBox(Sinusoid, 256);
  ContactQuery q;
  q.environment = &env;
  q.X_WO = EnvironmentPose();
  q.window = ContactWindow::Make({0.0, 0.0, 0.0}, {0.0, 0.0, 1.0}, 0.02, 25);
  std::vector<DepthSample> samples(kGradientSamples,
                                   {-std::numeric_limits<double>::infinity(), -1});
  ContactLinearization lin;
  lin.depth_m = -std::numeric_limits<double>::infinity();
  DepthRefiner refiner;
  EXPECT_FALSE(refiner.Refine(tool, CurvedToolPose(0.0, 0.0), q, samples, lin));
  EXPECT_EQ(lin.depth_m, -std::numeric_limits<double>::infinity());
  EXPECT_EQ(samples[0].cell, -1);
  // Too few samples, or no environment: refused.
  std::vector<DepthSample> few(3, {0.0, 0});
  EXPECT_FALSE(refiner.Refine(tool, CurvedToolPose(0.0, 0.0), q, few, lin));
  q.environment = nullptr;
  std::vector<DepthSample> some(kGradientSamples, {0.0, 0});
  EXPECT_FALSE(refiner.Refine(tool, CurvedToolPose(0.0, 0.0), q, some, lin));
  EXPECT_EQ(refiner.counters().contacts, 0u);
}

// Parallax (DepthRefinementOptions::parallax, docs/frontier/issue32/twelfth_stop): the
// environment box's textured face tilted by θ about y from the window's n = z. Its displaced
// surface in the face's own frame is (x, y, h(x)), in world R_y(θ)·(x, y, h(x)) = (x cosθ +
// h sinθ, y, −x sinθ + h cosθ); its height along z at world s solves x cosθ + h(x) sinθ = s
// (monotone here: |h'| sinθ < cosθ), by bisection: a route independent of the texture and of
// the fixed-point steps.
RigidTransform TiltedEnvironmentPose(double theta) {
  RigidTransform R;
  R.rotation = glm::angleAxis(theta, glm::dvec3(0.0, 1.0, 0.0));
  return R * EnvironmentPose();
}

// Stage 5's grid on a contact with the environment tilted by θ (TiltedEnvironmentPose), the
// window's n = z at the origin, 20 mm, N cells: the query, its samples and its linearization, and
// whether the backend linearized it.
struct TiltedContact {
  bool ok = false;
  ContactQuery query;
  std::vector<DepthSample> samples;
  ContactLinearization grid;
};
TiltedContact LinearizeOnTiltedFacet(const HapticModel& tool, const RigidTransform& X_WT,
                                     const HapticModel& env, double theta, int n) {
  TiltedContact c;
  c.query.environment = &env;
  c.query.X_WO = TiltedEnvironmentPose(theta);
  c.query.window = ContactWindow::Make({0.0, 0.0, 0.0}, {0.0, 0.0, 1.0}, 0.02, n);
  c.query.stiffness_n_per_m = 1000.0;
  CpuPenetrationDepthBackend backend(128);
  c.samples.resize(kGradientSamples);
  std::vector<ContactLinearization> out(1);
  c.ok = backend.LinearizeBatch(tool, X_WT, {&c.query, 1}, out, c.samples);
  c.grid = out[0];
  return c;
}

double DisplacedHeightAlongZ(const std::function<double(double)>& h, double theta, double s) {
  double lo = -0.03, hi = 0.03;
  for (int i = 0; i < 200; ++i) {
    const double mid = 0.5 * (lo + hi);
    (mid * std::cos(theta) + h(mid) * std::sin(theta) < s ? lo : hi) = mid;
  }
  const double x = 0.5 * (lo + hi);
  return -x * std::sin(theta) + h(x) * std::cos(theta);
}

std::vector<int> AllTriangles(const HapticModel& m) {
  std::vector<int> all(m.triangles.size());
  for (std::size_t f = 0; f < all.size(); ++f) all[f] = static_cast<int>(f);
  return all;
}

// A constant height h0 on a facet tilted by θ is the facet's offset plane: along n it stands
// h0/cosθ above the facet. The render's form, h0·(N·n), reads h0·cosθ: 0.73 mm low at 50°.
TEST(DepthRefinement, ParallaxReadsAConstantHeightOnATiltedFacetAsItsOffsetPlane) {
  constexpr double kH0 = 0.8e-3;
  const double theta = 50.0 * std::numbers::pi / 180.0;
  const HapticModel env = EnvironmentBox([](double, double) { return kH0; }, 256);
  const RigidTransform X = TiltedEnvironmentPose(theta);
  const ContactWindow w = ContactWindow::Make({0.0, 0.0, 0.0}, {0.0, 0.0, 1.0}, 0.02, 50);
  const std::vector<int> all = AllTriangles(env);
  for (const double s : {-4e-3, -1.3e-3, 0.0, 0.7e-3, 5e-3}) {
    for (const double t : {-3e-3, 0.0, 2e-3}) {
      const double expected = DisplacedHeightAlongZ([](double) { return kH0; }, theta, s);
      EXPECT_NEAR(expected, -s * std::tan(theta) + kH0 / std::cos(theta), 1e-9);
      const double parallax =
          PatchHeightAt(env, X, all, w, PatchSide::kEnvironment, s, t, 0, /*parallax=*/true);
      const double render = PatchHeightAt(env, X, all, w, PatchSide::kEnvironment, s, t, 0);
      EXPECT_NEAR(parallax, expected, 0.5e-6) << s << " " << t;
      EXPECT_NEAR(render, -s * std::tan(theta) + kH0 * std::cos(theta), 0.5e-6) << s << " " << t;
      EXPECT_GT(expected - render, 0.7e-3) << s << " " << t;
    }
  }
}

// A sinusoid of 0.2 mm amplitude and 2 mm period on a facet tilted by 40°: the parallax height
// matches the displaced surface's (bisection above) within the texture's bilinear error at 200
// random points; the render's form misses it by tens of micrometres.
TEST(DepthRefinement, ParallaxOnATiltedSinusoidMatchesTheDisplacedSurface) {
  constexpr double kAmp = 200e-6;
  const auto h = [](double x) { return kAmp * std::cos(kK * x); };
  const double theta = 40.0 * std::numbers::pi / 180.0;
  const HapticModel env = EnvironmentBox([&](double x, double) { return h(x); }, 1024);
  const RigidTransform X = TiltedEnvironmentPose(theta);
  const ContactWindow w = ContactWindow::Make({0.0, 0.0, 0.0}, {0.0, 0.0, 1.0}, 0.02, 50);
  const std::vector<int> all = AllTriangles(env);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> U(-6e-3, 6e-3);
  double worst_parallax = 0.0, worst_render = 0.0;
  int settled = 0;
  for (int i = 0; i < 200; ++i) {
    const double s = U(rng), t = U(rng);
    const double expected = DisplacedHeightAlongZ(h, theta, s);
    const double parallax =
        PatchHeightAt(env, X, all, w, PatchSide::kEnvironment, s, t, 0, /*parallax=*/true);
    const double render = PatchHeightAt(env, X, all, w, PatchSide::kEnvironment, s, t, 0);
    if (std::isfinite(parallax)) {
      ++settled;
      worst_parallax = std::max(worst_parallax, std::abs(parallax - expected));
    }
    worst_render = std::max(worst_render, std::abs(render - expected));
  }
  std::printf("tilted sinusoid: parallax worst %.2f um over %d points, render worst %.1f um\n",
              worst_parallax * 1e6, settled, worst_render * 1e6);
  EXPECT_EQ(settled, 200);
  EXPECT_LT(worst_parallax, 3e-6);
  EXPECT_GT(worst_render, 50e-6);
}

// Where the coarse normal is n (the face untilted) the parallax is the render's form exactly.
TEST(DepthRefinement, ParallaxIsTheRendersFormWhereTheNormalIsTheWindows) {
  const HapticModel env = EnvironmentBox(Sinusoid, 512);
  const ContactWindow w = ContactWindow::Make({0.0, 0.0, 0.0}, {0.0, 0.0, 1.0}, 0.02, 50);
  const std::vector<int> all = AllTriangles(env);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> U(-9e-3, 9e-3);
  for (int i = 0; i < 100; ++i) {
    const double s = U(rng), t = U(rng);
    const double render =
        PatchHeightAt(env, EnvironmentPose(), all, w, PatchSide::kEnvironment, s, t, 0);
    ASSERT_TRUE(std::isfinite(render));
    EXPECT_NEAR(PatchHeightAt(env, EnvironmentPose(), all, w, PatchSide::kEnvironment, s, t, 0,
                              /*parallax=*/true),
                render, 1e-12);
  }
}

// A convex crease whose two faces keep their own corner normals (a roof of slope α, constant
// height h0): the offset planes z = ∓x·tanα + h0/cosα part over |x| < h0·sinα, where no
// displaced surface crosses the line along z. The skirt bridges the crack at the planes' edge
// height h0·cosα (both edges stand there), so the envelope has no hole; outside it the offset
// planes are read exactly.
TEST(DepthRefinement, ParallaxBridgesTheCrackAtACreaseWithSplitNormals) {
  constexpr double kL = 0.01, kH0 = 0.5e-3;
  const double alpha = 20.0 * std::numbers::pi / 180.0, c = std::cos(alpha), sn = std::sin(alpha);
  HapticModel roof;
  roof.name = "roof";
  roof.vertices_O = {
      {0.0, -kL, 0.0}, {0.0, kL, 0.0}, {-kL * c, 0.0, -kL * sn}, {kL * c, 0.0, -kL * sn}};
  roof.triangles = {{0, 1, 2}, {1, 0, 3}};
  const glm::dvec3 nA(-sn, 0.0, c), nB(sn, 0.0, c);
  roof.corner_normals_O = {nA, nA, nA, nB, nB, nB};
  roof.corner_uvs = {{0.1f, 0.1f}, {0.4f, 0.1f}, {0.1f, 0.4f},
                     {0.6f, 0.6f}, {0.9f, 0.6f}, {0.6f, 0.9f}};
  roof.textured = {1, 1};
  roof.texel_size_m = {kL / 4.0, kL / 4.0};
  roof.texture =
      HeightField(16, 16, std::vector<float>(256, static_cast<float>(kH0)), false, false);
  const ContactWindow w = ContactWindow::Make({0.0, 0.0, 0.0}, {0.0, 0.0, 1.0}, 0.02, 50);
  const std::vector<int> all = AllTriangles(roof);
  const RigidTransform X;
  const double gap = kH0 * sn;
  for (const double x : {-3.0 * gap, -1.5 * gap, -0.5 * gap, 0.0, 0.7 * gap, 2.0 * gap}) {
    const double h = PatchHeightAt(roof, X, all, w, PatchSide::kEnvironment, x, 1e-3, 0, true);
    const double expected = std::abs(x) < gap ? kH0 * c : -std::abs(x) * std::tan(alpha) + kH0 / c;
    EXPECT_NEAR(h, expected, 0.2e-6) << x;
  }
}

// Stage 5b with parallax on a contact whose environment facet is tilted 30° under a 0.8 mm
// height (fig77's case, smaller): the curved tool's paraboloid pressed into the offset plane;
// the refined δ0 is the displaced surface's closed form, where the render's form reads it
// h0·(1/cosθ − cosθ) = 0.23 mm low.
TEST(DepthRefinement, RefinedWithParallaxATiltedFacetsDepthIsTheDisplacedSurfaces) {
  constexpr double kH0 = 0.8e-3;
  const double theta = 30.0 * std::numbers::pi / 180.0;
  const HapticModel env = EnvironmentBox([](double, double) { return kH0; }, 256);
  const HapticModel tool = CurvedTool();
  // The paraboloid's lowest point at (x0, 0, z0); the offset plane's height there is
  // −x0 tanθ + h0/cosθ and δ = max over x of plane − paraboloid, in closed form: the tangent
  // point lies where the paraboloid's slope (x − x0)/R equals the plane's, −tanθ.
  const double x0 = 0.5e-3, z0 = kH0 / std::cos(theta) - x0 * std::tan(theta) - 60e-6;
  const double xs = x0 - kR * std::tan(theta);
  const double plane = -xs * std::tan(theta) + kH0 / std::cos(theta);
  const double expected = plane - ((xs - x0) * (xs - x0) / (2.0 * kR) + z0);
  ASSERT_GT(xs, x0 - kToolHalf);
  const RigidTransform X_WT = CurvedToolPose(x0, z0);
  const TiltedContact c = LinearizeOnTiltedFacet(tool, X_WT, env, theta, 50);
  ASSERT_TRUE(c.ok);
  const ContactQuery& q = c.query;
  for (const bool parallax : {false, true}) {
    DepthRefinementOptions o;
    o.parallax = parallax;
    DepthRefiner refiner(o);
    ContactLinearization lin = c.grid;
    std::vector<DepthSample> s = c.samples;
    const bool refined = refiner.Refine(tool, X_WT, q, s, lin);
    std::printf("tilted facet: parallax %d refined %d delta %.1f um, closed form %.1f um\n",
                int(parallax), int(refined), lin.depth_m * 1e6, expected * 1e6);
    if (parallax) {
      ASSERT_TRUE(refined);
      EXPECT_NEAR(lin.depth_m, expected, 5e-6);
    } else {
      EXPECT_LT(lin.depth_m, expected - 200e-6);
    }
  }
}

// Seeds carried by parallax (DepthRefinementOptions::parallax_offset_seeds, issue 32's
// thirty-third stop): a Gaussian bump of 0.8 mm on a facet tilted 50°, under the tool's flat face
// tilted alike, 60 µm into the bump along the facet's normal. Along the window's n = z the two
// parallel planes stand (A − g)/cosθ apart at the bump's top, the closed form. The render's form
// reads the bump at its coarse point, A·sinθ = 0.61 mm (three cells at N = 100) beside where its
// displaced top lies, and there it reads no overlap at all; the carried seed is searched where
// the top is.
TEST(DepthRefinement, ParallaxOffsetSeedsFindTheBumpTheRendersFormPutsBeside) {
  constexpr double kBump = 0.8e-3, kSigma = 0.4e-3, kPress = 60e-6;
  const double theta = 50.0 * std::numbers::pi / 180.0;
  const HapticModel env = EnvironmentBox(
      [](double x, double y) {
        return kBump * std::exp(-(x * x + y * y) / (2.0 * kSigma * kSigma));
      },
      1024);
  const HapticModel tool = ToolBox([](double, double) { return 0.0; });
  RigidTransform tilt;
  tilt.rotation = glm::angleAxis(theta, glm::dvec3(0.0, 1.0, 0.0));
  const RigidTransform X_WT = tilt * ToolPose(0.0, 0.0, kBump - kPress);
  const double expected = kPress / std::cos(theta);
  const TiltedContact c = LinearizeOnTiltedFacet(tool, X_WT, env, theta, 100);
  ASSERT_TRUE(c.ok);
  const ContactQuery& q = c.query;
  EXPECT_LT(c.grid.depth_m, 0.0) << "the render's form reads no overlap";
  double with = 0.0, without = 0.0;
  for (const bool offset : {false, true}) {
    DepthRefinementOptions o;
    o.parallax_offset_seeds = offset;
    DepthRefiner refiner(o);
    ContactLinearization lin = c.grid;
    std::vector<DepthSample> s = c.samples;
    refiner.Refine(tool, X_WT, q, s, lin);
    std::printf(
        "bump on a 50 deg facet: offset seeds %d, delta %.1f um (closed form %.1f um), "
        "%llu carried seeds\n",
        int(offset), lin.depth_m * 1e6, expected * 1e6,
        static_cast<unsigned long long>(refiner.counters().parallax_offset_seeds));
    (offset ? with : without) = lin.depth_m;
    if (offset) {
      EXPECT_GT(refiner.counters().parallax_offset_seeds, 0u);
      EXPECT_GT(refiner.counters().parallax_offset_found, 0u);
    } else {
      EXPECT_EQ(refiner.counters().parallax_offset_seeds, 0u);
    }
  }
  EXPECT_NEAR(with, expected, 3e-6);
  EXPECT_GE(with, without) << "a carried seed only adds a candidate";
  // Without parallax the option does nothing: the render's form alone.
  DepthRefinementOptions plain;
  plain.parallax = false;
  DepthRefinementOptions plain_offset = plain;
  plain_offset.parallax_offset_seeds = true;
  DepthRefiner a(plain), b(plain_offset);
  ContactLinearization la = c.grid, lb = c.grid;
  std::vector<DepthSample> sa = c.samples, sb = c.samples;
  a.Refine(tool, X_WT, q, sa, la);
  b.Refine(tool, X_WT, q, sb, lb);
  EXPECT_EQ(la.depth_m, lb.depth_m);
  EXPECT_EQ(b.counters().parallax_offset_seeds, 0u);
}

// The translation patch (DepthRefinementOptions::translation_patch, issue 32's nineteenth stop)
// under the curved tool on the sinusoid (N = 50: nodes 0.4 mm apart, the patch ±0.8 mm, the
// period 2 mm). Two routes to each node: the patch's value and the refinement run afresh with the
// tool translated to that node. The closed form between the nodes: the model with the patch
// follows the pushing depth max(δ, 0) over the patch where the linear model leaves it within a
// fraction of the period. At q0 the patch changes nothing.
// Index of node (i, j) in TranslationPatch::depth_m.
std::size_t PatchIndex(int i, int j) {
  constexpr int R = kTranslationPatchRadius;
  return static_cast<std::size_t>((j + R) * kTranslationPatchSide + (i + R));
}

// What node (i, j) of a patch with spacing h (m) made at the curved tool's pose (x0, z0) should
// hold: the refined depth (m) with the tool translated there, the window staying where it is.
double RefinedDepthAtNode(const HapticModel& tool, const HapticModel& env, int n, double x0,
                          double z0, int i, int j, double h) {
  RigidTransform X_moved = CurvedToolPose(x0, z0);
  X_moved.translation += glm::dvec3(i * h, j * h, 0.0);
  return LinearizeAndRefine(tool, X_moved, env, n).refined.depth_m;
}

TEST(DepthRefinement, TranslationPatchHoldsTheDepthOverTheToolsSlide) {
  const HapticModel tool = CurvedTool();
  const HapticModel env = EnvironmentBox(Sinusoid, 1024);
  DepthRefinementOptions with_patch;
  with_patch.translation_patch = true;
  constexpr int n = 50;
  const double h = 0.02 / n;
  constexpr int R = kTranslationPatchRadius;
  for (const double x0 : {0.15e-3, 0.55e-3, -0.4e-3}) {
    double at = 0.0;
    const double z0 = ClosedFormDepth(x0, 0.0, at) - 15e-6;
    const Refined plain = LinearizeAndRefine(tool, CurvedToolPose(x0, z0), env, n);
    const Refined patched = LinearizeAndRefine(tool, CurvedToolPose(x0, z0), env, n, with_patch);
    const ContactLinearization& c = patched.refined;
    // A refiner built without the patch and switched on later gives the same patch.
    const ContactLinearization switched =
        LinearizeAndRefine(tool, CurvedToolPose(x0, z0), env, n, {}, true).refined;
    EXPECT_EQ(switched.patch.step_m, c.patch.step_m);
    EXPECT_EQ(switched.patch.depth_m, c.patch.depth_m);
    EXPECT_EQ(switched.depth_m, c.depth_m);
    // At q0 the contact is the default's.
    EXPECT_EQ(plain.refined.patch.step_m, 0.0);
    ASSERT_EQ(c.patch.step_m, h);
    EXPECT_EQ(c.depth_m, plain.refined.depth_m);
    EXPECT_EQ(c.gradient.d_translation_W, plain.refined.gradient.d_translation_W);
    EXPECT_EQ(c.gradient.d_rotation_W, plain.refined.gradient.d_rotation_W);
    PenetrationGradient g0;
    EXPECT_DOUBLE_EQ(ContactDepthAt(c, Twist{}, &g0), c.depth_m);
    EXPECT_NEAR(glm::length(g0.d_translation_W - c.gradient.d_translation_W), 0.0, 1e-12);
    // Each node against the refinement at the translated pose (the window stays where it is),
    // also with the nodes climbed from their neighbours' maxima too.
    DepthRefinementOptions climbs = with_patch;
    climbs.translation_patch_neighbour_climbs = true;
    const ContactLinearization from_grid =
        LinearizeAndRefine(tool, CurvedToolPose(x0, z0), env, n, climbs).refined;
    for (int j = -R; j <= R; ++j) {
      for (int i = -R; i <= R; ++i) {
        const double moved = RefinedDepthAtNode(tool, env, n, x0, z0, i, j, h);
        const std::size_t k = PatchIndex(i, j);
        const double node = c.depth_m + c.patch.depth_m[k];
        EXPECT_NEAR(node, moved, 0.3e-6) << "x0 " << x0 << " node " << i << ", " << j;
        EXPECT_NEAR(from_grid.depth_m + from_grid.patch.depth_m[k], moved, 0.3e-6)
            << "with neighbour climbs: x0 " << x0 << " node " << i << ", " << j;
        Twist dq;
        dq.linear = {i * h, j * h, 0.0};
        EXPECT_NEAR(ContactDepthAt(c, dq), node, 1e-9) << "the interpolant passes its nodes";
      }
    }
    // Between the nodes, against the closed form (crests run along y: a slide along x).
    double patch_sq = 0.0, linear_sq = 0.0;
    for (const double dx : {-0.7e-3, -0.5e-3, -0.3e-3, -0.1e-3, 0.1e-3, 0.3e-3, 0.5e-3, 0.7e-3}) {
      double unused = 0.0;
      const double truth = std::max(ClosedFormDepth(x0 + dx, z0, unused), 0.0);
      Twist dq;
      dq.linear = {dx, 0.0, 0.0};
      // The depth that pushes (a separated pose pushes with nothing however far apart: the
      // 0.4 mm nodes do not hold the trough between two crests' maxima, 0.2 mm wide).
      const double with = std::max(ContactDepthAt(c, dq), 0.0);
      const double without = std::max(ContactDepthAt(plain.refined, dq), 0.0);
      patch_sq += (with - truth) * (with - truth);
      linear_sq += (without - truth) * (without - truth);
      std::printf("x0 %+.2f mm dx %+.1f mm: closed form %.2f µm, patch %.2f µm, linear %.2f µm\n",
                  x0 * 1e3, dx * 1e3, truth * 1e6, with * 1e6, without * 1e6);
    }
    const double patch_rms = std::sqrt(patch_sq / 8.0), linear_rms = std::sqrt(linear_sq / 8.0);
    EXPECT_LT(patch_rms, 0.25 * linear_rms) << "x0 " << x0;
    EXPECT_LT(patch_rms, 2e-6) << "x0 " << x0;
  }
  // A patch with a non-finite node is not read: the planes alone.
  const Refined r = LinearizeAndRefine(tool, CurvedToolPose(0.15e-3, 10e-6), env, n, with_patch);
  ContactLinearization broken = r.refined;
  broken.patch.depth_m[3] = std::numeric_limits<float>::quiet_NaN();
  ContactLinearization none = r.refined;
  none.patch.step_m = 0.0;
  Twist dq;
  dq.linear = {0.5e-3, 0.2e-3, -1e-6};
  EXPECT_EQ(ContactDepthAt(broken, dq), ContactDepthAt(none, dq));
  EXPECT_NE(ContactDepthAt(r.refined, dq), ContactDepthAt(none, dq));
}

// DepthRefinementOptions::translation_patch_spacing_cells: nodes m cells apart, each the refined
// depth at the tool translated there (searched, not the rendered samples, which lie one cell
// away), so that the patch spans ±2m cells; the model passes its nodes (the contact's secant is
// not the nodes' central difference here, and is what the patch's residual is taken from one
// node on), and δ and ∇δ at q0 are the contact's own.
TEST(DepthRefinement, APatchTwoCellsApartHoldsItsNodesTwiceAsFar) {
  const HapticModel tool = CurvedTool();
  const HapticModel env = EnvironmentBox(Sinusoid, 1024);
  DepthRefinementOptions wide;
  wide.translation_patch = true;
  wide.translation_patch_spacing_cells = 2;
  constexpr int n = 50;
  const double h = 2.0 * 0.02 / n;
  constexpr int R = kTranslationPatchRadius;
  const double x0 = 0.55e-3;
  double at = 0.0;
  const double z0 = ClosedFormDepth(x0, 0.0, at) - 15e-6;
  const Refined plain = LinearizeAndRefine(tool, CurvedToolPose(x0, z0), env, n);
  const ContactLinearization c =
      LinearizeAndRefine(tool, CurvedToolPose(x0, z0), env, n, wide).refined;
  ASSERT_EQ(c.patch.step_m, h);
  EXPECT_EQ(c.depth_m, plain.refined.depth_m);
  EXPECT_EQ(c.gradient.d_translation_W, plain.refined.gradient.d_translation_W);
  PenetrationGradient g0;
  EXPECT_DOUBLE_EQ(ContactDepthAt(c, Twist{}, &g0), c.depth_m);
  EXPECT_NEAR(glm::length(g0.d_translation_W - c.gradient.d_translation_W), 0.0, 1e-12);
  for (int j = -R; j <= R; ++j) {
    for (int i = -R; i <= R; ++i) {
      const double node = c.depth_m + c.patch.depth_m[PatchIndex(i, j)];
      EXPECT_NEAR(node, RefinedDepthAtNode(tool, env, n, x0, z0, i, j, h), 0.3e-6)
          << "node " << i << ", " << j;
      Twist dq;
      dq.linear = {i * h, j * h, 0.0};
      EXPECT_NEAR(ContactDepthAt(c, dq), node, 1e-9) << "the model passes its nodes";
    }
  }
  DepthRefinementOptions bad = wide;
  for (const int cells : {0, kMaxTranslationPatchSpacing + 1}) {
    bad.translation_patch_spacing_cells = cells;
    EXPECT_THROW(DepthRefiner{bad}, std::invalid_argument) << cells;
  }
}

// Past the patch's edge (±R·h) the model holds instead of carrying a ridge's slope on: the in-plane
// slope fades from the interpolant's at the edge to zero within a node spacing. Against the
// closed form, however far the tool slides along x, the depth stays within the sinusoid's own
// range plus that fade, where the tangent carried on from the edge is off by more; and the
// gradient the loop gets is the derivative of the depth it gets through the edge and beyond,
// along x and, past the edge along x, along y too (the cross term): a conservative field whose
// force has no step at the edge.
TEST(DepthRefinement, PastThePatchsEdgeTheDepthHoldsInsteadOfCarryingTheSlopeOn) {
  const HapticModel tool = CurvedTool();
  const HapticModel env = EnvironmentBox(Sinusoid, 1024);
  DepthRefinementOptions with_patch;
  with_patch.translation_patch = true;
  constexpr int n = 50;
  const double h = 0.02 / n;
  const double edge = kTranslationPatchRadius * h;
  double held_sq = 0.0, carried_sq = 0.0;
  for (const double x0 : {0.15e-3, 0.55e-3, -0.4e-3}) {
    double at = 0.0;
    const double z0 = ClosedFormDepth(x0, 0.0, at) - 15e-6;
    const ContactLinearization c =
        LinearizeAndRefine(tool, CurvedToolPose(x0, z0), env, n, with_patch).refined;
    ASSERT_EQ(c.patch.step_m, h);
    const auto depth = [&](double dx, double dy, PenetrationGradient* g = nullptr) {
      Twist dq;
      dq.linear = {dx, dy, 0.0};
      return ContactDepthAt(c, dq, g);
    };
    for (const double side : {-1.0, 1.0}) {
      const double at_edge = depth(side * edge, 0.0);
      const double held = depth(side * (edge + h), 0.0);
      for (const double dx : {1.5e-3, 2.5e-3, 4e-3, 20e-3}) {
        EXPECT_NEAR(depth(side * dx, 0.0), held, 1e-9) << "x0 " << x0 << " dx " << side * dx;
        double unused = 0.0;
        const double truth = ClosedFormDepth(x0 + side * dx, z0, unused);
        if (dx > 5e-3) continue;
        EXPECT_LT(std::abs(depth(side * dx, 0.0) - truth), 3.0 * kA)
            << "x0 " << x0 << " dx " << side * dx;
        const double carried =
            at_edge + c.gradient.d_translation_W.x * side * (dx - edge);  // the tangent, on
        held_sq += (depth(side * dx, 0.0) - truth) * (depth(side * dx, 0.0) - truth);
        carried_sq += (carried - truth) * (carried - truth);
        std::printf("x0 %+.2f mm dx %+.1f mm: closed form %.1f µm, held %.1f µm, carried %.1f µm\n",
                    x0 * 1e3, side * dx * 1e3, truth * 1e6, depth(side * dx, 0.0) * 1e6,
                    carried * 1e6);
      }
      // The gradient against central differences, either side of the edge and past the fade.
      for (const double dx : {edge - 0.05e-3, edge - 1e-6, edge + 1e-6, edge + 0.04e-3,
                              edge + 0.2e-3, edge + h - 1e-6, edge + h + 0.1e-3}) {
        for (const double dy : {0.0, 0.3e-3}) {
          PenetrationGradient g;
          depth(side * dx, dy, &g);
          const double e = 1e-7;
          EXPECT_NEAR(g.d_translation_W.x,
                      (depth(side * dx + e, dy) - depth(side * dx - e, dy)) / (2.0 * e), 1e-5)
              << "x0 " << x0 << " dx " << side * dx << " dy " << dy;
          EXPECT_NEAR(g.d_translation_W.y,
                      (depth(side * dx, dy + e) - depth(side * dx, dy - e)) / (2.0 * e), 1e-5)
              << "x0 " << x0 << " dx " << side * dx << " dy " << dy;
        }
      }
      // No step in the slope at the edge.
      PenetrationGradient in, out;
      depth(side * (edge - 1e-9), 0.0, &in);
      depth(side * (edge + 1e-9), 0.0, &out);
      EXPECT_NEAR(in.d_translation_W.x, out.d_translation_W.x, 1e-5) << "x0 " << x0;
    }
  }
  EXPECT_LT(held_sq, 0.25 * carried_sq)
      << "held against the tangent carried on from the edge, RMS over the slides: the test tells "
         "the two apart";
}

// The patch's lever (DepthRefinementOptions::translation_patch_follows_rotation): a turn Δθ
// reads the patch at the contact's slide Δθ × lever. Two routes: the residual of a turn equals
// the residual of that slide as a translation, and the gradient the loop gets is the derivative
// of the depth it gets (central differences, away from the nodes, where the bicubic's curvature
// jumps, and inside the patch's edge).
TEST(DepthRefinement, APatchWithALeverIsReadWhereATurnSlidesTheContact) {
  const HapticModel tool = CurvedTool();
  const HapticModel env = EnvironmentBox(Sinusoid, 1024);
  DepthRefinementOptions o;
  o.translation_patch = true;
  o.translation_patch_follows_rotation = true;
  const double x0 = 0.55e-3;
  double at = 0.0;
  const double z0 = ClosedFormDepth(x0, 0.0, at) - 15e-6;
  const ContactLinearization c =
      LinearizeAndRefine(tool, CurvedToolPose(x0, z0), env, 50, o).refined;
  ASSERT_GT(c.patch.step_m, 0.0);
  // The refined point (on the window plane) less the tool's centre of mass.
  EXPECT_NEAR(glm::length(c.patch.lever_W - (c.point_W - CurvedToolPose(x0, z0).translation)), 0.0,
              1e-12);
  ContactLinearization c_turned = c;
  c_turned.patch.lever_W = {0.0, 0.02, -0.01};  // a contact 20 mm off the axis of a turn about z
  ContactLinearization no_lever = c_turned;
  no_lever.patch.lever_W = glm::dvec3(0.0);
  const auto linear = [&](const Twist& dq) { return c.depth_m + c.gradient.Dot(dq); };
  for (const double turn : {-0.03, -0.01, 0.013, 0.027}) {
    Twist rot;
    rot.angular = {0.0, 0.0, turn};
    Twist slide;
    slide.linear = glm::cross(rot.angular, c_turned.patch.lever_W);
    EXPECT_NEAR(ContactDepthAt(c_turned, rot) - linear(rot),
                ContactDepthAt(no_lever, slide) - linear(slide), 1e-12)
        << turn;
    EXPECT_NE(ContactDepthAt(c_turned, rot), linear(rot)) << "the slide crosses the ridges";
    // The gradient against central differences, about z and along x.
    PenetrationGradient g;
    ContactDepthAt(c_turned, rot, &g);
    const double e = 1e-7;
    Twist up = rot, down = rot;
    up.angular.z += e;
    down.angular.z -= e;
    EXPECT_NEAR(g.d_rotation_W.z,
                (ContactDepthAt(c_turned, up) - ContactDepthAt(c_turned, down)) / (2.0 * e), 1e-6)
        << turn;
    up = rot;
    down = rot;
    up.linear.x += e;
    down.linear.x -= e;
    EXPECT_NEAR(g.d_translation_W.x,
                (ContactDepthAt(c_turned, up) - ContactDepthAt(c_turned, down)) / (2.0 * e), 1e-6)
        << turn;
  }
}

TEST(DepthRefinement, OptionsOutOfRangeAreRefused) {
  DepthRefinementOptions o;
  o.max_subsamples = 0;
  EXPECT_THROW(DepthRefiner{o}, std::invalid_argument);
  o = {};
  o.search_floor_texels = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(DepthRefiner{o}, std::invalid_argument);
  o = {};
  o.screen_tolerance_m = -1e-6;
  EXPECT_THROW(DepthRefiner{o}, std::invalid_argument);
  o = {};
  o.max_screen_leaves = 0;
  EXPECT_THROW(DepthRefiner{o}, std::invalid_argument);
  o = {};
  o.parallax = true;
  o.conservative_screen = true;
  EXPECT_THROW(DepthRefiner{o}, std::invalid_argument);
  o = {};
  o.parallax_iterations = 0;
  EXPECT_THROW(DepthRefiner{o}, std::invalid_argument);
  o = {};
  o.translation_patch_spacing_cells = 0;
  EXPECT_THROW(DepthRefiner{o}, std::invalid_argument);
  o.translation_patch_spacing_cells = kMaxTranslationPatchSpacing + 1;
  EXPECT_THROW(DepthRefiner{o}, std::invalid_argument);
}

}  // namespace
}  // namespace ht

namespace ht {
namespace {

// HeightField::LossAtLevel (issue 32, `slave_sim inspect`'s texture_detail): a smooth sinusoid
// of 64 texels' period loses little at half the size and more at each further halving, where
// texel-scale noise loses most of its amplitude at once; level 0 loses nothing.
TEST(TextureDetail, LossAtLevelGrowsWithTheDetailTheLevelCannotHold) {
  const int n = 256;
  std::vector<float> smooth(static_cast<std::size_t>(n) * n), noise(smooth.size());
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> U(-1e-5f, 1e-5f);
  for (int y = 0; y < n; ++y) {
    for (int x = 0; x < n; ++x) {
      smooth[static_cast<std::size_t>(y) * n + x] =
          static_cast<float>(1e-4 * std::sin(2.0 * std::numbers::pi * (x + 0.5) / 64.0));
      noise[static_cast<std::size_t>(y) * n + x] = U(rng);
    }
  }
  const HeightField s(n, n, smooth, true, true), r(n, n, noise, true, true);
  EXPECT_EQ(s.LossAtLevel(0).max_m, 0.0);
  double previous = 0.0;
  for (int level = 1; level <= 3; ++level) {
    const HeightField::LevelLoss loss = s.LossAtLevel(level);
    EXPECT_GT(loss.max_m, previous) << level;
    EXPECT_LE(loss.rms_m, loss.max_m) << level;
    previous = loss.max_m;
  }
  EXPECT_LT(s.LossAtLevel(1).rms_m, 0.02 * 1e-4);                  // 2 % of the amplitude at 128²
  EXPECT_GT(r.LossAtLevel(1).rms_m, 0.3 * 1e-5 / std::sqrt(3.0));  // noise: most of its RMS
  EXPECT_EQ(s.LossAtLevel(99).max_m, 0.0);                         // outside the chain
  EXPECT_EQ(HeightField().LossAtLevel(1).rms_m, 0.0);
}

}  // namespace
}  // namespace ht
