#include "haptic_core/contact_model.h"

#include <gtest/gtest.h>

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

}  // namespace
}  // namespace ht
