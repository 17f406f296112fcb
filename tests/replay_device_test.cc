// The replay device: a recorded trajectory is played at its own timestamps, and bad files give a
// clear error naming the file and the line.
#include "master_station/replay_device.h"

#include <gtest/gtest.h>

#include <fstream>

namespace ht {
namespace {

std::string WriteFile(const std::string& name, const std::string& text) {
  const std::string path = ::testing::TempDir() + "/" + name;
  std::ofstream(path) << text;
  return path;
}

TEST(ReplayDevice, PlaysAtTheFilesTimestampsWithInterpolationAndSlope) {
  const std::string path = WriteFile("replay_ok.csv",
                                     "t_s,x,y,z,rx,ry,rz\n"
                                     "0.0,0,0,0,0,0,0\n"
                                     "0.1,0.01,0,0,0,0,0.1\n"
                                     "0.3,0.01,0.02,0,0,0,0.1\n");
  ReplayDevice d(LoadReplayTrace(path, {}), path);
  EXPECT_NEAR(d.duration_s(), 0.3, 1e-12);
  d.Open();
  DeviceState s;
  const std::int64_t t0 = 5'000'000'000;
  ASSERT_TRUE(d.ReadState(t0, s));
  EXPECT_NEAR(s.X_MH.translation.x, 0.0, 1e-12);
  ASSERT_TRUE(d.ReadState(t0 + 50'000'000, s));  // halfway through the first interval
  EXPECT_NEAR(s.X_MH.translation.x, 0.005, 1e-12);
  EXPECT_NEAR(s.V_MH_M.linear.x, 0.1, 1e-9);  // 1 cm in 0.1 s
  EXPECT_NEAR(RotationVectorFromQuaternion(s.X_MH.rotation).z, 0.05, 1e-9);
  EXPECT_NEAR(s.V_MH_M.angular.z, 1.0, 1e-9);
  ASSERT_TRUE(d.ReadState(t0 + 200'000'000, s));
  EXPECT_NEAR(s.X_MH.translation.y, 0.01, 1e-12);
  EXPECT_NEAR(s.V_MH_M.linear.y, 0.1, 1e-9);
  ASSERT_TRUE(d.ReadState(t0 + 900'000'000, s));  // after the end: holds still
  EXPECT_NEAR(s.X_MH.translation.y, 0.02, 1e-12);
  EXPECT_EQ(s.V_MH_M.linear, glm::dvec3(0.0));
  EXPECT_TRUE(d.WriteWrench({}, t0));
  EXPECT_EQ(d.wrenches_written(), 1);
}

TEST(ReplayDevice, ReadsAStationTraceInWorldCoordinates) {
  const std::string path = WriteFile("replay_trace.csv",
                                     "t_s,phase,hand_x,hand_y,hand_z\n"
                                     "0.0,x,1.0,2.0,3.0\n"
                                     "0.001,x,1.001,2.0,3.0\n");
  const auto samples = LoadReplayTrace(path, {1.0, 2.0, 3.0});
  ASSERT_EQ(samples.size(), 2u);
  EXPECT_NEAR(samples[1].X_MH.translation.x, 0.001, 1e-12);
}

TEST(ReplayDevice, BadFilesNameTheFileAndTheLine) {
  const auto expect_error = [](const std::string& text, const std::string& fragment) {
    const std::string path = WriteFile("replay_bad.csv", text);
    try {
      LoadReplayTrace(path, {});
      ADD_FAILURE() << "accepted: " << text;
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("replay_bad.csv"), std::string::npos) << e.what();
    }
  };
  expect_error("time,a,b\n0,1,2\n", "header must name");
  expect_error("t_s,x,y,z\n0,0,0,0\n0,1,1,1\n", "line 3: time does not increase");
  expect_error("t_s,x,y,z\n0,0,0,0\n0.1,nan,0,0\n", "line 3: x is not a finite number");
  expect_error("t_s,x,y,z\n0,0,0,0\n0.1,0,0\n", "no z column");
  expect_error("t_s,x,y,z\n0,0,0,0\n", "fewer than 2");
  EXPECT_THROW(LoadReplayTrace(::testing::TempDir() + "/missing.csv", {}), std::runtime_error);
}

}  // namespace
}  // namespace ht
