// The contact model's depth field (depth_field.h): closed forms (a sphere slid across a rippled
// plate among them), the gradient against finite differences, the pruned smooth maximum against
// every node's own depth, the field against the texture stage's fresh render at displaced poses,
// fields on one lattice against each other, the cache, and no allocation in the loop's calls.

#include "haptic_core/depth_field.h"

#include <gtest/gtest.h>

#include <cmath>
#include <glm/gtc/quaternion.hpp>
#include <limits>
#include <random>

#include "allocation_counter.h"
#include "haptic_core/penetration_depth.h"
#include "test_scenes.h"

namespace ht {
namespace {

using testing_support::Allocations;

constexpr double kPi = 3.14159265358979323846;

/// A field on an n×n grid of spacing h with frame F at X_WF, its maps from callbacks (NaN: none),
/// the tool at X_WT0, prepared.
DepthField MakeField(int n, double h, const RigidTransform& X_WF, const RigidTransform& X_WT0,
                     double (*env)(double, double), double (*tool)(double, double),
                     double margin_m = 1e-3) {
  DepthField f;
  f.id = 7;
  f.X_WF = X_WF;
  f.cell_m = h;
  f.nx = f.ny = n;
  f.X_WT0 = X_WT0;
  f.travel_margin_m = margin_m;
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      f.env_height_m.push_back(static_cast<float>(env(i * h, j * h)));
      f.tool_height_m.push_back(static_cast<float>(tool(i * h, j * h)));
    }
  }
  EXPECT_TRUE(f.Prepare());
  return f;
}

RigidTransform TurnedFrame() {
  RigidTransform X;
  X.translation = {0.1, -0.05, 0.02};
  X.rotation = glm::normalize(glm::dquat(0.9, 0.2, -0.3, 0.1));
  return X;
}

constexpr int kN = 40;
constexpr double kH = 0.5e-3;
constexpr double kD = 50e-6;  // the flat face's overlap with the flat plate (m)

double Flat(double, double) { return 0.0; }
// A 10 mm square face 50 µm into the plate, on nodes 10..29.
double FaceInto(double x, double y) {
  const double lo = 10 * kH - 1e-9, hi = 29 * kH + 1e-9;
  return x >= lo && x <= hi && y >= lo && y <= hi ? -kD : std::nan("");
}

// The tool's centre of mass 5 mm above the face's centre, along z_F.
RigidTransform ToolAboveFace(const RigidTransform& X_WF) {
  RigidTransform X_WT;
  X_WT.translation = X_WF * glm::dvec3(19.5 * kH, 19.5 * kH, 5e-3);
  X_WT.rotation = X_WF.rotation;
  return X_WT;
}

TEST(DepthField, FlatFaceOnFlatPlateReadsItsOverlapPushesAlongTheNormalAndFollowsThePress) {
  const RigidTransform X_WF = TurnedFrame();
  const RigidTransform X_WT0 = ToolAboveFace(X_WF);
  const DepthField f = MakeField(kN, kH, X_WF, X_WT0, Flat, FaceInto);
  const glm::dvec3 n_W = X_WF.rotation * glm::dvec3(0, 0, 1);
  const DepthFieldEvaluation e = DepthFieldDepthAt(f, X_WT0);
  ASSERT_TRUE(e.valid);
  // The smooth maximum of 400 tied nodes: within [max, max + ε ln 400].
  EXPECT_GE(e.depth_m, kD - 1e-9);
  EXPECT_LE(e.depth_m, kD + f.smooth_max_m * std::log(400.0) + 1e-9);
  EXPECT_NEAR(glm::length(e.gradient.d_translation_W + n_W), 0.0, 1e-6);
  // Centred under the centre of mass: no lever.
  EXPECT_NEAR(glm::length(e.gradient.d_rotation_W), 0.0, 1e-6);
  // Pressed 100 µm further along −n: the depth grows by exactly that; slid 0.7 mm in the plane
  // over the flat plate: unchanged.
  RigidTransform pressed = X_WT0;
  pressed.translation -= 100e-6 * n_W;
  EXPECT_NEAR(DepthFieldDepthAt(f, pressed).depth_m - e.depth_m, 100e-6, 1e-9);
  RigidTransform slid = X_WT0;
  slid.translation += 0.7e-3 * (X_WF.rotation * glm::dvec3(0.6, 0.8, 0.0));
  EXPECT_NEAR(DepthFieldDepthAt(f, slid).depth_m, e.depth_m, 1e-9);
}

TEST(DepthField, TiltedFaceSumsItsMovedNodesAsTheirSmoothMaximumAndLevers) {
  // The second route: every face node moved rigidly with the tool over the flat plate (b = 0
  // exactly, so the interpolant is exact), their smooth maximum and softmax-weighted levers.
  const RigidTransform X_WF = TurnedFrame();
  const RigidTransform X_WT0 = ToolAboveFace(X_WF);
  const DepthField f = MakeField(kN, kH, X_WF, X_WT0, Flat, FaceInto);
  const double eps = f.smooth_max_m;
  for (const double theta : {0.5e-3, 2e-3, -5e-3, 10e-3}) {
    const glm::dvec3 axis_W = X_WF.rotation * glm::normalize(glm::dvec3(1.0, 0.4, 0.0));
    const RigidTransform X_WT = Displace(X_WT0, Twist{glm::dvec3(0.0), theta * axis_W});
    const RigidTransform D = X_WF.Inverse() * X_WT * X_WT0.Inverse() * X_WF;
    const glm::dvec3 c_F = X_WF.Inverse() * X_WT.translation;
    double deepest = -1.0;
    for (int j = 10; j <= 29; ++j) {
      for (int i = 10; i <= 29; ++i)
        deepest = std::max(deepest, -(D * glm::dvec3(i * kH, j * kH, -kD)).z);
    }
    // Every node within 10 ε of the deepest weighs in (the core); those below may be skipped
    // (the tail): the field's δ lies between the core's smooth maximum and the whole's, and its
    // lever within the tail's share of the weights (times the largest lever) of the core's.
    double core = 0.0, tail = 0.0, largest_lever = 0.0;
    glm::dvec3 torque_F{0.0};
    for (int j = 10; j <= 29; ++j) {
      for (int i = 10; i <= 29; ++i) {
        const glm::dvec3 s = D * glm::dvec3(i * kH, j * kH, -kD);
        const double w = std::exp((-s.z - deepest) / eps);
        const glm::dvec3 lever = glm::cross(s - c_F, glm::dvec3(0.0, 0.0, -1.0));
        largest_lever = std::max(largest_lever, glm::length(lever));
        if (-s.z >= deepest - 10.0 * eps) {
          core += w;
          torque_F += w * lever;
        } else {
          tail += w;
        }
      }
    }
    const DepthFieldEvaluation e = DepthFieldDepthAt(f, X_WT);
    ASSERT_TRUE(e.valid) << theta;
    EXPECT_NEAR(e.max_node_depth_m, deepest, 1e-10) << theta;  // a float map
    EXPECT_GE(e.depth_m, deepest + eps * std::log(core) - 1e-10) << theta;
    EXPECT_LE(e.depth_m, deepest + eps * std::log(core + tail) + 1e-10) << theta;
    const glm::dvec3 expected_W = X_WF.rotation * (torque_F / core);
    EXPECT_LE(glm::length(e.gradient.d_rotation_W - expected_W),
              2.0 * largest_lever * tail / core + 1e-9)
        << theta;
    // The lowest corner bears more as the tilt grows: the lever about the axis grows towards the
    // face's half diagonal's.
  }
}

