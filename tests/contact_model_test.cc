#include "haptic_core/contact_model.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

namespace ht {
namespace {

ContactModel TwoContactModel() {
  ContactModel m;
  m.X_WT0.translation = {0.01, 0.0, 0.03};
  m.num_contacts = 2;
  m.contacts[0].depth_m = 2e-4;
  m.contacts[0].gradient = {{0.3, -0.1, -1.0}, {0.002, 0.004, -0.001}};
  m.contacts[0].stiffness_n_per_m = 5000;
  m.contacts[1].depth_m = 1e-4;
  m.contacts[1].gradient = {{-0.2, 0.0, -1.0}, {-0.003, 0.001, 0.0005}};
  m.contacts[1].stiffness_n_per_m = 3000;
  return m;
}

TEST(ContactModel, EvaluatedAtQ0EqualsTheSumOfPenaltyWrenches) {
  const ContactModel m = TwoContactModel();
  const ContactModelEvaluation e = EvaluateContactModel(m, m.X_WT0);
  const Wrench expected = PenaltyWrench(2e-4, m.contacts[0].gradient, 5000) +
                          PenaltyWrench(1e-4, m.contacts[1].gradient, 3000);
  EXPECT_NEAR(glm::length(e.F_T_W.force - expected.force), 0.0, 1e-12);
  EXPECT_NEAR(glm::length(e.F_T_W.torque - expected.torque), 0.0, 1e-12);
  EXPECT_EQ(e.active_contacts, 2);
}

// G, the depth-weighted stiffness behind Hunt–Crossley damping: Σ k_i δ_i J_i J_iᵀ by hand, and
// zero for a contact that only touches (δ = 0), where −K is not.
TEST(ContactModel, DepthWeightedStiffnessIsSumOfKDeltaJJt) {
  const ContactModel m = TwoContactModel();
  const ContactModelEvaluation e = EvaluateContactModel(m, m.X_WT0);
  Stiffness6 expected = Stiffness6::Zero();
  for (int i = 0; i < 2; ++i) {
    const ContactLinearization& c = m.contacts[i];
    Eigen::Matrix<double, 6, 1> J;
    J << c.gradient.d_translation_W.x, c.gradient.d_translation_W.y, c.gradient.d_translation_W.z,
        c.gradient.d_rotation_W.x, c.gradient.d_rotation_W.y, c.gradient.d_rotation_W.z;
    expected += c.stiffness_n_per_m * c.depth_m * (J * J.transpose());
  }
  EXPECT_LT((e.G - expected).norm(), 1e-12 * expected.norm());
  ContactModel touching = m;
  touching.num_contacts = 1;
  touching.contacts[0].depth_m = 1e-12;
  const ContactModelEvaluation t = EvaluateContactModel(touching, touching.X_WT0);
  EXPECT_LT(t.G.norm(), 1e-6);
  EXPECT_GT((-t.K).norm(), 1000.0);
}

TEST(ContactModel, StiffnessMatchesFiniteDifferencesOfTheWrench) {
  const ContactModel m = TwoContactModel();
  const ContactModelEvaluation e0 = EvaluateContactModel(m, m.X_WT0);
  const double h = 1e-7;
  for (int j = 0; j < 6; ++j) {
    Twist d;
    (j < 3 ? d.linear[j] : d.angular[j - 3]) = h;
    const ContactModelEvaluation e = EvaluateContactModel(m, Displace(m.X_WT0, d));
    const glm::dvec3 df = (e.F_T_W.force - e0.F_T_W.force) / h;
    const glm::dvec3 dt = (e.F_T_W.torque - e0.F_T_W.torque) / h;
    for (int i = 0; i < 3; ++i) {
      EXPECT_NEAR(df[i], e0.K(i, j), 1e-3 * (1 + std::abs(e0.K(i, j))));
      EXPECT_NEAR(dt[i], e0.K(3 + i, j), 1e-3 * (1 + std::abs(e0.K(3 + i, j))));
    }
  }
}

TEST(ContactModel, ContactsSwitchOffWhenTheToolLeaves) {
  const ContactModel m = TwoContactModel();
  RigidTransform X = m.X_WT0;
  X.translation.z += 1.5e-4;  // δ1 = 1e-4 − 1.5e-4 < 0, δ0 = 0.5e-4 > 0
  EXPECT_EQ(EvaluateContactModel(m, X).active_contacts, 1);
  X.translation.z += 1e-3;
  const ContactModelEvaluation e = EvaluateContactModel(m, X);
  EXPECT_EQ(e.active_contacts, 0);
  EXPECT_EQ(glm::length(e.F_T_W.force), 0.0);
  EXPECT_EQ(e.K.norm(), 0.0);
}

// DESIGN.md §5's bound on the delivered stiffness: a contact whose force exceeds the bound pushes
// with exactly the bound, along its own direction, and adds no stiffness; one below the bound is
// untouched (the same numbers as without a bound); the bound is continuous at its edge.
TEST(ContactModel, TheForceBoundSaturatesOnlyTheContactsBeyondIt) {
  ContactModel m = TwoContactModel();
  m.contacts[0].depth_m = 0.03;  // a grazing contact's 30 mm: 5000 · 0.03 · |J_x| ≈ 157 N
  const ContactModelEvaluation free = EvaluateContactModel(m, m.X_WT0);
  const double bound = 20.0;
  const ContactModelEvaluation e = EvaluateContactModel(m, m.X_WT0, 1.0, bound);
  EXPECT_EQ(e.active_contacts, 2);
  EXPECT_EQ(e.saturated_contacts, 1);
  EXPECT_EQ(free.saturated_contacts, 0);
  const Wrench small = PenaltyWrench(1e-4, m.contacts[1].gradient, 3000);
  const Wrench big = (e.F_T_W + Wrench{-small.force, -small.torque});
  EXPECT_NEAR(glm::length(big.force), bound, 1e-9);
  const Wrench big_free = PenaltyWrench(0.03, m.contacts[0].gradient, 5000);
  EXPECT_NEAR(glm::length(glm::normalize(big.force) - glm::normalize(big_free.force)), 0.0, 1e-12);
  // Torque scales with the force (the same saturated depth).
  EXPECT_NEAR(glm::length(big.torque) / glm::length(big_free.torque),
              bound / glm::length(big_free.force), 1e-12);
  // Only the unsaturated contact stiffens: K is that contact's alone.
  ContactModel only_small = m;
  only_small.contacts[0].depth_m = -1.0;
  const ContactModelEvaluation s = EvaluateContactModel(only_small, m.X_WT0);
  EXPECT_NEAR((e.K - s.K).norm(), 0.0, 1e-12);
  // Below the bound nothing changes, bit for bit.
  const ContactModelEvaluation low = EvaluateContactModel(TwoContactModel(), m.X_WT0, 1.0, bound);
  const ContactModelEvaluation low_free = EvaluateContactModel(TwoContactModel(), m.X_WT0);
  EXPECT_EQ(low.F_T_W.force, low_free.F_T_W.force);
  EXPECT_EQ(low.K, low_free.K);
  EXPECT_EQ(low.saturated_contacts, 0);
  // Two blended evaluations of one model (scales β and 1 − β, as StepBlended does) add up to the
  // bound at most, not twice it.
  ContactModel deep = m;
  deep.contacts[1].depth_m = -1.0;
  const Wrench blended = EvaluateContactModel(deep, m.X_WT0, 0.25, bound).F_T_W +
                         EvaluateContactModel(deep, m.X_WT0, 0.75, bound).F_T_W;
  EXPECT_NEAR(glm::length(blended.force), bound, 1e-9);
  // Continuous at the edge: just beyond the bound the force is the bound.
  const double edge = bound / (5000 * glm::length(m.contacts[0].gradient.d_translation_W));
  m.contacts[0].depth_m = edge * (1 + 1e-9);
  EXPECT_NEAR(glm::length(EvaluateContactModel(m, m.X_WT0, 1.0, bound).F_T_W.force - small.force),
              bound, 1e-6);
}

TEST(ContactModel, NonFiniteInputsGiveZeroWrench) {
  ContactModel m = TwoContactModel();
  RigidTransform X = m.X_WT0;
  X.translation.x = NAN;
  EXPECT_EQ(glm::length(EvaluateContactModel(m, X).F_T_W.force), 0.0);
  m.contacts[0].depth_m = INFINITY;
  const ContactModelEvaluation e = EvaluateContactModel(m, m.X_WT0);
  EXPECT_EQ(e.active_contacts, 1);
  EXPECT_TRUE(IsFinite(e.F_T_W));
}

// A flat face resting on two edges r = 2 cm either side of the tool's centre of mass, as the
// remote step sends it (AddKinkPlanes): δ(θ) is a V in the tilt θ about y with its vertex at θ_v,
// δ_v deep there; at q0 (θ = 0) the bearing arm is the contact's own plane (slope +r) and the
// other arm a kink plane (slope −r).
constexpr double kR = 0.02, kDepthV = 1e-4, kThetaV = -1e-3;
ContactModel RestingFace() {
  ContactModel m;
  m.X_WT0.translation = {0.0, 0.0, 0.035};
  m.num_contacts = 1;
  ContactLinearization& c = m.contacts[0];
  c.depth_m = kDepthV + kR * (0.0 - kThetaV);
  c.gradient = {{0.0, 0.0, -1.0}, {0.0, kR, 0.0}};
  c.stiffness_n_per_m = 8000;
  c.num_kink_planes = 1;
  c.kink_planes[0] = {kDepthV - kR * (0.0 - kThetaV), {0.0, -kR, 0.0}};
  return m;
}

Twist Tilt(double theta) { return {{0, 0, 0}, {0, theta, 0}}; }

TEST(ContactModel, KinkPlanesGiveTheVAndBlendOnlyAtItsVertex) {
  const ContactModel m = RestingFace();
  const ContactLinearization& c = m.contacts[0];
  const double blend_half_width = kKinkBlendM / (2 * kR);  // rad: the arms' gap reaches ε
  double largest_step = 0.0, previous = 0.0;
  const int n = 4000;
  for (int i = 0; i <= n; ++i) {
    const double theta = kThetaV - 2e-3 + 4e-3 * i / n;
    PenetrationGradient J;
    const double depth = ContactDepthAt(c, Tilt(theta), &J);
    const double v = kDepthV + kR * std::abs(theta - kThetaV);
    if (std::abs(theta - kThetaV) > blend_half_width) {
      // The V exactly, along the bearing arm's gradient.
      EXPECT_NEAR(depth, v, 1e-15) << theta;
      EXPECT_NEAR(J.d_rotation_W.y, theta > kThetaV ? kR : -kR, 1e-15) << theta;
    } else {
      EXPECT_GE(depth, v - 1e-15) << theta;
      EXPECT_LE(depth, v + kKinkBlendM / 4 + 1e-15) << theta;
    }
    EXPECT_EQ(J.d_translation_W, c.gradient.d_translation_W);
    if (i > 0) largest_step = std::max(largest_step, std::abs(J.d_rotation_W.y - previous));
    previous = J.d_rotation_W.y;
  }
  // Continuous: the 4000 steps of 1 µrad cross the 0.5 mrad-wide blend in about 500 steps.
  EXPECT_LT(largest_step, 0.01 * 2 * kR);
  // At the vertex both edges bear half: no torque.
  PenetrationGradient J;
  EXPECT_NEAR(ContactDepthAt(c, Tilt(kThetaV), &J), kDepthV + kKinkBlendM / 4, 1e-15);
  EXPECT_NEAR(J.d_rotation_W.y, 0.0, 1e-15);
  // Without kink planes: the contact's own plane, δ0 + J·Δq.
  ContactLinearization one = c;
  one.num_kink_planes = 0;
  const Twist dq{{1e-4, -2e-4, 3e-4}, {2e-3, -4e-3, 1e-3}};
  EXPECT_EQ(ContactDepthAt(one, dq), one.depth_m + one.gradient.Dot(dq));
}

TEST(ContactModel, KinkCurvatureAndStiffnessMatchFiniteDifferences) {
  // Inside the blend (a quarter of its half-width from the vertex), two routes to one number:
  // the curvature against differences of the gradient, and K against differences of the wrench.
  const ContactModel m = RestingFace();
  const double theta0 = kThetaV + 0.25 * kKinkBlendM / (2 * kR);
  PenetrationGradient J0;
  Stiffness6 H;
  ContactDepthAt(m.contacts[0], Tilt(theta0), &J0, &H);
  const double h = 1e-9;
  PenetrationGradient J1;
  ContactDepthAt(m.contacts[0], Tilt(theta0 + h), &J1);
  EXPECT_NEAR((J1.d_rotation_W.y - J0.d_rotation_W.y) / h, H(4, 4), 1e-4 * H(4, 4));
  EXPECT_GT(H(4, 4), 0.0);
  EXPECT_EQ((H.topLeftCorner<3, 3>().norm()), 0.0);

  const RigidTransform X0 = Displace(m.X_WT0, Tilt(theta0));
  const ContactModelEvaluation e0 = EvaluateContactModel(m, X0);
  for (int j = 0; j < 6; ++j) {
    Twist d;
    (j < 3 ? d.linear[j] : d.angular[j - 3]) = h;
    const ContactModelEvaluation e = EvaluateContactModel(m, Displace(X0, d));
    const glm::dvec3 df = (e.F_T_W.force - e0.F_T_W.force) / h;
    const glm::dvec3 dt = (e.F_T_W.torque - e0.F_T_W.torque) / h;
    for (int i = 0; i < 3; ++i) {
      EXPECT_NEAR(df[i], e0.K(i, j), 1e-3 * (1 + std::abs(e0.K(i, j)))) << i << " " << j;
      EXPECT_NEAR(dt[i], e0.K(3 + i, j), 1e-3 * (1 + std::abs(e0.K(3 + i, j)))) << i << " " << j;
    }
  }
}

// Translation kink planes (issue 32, ninth stop): a tool whose texture lies between two ridges'
// flanks has a depth shaped like a V in its position x, with its vertex at x_v; the contact's own
// plane is one arm (slope +s along x) and a kink plane with its own translation slope the other
// (−s: offset −2s). The V exactly outside the blend, the slope flipping continuously inside it,
// and the curvature's translation block against differences of the gradient (two routes).
TEST(ContactModel, TranslationKinkPlanesGiveTheVInPosition) {
  constexpr double s = 0.6, x_v = -2e-5, d_v = 5e-5;
  ContactLinearization c;
  c.depth_m = d_v + s * (0.0 - x_v);
  c.gradient = {{s, 0.0, -1.0}, {0.0, 0.01, 0.0}};
  c.stiffness_n_per_m = 8000;
  c.num_kink_planes = 1;
  c.kink_planes[0].depth_m = d_v - s * (0.0 - x_v);
  c.kink_planes[0].d_rotation_W = c.gradient.d_rotation_W;
  c.kink_planes[0].d_translation_offset_W = {-2.0 * s, 0.0, 0.0};
  const double blend_half_width = kKinkBlendM / (2 * s);
  double largest_step = 0.0, previous = 0.0;
  const int n = 4000;
  for (int i = 0; i <= n; ++i) {
    const double x = x_v - 1e-4 + 2e-4 * i / n;
    PenetrationGradient J;
    const double depth = ContactDepthAt(c, {{x, 0.0, 0.0}, {0.0, 0.0, 0.0}}, &J);
    const double v = d_v + s * std::abs(x - x_v);
    if (std::abs(x - x_v) > blend_half_width) {
      EXPECT_NEAR(depth, v, 1e-15) << x;
      EXPECT_NEAR(J.d_translation_W.x, x > x_v ? s : -s, 1e-15) << x;
    } else {
      EXPECT_GE(depth, v - 1e-15) << x;
      EXPECT_LE(depth, v + kKinkBlendM / 4 + 1e-15) << x;
    }
    EXPECT_EQ(J.d_translation_W.z, -1.0);
    EXPECT_EQ(J.d_rotation_W, c.gradient.d_rotation_W);  // the arms share ∂δ/∂θ
    if (i > 0) largest_step = std::max(largest_step, std::abs(J.d_translation_W.x - previous));
    previous = J.d_translation_W.x;
  }
  EXPECT_LT(largest_step, 0.01 * 2 * s);  // continuous across the ≈17 µm-wide blend
  // Inside the blend: the curvature against differences of the gradient, translation block only.
  const double x0 = x_v + 0.25 * blend_half_width, h = 1e-10;
  PenetrationGradient J0, J1;
  Stiffness6 H;
  ContactDepthAt(c, {{x0, 0.0, 0.0}, {0.0, 0.0, 0.0}}, &J0, &H);
  ContactDepthAt(c, {{x0 + h, 0.0, 0.0}, {0.0, 0.0, 0.0}}, &J1);
  EXPECT_GT(H(0, 0), 0.0);
  EXPECT_NEAR((J1.d_translation_W.x - J0.d_translation_W.x) / h, H(0, 0), 1e-4 * H(0, 0));
  EXPECT_EQ((H.bottomRightCorner<3, 3>().norm()), 0.0);
  // The plane's own slope on a contact without it: the contact's ∂δ/∂x plus the offset.
  ContactLinearization alone = c;
  alone.depth_m = -1.0;  // the plane alone bears
  PenetrationGradient J;
  ContactDepthAt(alone, {{1e-4, 0.0, 0.0}, {0.0, 0.0, 0.0}}, &J);
  EXPECT_DOUBLE_EQ(J.d_translation_W.x, -s);
}

// Issue 33's attribution rests on the loop being conservative within one model: the wrench is
// the negative gradient of the potential (two routes: the potential's central differences and the
// wrench), unsaturated, with one contact held at the force bound, and inside a kink blend.
TEST(ContactModel, TheWrenchIsTheNegativeGradientOfThePotential) {
  const auto check = [](const ContactModel& m, const RigidTransform& X0, double bound,
                        const char* what) {
    const ContactModelEvaluation e0 = EvaluateContactModel(m, X0, 1.0, bound);
    ASSERT_GT(e0.potential_energy_j, 0.0) << what;
    const double h = 1e-8;
    for (int j = 0; j < 6; ++j) {
      Twist d;
      (j < 3 ? d.linear[j] : d.angular[j - 3]) = h;
      const double up = EvaluateContactModel(m, Displace(X0, d), 1.0, bound).potential_energy_j;
      const double down = EvaluateContactModel(m, Displace(X0, {-d.linear, -d.angular}), 1.0, bound)
                              .potential_energy_j;
      const double dU = (up - down) / (2 * h);
      const double F = j < 3 ? e0.F_T_W.force[j] : e0.F_T_W.torque[j - 3];
      EXPECT_NEAR(-dU, F, 1e-5 * (1 + std::abs(F))) << what << " " << j;
    }
  };
  const ContactModel two = TwoContactModel();
  check(two, two.X_WT0, std::numeric_limits<double>::infinity(), "unsaturated");
  // 5000 N/m · 2e-4 m · |(0.3, −0.1, −1)| ≈ 1.05 N: a 0.6 N bound holds the first contact only.
  const ContactModelEvaluation held = EvaluateContactModel(two, two.X_WT0, 1.0, 0.6);
  EXPECT_EQ(held.saturated_contacts, 1);
  check(two, two.X_WT0, 0.6, "one contact saturated");
  const ContactModel face = RestingFace();
  check(face, Displace(face.X_WT0, Tilt(kThetaV + 0.25 * kKinkBlendM / (2 * kR))),
        std::numeric_limits<double>::infinity(), "inside the kink blend");
  // ... and inside the blend of a translation arm (its own ∂δ/∂x: offset −2·0.4 along x).
  ContactModel slope = face;
  slope.contacts[0].gradient.d_translation_W = {0.4, 0.0, -1.0};
  slope.contacts[0].kink_planes[0] = {
      slope.contacts[0].depth_m - 2e-6, {0.0, kR, 0.0}, {-0.8, 0.0, 0.0}};
  check(slope, Displace(slope.X_WT0, {{-1e-6, 0.0, 0.0}, {0.0, 0.0, 0.0}}),
        std::numeric_limits<double>::infinity(), "inside a translation arm's blend");
  // Half the stiffness, half the potential (the blend's weights scale U linearly).
  EXPECT_NEAR(EvaluateContactModel(two, two.X_WT0, 0.5).potential_energy_j,
              0.5 * EvaluateContactModel(two, two.X_WT0).potential_energy_j, 1e-18);
}

}  // namespace
}  // namespace ht
