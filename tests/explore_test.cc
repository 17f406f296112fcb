// The explore experiment (master_station/experiment.h), the simulated hand's force control
// (master_station/simulated_operator.h) and the scene layout a remote node announces
// (slave_sim/remote_node.h MakeSceneLayout).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <set>
#include <string>

#include "haptic_core/demo/demo_scenes.h"
#include "haptic_core/demo/procedural_models.h"
#include "haptic_core/haptic_scene.h"
#include "haptic_core/hull_proximity.h"
#include "master_station/experiment.h"
#include "master_station/simulated_operator.h"
#include "slave_sim/remote_node.h"

namespace ht {
namespace {

ExperimentTarget Target(glm::dvec3 lo, glm::dvec3 hi, glm::dvec3 top, double approach_z) {
  ExperimentTarget t;
  t.box_min_M = lo;
  t.box_max_M = hi;
  t.top_M = top;
  t.approach_z_M = approach_z;
  return t;
}

/// Three objects: one under the workspace centre, two far away (a large scene).
ExperimentScene ThreeObjects() {
  ExperimentScene scene;
  scene.tool_extent_down_m = 0.01;
  scene.targets.push_back(
      Target({-0.05, -0.05, -0.1}, {0.05, 0.05, -0.02}, {0.001, 0.0, -0.021}, -0.0));
  scene.targets.push_back(Target({1.9, -0.1, -0.5}, {2.1, 0.1, -0.3}, {2.0, 0.02, -0.31}, -0.28));
  scene.targets.push_back(
      Target({-3.1, 0.9, -0.2}, {-2.9, 1.1, -0.05}, {-3.0, 1.0, -0.06}, -0.035));
  return scene;
}

std::string PhaseOf(const Experiment& e, double t) {
  return e.phase_names().at(static_cast<std::size_t>(e.Target(t).phase));
}

TEST(Explore, WithoutASceneItPressesBelowTheWorkspaceCentre) {
  ExploreParams p;
  p.duration_s = 4.0;
  const auto e = MakeExploreExperiment(p);
  EXPECT_EQ(e->name(), "explore");
  bool pressed = false;
  for (double t = 0.0; t < 4.0; t += 0.01) {
    const HandTarget h = e->Target(t);
    EXPECT_EQ(h.workspace_shift_M, glm::dvec3(0.0)) << "no jump needed at " << t;
    EXPECT_LT(std::hypot(h.X_MH.translation.x, h.X_MH.translation.y), 0.02);
    if (h.z_control == HandZControl::kPress) {
      pressed = true;
      EXPECT_EQ(h.press_force_n, p.press_force_n);
      EXPECT_LT(h.floor_z_m, h.X_MH.translation.z);
    }
  }
  EXPECT_TRUE(pressed);
  EXPECT_THROW(MakeExperiment("explore", -1.0), std::invalid_argument);
  EXPECT_NO_THROW(MakeExperiment("explore", 2.0));
}

TEST(Explore, VisitsEveryObjectAndJumpsOnlyBetweenFreeSpacePoints) {
  ExploreParams p;
  p.duration_s = 40.0;
  const auto e = MakeExploreExperiment(p);
  const ExperimentScene scene = ThreeObjects();
  e->SetScene(scene);
  ASSERT_EQ(e->phase_names().size(), 15u);
  std::set<std::string> pressed;
  int jumps = 0;
  HandTarget last = e->Target(0.0);
  for (double t = 0.001; t <= p.duration_s; t += 0.001) {
    const HandTarget h = e->Target(t);
    const std::string phase = PhaseOf(*e, t);
    if (h.z_control == HandZControl::kPress) pressed.insert(phase);
    // In the device, the handle never jumps sideways (1 ms apart: < 1.5 mm at ≤ 1 m/s; along z
    // the hand's own control takes over from the script in presses).
    const glm::dvec3 device_now = h.X_MH.translation - h.workspace_shift_M;
    const glm::dvec3 device_last = last.X_MH.translation - last.workspace_shift_M;
    EXPECT_LT(glm::length(glm::dvec2(device_now - device_last)), 1.5e-3) << phase << " at " << t;
    if (h.workspace_shift_M != last.workspace_shift_M) {
      ++jumps;
      // Only while moving between objects, in position control, and to a point the remote node
      // checked (the target's approach height over its top).
      EXPECT_EQ(phase.rfind("transfer@", 0), 0u) << phase;
      EXPECT_EQ(h.z_control, HandZControl::kPosition);
      EXPECT_EQ(last.z_control, HandZControl::kPosition);
      const int k = std::stoi(phase.substr(phase.find('@') + 1)) - 1;
      const ExperimentTarget& target = scene.targets[static_cast<std::size_t>(k)];
      EXPECT_NEAR(h.X_MH.translation.x, target.top_M.x, 0.041);
      EXPECT_NEAR(h.X_MH.translation.y, target.top_M.y, 0.041);
      EXPECT_NEAR(h.X_MH.translation.z,
                  std::max(target.approach_z_M, target.top_M.z + scene.tool_extent_down_m), 1e-12);
      // Where it left from: the point where the previous press started (free space too).
      EXPECT_GE(last.X_MH.translation.z, -0.3);
    }
    last = h;
  }
  for (int k = 1; k <= 3; ++k) {
    EXPECT_TRUE(pressed.count("press@" + std::to_string(k))) << "object " << k << " not pressed";
    EXPECT_TRUE(pressed.count("slide_x@" + std::to_string(k)));
    EXPECT_TRUE(pressed.count("slide_y@" + std::to_string(k)));
  }
  EXPECT_GE(jumps, 3) << "the far objects are reached by jumps";
}

/// A fixed hand target (for the hand's own force control).
class FixedTarget final : public Experiment {
 public:
  explicit FixedTarget(HandTarget target) : target_(target) {}
  const std::string& name() const noexcept override { return name_; }
  double duration_s() const noexcept override { return 100.0; }
  const std::vector<std::string>& phase_names() const noexcept override { return phases_; }
  HandTarget Target(double) const noexcept override { return target_; }
  HandTarget target_;