constexpr double kAmplitude = 100e-6, kPeriod = 4e-3;
double Sinusoid(double x, double) { return kAmplitude * std::sin(2.0 * kPi * x / kPeriod); }
// One tool node, at grid node (20, 20), 30 µm below the sinusoid's mean.
double PointTool(double x, double y) {
  return std::abs(x - 20 * kH) < 1e-9 && std::abs(y - 20 * kH) < 1e-9 ? -30e-6 : std::nan("");
}

TEST(DepthField, PointSlidOverASinusoidReadsItsHeightAndSlopeBetweenNodes) {
  const RigidTransform X_WF = TurnedFrame();
  RigidTransform X_WT0;
  X_WT0.translation = X_WF * glm::dvec3(20 * kH, 20 * kH, 3e-3);
  X_WT0.rotation = X_WF.rotation;
  const DepthField f = MakeField(kN, kH, X_WF, X_WT0, Sinusoid, PointTool, 6e-3);
  const glm::dvec3 x_W = X_WF.rotation * glm::dvec3(1, 0, 0);
  double largest_error = 0.0, largest_slope_error = 0.0;
  for (double dx = -3e-3; dx <= 3e-3; dx += 0.123e-3) {
    RigidTransform X_WT = X_WT0;
    X_WT.translation += dx * x_W;
    const DepthFieldEvaluation e = DepthFieldDepthAt(f, X_WT);
    ASSERT_TRUE(e.valid);
    const double x = 20 * kH + dx;
    const double truth = kAmplitude * std::sin(2.0 * kPi * x / kPeriod) + 30e-6;
    const double slope = kAmplitude * 2.0 * kPi / kPeriod * std::cos(2.0 * kPi * x / kPeriod);
    largest_error = std::max(largest_error, std::abs(e.depth_m - truth));
    largest_slope_error =
        std::max(largest_slope_error, std::abs(glm::dot(e.gradient.d_translation_W, x_W) - slope));
  }
  // Catmull–Rom at 8 nodes a period: within 1 % of the amplitude, the slope within 10 % of its
  // largest (2π·A/λ = 0.157; measured 8 %: the interpolant's slope is a cubic's, coarser than
  // its value).
  EXPECT_LT(largest_error, 0.01 * kAmplitude);
  EXPECT_LT(largest_slope_error, 0.10 * 2.0 * kPi * kAmplitude / kPeriod);
}

// A rough environment and a rough tool face (smooth enough between nodes for a finite difference).
double Rough(double x, double y) {
  return 40e-6 * std::sin(1700.0 * x + 0.3) * std::cos(2300.0 * y) + 15e-6 * std::sin(5100.0 * y);
}
double RoughFace(double x, double y) {
  const double lo = 8 * kH - 1e-9, hi = 31 * kH + 1e-9;
  if (!(x >= lo && x <= hi && y >= lo && y <= hi)) return std::nan("");
  return -30e-6 + 20e-6 * std::cos(2900.0 * x) * std::sin(1100.0 * y + 1.0);
}

// Rough with holes: no surface at every 5th node along x in rows 12..27 (under the face).
double RoughWithHoles(double x, double y) {
  const int i = static_cast<int>(std::lround(x / kH)), j = static_cast<int>(std::lround(y / kH));
  if (j >= 12 && j <= 27 && i % 5 == 2) return std::nan("");
  return Rough(x, y);
}

TEST(DepthField, GradientIsTheDerivativeOfTheDepthAlongEachOfTheSixAxes) {
  const RigidTransform X_WF = TurnedFrame();
  const RigidTransform X_WT0 = ToolAboveFace(X_WF);
  const DepthField f = MakeField(kN, kH, X_WF, X_WT0, Rough, RoughFace, 3e-3);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int trial = 0; trial < 20; ++trial) {
    const Twist dq{glm::dvec3(u(rng), u(rng), u(rng)) * 0.6e-3,
                   glm::dvec3(u(rng), u(rng), u(rng)) * 8e-3};
    const RigidTransform X_WT = Displace(X_WT0, dq);
    const DepthFieldEvaluation e = DepthFieldDepthAt(f, X_WT);
    ASSERT_TRUE(e.valid);
    const double g[6] = {e.gradient.d_translation_W.x, e.gradient.d_translation_W.y,
                         e.gradient.d_translation_W.z, e.gradient.d_rotation_W.x,
                         e.gradient.d_rotation_W.y,    e.gradient.d_rotation_W.z};
    for (int k = 0; k < 6; ++k) {
      const double step = k < 3 ? 1e-8 : 1e-7;
      Twist d{};
      if (k < 3)
        d.linear[k] = step;
      else
        d.angular[k - 3] = step;
      Twist dm{};
      if (k < 3)
        dm.linear[k] = -step;
      else
        dm.angular[k - 3] = -step;
      const double fd = (DepthFieldDepthAt(f, Displace(X_WT, d)).depth_m -
                         DepthFieldDepthAt(f, Displace(X_WT, dm)).depth_m) /
                        (2.0 * step);
      const double scale = k < 3 ? 1.0 : 0.01;  // m/m; m/rad over a 1 cm lever
      EXPECT_NEAR(g[k], fd, 1e-4 * scale) << "trial " << trial << " axis " << k;
    }
  }
}

