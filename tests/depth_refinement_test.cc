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

Refined LinearizeAndRefine(const HapticModel& tool, const RigidTransform& X_WT,
                           const HapticModel& env, int n, DepthRefinementOptions options = {}) {
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

// The last step's seeds: the narrow peak of the test above, hidden from the whole window's
// filtered grid, found on a step whose window holds it alone, is kept on the next step over the
// whole window; a refiner without a last step stays on the hump.
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
  DepthRefiner seeded{DepthRefinementOptions{}}, alone{DepthRefinementOptions{}};
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

// Parallax (DepthRefinementOptions::parallax, docs/DESIGN.md §4): the
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

// Seeds carried by parallax: a Gaussian bump of 0.8 mm on a facet tilted 50°, under the tool's flat
// face tilted alike, 60 µm into the bump along the facet's normal. Along the window's n = z the two
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
  DepthRefiner refiner{DepthRefinementOptions{}};
  ContactLinearization lin = c.grid;
  std::vector<DepthSample> s = c.samples;
  refiner.Refine(tool, X_WT, q, s, lin);
  std::printf("bump on a 50 deg facet: delta %.1f um (closed form %.1f um), %llu carried seeds\n",
              lin.depth_m * 1e6, expected * 1e6,
              static_cast<unsigned long long>(refiner.counters().parallax_offset_seeds));
  EXPECT_GT(refiner.counters().parallax_offset_seeds, 0u);
  EXPECT_GT(refiner.counters().parallax_offset_found, 0u);
  EXPECT_NEAR(lin.depth_m, expected, 3e-6);
  // Without parallax no seed is carried: the render's form alone.
  DepthRefinementOptions plain;
  plain.parallax = false;
  DepthRefiner b(plain);
  ContactLinearization lb = c.grid;
  std::vector<DepthSample> sb = c.samples;
  b.Refine(tool, X_WT, q, sb, lb);
  EXPECT_EQ(b.counters().parallax_offset_seeds, 0u);
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
