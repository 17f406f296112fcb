// The scripted motions of seed Figs. 76 and 77 (master_station/experiment.h): phases, ranges, and
// each target's velocity against finite differences of its pose (two routes to one number).

#include <gtest/gtest.h>

#include <cmath>

#include "master_station/experiment.h"

namespace ht {
namespace {

// Central difference of the script's pose against its own velocity, over the whole run.
void ExpectVelocityMatchesThePose(const Experiment& e) {
  const double h = 1e-5;
  for (double t = 0.01; t < e.duration_s() - 0.01; t += 0.0371) {
    const HandTarget a = e.Target(t - h), b = e.Target(t + h), c = e.Target(t);
    if (a.phase != b.phase) continue;  // a phase boundary
    const glm::dvec3 v = (b.X_MH.translation - a.X_MH.translation) / (2 * h);
    EXPECT_NEAR(glm::length(v - c.V_MH_M.linear), 0.0, 1e-6) << e.name() << " t " << t;
    const Twist d = PoseDifference(b.X_MH, a.X_MH);
    EXPECT_NEAR(glm::length(d.angular / (2 * h) - c.V_MH_M.angular), 0.0, 1e-5)
        << e.name() << " t " << t;
  }
}

TEST(Fig76Experiment, PressesThenTurnsAboutNWithinTheAmplitude) {
  Fig76Params p;
  const auto e = MakeFig76Experiment(p);
  EXPECT_EQ(e->phase_names().size(), 2u);
  EXPECT_EQ(e->Target(0.0).phase, 0);
  EXPECT_NEAR(e->Target(0.0).X_MH.translation.z, p.start_height_m, 1e-12);
  double max_theta = 0.0;
  for (double t = 1.0; t <= p.duration_s; t += 0.01) {
    const HandTarget h = e->Target(t);
    EXPECT_EQ(h.phase, 1);
    EXPECT_NEAR(h.X_MH.translation.z, -p.press_depth_m, 1e-12);  // keeps pressing
    const glm::dvec3 rv = RotationVectorFromQuaternion(h.X_MH.rotation);
    EXPECT_NEAR(rv.x, 0.0, 1e-12);  // about n only
    EXPECT_NEAR(rv.y, 0.0, 1e-12);
    max_theta = std::max(max_theta, std::abs(rv.z));
  }
  EXPECT_NEAR(max_theta, p.amplitude_rad, 1e-3);
  ExpectVelocityMatchesThePose(*e);
  EXPECT_THROW(MakeFig76Experiment({.duration_s = 0.0}), std::invalid_argument);
}

TEST(Fig77Experiment, ScrapesTheStrokeWithSwayAndYaw) {
  Fig77Params p;
  const auto e = MakeFig77Experiment(p);
  EXPECT_EQ(e->Target(0.0).phase, 0);
  const HandTarget end = e->Target(p.duration_s);
  EXPECT_EQ(end.phase, 1);
  EXPECT_NEAR(end.X_MH.translation.x, p.stroke_m, 1e-9);
  double max_y = 0.0, max_yaw = 0.0;
  for (double t = 1.0; t <= p.duration_s; t += 0.01) {
    const HandTarget h = e->Target(t);
    max_y = std::max(max_y, std::abs(h.X_MH.translation.y));
    max_yaw = std::max(max_yaw, std::abs(RotationVectorFromQuaternion(h.X_MH.rotation).z));
    EXPECT_NEAR(h.X_MH.translation.z, -p.press_depth_m, 1e-12);
  }
  EXPECT_NEAR(max_y, p.sway_m, 1e-4);
  EXPECT_NEAR(max_yaw, p.yaw_rad, 1e-3);
  ExpectVelocityMatchesThePose(*e);
  EXPECT_EQ(MakeExperiment("fig77", 3.0)->duration_s(), 3.0);
  EXPECT_THROW(MakeExperiment("fig78", 3.0), std::invalid_argument);
}

}  // namespace
}  // namespace ht