TEST(DepthField, PrunedSmoothMaximumEqualsTheSumOverEveryNodeAlone) {
  const RigidTransform X_WF = TurnedFrame();
  const RigidTransform X_WT0 = ToolAboveFace(X_WF);
  DepthField f = MakeField(kN, kH, X_WF, X_WT0, Rough, RoughFace, 3e-3);
  // A wide ε (many nodes weigh, none is pruned) and the default (the bound prunes).
  for (const double eps : {8e-6, kDepthFieldSmoothMaxM}) {
    f.smooth_max_m = eps;
    ASSERT_TRUE(f.Prepare());
    const RigidTransform X_WT =
        Displace(X_WT0, Twist{glm::dvec3(0.3e-3, -0.2e-3, 0.0), glm::dvec3(2e-3, 1e-3, 4e-3)});
    const DepthFieldEvaluation whole = DepthFieldDepthAt(f, X_WT);
    // The second route: a field per tool node (the same environment), each its node's δ_j.
    DepthField one = f;
    double m = -1.0;
    std::vector<double> depths;
    for (std::size_t k = 0; k < f.tool_height_m.size(); ++k) {
      if (!std::isfinite(f.tool_height_m[k])) continue;
      std::fill(one.tool_height_m.begin(), one.tool_height_m.end(), std::nanf(""));
      one.tool_height_m[k] = f.tool_height_m[k];
      ASSERT_TRUE(one.Prepare());
      const DepthFieldEvaluation e = DepthFieldDepthAt(one, X_WT);
      if (!std::isfinite(e.depth_m)) continue;
      depths.push_back(e.depth_m);  // ε·ln(exp(δ_j/ε)) = δ_j
      m = std::max(m, e.depth_m);
    }
    double sum = 0.0;
    for (const double d : depths) sum += std::exp((d - m) / f.smooth_max_m);
    // The nodes the bound skipped lie more than 10 ε below the maximum: together they lower δ by
    // at most ε·ln(1 + M·e^−10), M of them.
    const double skipped = static_cast<double>(depths.size()) - whole.nodes_evaluated;
    const double skipped_bound = f.smooth_max_m * std::log1p(skipped * std::exp(-10.0));
    EXPECT_LE(whole.depth_m, m + f.smooth_max_m * std::log(sum) + 1e-10) << eps;
    EXPECT_GE(whole.depth_m, m + f.smooth_max_m * std::log(sum) - skipped_bound - 1e-10) << eps;
    EXPECT_NEAR(whole.max_node_depth_m, m, 1e-12) << eps;
    if (eps == kDepthFieldSmoothMaxM) {
      EXPECT_LT(whole.nodes_evaluated, static_cast<int>(depths.size()));  // the bound pruned some
    }
  }
}

// Two routes to one evaluation: the nodes one at a time (kScalar) and four at a time in AVX2
// lanes (kAvx2), which take the same nodes (each tested against the running maximum as it stands
// at that node) and sum them in another order: depth, gradient and curvature agree to rounding,
// at poses that slide, press and tilt the rough face, with a wide and the default ε.
TEST(DepthField, TheAvx2KernelSumsWhatTheScalarOneSums) {
  if (!DepthFieldKernelAvailable(DepthFieldKernel::kAvx2)) {
    GTEST_SKIP() << "this CPU lacks AVX2 and FMA: only the scalar kernel runs";
  }
  const RigidTransform X_WF = TurnedFrame();
  const RigidTransform X_WT0 = ToolAboveFace(X_WF);
  std::mt19937 rng(41);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  int compared = 0;
  // The rough plate whole, and with holes under the face (the environment has no surface at
  // some nodes: a node whose bicubic reads one has no depth, and must add nothing, not NaN).
  for (const bool holes : {false, true}) {
    DepthField f = MakeField(kN, kH, X_WF, X_WT0, holes ? RoughWithHoles : Rough, RoughFace, 3e-3);
    for (const double eps : {8e-6, kDepthFieldSmoothMaxM}) {
      f.smooth_max_m = eps;
      ASSERT_TRUE(f.Prepare());
      for (int k = 0; k < 200; ++k) {
        const RigidTransform X_WT =
            Displace(X_WT0, Twist{glm::dvec3(u(rng) * 1e-3, u(rng) * 1e-3, u(rng) * 30e-6),
                                  glm::dvec3(u(rng), u(rng), u(rng)) * 5e-3});
        const DepthFieldEvaluation a = DepthFieldDepthAt(f, X_WT, DepthFieldKernel::kScalar);
        const DepthFieldEvaluation b = DepthFieldDepthAt(f, X_WT, DepthFieldKernel::kAvx2);
        ASSERT_EQ(a.valid, b.valid);
        EXPECT_EQ(a.within_margin, b.within_margin);
        EXPECT_GE(b.nodes_tested, a.nodes_tested);
        EXPECT_GE(b.nodes_evaluated, a.nodes_evaluated);
        if (!std::isfinite(a.depth_m)) {
          EXPECT_FALSE(std::isfinite(b.depth_m));
          continue;
        }
        ++compared;
        EXPECT_NEAR(b.depth_m, a.depth_m, 1e-12) << k;
        EXPECT_NEAR(b.max_node_depth_m, a.max_node_depth_m, 1e-15) << k;  // FMA rounding
        EXPECT_LT(glm::length(b.gradient.d_translation_W - a.gradient.d_translation_W), 1e-9) << k;
        EXPECT_LT(glm::length(b.gradient.d_rotation_W - a.gradient.d_rotation_W), 1e-11) << k;
        // The curvature is a covariance over ε, (E[J·Jᵀ] − E[J]·E[J]ᵀ)/ε: where the nodes'
        // gradients nearly agree it cancels, and the sums' rounding (relative to E[J·Jᵀ] ~ |∇δ|²)
        // shows.
        const double g2 = glm::dot(a.gradient.d_translation_W, a.gradient.d_translation_W);
        EXPECT_LE((b.curvature - a.curvature).norm(),
                  1e-6 * (1.0 + a.curvature.norm()) + 1e-9 * (1.0 + g2) / eps)
            << k;
        EXPECT_TRUE(std::isfinite(b.gradient.d_translation_W.x) &&
                    std::isfinite(b.gradient.d_rotation_W.z) && std::isfinite(b.curvature.sum()))
            << holes << " " << k;
      }
    }
  }
  EXPECT_GT(compared, 600);
}

// A flat face on a flat plate puts every node of the face at the deepest depth: 100² nodes, more
// than a field keeps (kDepthFieldDenseNodes). Prepare keeps every 4th node of the tool's lattice
// along each axis (every 2nd would leave 2,500), and the evaluation is the closed form over
// them: the smooth maximum of 625 tied nodes, kD + ε·ln 625, pushing along −n.
double BigFlatFace(double x, double y) {
  return x >= 5 * kH - 1e-9 && x <= 104 * kH + 1e-9 && y >= 5 * kH - 1e-9 && y <= 104 * kH + 1e-9
             ? -kD
             : std::nan("");
}

