// OpenHaptics backend against a fake HD library (fake_hd.cc) loaded through the backend's own
// dlopen path, its servo ticks run one at a time by the test: the messages when the library, a
// symbol or the device is missing, the capabilities the device reports, the frames and signs of
// pose, force and torque, the clamp to the device's limits, zero wrench on close and after a
// device error, and no allocation in the loop's calls or the servo callback. Its own program: it
// counts allocations (allocation_counter.h).

#include "master_station/openhaptics.h"

#include <dlfcn.h>
#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <numbers>
#include <stdexcept>
#include <string>

#include "allocation_counter.h"

namespace ht::openhaptics {
namespace {

constexpr unsigned int kHdCommError = 0x0302;  // hdDefines.h HD_COMM_ERROR
constexpr double kNoTorque[3] = {0.0, 0.0, 0.0};
constexpr double kPremiumTorque_mNm[3] = {188.0, 188.0, 150.0};

// The fake's controls, from the same file the backend loads.
struct Fake {
  void (*reset)(int, int, int, double, const double*);
  void (*set_stylus)(const double*, const double*, const double*, int);
  int (*tick)();
  void (*inject_error)(unsigned int, int);
  void (*outputs)(double*, double*, double*, long*);
  void (*log)(char*, int);

  static const Fake& Instance() {
    static const Fake fake = [] {
      void* h = dlopen(HT_FAKE_HD, RTLD_NOW | RTLD_LOCAL);
      if (!h) throw std::runtime_error(std::string("cannot load the fake: ") + dlerror());
      Fake f;
      f.reset = reinterpret_cast<decltype(f.reset)>(dlsym(h, "fake_hd_reset"));
      f.set_stylus = reinterpret_cast<decltype(f.set_stylus)>(dlsym(h, "fake_hd_set_stylus"));
      f.tick = reinterpret_cast<decltype(f.tick)>(dlsym(h, "fake_hd_tick"));
      f.inject_error = reinterpret_cast<decltype(f.inject_error)>(dlsym(h, "fake_hd_inject_error"));
      f.outputs = reinterpret_cast<decltype(f.outputs)>(dlsym(h, "fake_hd_outputs"));
      f.log = reinterpret_cast<decltype(f.log)>(dlsym(h, "fake_hd_log"));
      return f;
    }();
    return fake;
  }
  struct Outputs {
    glm::dvec3 force, torque_mNm, force_at_stop;
    long force_sets, torque_sets, sets_outside_frame;
  };
  Outputs Read() const {
    double f[3], t[3], s[3];
    long counts[3];
    outputs(f, t, s, counts);
    return {{f[0], f[1], f[2]}, {t[0], t[1], t[2]}, {s[0], s[1], s[2]},
            counts[0],          counts[1],          counts[2]};
  }
  std::string Log() const {
    char text[512];
    log(text, sizeof text);
    return text;
  }
};

// The simulated clock the device and the test share (ns).
std::atomic<std::int64_t> g_now_ns{1'000'000'000};
std::int64_t TestClock() noexcept { return g_now_ns.load(); }

OpenHapticsConfig FakeConfig(const char* library = HT_FAKE_HD) {
  OpenHapticsConfig c;
  c.library_path = library;
  c.clock_ns = &TestClock;
  return c;
}

std::string OpenMessage(OpenHapticsDevice& d) {
  try {
    d.Open();
  } catch (const std::runtime_error& e) {
    return e.what();
  }
  return "";
}

void ExpectNear(const glm::dvec3& a, const glm::dvec3& b, double tol, const char* what) {
  EXPECT_NEAR(a.x, b.x, tol) << what;
  EXPECT_NEAR(a.y, b.y, tol) << what;
  EXPECT_NEAR(a.z, b.z, tol) << what;
}

class OpenHapticsTest : public ::testing::Test {
 protected:
  void SetUp() override { Touch(); }
  // A Touch: 6-DoF in, 3-DoF out, 3.3 N.
  void Touch() { fake.reset(1, 6, 3, 3.3, kNoTorque); }
  // A Phantom Premium 6DOF: 6-DoF in and out, 8.5 N, per-axis torque in mN·m.
  void Premium() { fake.reset(1, 6, 6, 8.5, kPremiumTorque_mNm); }
  const Fake& fake = Fake::Instance();
};

TEST_F(OpenHapticsTest, AnAbsentLibraryIsNamedWithWhatToInstall) {
  OpenHapticsDevice d(FakeConfig("/nonexistent/libHD.so"));
  const std::string m = OpenMessage(d);
  EXPECT_NE(m.find("OpenHaptics"), std::string::npos) << m;
  EXPECT_NE(m.find("/nonexistent/libHD.so"), std::string::npos) << m;
  EXPECT_NE(m.find("Install OpenHaptics"), std::string::npos) << m;
  EXPECT_NE(m.find("--device-library"), std::string::npos) << m;
}

TEST_F(OpenHapticsTest, WithoutAPathTheUsualNamesAreTriedAndListed) {
  if (void* h = dlopen("libHD.so", RTLD_NOW | RTLD_LOCAL)) {
    dlclose(h);
    GTEST_SKIP() << "an HD library is installed here";
  }
  OpenHapticsConfig c = FakeConfig();
  c.library_path.clear();
  OpenHapticsDevice d(c);
  const std::string m = OpenMessage(d);
  EXPECT_NE(m.find("libHD.so, libHD.so.3.4"), std::string::npos) << m;
  EXPECT_NE(m.find("Install OpenHaptics"), std::string::npos) << m;
}

TEST_F(OpenHapticsTest, AMissingSymbolIsNamed) {
  OpenHapticsDevice d(FakeConfig(HT_FAKE_HD_INCOMPLETE));
  const std::string m = OpenMessage(d);
  EXPECT_NE(m.find("has no hdScheduleAsynchronous"), std::string::npos) << m;
  EXPECT_NE(m.find("Install OpenHaptics"), std::string::npos) << m;
}

TEST_F(OpenHapticsTest, NoDeviceGivesHdsErrorTextAndCode) {
  fake.reset(0, 6, 3, 3.3, kNoTorque);
  OpenHapticsDevice d(FakeConfig());
  const std::string m = OpenMessage(d);
  EXPECT_NE(m.find("hdInitDevice(HD_DEFAULT_DEVICE)"), std::string::npos) << m;
  EXPECT_NE(m.find("fake: communication error"), std::string::npos) << m;
  EXPECT_NE(m.find("0x0302"), std::string::npos) << m;
  EXPECT_NE(m.find("Touch_Setup"), std::string::npos) << m;
}

TEST_F(OpenHapticsTest, CapabilitiesComeFromTheDevice) {
  OpenHapticsDevice d(FakeConfig());
  EXPECT_EQ(d.capabilities().max_force_n, 0.0);  // nothing is known before Open
  d.Open();
  const DeviceCapabilities c = d.capabilities();
  EXPECT_NE(c.name.find("Fake Touch"), std::string::npos) << c.name;
  EXPECT_EQ(c.max_force_n, 3.3);
  EXPECT_EQ(c.max_torque_nm, 0.0);
  EXPECT_NEAR(c.max_stiffness_n_per_m, 750.0, 1e-9);  // 0.75 N/mm
  EXPECT_NEAR(c.max_damping_ns_per_m, 4.0, 1e-9);     // 0.004 N·s/mm
  EXPECT_EQ(c.dof_in, 6);
  EXPECT_EQ(c.dof_out, 3);
  // Usable workspace 160 x 120 x 80 mm (x, y up, z towards the operator) -> in M: x, z, y.
  ExpectNear(c.workspace_half_extents_m, {0.080, 0.040, 0.060}, 1e-12, "half extents in M");
  d.Close();

  Premium();
  OpenHapticsDevice p(FakeConfig());
  p.Open();
  const DeviceCapabilities pc = p.capabilities();
  EXPECT_EQ(pc.dof_out, 6);
  EXPECT_NEAR(pc.max_torque_nm, 0.150, 1e-12);  // the weakest gimbal axis, mN·m -> N·m
  EXPECT_NEAR(pc.max_rotational_stiffness_nm_per_rad, 0.3, 1e-12);
}

TEST_F(OpenHapticsTest, PoseAndTwistAreTurnedIntoMWithZUpAboutTheWorkspaceCentre) {
  // P: +x right, +y up, +z towards the operator. The fake's workspace centre is (0, 20, 10) mm.
  const double a = std::numbers::pi / 6.0, c = std::cos(a), s = std::sin(a);
  // 30 degrees about P's +y (up), column-major, at (10, 20, 30) mm.
  const double T_up[16] = {c, 0, -s, 0, 0, 1, 0, 0, s, 0, c, 0, 10, 20, 30, 1};
  const double v[3] = {100.0, 200.0, 300.0};  // mm/s
  const double w[3] = {0.5, 1.0, 0.0};        // rad/s
  fake.set_stylus(T_up, v, w, 0x3);
  OpenHapticsDevice d(FakeConfig());
  d.Open();
  DeviceState st;
  EXPECT_FALSE(d.ReadState(g_now_ns.load(), st));  // no servo tick yet
  ASSERT_EQ(fake.tick(), 1);
  ASSERT_TRUE(d.ReadState(g_now_ns.load(), st));
  // About the centre: (10, 0, 20) mm = 1 cm right, 0 up, 2 cm towards the operator.
  ExpectNear(st.X_MH.translation, {0.010, -0.020, 0.0}, 1e-12, "p_MH");
  ExpectNear(st.X_MH.translation, kR_MP * glm::dvec3(0.010, 0.0, 0.020), 1e-12, "kR_MP p");
  ExpectNear(st.V_MH_M.linear, {0.1, -0.3, 0.2}, 1e-12, "v_MH_M");
  ExpectNear(st.V_MH_M.angular, {0.5, 0.0, 1.0}, 1e-12, "w_MH_M");
  ExpectNear(RotationVectorFromQuaternion(st.X_MH.rotation), {0.0, 0.0, a}, 1e-9,
             "a turn about up is a turn about +z_M");
  EXPECT_EQ(st.buttons, 0x3u);

  // 30 degrees about P's +z (towards the operator) = about -y_M.
  const double T_z[16] = {c, s, 0, 0, -s, c, 0, 0, 0, 0, 1, 0, 0, 20, 10, 1};
  fake.set_stylus(T_z, v, w, 0);
  ASSERT_EQ(fake.tick(), 1);
  ASSERT_TRUE(d.ReadState(g_now_ns.load(), st));
  ExpectNear(st.X_MH.translation, glm::dvec3(0.0), 1e-12, "the centre is M's origin");
  ExpectNear(RotationVectorFromQuaternion(st.X_MH.rotation), {0.0, -a, 0.0}, 1e-9,
             "a turn about the axis towards the operator is a turn about -y_M");
}

TEST_F(OpenHapticsTest, ForceAndTorqueReachTheDeviceInItsFrameAndUnits) {
  Premium();
  OpenHapticsDevice d(FakeConfig());
  d.Open();
  // 1 N right, 2 N away from the operator, 3 N up; torque likewise in N·m / 100.
  const Wrench F_H_M{{1.0, 2.0, 3.0}, {0.01, 0.02, 0.03}};
  ASSERT_TRUE(d.WriteWrench(F_H_M, g_now_ns.load()));
  ASSERT_EQ(fake.tick(), 1);
  const Fake::Outputs out = fake.Read();
  ExpectNear(out.force, {1.0, 3.0, -2.0}, 1e-12, "f_P (N)");
  ExpectNear(out.torque_mNm, {10.0, 30.0, -20.0}, 1e-9, "t_P (mN·m)");
  ExpectNear(out.force, glm::transpose(kR_MP) * F_H_M.force, 1e-12, "kR_MP^T f");
  EXPECT_EQ(out.sets_outside_frame, 0);
}

TEST_F(OpenHapticsTest, AThreeDofOutputDeviceIsNeverSentTorque) {
  OpenHapticsDevice d(FakeConfig());
  d.Open();
  ASSERT_TRUE(d.WriteWrench({{0.0, 0.0, 1.0}, {0.1, 0.1, 0.1}}, g_now_ns.load()));
  ASSERT_EQ(fake.tick(), 1);
  const Fake::Outputs out = fake.Read();
  EXPECT_EQ(out.force.y, 1.0);  // up
  EXPECT_EQ(out.torque_sets, 0);
}

TEST_F(OpenHapticsTest, ClampsToTheDevicesLimitsKeepingDirection) {
  Premium();
  OpenHapticsDevice d(FakeConfig());
  d.Open();
  ASSERT_TRUE(d.WriteWrench({{0.0, 30.0, 40.0}, {0.0, 0.0, 1.0}}, g_now_ns.load()));
  ASSERT_EQ(fake.tick(), 1);
  const Fake::Outputs out = fake.Read();
  EXPECT_NEAR(glm::length(out.force), 8.5, 1e-9);
  ExpectNear(out.force / glm::length(out.force), {0.0, 0.8, -0.6}, 1e-12, "direction kept");
  EXPECT_NEAR(out.torque_mNm.y, 150.0, 1e-9);  // 1 N·m about up, cut to 0.150 N·m
  EXPECT_GT(d.status().saturated_commands, 0u);
}

TEST_F(OpenHapticsTest, ADeviceErrorRendersZeroAndGivesNoStateUntilACleanFrame) {
  OpenHapticsDevice d(FakeConfig());
  d.Open();
  DeviceState st;
  ASSERT_TRUE(d.WriteWrench({{0.0, 0.0, 2.0}, {}}, g_now_ns.load()));
  ASSERT_EQ(fake.tick(), 1);
  ASSERT_EQ(fake.Read().force.y, 2.0);

  // An error while the frame reads: that frame renders zero and publishes no state.
  fake.inject_error(kHdCommError, 0);
  ASSERT_EQ(fake.tick(), 1);
  ExpectNear(fake.Read().force, glm::dvec3(0.0), 0.0, "the faulty frame");
  EXPECT_FALSE(d.ReadState(g_now_ns.load(), st));
  EXPECT_EQ(d.status().last_error_code, kHdCommError);
  ASSERT_EQ(fake.tick(), 1);  // a clean frame: state and force are back
  EXPECT_TRUE(d.ReadState(g_now_ns.load(), st));
  EXPECT_EQ(fake.Read().force.y, 2.0);

  // An error at the end of a frame (what it sent may be wrong): no state, the next frame zero.
  fake.inject_error(kHdCommError, 1);
  ASSERT_EQ(fake.tick(), 1);
  EXPECT_FALSE(d.ReadState(g_now_ns.load(), st));
  ASSERT_EQ(fake.tick(), 1);
  ExpectNear(fake.Read().force, glm::dvec3(0.0), 0.0, "the frame after");
  EXPECT_FALSE(d.ReadState(g_now_ns.load(), st));
  ASSERT_EQ(fake.tick(), 1);
  EXPECT_TRUE(d.ReadState(g_now_ns.load(), st));
  EXPECT_EQ(fake.Read().force.y, 2.0);
  EXPECT_EQ(d.status().device_errors, 2u);
}

TEST_F(OpenHapticsTest, ANonFiniteOrStaleWrenchRendersZero) {
  OpenHapticsDevice d(FakeConfig());
  d.Open();
  ASSERT_TRUE(d.WriteWrench({{0.0, 0.0, 2.0}, {}}, g_now_ns.load()));
  ASSERT_EQ(fake.tick(), 1);
  ASSERT_EQ(fake.Read().force.y, 2.0);
  EXPECT_FALSE(d.WriteWrench({{std::nan(""), 0.0, 0.0}, {}}, g_now_ns.load()));
  ASSERT_EQ(fake.tick(), 1);
  ExpectNear(fake.Read().force, glm::dvec3(0.0), 0.0, "non-finite");

  ASSERT_TRUE(d.WriteWrench({{0.0, 0.0, 2.0}, {}}, g_now_ns.load()));
  g_now_ns += 100'000'000;  // the loop has not written for 0.1 s (> wrench_timeout_s)
  ASSERT_EQ(fake.tick(), 1);
  ExpectNear(fake.Read().force, glm::dvec3(0.0), 0.0, "stale");
  EXPECT_GT(d.status().stale_wrenches, 0u);
}

TEST_F(OpenHapticsTest, CloseRendersZeroThenStopsTheSchedulerAndDisablesTheDevice) {
  Premium();
  OpenHapticsDevice d(FakeConfig());
  d.Open();
  ASSERT_TRUE(d.WriteWrench({{1.0, 1.0, 1.0}, {0.05, 0.0, 0.0}}, g_now_ns.load()));
  ASSERT_EQ(fake.tick(), 1);
  ASSERT_EQ(fake.Read().force.x, 1.0);
  d.Close();
  const Fake::Outputs out = fake.Read();
  ExpectNear(out.force_at_stop, glm::dvec3(0.0), 0.0, "force when the scheduler stopped");
  ExpectNear(out.torque_mNm, glm::dvec3(0.0), 0.0, "torque");
  EXPECT_EQ(out.sets_outside_frame, 0);
  EXPECT_EQ(fake.Log(),
            "init_default,enable_force,schedule_async,start_scheduler,schedule_sync,"
            "stop_scheduler,unschedule,disable_device");
  EXPECT_EQ(fake.tick(), 0);  // nothing runs any more
  DeviceState st;
  EXPECT_FALSE(d.ReadState(g_now_ns.load(), st));
  EXPECT_FALSE(d.WriteWrench({}, g_now_ns.load()));
}

TEST_F(OpenHapticsTest, TheLoopsCallsAndTheServoCallbackAllocateNothing) {
  Premium();
  OpenHapticsDevice d(FakeConfig());
  d.Open();
  DeviceState st;
  fake.tick();
  const long before = testing_support::Allocations();
  for (int i = 0; i < 200; ++i) {
    d.ReadState(g_now_ns.load(), st);
    d.WriteWrench({{0.0, 0.0, 0.001 * i}, {0.0, 0.0, 0.0001 * i}}, g_now_ns.load());
    fake.tick();  // the servo callback
  }
  EXPECT_EQ(testing_support::Allocations() - before, 0);
  EXPECT_EQ(d.status().frames, 201u);
}

}  // namespace
}  // namespace ht::openhaptics
