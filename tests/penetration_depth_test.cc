#include "haptic_core/penetration_depth.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>
#include <random>
#include <vector>

#include "haptic_core/connected_contacts.h"
#include "haptic_core/contact_linearization.h"
#include "haptic_core/penetration_depth_backend.h"
#include "test_scenes.h"

namespace ht {
namespace {

using testing::EnvironmentBox;
using testing::EnvironmentPose;
using testing::ToolBox;
using testing::ToolPose;

const auto kFlat = [](double, double) { return 0.0; };

TEST(PenetrationDepth, FlatPatchesGiveTheirOverlap) {
  const HapticModel a = ToolBox(kFlat), b = EnvironmentBox(kFlat);
  TexturePenetrationSolver solver;
  const ContactWindow w = ContactWindow::Make({0, 0, 0}, {0, 0, 1}, 0.02, 50);
  for (double overlap : {0.0, 1e-4, 1e-3, 4e-3}) {
    const DepthSample d =
        solver.Depth(a, ToolPose(0.001, -0.002, -overlap), b, EnvironmentPose(), w);
    EXPECT_NEAR(d.depth_m, overlap, 1e-7) << "overlap " << overlap;
  }
}

TEST(PenetrationDepth, ConstantTexturesAddToTheOverlap) {
  // Texture heights displace along the outward normals: both protrusions add to the overlap.
  const HapticModel a = ToolBox([](double, double) { return 3e-4; });
  const HapticModel b = EnvironmentBox([](double, double) { return 2e-4; });
  TexturePenetrationSolver solver;
  const ContactWindow w = ContactWindow::Make({0, 0, 0}, {0, 0, 1}, 0.02, 50);
  EXPECT_NEAR(solver.Depth(a, ToolPose(0, 0, 0.0), b, EnvironmentPose(), w).depth_m, 5e-4, 1e-7);
}

TEST(PenetrationDepth, SeparatedPatchesGiveNegativeDepthAndNoForce) {
  // Separated patches give no wrench, and a window the tool does not cover gives −∞ and a zero
  // gradient (nothing computed from a missing cell).
  const HapticModel a = ToolBox(kFlat), b = EnvironmentBox(kFlat);
  const ContactWindow w = ContactWindow::Make({0, 0, 0}, {0, 0, 1}, 0.02, 50);
  TexturePenetrationSolver solver;
  const ContactLinearization lin =
      solver.Linearize(a, ToolPose(0, 0, 2e-3), b, EnvironmentPose(), w, 1000.0);
  EXPECT_NEAR(lin.depth_m, -2e-3, 1e-7);
  const Wrench F = PenaltyWrench(lin.depth_m, lin.gradient, lin.stiffness_n_per_m);
  EXPECT_EQ(glm::length(F.force), 0.0);
  EXPECT_EQ(glm::length(F.torque), 0.0);
  const ContactLinearization off =
      solver.Linearize(a, ToolPose(0.2, 0, 0), b, EnvironmentPose(), w, 1000.0);
  EXPECT_TRUE(std::isinf(off.depth_m) && off.depth_m < 0.0);
  EXPECT_EQ(off.gradient.d_translation_W, glm::dvec3(0.0));
  EXPECT_EQ(off.gradient.d_rotation_W, glm::dvec3(0.0));
}

TEST(PenetrationDepth, NoOverlapOnTheWindowIsReported) {
  const HapticModel a = ToolBox(kFlat), b = EnvironmentBox(kFlat);
  TexturePenetrationSolver solver;
  // Tool far to the side: its patch does not cover the window.
  const ContactWindow w = ContactWindow::Make({0, 0, 0}, {0, 0, 1}, 0.01, 20);
  const DepthSample d = solver.Depth(a, ToolPose(0.2, 0, 0), b, EnvironmentPose(), w);
  EXPECT_EQ(d.cell, -1);
  EXPECT_TRUE(std::isinf(d.depth_m));
}

// Sinusoidal environment b(y) = A sin(ωy) under a tool with a smooth paraboloid bump
// h_A = c − κ|p − p_A|². The deepest point y* solves A ω cos(ω y*) = 2κ (y* − y_A); there the
// force is one force with tangential/normal ratio equal to the sinusoid's slope (DESIGN.md §4).
struct SmoothCase {
  double amp = 3e-4, omega = 2 * std::numbers::pi / 6e-3, kappa = 500.0, c = 1e-4;
  double y_tool = 0.8e-3, z_bottom = 1e-4;
  double DeepestY() const {
    double lo = y_tool - 5e-3, hi = y_tool + 5e-3;  // f(y) = Aω cos(ωy) − 2κ(y − y_A) decreases
    for (int i = 0; i < 200; ++i) {
      const double mid = 0.5 * (lo + hi);
      (amp * omega * std::cos(omega * mid) - 2 * kappa * (mid - y_tool) > 0 ? lo : hi) = mid;
    }
    return 0.5 * (lo + hi);
  }
  double Slope(double y) const { return amp * omega * std::cos(omega * y); }
  HapticModel Tool() const {
    return ToolBox([this](double x, double y) { return c - kappa * (x * x + y * y); }, 1024);
  }
  HapticModel Environment() const {
    return EnvironmentBox([this](double, double y) { return amp * std::sin(omega * y); }, 1024);
  }
  /// The analytic gradient at tool pose X_WT (envelope theorem): ∇δ = (g − n, r × (g − n)), g the
  /// tool surface slope at the deepest point p* (= ∂a/∂y there, since ∇a = ∇b at p*) and
  /// r = p* − centre of mass.
  PenetrationGradient AnalyticGradient(const RigidTransform& X_WT) const {
    const double y_star = DeepestY();
    const double a_star = z_bottom - (c - kappa * (y_star - y_tool) * (y_star - y_tool));
    const glm::dvec3 g_minus_n(0, Slope(y_star), -1);
    const glm::dvec3 r = glm::dvec3(0, y_star, a_star) - X_WT.translation;
    return {g_minus_n, glm::cross(r, g_minus_n)};
  }
};

TEST(PenetrationDepth, SinusoidForceRatioEqualsSlopeAtDeepestPoint) {
  const SmoothCase s;
  const HapticModel a = s.Tool(), b = s.Environment();
  TexturePenetrationSolver solver(200);
  const ContactWindow w = ContactWindow::Make({0, 0, 0}, {0, 0, 1}, 0.02, 200);
  const ContactLinearization lin =
      solver.Linearize(a, ToolPose(0, s.y_tool, s.z_bottom), b, EnvironmentPose(), w, 1000.0);
  ASSERT_GT(lin.depth_m, 0.0);
  const Wrench F = PenaltyWrench(lin.depth_m, lin.gradient, 1000.0);
  const double y_star = s.DeepestY();
  const double slope = s.Slope(y_star);
  ASSERT_GT(std::abs(slope), 0.1) << "the case must put the deepest point on a flank";
  EXPECT_NEAR(-F.force.y / F.force.z, slope, 0.05 * std::abs(slope));
  EXPECT_NEAR(F.force.x / F.force.z, 0.0, 0.01);
  EXPECT_NEAR(lin.point_W.y, y_star, 2 * w.cell_size_m());
}

TEST(PenetrationDepth, FiniteDifferenceGradientMatchesAnalyticGradient) {
  // Envelope theorem: ∇δ = (g − n, r × (g − n)) with g the tool surface slope at the deepest
  // point p* and r = p* − centre of mass. Two independent routes to the same six numbers.
  const SmoothCase s;
  const HapticModel a = s.Tool(), b = s.Environment();
  TexturePenetrationSolver solver(200);
  const ContactWindow w = ContactWindow::Make({0, 0, 0}, {0, 0, 1}, 0.02, 200);
  const RigidTransform X_WT = ToolPose(0, s.y_tool, s.z_bottom);
  const ContactLinearization lin = solver.Linearize(a, X_WT, b, EnvironmentPose(), w, 1000.0);

  const PenetrationGradient J = s.AnalyticGradient(X_WT);
  const glm::dvec3 J_x = J.d_translation_W, J_theta = J.d_rotation_W;
  const double tol_x = 0.05 * glm::length(J_x), tol_theta = 0.05 * glm::length(J_theta);
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(lin.gradient.d_translation_W[i], J_x[i], tol_x) << "translation axis " << i;
    EXPECT_NEAR(lin.gradient.d_rotation_W[i], J_theta[i], tol_theta) << "rotation axis " << i;
  }
}

TEST(PenetrationDepth, ActionEqualsMinusReaction) {
  // Swap the roles: the environment becomes the tool, n flips. The two wrenches, taken about the
  // world origin, must cancel.
  const SmoothCase s;
  const HapticModel a = s.Tool(), b = s.Environment();
  TexturePenetrationSolver solver(100);
  const RigidTransform X_WA = ToolPose(1e-3, s.y_tool, s.z_bottom), X_WB = EnvironmentPose();
  const double k = 1000.0;
  const ContactLinearization on_a =
      solver.Linearize(a, X_WA, b, X_WB, ContactWindow::Make({0, 0, 0}, {0, 0, 1}, 0.02, 100), k);
  const ContactLinearization on_b =
      solver.Linearize(b, X_WB, a, X_WA, ContactWindow::Make({0, 0, 0}, {0, 0, -1}, 0.02, 100), k);
  EXPECT_NEAR(on_a.depth_m, on_b.depth_m, 1e-7);
  const Wrench F_a = PenaltyWrench(on_a.depth_m, on_a.gradient, k);
  const Wrench F_b = PenaltyWrench(on_b.depth_m, on_b.gradient, k);
  const double scale = glm::length(F_a.force);
  ASSERT_GT(scale, 0.0);
  EXPECT_LT(glm::length(F_a.force + F_b.force), 0.03 * scale);
  const glm::dvec3 torque_o = F_a.torque + glm::cross(X_WA.translation, F_a.force) + F_b.torque +
                              glm::cross(X_WB.translation, F_b.force);
  EXPECT_LT(glm::length(torque_o), 0.03 * scale * 0.01);
}

TEST(PenetrationDepth, WindowRejectsBadArguments) {
  EXPECT_THROW(ContactWindow::Make({0, 0, 0}, {0, 0, 0}, 0.02, 50), std::invalid_argument);
  EXPECT_THROW(ContactWindow::Make({0, 0, 0}, {NAN, 0, 1}, 0.02, 50), std::invalid_argument);
  EXPECT_THROW(ContactWindow::Make({0, 0, 0}, {0, 0, 1}, -1.0, 50), std::invalid_argument);
  EXPECT_THROW(ContactWindow::Make({0, 0, 0}, {0, 0, 1}, 0.02, 1), std::invalid_argument);
  const ContactWindow w = ContactWindow::Make({0, 0, 0}, {0.3, -0.2, 0.9}, 0.02, 50);
  EXPECT_NEAR(glm::dot(glm::cross(w.axis_u_W, w.axis_v_W), w.normal_W), 1.0, 1e-12);
}

// Three 40 µm Gaussian bumps (σ = 1 mm) on a flat environment, at (−8, 0), (8, 0) and (8, 5) mm,
// under a flat tool 20 µm above their base: the scene of the OverlapRegions and OverlapOccupancy
// tests.
struct ThreeBumps {
  HapticModel env, tool;
  RigidTransform X_WT;
};
ThreeBumps MakeThreeBumps() {
  const auto bump = [](double x, double y, double cx, double cy) {
    return 40e-6 * std::exp(-((x - cx) * (x - cx) + (y - cy) * (y - cy)) / (2.0 * 1e-6));
  };
  return {testing::EnvironmentBox(
              [&](double x, double y) {
                return bump(x, y, -8e-3, 0.0) + bump(x, y, 8e-3, 0.0) + bump(x, y, 8e-3, 5e-3);
              },
              1024),
          testing::ToolBox([](double, double) { return 0.0; }, 512),
          testing::ToolPose(0.0, 0.0, 20e-6)};
}

// Stage 5c's footprints (connected_contacts.h): the overlap of the three bumps as blocks. With
// one-cell blocks the occupied count is the regions' cell count (two routes to one number); the
// gap between two windows' overlaps, one over each side's bumps, is the bumps' 16 mm less their
// overlaps' radii; the link fades with it.
TEST(OverlapOccupancy, BlocksHoldTheOverlapAndGiveTheGapBetweenOverlaps) {
  const ThreeBumps scene = MakeThreeBumps();
  const HapticModel& env = scene.env;
  const HapticModel& tool = scene.tool;
  const RigidTransform X_WT = scene.X_WT;
  TexturePenetrationSolver solver(128);
  const ContactWindow whole = ContactWindow::Make({0.0, 0.0, 0.0}, {0.0, 0.0, 1.0}, 0.036, 90);
  std::array<OverlapRegion, 8> regions{};
  const int count =
      solver.OverlapRegions(tool, X_WT, env, testing::EnvironmentPose(), whole, 1e-3, regions);
  ASSERT_EQ(count, 3);
  int cells = 0;
  for (int r = 0; r < count; ++r) cells += regions[static_cast<std::size_t>(r)].cells;
  std::vector<std::uint8_t> occupancy(90 * 90);
  EXPECT_EQ(
      solver.OverlapOccupancy(tool, X_WT, env, testing::EnvironmentPose(), whole, 1, occupancy),
      cells);
  // Too small a buffer, a bad block size: −1, nothing written.
  std::vector<std::uint8_t> small(10, 7);
  EXPECT_EQ(solver.OverlapOccupancy(tool, X_WT, env, testing::EnvironmentPose(), whole, 1, small),
            -1);
  EXPECT_EQ(small[0], 7);
  EXPECT_EQ(
      solver.OverlapOccupancy(tool, X_WT, env, testing::EnvironmentPose(), whole, 0, occupancy),
      -1);
  // One window over each side's bumps (12 mm, 0.4 mm cells, 1-cell blocks).
  const auto footprint = [&](glm::dvec3 centre, std::vector<std::uint8_t>& storage) {
    const ContactWindow w = ContactWindow::Make(centre, {0.0, 0.0, 1.0}, 0.012, 30);
    storage.assign(30 * 30, 0);
    const int occupied =
        solver.OverlapOccupancy(tool, X_WT, env, testing::EnvironmentPose(), w, 1, storage);
    EXPECT_GT(occupied, 0);
    return OverlapFootprint{w, 1, 30, storage};
  };
  std::vector<std::uint8_t> sa, sb;
  const OverlapFootprint left = footprint({-8e-3, 0.0, 0.0}, sa);
  const OverlapFootprint right = footprint({8e-3, 2.5e-3, 0.0}, sb);
  // Each bump overlaps where 40 µm·exp(−r²/2σ²) > 20 µm: r < σ·sqrt(2 ln 2) = 1.18 mm.
  const double radius = 1e-3 * std::sqrt(2.0 * std::log(2.0));
  const double gap = FootprintGap(left, right);
  EXPECT_NEAR(gap, 16e-3 - 2.0 * radius, 0.5e-3);      // to within the cells
  EXPECT_EQ(FootprintGap(right, left), gap);           // symmetric
  EXPECT_LE(FootprintGap(left, right, 20e-3), 20e-3);  // an early stop still links
  EXPECT_NEAR(FootprintGap(right, right), 0.0, 1e-12);
  EXPECT_EQ(OverlapLink(gap, 5e-3, 5e-3), 0.0);
  EXPECT_EQ(OverlapLink(gap, 15e-3, 5e-3), 1.0);
  EXPECT_NEAR(OverlapLink(gap, gap - 2.5e-3, 5e-3), 0.5, 1e-9);
  EXPECT_EQ(OverlapLink(gap, gap - 1e-9, 0.0), 0.0);  // no fade: a step at the link
  EXPECT_EQ(OverlapLink(std::numeric_limits<double>::quiet_NaN(), 10e-3, 5e-3), 0.0);
  // Malformed or empty: no gap.
  OverlapFootprint empty = left;
  empty.blocks_per_side = 0;
  EXPECT_EQ(FootprintGap(empty, right), std::numeric_limits<double>::infinity());
}

// LinkedPenaltyShares: unlinked contacts keep their penalty; a linked pair or clique shares the
// soft maximum of its depths (Σ s = 1, computed here by hand: two routes); continuous in the
// depths and the links; non-finite depths get nothing.
TEST(PenaltyShares, SoftMaximumOverLinkedContacts) {
  std::array<double, 3> s{};
  const std::array<double, 9> none{};
  const std::array<double, 9> all{0, 1, 1, 1, 0, 1, 1, 1, 0};
  LinkedPenaltyShares(std::array<double, 3>{100e-6, 50e-6, 20e-6}, none, 5e-6, s);
  for (double x : s) EXPECT_EQ(x, 1.0);
  LinkedPenaltyShares(std::array<double, 3>{100e-6, 100e-6, 100e-6}, all, 5e-6, s);
  for (double x : s) EXPECT_NEAR(x, 1.0 / 3.0, 1e-12);
  const std::array<double, 3> d{102e-6, 100e-6, 95e-6};
  LinkedPenaltyShares(d, all, 5e-6, s);
  double z = 0.0;
  for (double x : d) z += std::exp(x / 5e-6);
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(s[i], std::exp(d[i] / 5e-6) / z, 1e-12) << i;
  EXPECT_NEAR(s[0] + s[1] + s[2], 1.0, 1e-12);
  // The clique pushes between the mean and the deepest; a contact deeper by 10 τ takes nearly all.
  const double group = s[0] * d[0] + s[1] * d[1] + s[2] * d[2];
  EXPECT_LE(group, d[0]);
  EXPECT_GE(group, (d[0] + d[1] + d[2]) / 3.0);
  LinkedPenaltyShares(std::array<double, 3>{150e-6, 100e-6, 50e-6}, all, 5e-6, s);
  EXPECT_GT(s[0], 1.0 - 1e-4);
  // Two linked contacts 5 mm below an unlinked deepest one: their weights relative to it
  // underflow, and they still share as a pair (a half each), not 0/0.
  const std::array<double, 9> pair{0, 0, 0, 0, 0, 1, 0, 1, 0};
  LinkedPenaltyShares(std::array<double, 3>{5e-3, 0.0, 0.0}, pair, 5e-6, s);
  EXPECT_EQ(s[0], 1.0);
  EXPECT_NEAR(s[1], 0.5, 1e-12);
  EXPECT_NEAR(s[2], 0.5, 1e-12);
  // Continuous where the deepest contact changes, and as a link fades in.
  std::array<double, 3> s2{};
  LinkedPenaltyShares(std::array<double, 3>{100e-6 + 1e-12, 100e-6, 0.0}, all, 5e-6, s);
  LinkedPenaltyShares(std::array<double, 3>{100e-6, 100e-6 + 1e-12, 0.0}, all, 5e-6, s2);
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(s[i], s2[i], 1e-6) << i;
  const std::array<double, 4> faint{0, 1e-9, 1e-9, 0};
  std::array<double, 2> p{};
  LinkedPenaltyShares(std::array<double, 2>{100e-6, 100e-6}, faint, 5e-6, p);
  EXPECT_NEAR(p[0], 1.0, 1e-8);
  const std::array<double, 4> half{0, 0.5, 0.5, 0};
  LinkedPenaltyShares(std::array<double, 2>{100e-6, 100e-6}, half, 5e-6, p);
  EXPECT_NEAR(p[0], 2.0 / 3.0, 1e-12);
  // A chain 0–1–2 (0 and 2 unlinked): its closure links the ends, at its weakest link.
  std::array<double, 9> chain{0, 1, 0, 1, 0, 0.5, 0, 0.5, 0};
  StrongestPathLinks(chain, 3);
  EXPECT_EQ(chain[2], 0.5);
  EXPECT_EQ(chain[6], 0.5);
  EXPECT_EQ(chain[1], 1.0);
  std::array<double, 9> full_chain{0, 1, 0, 1, 0, 1, 0, 1, 0};
  StrongestPathLinks(full_chain, 3);
  EXPECT_EQ(full_chain, all);
  // Non-finite depths take no part; a short links span writes nothing.
  const double inf = std::numeric_limits<double>::infinity();
  const double nan = std::numeric_limits<double>::quiet_NaN();
  LinkedPenaltyShares(std::array<double, 3>{-inf, 100e-6, nan}, all, 5e-6, s);
  EXPECT_EQ(s[0], 0.0);
  EXPECT_EQ(s[1], 1.0);
  EXPECT_EQ(s[2], 0.0);
  s = {7.0, 7.0, 7.0};
  LinkedPenaltyShares(std::array<double, 3>{1e-6, 1e-6, 1e-6}, std::array<double, 4>{}, 5e-6, s);
  EXPECT_EQ(s[0], 7.0);
}

}  // namespace
}  // namespace ht