TEST(DepthField, ADenseFieldKeepsEveryFewNodesOfItsLatticeAndReadsThemAsTheClosedForm) {
  const RigidTransform X_WF = TurnedFrame();
  RigidTransform X_WT0;
  X_WT0.translation = X_WF * glm::dvec3(54.5 * kH, 54.5 * kH, 5e-3);
  X_WT0.rotation = X_WF.rotation;
  const DepthField big = MakeField(110, kH, X_WF, X_WT0, Flat, BigFlatFace);
  EXPECT_EQ(big.node_stride, 4);
  // The kept grid is the tool's map at every 4th node; the map itself is left whole.
  ASSERT_EQ(big.tool_nx, 28);
  ASSERT_EQ(big.tool_ny, 28);
  int kept = 0;
  for (int q = 0; q < big.tool_ny; ++q) {
    for (int p = 0; p < big.tool_nx; ++p) {
      const float a = big.tool_grid_m[static_cast<std::size_t>(q * big.tool_nx + p)];
      EXPECT_EQ(std::isfinite(a), std::isfinite(BigFlatFace(4 * p * kH, 4 * q * kH)));
      kept += std::isfinite(a) ? 1 : 0;
    }
  }
  int whole = 0;
  for (const float a : big.tool_height_m) whole += std::isfinite(a) ? 1 : 0;
  EXPECT_EQ(whole, 100 * 100);
  ASSERT_EQ(kept, 625);
  const DepthFieldEvaluation e = DepthFieldDepthAt(big, X_WT0);
  ASSERT_TRUE(e.valid);
  EXPECT_EQ(e.nodes_evaluated, kept);
  EXPECT_NEAR(e.depth_m, kD + big.smooth_max_m * std::log(static_cast<double>(kept)), 1e-9);
  const glm::dvec3 n_W = X_WF.rotation * glm::dvec3(0, 0, 1);
  EXPECT_NEAR(glm::length(e.gradient.d_translation_W + n_W), 0.0, 1e-6);
  // The kept nodes follow the tool's lattice: at lattice coordinates (i − 3, j + 5), nodes
  // 3, 7, 11, … along both axes, 25 of them on the face each way.
  DepthField shifted = MakeField(110, kH, X_WF, X_WT0, Flat, BigFlatFace);
  shifted.tool_lattice_i0 = -3;
  shifted.tool_lattice_j0 = 5;
  ASSERT_TRUE(shifted.Prepare());
  EXPECT_EQ(shifted.node_stride, 4);
  EXPECT_EQ(shifted.tool_i0, 3);
  EXPECT_EQ(shifted.tool_j0, 3);
  const DepthFieldEvaluation es = DepthFieldDepthAt(shifted, X_WT0);
  EXPECT_EQ(es.nodes_evaluated, 625);
  EXPECT_NEAR(es.depth_m, kD + shifted.smooth_max_m * std::log(625.0), 1e-9);
  // Coordinates off the wire at the ends of their range align without overflow.
  shifted.tool_lattice_i0 = std::numeric_limits<std::int32_t>::min();
  shifted.tool_lattice_j0 = std::numeric_limits<std::int32_t>::max();
  ASSERT_TRUE(shifted.Prepare());
  EXPECT_EQ(shifted.tool_i0, 0);
  EXPECT_EQ(shifted.tool_j0, 1);
  // A field that fits is kept whole.
  const DepthField small = MakeField(kN, kH, X_WF, ToolAboveFace(X_WF), Flat, FaceInto);
  EXPECT_EQ(small.node_stride, 1);
}

// The same face tilted by 0.1 over the plate: at X_WT0 only the nodes along its lowest edge lie
// within the smooth maximum's cutoff, and the field is kept whole; turned level, all 100² nodes
// tie, more than the loop's budget. The evaluation stops there (the plain call computes them
// all); the cache then leaves that field alone until its slot takes another.
double TiltedBigFace(double x, double y) {
  return std::isfinite(BigFlatFace(x, y)) ? -kD - 0.1 * (x - 5 * kH) : std::nan("");
}

// A plate of pins, one node 100 µm high every 12 nodes each way, under a flat 90 mm face resting
// on them: only the cells next to a pin reach the deepest node's cutoff, so the evaluation
// computes a few nodes per pin (far fewer than kDepthFieldDenseNodes) but tests nearly every
// node, since every block's footprint reaches a pin.
double Pins(double x, double y) {
  const long i = std::lround(x / kH), j = std::lround(y / kH);
  return i % 12 == 0 && j % 12 == 0 ? 100e-6 : 0.0;
}
double BigFace(double x, double y) {
  const double lo = 10 * kH - 1e-9, hi = 189 * kH + 1e-9;
  return x >= lo && x <= hi && y >= lo && y <= hi ? 95e-6 : std::nan("");
}
TEST(DepthField, AFieldWhoseEvaluationTestsManyNodesKeepsEveryOtherNode) {
  const RigidTransform X_WF = TurnedFrame();
  RigidTransform X_WT0;
  X_WT0.translation = X_WF * glm::dvec3(99.5 * kH, 99.5 * kH, 5e-3);
  X_WT0.rotation = X_WF.rotation;
  const DepthField f = MakeField(200, kH, X_WF, X_WT0, Pins, BigFace);
  const DepthFieldEvaluation e = DepthFieldDepthAt(f, X_WT0);
  ASSERT_TRUE(e.valid);
  // The nodes computed are far below kDepthFieldDenseNodes at stride 1 too (with pins every 14
  // nodes the field keeps every node, computing 699 and testing 6,320): the tested ones decide.
  EXPECT_LT(e.nodes_evaluated, kDepthFieldDenseNodes / 4);
  EXPECT_EQ(f.node_stride, 2);
  EXPECT_LE(e.nodes_tested, kDepthFieldDenseTestedNodes);
  EXPECT_NEAR(e.max_node_depth_m, 5e-6, 1e-9);  // a pin 5 µm into the face
}

