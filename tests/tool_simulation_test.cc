#include "haptic_core/tool_simulation.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <vector>

#include "haptic_core/demo/demo_scenes.h"

namespace ht {
namespace {

TEST(ToolSimulation, ToolSettlesOnTheHandleInFreeSpace) {
  const ToolSimulator sim(BlockOnGearToolInertia(), VirtualCoupling{});
  ToolState s;
  RigidTransform X_WH;
  X_WH.translation = {0.01, -0.02, 0.005};
  X_WH.rotation = QuaternionFromRotationVector({0.1, -0.2, 0.05});
  const ContactModel none;
  for (int i = 0; i < 5000; ++i) ASSERT_TRUE(sim.Step(s, X_WH, {}, none, 1.0, 1e-3).ok);
  const Twist d = PoseDifference(X_WH, s.X_WT);
  EXPECT_LT(glm::length(d.linear), 1e-6);
  EXPECT_LT(glm::length(d.angular), 1e-5);
}

TEST(ToolSimulation, StiffContactBalancesTheCouplingAtRest) {
  // A wall below the tool (δ = −z, k = 1e5 N/m, far stiffer than the coupling): pushing the
  // handle 5 mm into it, the tool rests where the coupling force equals the contact force.
  const ToolSimulator sim(BlockOnGearToolInertia(), VirtualCoupling{});
  ContactModel wall;
  wall.num_contacts = 1;
  wall.contacts[0].depth_m = 0.0;
  wall.contacts[0].gradient = {{0, 0, -1}, {0, 0, 0}};
  wall.contacts[0].stiffness_n_per_m = 1e5;
  RigidTransform X_WH;
  X_WH.translation = {0, 0, -5e-3};
  ToolState s;
  ToolStepResult r;
  for (int i = 0; i < 3000; ++i) r = sim.Step(s, X_WH, {}, wall, 1.0, 1e-3);
  const double k_c = VirtualCoupling{}.k_translation_n_per_m;
  const double z_expected = -k_c * 5e-3 / (k_c + 1e5);  // series springs
  EXPECT_NEAR(s.X_WT.translation.z, z_expected, 1e-7);
  EXPECT_NEAR(r.F_coupling_T_W.force.z + r.F_contact_T_W.force.z, 0.0, 1e-3);
}

// With a bound on a contact's force, a wall whose penalty force would exceed it holds the tool
// with the bound: pushed 5 mm in by the handle, the tool sinks until the coupling's force equals
// the bound (the wall adds no stiffness beyond it), and the step says the contact saturated.
TEST(ToolSimulation, ABoundedContactHoldsTheToolWithTheBound) {
  ToolSimulator sim(BlockOnGearToolInertia(), VirtualCoupling{});
  EXPECT_THROW(sim.set_max_contact_force(0.0), std::invalid_argument);
  EXPECT_THROW(sim.set_max_contact_force(std::nan("")), std::invalid_argument);
  const double bound = 2.0;
  sim.set_max_contact_force(bound);
  ContactModel wall;
  wall.num_contacts = 1;
  wall.contacts[0].depth_m = 0.0;
  wall.contacts[0].gradient = {{0, 0, -1}, {0, 0, 0}};
  wall.contacts[0].stiffness_n_per_m = 1e5;
  RigidTransform X_WH;
  X_WH.translation = {0, 0, -5e-3};  // unbounded, the wall would push back with 4.95 N
  ToolState s;
  ToolStepResult r;
  for (int i = 0; i < 3000; ++i) r = sim.Step(s, X_WH, {}, wall, 1.0, 1e-3);
  EXPECT_EQ(r.saturated_contacts, 1);
  EXPECT_NEAR(r.F_contact_T_W.force.z, bound, 1e-9);
  const double k_c = VirtualCoupling{}.k_translation_n_per_m;
  EXPECT_NEAR(s.X_WT.translation.z, -5e-3 + bound / k_c, 1e-7);  // coupling force = the bound
}

// Hunt–Crossley contact damping (D = −α·G, set_contact_damping_hunt_crossley): with no contact it
// changes nothing; on a wall it damps the contact's oscillation and leaves the resting pose where
// it was (a damper adds no force at rest).
TEST(ToolSimulation, ContactDampingDampsTheContactAndNothingElse) {
  ToolSimulator plain(BlockOnGearToolInertia(), VirtualCoupling{});
  ToolSimulator damped(BlockOnGearToolInertia(), VirtualCoupling{});
  EXPECT_THROW(damped.set_contact_damping_hunt_crossley(-1.0), std::invalid_argument);
  EXPECT_THROW(damped.set_contact_damping_hunt_crossley(std::nan("")), std::invalid_argument);
  damped.set_contact_damping_hunt_crossley(20.0);
  RigidTransform X_WH;
  X_WH.translation = {0.002, -0.001, 0.003};
  const ContactModel none;
  ToolState a, b;
  for (int i = 0; i < 200; ++i) {
    plain.Step(a, X_WH, {}, none, 1.0, 1e-3);
    damped.Step(b, X_WH, {}, none, 1.0, 1e-3);
    ASSERT_EQ(a.X_WT.translation, b.X_WT.translation) << i;
  }
  // A wall (k = 1e4 N/m) the tool hits at 0.1 m/s with the handle 1 mm inside it (rest depth
  // about 0.09 mm: α = 20 s/m damps there as β = 1.8 ms would).
  ContactModel wall;
  wall.num_contacts = 1;
  wall.contacts[0].depth_m = 0.0;
  wall.contacts[0].gradient = {{0, 0, -1}, {0, 0, 0}};
  wall.contacts[0].stiffness_n_per_m = 1e4;
  X_WH.translation = {0.0, 0.0, -1e-3};
  const auto bounce = [&](const ToolSimulator& sim, double& rest_z) {
    ToolState s;
    s.V_WT_W.linear = {0.0, 0.0, -0.1};
    double late_swing = 0.0;  // largest |v_z| from 30 ms on
    for (int i = 0; i < 3000; ++i) {
      sim.Step(s, X_WH, {}, wall, 1.0, 1e-3);
      if (i >= 30 && i < 60) late_swing = std::max(late_swing, std::abs(s.V_WT_W.linear.z));
    }
    rest_z = s.X_WT.translation.z;
    return late_swing;
  };
  double rest_plain = 0.0, rest_damped = 0.0;
  const double swing_plain = bounce(plain, rest_plain);
  const double swing_damped = bounce(damped, rest_damped);
  std::printf(
      "|v_z| 30-60 ms after the impact: %.4f m/s undamped, %.4f m/s with Hunt-Crossley "
      "20 s/m\n",
      swing_plain, swing_damped);
  EXPECT_LT(swing_damped, 0.5 * swing_plain);
  EXPECT_NEAR(rest_damped, rest_plain, 1e-9);
}

TEST(ToolSimulation, NonFiniteHandleHoldsTheTool) {
  const ToolSimulator sim(BlockOnGearToolInertia(), VirtualCoupling{});
  ToolState s;
  s.V_WT_W.linear = {0.1, 0, 0};
  RigidTransform bad;
  bad.translation.y = NAN;
  const ToolStepResult r = sim.Step(s, bad, {}, ContactModel{}, 1.0, 1e-3);
  EXPECT_FALSE(r.ok);
  EXPECT_TRUE(IsFiniteRigidTransform(s.X_WT));
  EXPECT_EQ(glm::length(s.V_WT_W.linear), 0.0);
  EXPECT_TRUE(IsFinite(r.F_coupling_T_W));
}

TEST(ToolSimulation, RejectsBadParameters) {
  VirtualCoupling c;
  c.k_translation_n_per_m = -1;
  EXPECT_THROW(ToolSimulator(BlockOnGearToolInertia(), c), std::invalid_argument);
  EXPECT_THROW(ToolSimulator(ToolInertia{0.0, {1, 1, 1}}, VirtualCoupling{}),
               std::invalid_argument);
}

TEST(ToolSimulation, ANewModelBlendsInWithBoundedForceSteps) {
  // Two contact models that disagree (a 1 mm deeper contact): switching at once jumps the contact
  // force by k·1 mm; blending over N ticks moves it by about a N-th of that per tick.
  const ToolSimulator sim(BlockOnGearToolInertia(), VirtualCoupling{});
  ContactModel a;
  a.num_contacts = 1;
  a.contacts[0].depth_m = 0.5e-3;
  a.contacts[0].gradient.d_translation_W = {0, 0, -1};
  a.contacts[0].stiffness_n_per_m = 4000;
  a.contacts[0].normal_W = {0, 0, 1};
  ContactModel b = a;
  b.contacts[0].depth_m = 1.5e-3;
  const int N = 4;
  ToolState s;
  const RigidTransform X_WH;
  double last = EvaluateContactModel(a, s.X_WT).F_T_W.force.z;
  double largest_step = 0.0;
  for (int k = 1; k <= N; ++k) {
    ToolState probe = s;  // the same tool pose each tick: only the blend changes
    const ToolStepResult r = sim.StepBlended(probe, X_WH, {}, b, a, double(k) / N, 1e-3);
    largest_step = std::max(largest_step, std::abs(r.F_contact_T_W.force.z - last));
    last = r.F_contact_T_W.force.z;
  }
  const double jump = 4000 * 1e-3;
  EXPECT_NEAR(last, EvaluateContactModel(b, s.X_WT).F_T_W.force.z, 1e-9);
  EXPECT_NEAR(largest_step, jump / N, 1e-9);
  // Blend 1 is the plain step with the current model, blend 0 the previous one.
  ToolState p1 = s, p2 = s;
  EXPECT_EQ(sim.StepBlended(p1, X_WH, {}, b, a, 1.0, 1e-3).F_contact_T_W.force,
            sim.Step(p2, X_WH, {}, b, 1.0, 1e-3).F_contact_T_W.force);
}

}  // namespace
}  // namespace ht