namespace ht {
namespace {

// One pass keeping the first strictly larger difference of finite pairs: the definition the
// SIMD lane scan of DirectionalPenetrationDepth(Shifted) must reproduce bit for bit.
DepthSample OnePassDepth(const std::vector<float>& b, const std::vector<float>& a) {
  DepthSample best{-std::numeric_limits<double>::infinity(), -1};
  float best_value = -std::numeric_limits<float>::infinity();
  for (std::size_t k = 0; k < std::min(a.size(), b.size()); ++k) {
    if (!(std::isfinite(b[k]) && std::isfinite(a[k]))) continue;
    if (b[k] - a[k] > best_value) {
      best_value = b[k] - a[k];
      best.cell = static_cast<int>(k);
    }
  }
  if (best.cell >= 0) best.depth_m = best_value;
  return best;
}

TEST(PenetrationDepth, LaneScanDepthIsTheOnePassDefinitionWithTiesInfinitiesAndSignedZeros) {
  std::mt19937 rng(77);
  std::uniform_real_distribution<float> h(-1e-3f, 1e-3f);
  const float inf = std::numeric_limits<float>::infinity();
  int found = 0;
  for (int trial = 0; trial < 400; ++trial) {
    const int n = 2 + trial % 29, m = 1;  // rows of 2–30 cells: the 4- and 8-lane steps and tails
    const int nt = n + 2 * m;
    std::vector<float> b(static_cast<std::size_t>(n) * n), a_ext(static_cast<std::size_t>(nt) * nt);
    // Few distinct values (ties), ±0, empty cells, a NaN now and then, one overflow.
    const auto draw = [&](float empty) {
      const int pick = static_cast<int>(rng() % 10);
      if (pick < 3) return empty;
      if (pick == 3) return 0.0f;
      if (pick == 4) return -0.0f;
      if (pick == 5 && trial % 7 == 0) return std::numeric_limits<float>::quiet_NaN();
      if (pick == 6 && trial % 11 == 0) return empty > 0 ? -3e38f : 3e38f;
      return trial % 3 == 0 ? static_cast<float>(rng() % 4) * 1e-4f : h(rng);
    };
    for (float& x : b) x = draw(-inf);
    for (float& x : a_ext) x = draw(inf);
    for (int dj = -m; dj <= m; ++dj) {
      for (int di = -m; di <= m; ++di) {
        std::vector<float> a(b.size());
        for (int j = 0; j < n; ++j) {
          for (int i = 0; i < n; ++i) {
            a[static_cast<std::size_t>(j * n + i)] =
                a_ext[static_cast<std::size_t>((j + m + dj) * nt + (i + m + di))];
          }
        }
        const DepthSample want = OnePassDepth(b, a);
        const DepthSample plain = DirectionalPenetrationDepth(b, a);
        const DepthSample shifted = DirectionalPenetrationDepthShifted(b, n, a_ext, m, di, dj);
        for (const DepthSample& got : {plain, shifted}) {
          ASSERT_EQ(got.cell, want.cell) << "trial " << trial;
          ASSERT_EQ(std::signbit(got.depth_m), std::signbit(want.depth_m)) << "trial " << trial;
          ASSERT_EQ(got.depth_m, want.depth_m) << "trial " << trial;
        }
        found += want.cell >= 0;
      }
    }
  }
  EXPECT_GT(found, 1000);
}

}  // namespace
}  // namespace ht