TEST(DepthField, AnEvaluationPastTheNodeBudgetStopsAndTheCacheLeavesTheFieldAlone) {
  const RigidTransform X_WF = TurnedFrame();
  RigidTransform X_WT0;
  X_WT0.translation = X_WF * glm::dvec3(54.5 * kH, 54.5 * kH, 5e-3);
  X_WT0.rotation = X_WF.rotation;
  DepthField big = MakeField(110, kH, X_WF, X_WT0, Flat, TiltedBigFace);
  EXPECT_EQ(big.node_stride, 1);
  // Turned about y_F by −atan 0.1: the face level.
  const glm::dvec3 y_W = X_WF.rotation * glm::dvec3(0, 1, 0);
  const RigidTransform level = Displace(X_WT0, Twist{glm::dvec3(0.0), -std::atan(0.1) * y_W});
  const DepthFieldEvaluation whole = DepthFieldDepthAt(big, level);
  ASSERT_TRUE(whole.valid);
  EXPECT_GT(whole.nodes_evaluated, kDepthFieldMaxNodes);
  for (const DepthFieldKernel kernel : {DepthFieldKernel::kScalar, DepthFieldKernel::kAvx2}) {
    if (!DepthFieldKernelAvailable(kernel)) continue;
    const DepthFieldEvaluation capped = DepthFieldDepthAt(big, level, kernel, 1000);
    EXPECT_TRUE(capped.over_budget);
    EXPECT_FALSE(capped.valid);
    EXPECT_LT(capped.nodes_evaluated, 1000 + 64);  // stops within a sub-block of the budget
  }
  DepthFieldCache cache(1);
  big.Reserve();
  ASSERT_TRUE(cache.Take(big, {}));
  const std::uint32_t id = 7;
  EXPECT_TRUE(cache.Evaluate(id, X_WT0).valid);
  EXPECT_TRUE(cache.Evaluate(id, level).over_budget);
  EXPECT_EQ(cache.over_budget(), 1);
  const DepthFieldEvaluation again = cache.Evaluate(id, X_WT0);
  EXPECT_TRUE(again.over_budget);
  EXPECT_EQ(again.nodes_tested, 0);  // not evaluated again
  EXPECT_EQ(cache.over_budget(), 1);
  // Another field in the slot is evaluated.
  DepthField small = MakeField(kN, kH, X_WF, ToolAboveFace(X_WF), Flat, FaceInto);
  small.id = 8;
  small.Reserve();
  ASSERT_TRUE(cache.Take(small, {}));
  EXPECT_TRUE(cache.Evaluate(8, ToolAboveFace(X_WF)).valid);
}

TEST(DepthField, SaysWhetherTheToolIsWithinItsTravelMargin) {
  const RigidTransform X_WF = TurnedFrame();
  const RigidTransform X_WT0 = ToolAboveFace(X_WF);
  const DepthField f = MakeField(kN, kH, X_WF, X_WT0, Flat, FaceInto, 1e-3);
  const glm::dvec3 in_plane_W = X_WF.rotation * glm::dvec3(0.6, 0.8, 0.0);
  const glm::dvec3 n_W = X_WF.rotation * glm::dvec3(0.0, 0.0, 1.0);
  RigidTransform X_WT = X_WT0;
  X_WT.translation += 0.9e-3 * in_plane_W;
  EXPECT_TRUE(DepthFieldDepthAt(f, X_WT).within_margin);
  X_WT.translation += 0.2e-3 * in_plane_W;
  EXPECT_FALSE(DepthFieldDepthAt(f, X_WT).within_margin);
  // Along the normal the field holds however far the tool goes.
  X_WT = X_WT0;
  X_WT.translation -= 5e-3 * n_W;
  EXPECT_TRUE(DepthFieldDepthAt(f, X_WT).within_margin);
  // A turn moves the face's far corners by θ times their distance (about 9 mm).
  EXPECT_TRUE(DepthFieldDepthAt(f, Displace(X_WT0, Twist{{}, {0.0, 0.0, 5e-4}})).within_margin);
  // Turned about the normal through the face's centre by 0.2 rad: its corners move 1.3 mm.
  const DepthFieldEvaluation turned = DepthFieldDepthAt(f, Displace(X_WT0, Twist{{}, 0.2 * n_W}));
  EXPECT_FALSE(turned.within_margin);
  EXPECT_TRUE(turned.valid);  // still evaluated: the face's nodes still over the plate
  EXPECT_NEAR(turned.max_node_depth_m, kD, 1e-9);
  DepthField unprepared;
  EXPECT_FALSE(DepthFieldDepthAt(unprepared, X_WT0).valid);
}

TEST(DepthField, PrepareRefusesABadField) {
  const RigidTransform X_WF = TurnedFrame();
  const RigidTransform X_WT0 = ToolAboveFace(X_WF);
  DepthField f = MakeField(kN, kH, X_WF, X_WT0, Flat, FaceInto);
  DepthField bad = f;
  bad.id = 0;
  EXPECT_FALSE(bad.Prepare());
  bad = f;
  bad.tool_height_m.pop_back();
  EXPECT_FALSE(bad.Prepare());
  bad = f;
  bad.travel_margin_m = std::nan("");
  EXPECT_FALSE(bad.Prepare());
  bad = f;
  bad.cell_m = 0.0;
  EXPECT_FALSE(bad.Prepare());
  bad = f;
  bad.nx = bad.ny = kMaxDepthFieldSide + 1;
  EXPECT_FALSE(bad.Prepare());
  EXPECT_FALSE(bad.prepared);
}

TEST(DepthField, CacheFindsByIdEvictsTheOldestUnkeptAndNeverAllocates) {
  const RigidTransform X_WF = TurnedFrame();
  const RigidTransform X_WT0 = ToolAboveFace(X_WF);
  const DepthField base = MakeField(kN, kH, X_WF, X_WT0, Flat, FaceInto);
  DepthFieldCache cache(2);
  std::vector<DepthField> incoming(4, base);
  for (std::uint32_t k = 0; k < 4; ++k) {
    incoming[k].id = 10 + k;
    incoming[k].Reserve();
  }
  const std::uint32_t keep[] = {10};
  const long before = Allocations();
  EXPECT_TRUE(cache.Take(incoming[0], keep));
  EXPECT_TRUE(cache.Take(incoming[1], keep));
  EXPECT_TRUE(cache.Take(incoming[2], keep));  // evicts 11, the oldest not kept
  const DepthField* f10 = cache.Find(10);
  const DepthFieldEvaluation e =
      f10 != nullptr ? DepthFieldDepthAt(*f10, X_WT0) : DepthFieldEvaluation{};
  const DepthFieldEvaluation memo1 = cache.Evaluate(10, X_WT0);
  const DepthFieldEvaluation memo2 = cache.Evaluate(10, X_WT0);  // remembered
  EXPECT_EQ(Allocations() - before, 0);
  EXPECT_EQ(memo1.depth_m, e.depth_m);
  EXPECT_EQ(memo2.depth_m, e.depth_m);
  EXPECT_FALSE(cache.Evaluate(11, X_WT0).valid);  // evicted
  ASSERT_NE(f10, nullptr);
  EXPECT_TRUE(e.valid);
  EXPECT_EQ(cache.Find(11), nullptr);
  EXPECT_NE(cache.Find(12), nullptr);
  const std::uint32_t keep_both[] = {10, 12};
  EXPECT_FALSE(cache.Take(incoming[3], keep_both));  // every slot kept
  DepthField unprepared;
  unprepared.id = 99;
  EXPECT_FALSE(cache.Take(unprepared, {}));
  EXPECT_EQ(cache.refused(), 2);
  EXPECT_EQ(cache.Find(0), nullptr);
  // A new session: every field forgotten, and the remembered result with it.
  const long before_clear = Allocations();
  cache.Clear();
  EXPECT_EQ(Allocations() - before_clear, 0);
  EXPECT_EQ(cache.Find(10), nullptr);
  EXPECT_EQ(cache.Find(12), nullptr);
  EXPECT_FALSE(cache.Evaluate(10, X_WT0).valid);
  incoming[3].id = 10;
  EXPECT_TRUE(cache.Take(incoming[3], keep_both));  // every slot free again
  EXPECT_NE(cache.Find(10), nullptr);
}