 private:
  std::string name_ = "fixed";
  std::vector<std::string> phases_ = {"fixed"};
};

/// Runs the simulated hand for `seconds` at 1 kHz against a spring wall at z = wall_z (N/m),
/// returning the last upward force.
double PressOnWall(SimulatedOperatorDevice& device, double wall_z, double k, double seconds,
                   std::int64_t& now_ns, DeviceState& state) {
  double force = 0.0;
  for (int i = 0; i < static_cast<int>(seconds * 1000); ++i) {
    now_ns += 1000000;
    EXPECT_TRUE(device.ReadState(now_ns, state));
    const double z = state.X_MH.translation.z;
    force = z < wall_z ? k * (wall_z - z) - 20.0 * std::min(0.0, state.V_MH_M.linear.z) : 0.0;
    force = std::max(0.0, force);
    Wrench w;
    w.force.z = force;
    EXPECT_TRUE(device.WriteWrench(w, now_ns));
  }
  return force;
}

/// A force-controlled press target at the workspace centre.
HandTarget Press(double force_n, double floor_z_m, double slow_below_z_m) {
  HandTarget press;
  press.z_control = HandZControl::kPress;
  press.press_force_n = force_n;
  press.floor_z_m = floor_z_m;
  press.slow_below_z_m = slow_below_z_m;
  return press;
}

TEST(SimulatedOperator, PressFindsASurfaceOfUnknownHeightAndHoldsTheForce) {
  FixedTarget script(Press(2.0, -0.2, -0.03));
  SimulatedOperatorDevice device(script);
  device.Open();
  std::int64_t now = 1000000000;
  DeviceState s;
  const double wall_z = -0.07, k = 2000.0;
  const double f = PressOnWall(device, wall_z, k, 4.0, now, s);
  EXPECT_NEAR(f, 2.0, 0.05) << "the hand holds the wanted force";
  EXPECT_NEAR(s.X_MH.translation.z, wall_z - 2.0 / k, 1e-4);
  // Lifting off: rises by lift_m from where it pressed, and the force goes.
  script.target_.z_control = HandZControl::kLift;
  script.target_.lift_m = 0.005;
  const double f_lift = PressOnWall(device, wall_z, k, 2.0, now, s);
  EXPECT_EQ(f_lift, 0.0);
  EXPECT_GT(s.X_MH.translation.z, wall_z);
  EXPECT_LT(s.X_MH.translation.z, wall_z + 0.006);
}

// A tool wedged against a side pushes the hand sideways as well as up: lifting off, the hand also
// moves along that push (the contact's normal), and keeps that offset once the push is gone,
// until the script moves it sideways again.
TEST(SimulatedOperator, ALiftLeavesAlongTheFeltForceAndKeepsThatOffset) {
  HandTarget lift;
  lift.z_control = HandZControl::kLift;
  lift.lift_m = 0.005;
  FixedTarget script(lift);
  SimulatedOperatorDevice device(script);
  device.Open();
  std::int64_t now = 1000000000;
  DeviceState s;
  const auto run = [&](double seconds, const glm::dvec3& felt) {
    for (int i = 0; i < static_cast<int>(seconds * 1000); ++i) {
      now += 1000000;
      ASSERT_TRUE(device.ReadState(now, s));
      Wrench w;
      w.force = felt;
      ASSERT_TRUE(device.WriteWrench(w, now));
    }
  };
  run(0.1, {3.0, 0.0, 1.0});  // wedged: pushed along +x (and up)
  run(1.0, {0.0, 0.0, 0.0});  // free
  // 0.1 s at the slow speed times the push's sideways share (3/√10): about 4.7 mm.
  const double expected =
      0.1 * OperatorHandParams{}.press_slow_speed_m_per_s * 3.0 / std::sqrt(10.0);
  EXPECT_NEAR(s.X_MH.translation.x, expected, 0.2 * expected);
  EXPECT_NEAR(s.X_MH.translation.y, 0.0, 1e-5);
  // The script moves the hand sideways again: the offset is taken back.
  script.target_.z_control = HandZControl::kPosition;
  script.target_.V_MH_M.linear.y = 1e-6;
  run(1.0, {0.0, 0.0, 0.0});
  EXPECT_NEAR(s.X_MH.translation.x, 0.0, 1e-4);
}

TEST(SimulatedOperator, PressWithNothingBelowStopsAtTheFloor) {
  FixedTarget script(Press(1.5, -0.05, -0.01));
  SimulatedOperatorDevice device(script);
  device.Open();
  std::int64_t now = 1000000000;
  DeviceState s;
  PressOnWall(device, -1.0, 1000.0, 3.0, now, s);
  EXPECT_NEAR(s.X_MH.translation.z, -0.05, 1e-3);
  // Back to position control: returns to the script's z (0) at the fast speed.
  script.target_.z_control = HandZControl::kPosition;
  PressOnWall(device, -1.0, 1000.0, 1.0, now, s);
  EXPECT_NEAR(s.X_MH.translation.z, 0.0, 1e-3);
}

TEST(SceneLayout, BlockOnGearHasTheGearAsItsTargetAndAClearApproach) {
  const HapticScene scene = MakeBlockOnGearScene();
  const wire::SceneLayout layout = MakeSceneLayout(scene);
  EXPECT_EQ(layout.X_WT_home.translation, scene.X_WT_home.translation);
  EXPECT_EQ(layout.tool_mass_kg, scene.tool->mass_kg);
  EXPECT_NEAR(layout.tool_extent_down_m, RidgedBlockParams{}.half_extents_m.z, 1e-3);
  ASSERT_EQ(layout.num_targets, 1);
  const wire::WelcomeTarget& t = layout.targets[0];
  for (int a = 0; a < 3; ++a) {
    EXPECT_LE(t.box_min_W[a], t.top_W[a]);
    EXPECT_GE(t.box_max_W[a], t.top_W[a]);
  }
  // The approach is clear (an independent query at a tolerance of 0.5 mm finds nothing) and
  // tight (the first candidate: tool reach + at most 2 cm of texture + 1 cm).
  RigidTransform X_WT = scene.X_WT_home;
  X_WT.translation = t.top_W + t.approach_m * glm::dvec3(0, 0, 1);
  HullProximityQuery query;
  ProximityQueryOptions options;
  options.tolerance_m = 5e-4;
  const auto& gear = scene.touchables[0];
  EXPECT_TRUE(query.Query(*scene.tool, X_WT, *gear.model, gear.X_WO, options).empty());
  EXPECT_LE(t.approach_m, layout.tool_extent_down_m + 0.03 + 1e-9);
  EXPECT_GE(t.approach_m, layout.tool_extent_down_m);
}

TEST(SceneLayout, AnObjectUnderAnotherIsApproachedAboveTheOneOnTop) {
  HapticScene scene;
  scene.name = "shelf";
  scene.tool = std::make_shared<const HapticModel>(MakeRidgedBlock());
  const auto flat = [](double, double) { return 0.0; };
  // A small box on the floor, and a wide slab 2 cm above it covering it (the gap is too low for
  // the 2 cm tall tool).
  auto small = std::make_shared<const HapticModel>(
      MakeTexturedBox({0.02, 0.02, 0.02}, flat, 16, 0.1, "small"));
  auto slab =
      std::make_shared<const HapticModel>(MakeTexturedBox({0.2, 0.2, 0.01}, flat, 16, 1.0, "slab"));
  TouchableObject a{small, {}, 8000.0};
  a.X_WO.translation = {0.0, 0.0, 0.02};
  TouchableObject b{slab, {}, 8000.0};
  b.X_WO.translation = {0.0, 0.0, 0.07};
  scene.touchables = {a, b};
  scene.X_WT_home.translation = {0.0, 0.0, 0.10};
  const wire::SceneLayout layout = MakeSceneLayout(scene);
  ASSERT_EQ(layout.num_targets, 2);
  EXPECT_NEAR(layout.targets[0].top_W.z, 0.08, 1e-9) << "the larger first: the slab";
  EXPECT_NEAR(layout.targets[1].top_W.z, 0.04, 1e-9);
  // Over the small box, the tool can only be put above the slab.
  EXPECT_GE(layout.targets[1].top_W.z + layout.targets[1].approach_m,
            0.08 + layout.tool_extent_down_m);
  EXPECT_LE(layout.targets[0].approach_m, layout.tool_extent_down_m + 0.03 + 1e-9);
}

TEST(SceneLayout, AFlatTopIsPressedAtItsMiddleNotAtACorner) {
  // A flat 4 × 4 cm plate (issue 33: explore pressed its corner, the highest vertex that came
  // first, and slid off its edge). Turned 30° about up and moved, its top's target is the middle
  // of the top face; a pyramid's is its apex (no flat top: the highest vertex).
  HapticScene scene;
  scene.name = "plate";
  scene.tool = std::make_shared<const HapticModel>(MakeRidgedBlock());
  const auto flat = [](double, double) { return 0.0; };
  TouchableObject plate{std::make_shared<const HapticModel>(
                            MakeTexturedBox({0.02, 0.02, 0.0025}, flat, 16, 0.1, "plate")),
                        {},
                        8000.0};
  plate.X_WO.translation = {0.1, -0.05, 0.0};
  plate.X_WO.rotation = glm::angleAxis(0.5, glm::dvec3(0.0, 0.0, 1.0));
  scene.touchables = {plate};
  scene.X_WT_home.translation = {0.1, -0.05, 0.05};
  const wire::SceneLayout layout = MakeSceneLayout(scene);
  ASSERT_EQ(layout.num_targets, 1);
  EXPECT_NEAR(layout.targets[0].top_W.x, 0.1, 1e-12);
  EXPECT_NEAR(layout.targets[0].top_W.y, -0.05, 1e-12);
  EXPECT_NEAR(layout.targets[0].top_W.z, 0.0025, 1e-12);
  // A tetrahedron standing on a face: its apex.
  HapticModel tip = MakeRidgedBlock();
  tip.vertices_O = {{-0.01, -0.01, 0.0}, {0.01, -0.01, 0.0}, {0.0, 0.01, 0.0}, {0.002, 0.0, 0.02}};
  tip.triangles = {{0, 2, 1}, {0, 1, 3}, {1, 2, 3}, {2, 0, 3}};
  tip.hull_vertices_O = tip.vertices_O;  // (the other per-triangle arrays are not read here)
  scene.touchables[0].model = std::make_shared<const HapticModel>(tip);
  scene.touchables[0].X_WO = {};
  const wire::SceneLayout apex = MakeSceneLayout(scene);
  ASSERT_EQ(apex.num_targets, 1);
  EXPECT_EQ(apex.targets[0].top_W, glm::dvec3(0.002, 0.0, 0.02));
}

}  // namespace
}  // namespace ht
