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

// Issue 33's attribution rests on the loop being conservative within one model: the wrench is
// the negative gradient of the potential (two routes: the potential's central differences and the
// wrench), unsaturated and with one contact held at the force bound.
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
  // Half the stiffness, half the potential.
  EXPECT_NEAR(EvaluateContactModel(two, two.X_WT0, 0.5).potential_energy_j,
              0.5 * EvaluateContactModel(two, two.X_WT0).potential_energy_j, 1e-18);
}

}  // namespace
}  // namespace ht