// The remote node's render against the texture stage's own depth at displaced poses: a textured
// block pressed onto a textured plate (test_scenes.h).
double PlateTexture(double x, double y) {
  return 60e-6 * std::sin(2.0 * kPi * x / 3e-3) + 25e-6 * std::cos(2.0 * kPi * y / 2.2e-3);
}
double BlockTexture(double x, double y) { return 20e-6 * std::sin(2.0 * kPi * (x + y) / 5e-3); }

TEST(DepthField, RenderedFieldReadsTheTextureStagesDepthAtDisplacedPoses) {
  // A 16 mm block: inside the 20 mm window, so that its whole face is in the field and stays in
  // it within the margin, and the texture stage's grown window sees all of it too.
  const HapticModel tool =
      MakeTexturedBox({0.008, 0.008, testing::kHalfHeight}, BlockTexture, 512, 0.1, "tool");
  const HapticModel env = testing::EnvironmentBox(PlateTexture);
  ContactQuery q;
  q.environment = &env;
  q.X_WO = testing::EnvironmentPose();
  q.window = ContactWindow::Make({0.0, 0.0, 0.0}, {0.0, 0.0, 1.0}, 0.02, 50);
  q.stiffness_n_per_m = 1e4;
  // The tool's centre of mass on the environment's lattice (whole cells from its origin), so
  // that the tool's nodes and the environment's coincide as the texture stage's do.
  const RigidTransform X_WT0 = testing::ToolPose(0.0012, -0.0004, -40e-6);
  const double h = q.window.cell_size_m();
  const DepthFieldLattice lattice{q.window.axis_u_W, q.window.axis_v_W, q.window.normal_W, h};
  DepthFieldRenderer renderer;
  DepthField f;
  ASSERT_TRUE(renderer.Render(tool, X_WT0, q, lattice, 10 * h, 1, kDepthFieldSmoothMaxM, f));
  EXPECT_EQ(f.nx, 70);
  EXPECT_NEAR(f.travel_margin_m, 10 * h, 1e-12);
  EXPECT_NEAR(f.tool_offset_u_m, 0.0, 1e-9);
  EXPECT_NEAR(f.tool_offset_v_m, 0.0, 1e-9);
  TexturePenetrationSolver solver(128, 4096);
  // The texture stage on the field's grid: its nodes are the grown window's cell centres.
  const glm::dvec3 centre =
      f.X_WF.translation + (0.5 * (f.nx - 1) * h) * (q.window.axis_u_W + q.window.axis_v_W);
  const ContactWindow grown =
      ContactWindow::Make({centre.x, centre.y, 0.0}, {0.0, 0.0, 1.0}, f.nx * h, f.nx);
  // Whole cells: the tool's nodes land on the environment's, the same cells the texture stage
  // renders (within the smooth maximum's lift, and the tool's render at the moved pose).
  for (const glm::dvec3 d : {glm::dvec3(0.0), glm::dvec3(h, 0.0, 0.0),
                             glm::dvec3(-2 * h, 3 * h, 0.0), glm::dvec3(5 * h, -4 * h, -10e-6)}) {
    RigidTransform X_WT = X_WT0;
    X_WT.translation += d;
    const DepthSample truth = solver.Depth(tool, X_WT, env, q.X_WO, grown);
    const DepthFieldEvaluation e = DepthFieldDepthAt(f, X_WT);
    ASSERT_TRUE(e.valid);
    EXPECT_NEAR(e.max_node_depth_m, truth.depth_m, 1e-6) << d.x << " " << d.y;
    EXPECT_GE(e.depth_m, e.max_node_depth_m);
    EXPECT_LE(e.depth_m, e.max_node_depth_m + f.smooth_max_m * std::log(e.nodes_evaluated));
  }
  // Between cells and tilted: the interpolated field against a fresh render, which samples the
  // plate's peaks at other points: each misses a peak's top by up to A(1 − cos(π h / λ)), 5 µm
  // for the 60 µm, 3 mm ridges at h = 0.4 mm.
  for (const Twist dq :
       {Twist{{0.5e-3 + 0.13e-3, 0.21e-3, 0.0}, {}}, Twist{{1.5e-3, -0.77e-3, 0.0}, {}},
        Twist{{}, {1e-3, 0.0, 0.0}}, Twist{{}, {0.0, 0.0, 10e-3}},
        Twist{{0.3e-3, 0.0, 0.0}, {0.0, 2e-3, 0.0}}}) {
    const RigidTransform X_WT = Displace(X_WT0, dq);
    const DepthSample truth = solver.Depth(tool, X_WT, env, q.X_WO, grown);
    const DepthFieldEvaluation e = DepthFieldDepthAt(f, X_WT);
    ASSERT_TRUE(e.valid);
    EXPECT_NEAR(e.max_node_depth_m, truth.depth_m, 6e-6) << dq.linear.x << " " << dq.angular.z;
  }
}