namespace ht {
namespace {

// TexturePenetrationSolver::OverlapRegions (stage 5a, PipelineOptions): three 40 µm Gaussian bumps
// (σ 1 mm) under a flat tool at 20 µm, so each overlaps within about 1.2 mm of its top. Two lie 5
// mm apart (2.6 mm of gap) and one 16 mm from them: linked at 5 mm the overlap is two regions, the
// lone bump's box around its own top; at 20 mm one region; at 1 mm three. Each region's depth is
// its bump's b − a at the cells (≤ 20 µm, within the filtered grid's loss of a few µm).
TEST(OverlapRegions, SeparatedBumpsAreSeparateRegionsAtTheClusteringDistance) {
  const ThreeBumps scene = MakeThreeBumps();
  const HapticModel& env = scene.env;
  const HapticModel& tool = scene.tool;
  const RigidTransform X_WT = scene.X_WT;
  const ContactWindow w = ContactWindow::Make({0.0, 0.0, 0.0}, {0.0, 0.0, 1.0}, 0.036, 90);
  TexturePenetrationSolver solver(128);
  std::array<OverlapRegion, 8> out{};
  ASSERT_EQ(solver.OverlapRegions(tool, X_WT, env, testing::EnvironmentPose(), w, 5e-3, out), 2);
  const auto centre_u = [&](const OverlapRegion& g) {
    return (0.5 * (g.i0 + g.i1 + 1)) * w.cell_size_m() - 0.5 * w.extent_m;
  };
  // The pair (two tops) and the lone bump; u is world x here.
  ASSERT_NEAR(std::abs(glm::dot(w.axis_u_W, glm::dvec3(1, 0, 0))), 1.0, 1e-12);
  const double u_sign = glm::dot(w.axis_u_W, glm::dvec3(1, 0, 0));
  int lone = -1;
  for (int r = 0; r < 2; ++r) {
    const double x = u_sign * centre_u(out[static_cast<std::size_t>(r)]);
    if (x < 0.0) lone = r;
    EXPECT_NEAR(std::abs(x), 8e-3, 0.5e-3) << r;
    EXPECT_LE(out[static_cast<std::size_t>(r)].depth_m, 20e-6 + 1e-7) << r;
    EXPECT_GT(out[static_cast<std::size_t>(r)].depth_m, 14e-6) << r;
  }
  ASSERT_GE(lone, 0);
  EXPECT_GT(out[static_cast<std::size_t>(1 - lone)].cells,
            out[static_cast<std::size_t>(lone)].cells);
  EXPECT_GE(out[0].depth_m, out[1].depth_m);  // deepest first
  EXPECT_EQ(solver.OverlapRegions(tool, X_WT, env, testing::EnvironmentPose(), w, 20e-3, out), 1);
  EXPECT_EQ(solver.OverlapRegions(tool, X_WT, env, testing::EnvironmentPose(), w, 1e-3, out), 3);
  // Lifted clear of the bumps: no overlap, no region.
  EXPECT_EQ(solver.OverlapRegions(tool, testing::ToolPose(0.0, 0.0, 60e-6), env,
                                  testing::EnvironmentPose(), w, 5e-3, out),
            0);
}

// OverlapRegions' bridge levels (stage 5a's bridge fade, PipelineOptions):
// the three bumps linked at 1 mm are three regions. The pair 5 mm apart joins at the level where
// its superlevel sets come within the link: by symmetry on the segment between the tops, t* =
// f(2.5 mm − L/2) − 20 µm with f the two bumps' sum, −14.1 µm (±0.2 mm of cells: −15.7 to
// −11.8 µm). The lone bump joins only where the flat between them is reached, at −20 µm. The
// deepest keeps −∞; above a 17 µm floor the lone one is never reached. Lowering the flat tool by
// 5 µm raises every b − a by 5 µm, and every bridge level with it (two routes to one number).
TEST(OverlapRegions, BridgeLevelsAreTheSaddlesOfTheOverlapsMergeTree) {
  const ThreeBumps scene = MakeThreeBumps();
  const ContactWindow w = ContactWindow::Make({0.0, 0.0, 0.0}, {0.0, 0.0, 1.0}, 0.036, 90);
  TexturePenetrationSolver solver(128);
  const auto bridges = [&](double tool_z, double floor) {
    std::array<OverlapRegion, 8> out{};
    const int count = solver.OverlapRegions(scene.tool, testing::ToolPose(0.0, 0.0, tool_z),
                                            scene.env, testing::EnvironmentPose(), w, 1e-3, out,
                                            TriangleSubset::All(), TriangleSubset::All(), floor);
    EXPECT_EQ(count, 3);
    std::vector<double> levels;
    for (int r = 0; r < 3; ++r) {
      const OverlapRegion& g = out[static_cast<std::size_t>(r)];
      // The peak cell is the region's deepest sample.
      const int i = g.peak_cell % w.resolution, j = g.peak_cell / w.resolution;
      EXPECT_TRUE(i >= g.i0 && i <= g.i1 && j >= g.j0 && j <= g.j1) << r;
      levels.push_back(g.bridge_m);
    }
    EXPECT_EQ(out[0].bridge_m, -std::numeric_limits<double>::infinity());  // the deepest
    std::sort(levels.begin(), levels.end());
    return levels;
  };
  // Without a floor nothing is computed.
  for (const double level : bridges(20e-6, 0.0)) {
    EXPECT_EQ(level, -std::numeric_limits<double>::infinity());
  }
  const auto f = [](double y_mm) {
    return 40.0 * (std::exp(-y_mm * y_mm / 2.0) + std::exp(-(y_mm - 5.0) * (y_mm - 5.0) / 2.0));
  };
  EXPECT_NEAR(f(2.0) - 20.0, -14.14, 0.01);
  const std::vector<double> at20 = bridges(20e-6, 30e-6);
  EXPECT_EQ(at20[0], -std::numeric_limits<double>::infinity());
  EXPECT_NEAR(at20[1], -20e-6, 0.3e-6);  // the lone bump, over the flat
  EXPECT_GT(at20[2], (f(2.2) - 20.0) * 1e-6);
  EXPECT_LT(at20[2], (f(1.8) - 20.0) * 1e-6);
  const std::vector<double> floor17 = bridges(20e-6, 17e-6);
  EXPECT_EQ(floor17[1], -std::numeric_limits<double>::infinity());
  EXPECT_NEAR(floor17[2], at20[2], 1e-9);
  const std::vector<double> at15 = bridges(15e-6, 30e-6);
  EXPECT_NEAR(at15[1] - at20[1], 5e-6, 0.05e-6);
  EXPECT_NEAR(at15[2] - at20[2], 5e-6, 0.05e-6);
}

// Stage 5a reads its regions from stage 5's base render (PenetrationDepthBackend::base_overlap)
// where the backend keeps it, and renders the base pose again
// elsewhere. Two routes to one set of regions: the field the backend kept and a fresh
// render give the same regions, boxes, cell counts and peak cells, with depths and bridge levels
// within float rounding of the window's heights, and stage 5c's block occupancy the same bytes,
// on every texture-stage path (the fast path
// alone and with parallel renders, the reference path) and with the tool tilted. The field's
// largest value is stage 5's δ0 itself. Nothing is kept where a side has no surface on the
// window (δ0 = −∞), nor when keeping is off.
TEST(OverlapRegions, StageFivesBaseRenderGivesTheRenderedRegions) {
  const ThreeBumps scene = MakeThreeBumps();
  const ContactWindow w = ContactWindow::Make({0.0, 0.0, 0.0}, {0.0, 0.0, 1.0}, 0.036, 90);
  ContactQuery q;
  q.environment = &scene.env;
  q.X_WO = testing::EnvironmentPose();
  q.window = w;
  q.stiffness_n_per_m = 1000.0;
  struct Path {
    TextureStagePath path;
    int threads;
  };
  int compared = 0;
  for (const Path p : {Path{TextureStagePath::kFast, 1}, Path{TextureStagePath::kFast, 2},
                       Path{TextureStagePath::kReference, 1}}) {
    CpuPenetrationDepthBackend backend(128, p.path, p.threads);
    TexturePenetrationSolver solver(128, 4096, p.path);
    for (const double tilt : {0.0, 2e-3}) {
      RigidTransform X_WT = testing::ToolPose(0.3e-3, -0.2e-3, 18e-6);
      X_WT.rotation = glm::angleAxis(tilt, glm::normalize(glm::dvec3(1.0, 2.0, 0.0)));
      std::array<ContactLinearization, 1> out{};
      backend.set_keep_base_overlap(0);
      ASSERT_TRUE(backend.LinearizeBatch(scene.tool, X_WT, {&q, 1}, out));
      EXPECT_TRUE(backend.base_overlap(0).empty());
      backend.set_keep_base_overlap(w.resolution);
      ASSERT_TRUE(backend.LinearizeBatch(scene.tool, X_WT, {&q, 1}, out));
      const std::span<const float> field = backend.base_overlap(0);
      ASSERT_EQ(field.size(), static_cast<std::size_t>(w.resolution) * w.resolution);
      EXPECT_TRUE(backend.base_overlap(1).empty());  // past the batch
      {
        // A window larger than the reserve is not kept.
        CpuPenetrationDepthBackend small(128, p.path, p.threads);
        small.set_keep_base_overlap(w.resolution - 1);
        std::array<ContactLinearization, 1> o{};
        ASSERT_TRUE(small.LinearizeBatch(scene.tool, X_WT, {&q, 1}, o));
        EXPECT_TRUE(small.base_overlap(0).empty());
        EXPECT_EQ(o[0].depth_m, out[0].depth_m);
      }
      EXPECT_EQ(static_cast<float>(out[0].depth_m), *std::max_element(field.begin(), field.end()));
      for (const int block : {1, 4}) {
        std::array<std::uint8_t, 90 * 90> by_field{}, by_render{};
        const int a = solver.OverlapOccupancy(field, w, block, by_field);
        const int b =
            solver.OverlapOccupancy(scene.tool, X_WT, scene.env, q.X_WO, w, block, by_render);
        EXPECT_GT(a, 0);
        EXPECT_EQ(a, b);
        EXPECT_EQ(by_field, by_render);
      }
      for (const double link : {1e-3, 5e-3}) {
        std::array<OverlapRegion, 8> kept{}, rendered{};
        const int a = solver.OverlapRegions(field, w, link, kept, 30e-6);
        const int b = solver.OverlapRegions(scene.tool, X_WT, scene.env, q.X_WO, w, link, rendered,
                                            TriangleSubset::All(), TriangleSubset::All(), 30e-6);
        ASSERT_EQ(a, b) << tilt << " " << link;
        ASSERT_GE(a, 2);
        for (int r = 0; r < a; ++r) {
          const OverlapRegion& x = kept[static_cast<std::size_t>(r)];
          const OverlapRegion& y = rendered[static_cast<std::size_t>(r)];
          EXPECT_EQ(x.i0, y.i0);
          EXPECT_EQ(x.i1, y.i1);
          EXPECT_EQ(x.j0, y.j0);
          EXPECT_EQ(x.j1, y.j1);
          EXPECT_EQ(x.cells, y.cells);
          EXPECT_EQ(x.peak_cell, y.peak_cell);
          EXPECT_NEAR(x.depth_m, y.depth_m, 1e-9);
          if (std::isfinite(y.bridge_m)) {
            EXPECT_NEAR(x.bridge_m, y.bridge_m, 1e-9);
          } else {
            EXPECT_EQ(x.bridge_m, y.bridge_m);
          }
          ++compared;
        }
      }
      // Lifted clear: δ0 < 0, the field kept, no region in it.
      ASSERT_TRUE(
          backend.LinearizeBatch(scene.tool, testing::ToolPose(0.0, 0.0, 60e-6), {&q, 1}, out));
      EXPECT_LT(out[0].depth_m, 0.0);
      std::array<OverlapRegion, 8> none{};
      EXPECT_EQ(solver.OverlapRegions(backend.base_overlap(0), w, 1e-3, none), 0);
      // Moved off the window: no tool surface over it (δ0 = −∞), nothing kept.
      ASSERT_TRUE(
          backend.LinearizeBatch(scene.tool, testing::ToolPose(0.5, 0.0, 18e-6), {&q, 1}, out));
      EXPECT_EQ(out[0].depth_m, -std::numeric_limits<double>::infinity());
      EXPECT_TRUE(backend.base_overlap(0).empty());
    }
  }
  EXPECT_GE(compared, 24);
  // A field shorter than the window's cells gives no region.
  TexturePenetrationSolver solver(128);
  std::array<OverlapRegion, 8> out{};
  const std::vector<float> short_field(10, 1.0f);
  EXPECT_EQ(solver.OverlapRegions(short_field, w, 1e-3, out), 0);
  std::array<std::uint8_t, 90 * 90> occupancy{};
  EXPECT_EQ(solver.OverlapOccupancy(short_field, w, 1, occupancy), -1);
}

}  // namespace
}  // namespace ht