TEST(DepthField, FieldsOnOneLatticeFromOtherWindowsAndToolPosesAgreeWhereBothHoldTheTool) {
  // Two renders of one contact as successive remote steps make them: the window's centre moved
  // by a fraction of a cell and the tool slid between them. On one lattice both sample the same
  // points of both surfaces, so they give one depth and one force at any pose both hold (what
  // keeps a new field from stepping the force); on grids centred on each window they would not.
  const HapticModel tool =
      MakeTexturedBox({0.00607, 0.00607, testing::kHalfHeight}, BlockTexture, 512, 0.1, "tool");
  const HapticModel env = testing::EnvironmentBox(PlateTexture);
  ContactQuery q;
  q.environment = &env;
  q.X_WO = testing::EnvironmentPose();
  q.window = ContactWindow::Make({0.0, 0.0, 0.0}, {0.0, 0.0, 1.0}, 0.02, 50);
  q.stiffness_n_per_m = 1e4;
  // (The face's edges off the lattice: a node on an edge is in or out of the face by rounding.)
  const double h = 0.2e-3;
  const DepthFieldLattice lattice{q.window.axis_u_W, q.window.axis_v_W, q.window.normal_W, h};
  const RigidTransform X_WT0 = testing::ToolPose(0.00031, -0.00017, -30e-6);
  const RigidTransform X_WT1 = Displace(X_WT0, Twist{{0.23e-3, 0.11e-3, 2e-6}, {0.0, 0.0, 0.0}});
  ContactQuery q1 = q;
  q1.window.center_W += glm::dvec3(0.37e-3, -0.13e-3, 0.0);
  DepthFieldRenderer renderer;
  DepthField f0, f1;
  ASSERT_TRUE(renderer.Render(tool, X_WT0, q, lattice, 2e-3, 1, kDepthFieldSmoothMaxM, f0));
  ASSERT_TRUE(renderer.Render(tool, X_WT1, q1, lattice, 2e-3, 2, kDepthFieldSmoothMaxM, f1));
  // Offsets within ±h/2 that put the tool's nodes on its own lattice: different for the two.
  EXPECT_GT(std::abs(f0.tool_offset_u_m - f1.tool_offset_u_m), 1e-6);
  // The maps' places on the lattices: the environment's grids start where their frames say, and
  // a tool node of one field is the node with the same tool-lattice coordinates in the other
  // (its height 2 µm higher, as the tool rose).
  const glm::dvec3 shift = (f1.X_WF.translation - f0.X_WF.translation) / h;
  EXPECT_NEAR(f1.lattice_i0 - f0.lattice_i0, shift.x, 1e-6);
  EXPECT_NEAR(f1.lattice_j0 - f0.lattice_j0, shift.y, 1e-6);
  int matched = 0;
  for (int j = 0; j < f1.ny; ++j) {
    for (int i = 0; i < f1.nx; ++i) {
      const int i0 = i + f1.tool_lattice_i0 - f0.tool_lattice_i0;
      const int j0 = j + f1.tool_lattice_j0 - f0.tool_lattice_j0;
      if (i0 < 0 || j0 < 0 || i0 >= f0.nx || j0 >= f0.ny) continue;
      const float a0 = f0.tool_height_m[static_cast<std::size_t>(j0 * f0.nx + i0)];
      const float a1 = f1.tool_height_m[static_cast<std::size_t>(j * f1.nx + i)];
      ASSERT_EQ(std::isnan(a0), std::isnan(a1)) << i << " " << j;
      if (std::isnan(a0)) continue;
      EXPECT_NEAR(a1 - a0, 2e-6, 1e-9);
      ++matched;
    }
  }
  EXPECT_GT(matched, 3000);
  for (const Twist dq : {Twist{}, Twist{{0.1e-3, 0.05e-3, 0.0}, {}},
                         Twist{{0.17e-3, 0.02e-3, -3e-6}, {0.5e-3, -0.3e-3, 0.0}}}) {
    const RigidTransform X_WT = Displace(X_WT1, dq);
    const DepthFieldEvaluation e0 = DepthFieldDepthAt(f0, X_WT);
    const DepthFieldEvaluation e1 = DepthFieldDepthAt(f1, X_WT);
    ASSERT_TRUE(e0.valid && e1.valid);
    ASSERT_GT(e0.depth_m, 0.0);
    EXPECT_NEAR(e0.depth_m, e1.depth_m, 1e-8) << dq.linear.x;
    EXPECT_LT(glm::length(e0.gradient.d_translation_W - e1.gradient.d_translation_W), 1e-3);
    EXPECT_LT(glm::length(e0.gradient.d_rotation_W - e1.gradient.d_rotation_W), 1e-5);
  }
}

namespace closed_form {

// A sphere of radius R as the bottom of a box (the cap protrudes T(x, y) below the box's bottom
// face, T = √(R² − r²) − √(R² − r_corner²) ≥ 0), slid across a plate rippled along x.
constexpr double kR = 0.03, kBoxHalf = 0.006;
constexpr double kRipple = 100e-6, kWavelength = 4e-3;
double Cap(double x, double y) {
  const double r_corner2 = 2.0 * kBoxHalf * kBoxHalf;
  return std::sqrt(kR * kR - (x * x + y * y)) - std::sqrt(kR * kR - r_corner2);
}
double Plate(double x, double) { return kRipple * std::sin(2.0 * kPi * x / kWavelength); }
double PlateSlope(double x) {
  return kRipple * 2.0 * kPi / kWavelength * std::cos(2.0 * kPi * x / kWavelength);
}

/// The closed form at the tool's bottom face z_b and centre x = t (y = 0; the maximizer lies in
/// the plane y = 0 by symmetry): g(x) = plate(x) − (z_b − Cap(x − t)), δ = max g, reached at
/// x*; and the second-highest local maximum of g (another ripple's crest) and where, which
/// ties with the first where the slide hands the contact from one crest to the next. A 1 µm
/// scan refined by golden section.
struct Crests {
  double depth = -1.0, x = 0.0, second_depth = -1.0, second_x = 0.0;
};
Crests Depth(double t, double z_b) {
  const auto g = [&](double x) { return Plate(x, 0.0) + Cap(x - t, 0.0) - z_b; };
  const auto refine = [&](double x) {
    double lo = x - 1e-6, hi = x + 1e-6;
    for (int k = 0; k < 60; ++k) {
      const double m1 = lo + 0.382 * (hi - lo), m2 = lo + 0.618 * (hi - lo);
      if (g(m1) < g(m2)) {
        lo = m1;
      } else {
        hi = m2;
      }
    }
    return 0.5 * (lo + hi);
  };
  Crests c;
  double previous = g(t - 5.5e-3), current = g(t - 5.5e-3 + 1e-6);
  for (double x = t - 5.5e-3 + 1e-6; x <= t + 5.5e-3; x += 1e-6) {
    const double next = g(x + 1e-6);
    if (current >= previous && current > next) {  // a local maximum
      const double xs = refine(x), v = g(xs);
      if (v > c.depth) {
        c.second_depth = c.depth;
        c.second_x = c.x;
        c.depth = v;
        c.x = xs;
      } else if (v > c.second_depth) {
        c.second_depth = v;
        c.second_x = xs;
      }
    }
    previous = current;
    current = next;
  }
  return c;
}

/// The angle (rad) of the plate's normal at x in the x–z plane, from +z towards +x.
double NormalAngle(double x) { return std::atan2(-PlateSlope(x), 1.0); }

}  // namespace closed_form

// Two surfaces one behind the other along n (a thin fin's face, and beyond its rim the next
// fin's face 10 mm further back): b steps between two nodes.
double FinFaceThenStep(double x, double) { return x <= 20 * kH + 1e-9 ? 0.0 : -10e-3; }
double FaceOverTheRim(double x, double y) {
  const double lo = 10 * kH - 1e-9, hi = 29 * kH + 1e-9;
  return x >= lo && x <= hi && y >= lo && y <= hi ? -0.3e-3 : std::nan("");
}

TEST(DepthField, AStepBetweenTwoSurfacesBecomesAChamferAndAFaceOverItIsPushedSidewaysFarLess) {
  // A flat face pressed 0.3 mm into the upper surface, half of it beyond the rim, slid across
  // the rim by two cells: the bicubic across the raw step overshoots the upper surface (by 7 %
  // of the step) with slopes of tens, and the face's deepest nodes ride that bump; limited to
  // kDepthFieldMaxDescentSlope the step is a chamfer below the rim, and the face rests on the
  // upper surface: its depth is its press (plus at most the bicubic's overshoot at the chamfer's
  // edge), its force within about 45° of the normal.
  const RigidTransform X_WF = TurnedFrame();
  const RigidTransform X_WT0 = ToolAboveFace(X_WF);
  DepthField raw = MakeField(kN, kH, X_WF, X_WT0, FinFaceThenStep, FaceOverTheRim);
  DepthField limited = raw;
  LimitDepthMapDescent(limited.nx, limited.ny, limited.cell_m, kDepthFieldMaxDescentSlope,
                       limited.env_height_m);
  ASSERT_TRUE(limited.Prepare());
  // Only the lower surface moved, and no neighbour falls more than the limit below another.
  for (int j = 0; j < kN; ++j) {
    for (int i = 0; i + 1 < kN; ++i) {
      const float b0 = limited.env_height_m[static_cast<std::size_t>(j * kN + i)];
      const float b1 = limited.env_height_m[static_cast<std::size_t>(j * kN + i + 1)];
      EXPECT_LE(b0 - b1, kDepthFieldMaxDescentSlope * kH * (1.0 + 1e-5)) << i << " " << j;
      if (i <= 20) EXPECT_EQ(b0, 0.0f);
    }
  }
  const glm::dvec3 u_W = X_WF.rotation * glm::dvec3(1.0, 0.0, 0.0);
  double raw_worst = 0.0, worst = 0.0;
  for (double t = -1.0; t <= 1.0 + 1e-9; t += 0.125) {
    RigidTransform X_WT = X_WT0;
    X_WT.translation += t * kH * u_W;
    const DepthFieldEvaluation e = DepthFieldDepthAt(limited, X_WT);
    ASSERT_TRUE(e.valid);
    // At most the bicubic's overshoot at the chamfer's upper edge (7 % of a cell's fall).
    EXPECT_GE(e.max_node_depth_m, 0.3e-3 - 1e-6) << t;
    EXPECT_LE(e.max_node_depth_m, 0.3e-3 + 0.08 * kDepthFieldMaxDescentSlope * kH) << t;
    worst = std::max(worst, std::abs(glm::dot(e.gradient.d_translation_W, u_W)));
    raw_worst = std::max(
        raw_worst, std::abs(glm::dot(DepthFieldDepthAt(raw, X_WT).gradient.d_translation_W, u_W)));
  }
  std::printf("face over a 10 mm step: largest |d(depth)/du| %.2f raw, %.2f chamfered\n", raw_worst,
              worst);
  EXPECT_LT(worst, 1.5);
  EXPECT_GT(raw_worst, 5.0 * worst) << "the raw step's bump pushes sideways";
}

TEST(DepthField, SphereSlidAcrossARippledPlateFollowsTheClosedFormInDepthAndDirection) {
  // Rendered once at q0, evaluated along a 5 mm slide within its margin at poses held 60 µm deep
  // by the closed form: the depth within 20 µm and the force within 3° of the plate's normal at
  // the contact point (the envelope theorem: ∇δ = (plate'(x*), 0, −1)). What the operator's loop
  // renders a round trip after the field was made, with the tool sliding over ripples.
  using namespace closed_form;
  const HapticModel tool =
      MakeTexturedBox({kBoxHalf, kBoxHalf, testing::kHalfHeight}, Cap, 512, 0.1, "sphere");
  const HapticModel env = testing::EnvironmentBox(Plate);
  ContactQuery q;
  q.environment = &env;
  q.X_WO = testing::EnvironmentPose();
  q.window = ContactWindow::Make({0.0, 0.0, 0.0}, {0.0, 0.0, 1.0}, 0.02, 50);
  q.stiffness_n_per_m = 1e4;
  const double h = 0.2e-3;
  const DepthFieldLattice lattice{q.window.axis_u_W, q.window.axis_v_W, q.window.normal_W, h};
  const auto pose_at = [&](double t, double* z_b) {
    *z_b = Depth(t, 0.0).depth - 60e-6;  // δ is linear in z_b: this puts it at 60 µm
    return testing::ToolPose(t, 0.0, *z_b);
  };
  double z0;
  const RigidTransform X_WT0 = pose_at(0.0, &z0);
  DepthFieldRenderer renderer;
  DepthField f;
  ASSERT_TRUE(renderer.Render(tool, X_WT0, q, lattice, 5.6e-3, 1, kDepthFieldSmoothMaxM, f));
  double worst_depth = 0.0, worst_angle = 0.0;
  int ties = 0;
  for (double t = -2.5e-3; t <= 2.5e-3 + 1e-9; t += 0.125e-3) {
    double z_b;
    const RigidTransform X_WT = pose_at(t, &z_b);
    const Crests truth = Depth(t, z_b);
    const DepthFieldEvaluation e = DepthFieldDepthAt(f, X_WT);
    ASSERT_TRUE(e.valid && e.within_margin) << t;
    worst_depth = std::max(worst_depth, std::abs(e.depth_m - truth.depth));
    EXPECT_NEAR(e.depth_m, truth.depth, 20e-6) << "slide " << t * 1e3 << " mm";
    // The force's direction in the x–z plane against the normal at the deepest crest; where a
    // second crest is within 5 ε, anywhere between the two crests' normals (δ has a kink there
    // and the smooth maximum mixes the two).
    const glm::dvec3 force = -e.gradient.d_translation_W;
    EXPECT_LT(std::abs(force.y), 1e-3 * glm::length(force));
    const double angle = std::atan2(force.x, force.z);
    double lo = NormalAngle(truth.x), hi = lo;
    if (truth.depth - truth.second_depth < 5.0 * kDepthFieldSmoothMaxM) {
      ++ties;
      lo = std::min(lo, NormalAngle(truth.second_x));
      hi = std::max(hi, NormalAngle(truth.second_x));
    }
    const double off = std::max({0.0, lo - angle, angle - hi});
    worst_angle = std::max(worst_angle, off);
    EXPECT_LT(off, 3.0 * kPi / 180.0) << "slide " << t * 1e3 << " mm";
  }
  EXPECT_GE(ties, 1) << "the slide hands the contact from one crest to the next";
  std::printf("sphere on ripples: depth within %.2f um, direction within %.2f deg, %d ties\n",
              worst_depth * 1e6, worst_angle * 180.0 / kPi, ties);
}

}  // namespace
}  // namespace ht
