// Force Dimension backend against a fake DHD library (fake_dhd.cc) loaded through the backend's
// own dlopen path: the messages when the library, a symbol or the device is missing, the
// capabilities it reads, the frames and signs of pose, force and torque, the clamp to the
// device's limits, zero wrench on close and on a fault, and no allocation per tick. Its own
// program: it counts allocations (allocation_counter.h).

#include "master_station/force_dimension.h"

#include <dlfcn.h>
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <functional>
#include <numbers>
#include <stdexcept>
#include <string>
#include <thread>

#include "allocation_counter.h"

namespace ht::force_dimension {
namespace {

using namespace std::chrono_literals;

// dhdc.h device types.
constexpr int kOmega6Right = 34;
constexpr int kOmega7Right = 35;
constexpr int kSigma7Right = 104;

// The fake's controls, from the same file the backend loads.
struct Fake {
  void (*reset)(int, int, int, int, int);
  void (*set_limits)(double, double);
  void (*set_handle)(const double*, const double*, const double*, const double*, unsigned int);
  void (*fail_reads)(int);
  void (*mark)();
  void (*since_mark)(long*, long*);
  void (*wrenches)(double*, double*);
  void (*set_counts)(long*, long*);
  void (*log)(char*, int);

  static const Fake& Instance() {
    static const Fake fake = [] {
      void* h = dlopen(HT_FAKE_DHD, RTLD_NOW | RTLD_LOCAL);
      if (!h) throw std::runtime_error(std::string("cannot load the fake: ") + dlerror());
      Fake f;
      f.reset = reinterpret_cast<decltype(f.reset)>(dlsym(h, "fake_dhd_reset"));
      f.set_limits = reinterpret_cast<decltype(f.set_limits)>(dlsym(h, "fake_dhd_set_limits"));
      f.set_handle = reinterpret_cast<decltype(f.set_handle)>(dlsym(h, "fake_dhd_set_handle"));
      f.fail_reads = reinterpret_cast<decltype(f.fail_reads)>(dlsym(h, "fake_dhd_fail_reads"));
      f.mark = reinterpret_cast<decltype(f.mark)>(dlsym(h, "fake_dhd_mark"));
      f.since_mark = reinterpret_cast<decltype(f.since_mark)>(dlsym(h, "fake_dhd_since_mark"));
      f.wrenches = reinterpret_cast<decltype(f.wrenches)>(dlsym(h, "fake_dhd_wrenches"));
      f.set_counts = reinterpret_cast<decltype(f.set_counts)>(dlsym(h, "fake_dhd_set_counts"));
      f.log = reinterpret_cast<decltype(f.log)>(dlsym(h, "fake_dhd_log"));
      return f;
    }();
    return fake;
  }
  std::string Log() const {
    char text[512];
    log(text, sizeof text);
    return text;
  }
  struct Commanded {
    glm::dvec3 force, torque;
    double gripper;
  };
  Commanded Last() const {
    double last[7], before_stop[7];
    wrenches(last, before_stop);
    return {{last[0], last[1], last[2]}, {last[3], last[4], last[5]}, last[6]};
  }
  Commanded BeforeStop() const {
    double last[7], before_stop[7];
    wrenches(last, before_stop);
    return {{before_stop[0], before_stop[1], before_stop[2]},
            {before_stop[3], before_stop[4], before_stop[5]},
            before_stop[6]};
  }
};

// The simulated clock the device and the test share (ns): wrenches are fresh until it is moved.
std::atomic<std::int64_t> g_now_ns{1'000'000'000};
std::int64_t TestClock() noexcept { return g_now_ns.load(); }

ForceDimensionConfig FakeConfig(const char* library = HT_FAKE_DHD) {
  ForceDimensionConfig c;
  c.library_path = library;
  c.clock_ns = &TestClock;
  return c;
}

// Polls `done` every millisecond until it holds or `timeout` passes (a bound, not a timing
// check: the I/O thread runs at its own pace).
bool WaitUntil(const std::function<bool()>& done, std::chrono::milliseconds timeout = 5s) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (!done()) {
    if (std::chrono::steady_clock::now() > deadline) return false;
    std::this_thread::sleep_for(1ms);
  }
  return true;
}

std::string OpenMessage(ForceDimensionDevice& d) {
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

class ForceDimensionTest : public ::testing::Test {
 protected:
  void SetUp() override { Reset(kSigma7Right, true, true, false); }
  void Reset(int type, bool wrist, bool active_wrist, bool gripper) {
    Fake::Instance().reset(1, type, wrist, active_wrist, gripper);
  }
  const Fake& fake = Fake::Instance();
};

TEST_F(ForceDimensionTest, AnAbsentLibraryIsNamedWithWhatToInstall) {
  ForceDimensionDevice d(FakeConfig("/nonexistent/libdhd.so"));
  const std::string m = OpenMessage(d);
  EXPECT_NE(m.find("Force Dimension"), std::string::npos) << m;
  EXPECT_NE(m.find("/nonexistent/libdhd.so"), std::string::npos) << m;
  EXPECT_NE(m.find("Install the Force Dimension SDK"), std::string::npos) << m;
  EXPECT_NE(m.find("--device-library"), std::string::npos) << m;
}

TEST_F(ForceDimensionTest, WithoutAPathTheUsualNamesAreTriedAndListed) {
  if (void* h = dlopen("libdhd.so", RTLD_NOW | RTLD_LOCAL)) {
    dlclose(h);
    GTEST_SKIP() << "a DHD library is installed here";
  }
  ForceDimensionConfig c = FakeConfig();
  c.library_path.clear();
  ForceDimensionDevice d(c);
  const std::string m = OpenMessage(d);
  EXPECT_NE(m.find("libdhd.so, libdhd.so.3"), std::string::npos) << m;
  EXPECT_NE(m.find("Install the Force Dimension SDK"), std::string::npos) << m;
}

TEST_F(ForceDimensionTest, AMissingSymbolIsNamed) {
  ForceDimensionDevice d(FakeConfig(HT_FAKE_DHD_INCOMPLETE));
  const std::string m = OpenMessage(d);
  EXPECT_NE(m.find("has no dhdSetForceAndTorque"), std::string::npos) << m;
  EXPECT_NE(m.find("Force Dimension SDK"), std::string::npos) << m;
}

TEST_F(ForceDimensionTest, NoDeviceGivesTheLibrarysErrorText) {
  fake.reset(0, kSigma7Right, 1, 1, 0);
  ForceDimensionDevice d(FakeConfig());
  const std::string m = OpenMessage(d);
  EXPECT_NE(m.find("dhdOpen found no device"), std::string::npos) << m;
  EXPECT_NE(m.find("fake: no device found"), std::string::npos) << m;
  EXPECT_FALSE(d.status().running);
}

TEST_F(ForceDimensionTest, CapabilitiesComeFromTheDeviceAfterOpen) {
  ForceDimensionDevice d(FakeConfig());
  EXPECT_EQ(d.capabilities().max_force_n, 0.0);  // nothing is known before Open
  fake.set_limits(8.0, -1.0);                    // a force limit set on the device, no torque one
  d.Open();
  const DeviceCapabilities c = d.capabilities();
  EXPECT_NE(c.name.find("fake.7"), std::string::npos) << c.name;
  EXPECT_EQ(c.max_force_n, 8.0);    // the device's limit, below sigma.7's 12 N
  EXPECT_EQ(c.max_torque_nm, 0.2);  // sigma.7
  EXPECT_EQ(c.max_stiffness_n_per_m, 4000.0);
  EXPECT_EQ(c.dof_in, 6);
  EXPECT_EQ(c.dof_out, 6);
  EXPECT_NEAR(glm::length(c.workspace_half_extents_m), 0.075, 1e-12);  // the cube in r = 7.5 cm
  d.Close();

  Reset(kOmega6Right, true, false, false);  // a passive wrist: orientation in, no torque out
  ForceDimensionDevice omega(FakeConfig());
  omega.Open();
  const DeviceCapabilities o = omega.capabilities();
  EXPECT_EQ(o.max_force_n, 12.0);
  EXPECT_EQ(o.max_torque_nm, 0.0);
  EXPECT_EQ(o.dof_in, 6);
  EXPECT_EQ(o.dof_out, 3);
}

TEST_F(ForceDimensionTest, PoseAndTwistAreTurnedIntoMWithZUp) {
  // DHD's base: +x towards the operator, +y right, +z up. M: +x right, +y away, +z up.
  // 30 degrees about DHD's +z (up) and, separately checked, about its +x.
  const double a = std::numbers::pi / 6.0, c = std::cos(a), s = std::sin(a);
  const double p[3] = {0.01, 0.02, 0.03};  // 1 cm towards the operator, 2 right, 3 up
  const double Rz[9] = {c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0};
  const double v[3] = {0.1, 0.2, 0.3};
  const double w[3] = {0.5, 0.0, 1.0};
  fake.set_handle(p, Rz, v, w, 0x5);
  ForceDimensionDevice d(FakeConfig());
  d.Open();
  DeviceState st;
  ASSERT_TRUE(WaitUntil([&] { return d.ReadState(g_now_ns.load(), st); }));
  // By the meaning of the axes: right = +x_M, towards the operator = -y_M, up = +z_M.
  ExpectNear(st.X_MH.translation, {0.02, -0.01, 0.03}, 1e-12, "p_MH");
  ExpectNear(st.V_MH_M.linear, {0.2, -0.1, 0.3}, 1e-12, "v_MH_M");
  ExpectNear(st.V_MH_M.angular, {0.0, -0.5, 1.0}, 1e-12, "w_MH_M");
  // The same numbers through kR_MD.
  ExpectNear(st.X_MH.translation, kR_MD * glm::dvec3(0.01, 0.02, 0.03), 1e-12, "kR_MD p");
  // A turn about the vertical stays a turn about the vertical, by the same angle.
  const glm::dvec3 rv = RotationVectorFromQuaternion(st.X_MH.rotation);
  ExpectNear(rv, {0.0, 0.0, a}, 1e-9, "rotation about up");
  EXPECT_EQ(st.buttons, 0x5u);
  d.Close();

  const double Rx[9] = {1.0, 0.0, 0.0, 0.0, c, -s, 0.0, s, c};  // about the operator-facing axis
  fake.set_handle(p, Rx, v, w, 0);
  ForceDimensionDevice d2(FakeConfig());
  d2.Open();
  ASSERT_TRUE(WaitUntil([&] { return d2.ReadState(g_now_ns.load(), st); }));
  ExpectNear(RotationVectorFromQuaternion(st.X_MH.rotation), {0.0, -a, 0.0}, 1e-9,
             "rotation about the axis towards the operator = about -y_M");
}

TEST_F(ForceDimensionTest, ForceAndTorqueReachTheDeviceInItsFrame) {
  ForceDimensionDevice d(FakeConfig());
  d.Open();
  // 1 N right, 2 N away from the operator, 3 N up; torque likewise in N·m / 100.
  const Wrench F_H_M{{1.0, 2.0, 3.0}, {0.01, 0.02, 0.03}};
  ASSERT_TRUE(d.WriteWrench(F_H_M, g_now_ns.load()));
  ASSERT_TRUE(WaitUntil([&] { return fake.Last().force.z == 3.0; }));
  const Fake::Commanded got = fake.Last();
  // DHD: +x towards the operator (= -away), +y right, +z up.
  ExpectNear(got.force, {-2.0, 1.0, 3.0}, 1e-12, "f_D");
  ExpectNear(got.torque, {-0.02, 0.01, 0.03}, 1e-12, "t_D");
  ExpectNear(got.force, glm::transpose(kR_MD) * F_H_M.force, 1e-12, "kR_MD^T f");
}

TEST_F(ForceDimensionTest, ClampsToTheDevicesLimitsKeepingDirection) {
  ForceDimensionDevice d(FakeConfig());
  d.Open();
  ASSERT_TRUE(d.WriteWrench({{0.0, 30.0, 40.0}, {0.0, 0.0, 1.0}}, g_now_ns.load()));
  ASSERT_TRUE(WaitUntil([&] { return fake.Last().force.z > 0.0; }));
  const Fake::Commanded got = fake.Last();
  EXPECT_NEAR(glm::length(got.force), 12.0, 1e-9);  // sigma.7: 12 N
  ExpectNear(got.force / glm::length(got.force), {-0.6, 0.0, 0.8}, 1e-12, "direction kept");
  EXPECT_NEAR(got.torque.z, 0.2, 1e-12);  // 0.2 N·m
  EXPECT_GT(d.status().saturated_commands, 0u);
  d.Close();

  // A passive wrist gets no torque at all.
  Reset(kOmega6Right, true, false, false);
  ForceDimensionDevice omega(FakeConfig());
  omega.Open();
  ASSERT_TRUE(omega.WriteWrench({{0.0, 0.0, 1.0}, {0.1, 0.1, 0.1}}, g_now_ns.load()));
  ASSERT_TRUE(WaitUntil([&] { return fake.Last().force.z == 1.0; }));
  ExpectNear(fake.Last().torque, glm::dvec3(0.0), 0.0, "no torque on omega.6");
}

TEST_F(ForceDimensionTest, AnActiveGripperIsCommandedZeroGripperForce) {
  Reset(kOmega7Right, true, false, true);
  ForceDimensionDevice d(FakeConfig());
  d.Open();
  ASSERT_TRUE(d.WriteWrench({{0.0, 0.0, 2.0}, {}}, g_now_ns.load()));
  ASSERT_TRUE(WaitUntil([&] { return fake.Last().force.z == 2.0; }));
  long sets = 0, gripper_sets = 0;
  fake.set_counts(&sets, &gripper_sets);
  EXPECT_GT(gripper_sets, 0);
  EXPECT_EQ(fake.Last().gripper, 0.0);
}

TEST_F(ForceDimensionTest, CloseCommandsZeroThenStopsAndCloses) {
  ForceDimensionDevice d(FakeConfig());
  d.Open();
  ASSERT_TRUE(d.WriteWrench({{1.0, 1.0, 1.0}, {0.05, 0.0, 0.0}}, g_now_ns.load()));
  ASSERT_TRUE(WaitUntil([&] { return fake.Last().force.z == 1.0; }));
  d.Close();
  EXPECT_EQ(fake.Log(), "open,enable_force,stop,close");
  const Fake::Commanded before_stop = fake.BeforeStop();
  ExpectNear(before_stop.force, glm::dvec3(0.0), 0.0, "force before dhdStop");
  ExpectNear(before_stop.torque, glm::dvec3(0.0), 0.0, "torque before dhdStop");
  DeviceState st;
  EXPECT_FALSE(d.ReadState(g_now_ns.load(), st));
  EXPECT_FALSE(d.WriteWrench({}, g_now_ns.load()));
}

TEST_F(ForceDimensionTest, AFailedReadingRendersZeroAndGivesNoState) {
  ForceDimensionDevice d(FakeConfig());
  d.Open();
  ASSERT_TRUE(d.WriteWrench({{0.0, 0.0, 2.0}, {}}, g_now_ns.load()));
  ASSERT_TRUE(WaitUntil([&] { return fake.Last().force.z == 2.0; }));
  fake.fail_reads(1);
  fake.mark();
  long commands = 0, nonzero = 0;
  ASSERT_TRUE(WaitUntil([&] {
    fake.since_mark(&commands, &nonzero);
    return commands >= 3;
  }));
  // At most the one exchange that read before the fault began renders the old wrench.
  EXPECT_LE(nonzero, 1);
  ExpectNear(fake.Last().force, glm::dvec3(0.0), 0.0, "force during the fault");
  DeviceState st;
  EXPECT_FALSE(d.ReadState(g_now_ns.load(), st));
  EXPECT_GT(d.status().read_faults, 0u);
  // The fault clears: state and force come back.
  fake.fail_reads(0);
  ASSERT_TRUE(WaitUntil([&] { return d.ReadState(g_now_ns.load(), st); }));
  ASSERT_TRUE(d.WriteWrench({{0.0, 0.0, 2.0}, {}}, g_now_ns.load()));
  EXPECT_TRUE(WaitUntil([&] { return fake.Last().force.z == 2.0; }));
}

TEST_F(ForceDimensionTest, ANonFiniteOrStaleWrenchRendersZero) {
  ForceDimensionDevice d(FakeConfig());
  d.Open();
  ASSERT_TRUE(d.WriteWrench({{0.0, 0.0, 2.0}, {}}, g_now_ns.load()));
  ASSERT_TRUE(WaitUntil([&] { return fake.Last().force.z == 2.0; }));
  EXPECT_FALSE(d.WriteWrench({{0.0, 0.0, std::nan("")}, {}}, g_now_ns.load()));
  ASSERT_TRUE(WaitUntil([&] { return fake.Last().force.z == 0.0; }));

  ASSERT_TRUE(d.WriteWrench({{0.0, 0.0, 2.0}, {}}, g_now_ns.load()));
  ASSERT_TRUE(WaitUntil([&] { return fake.Last().force.z == 2.0; }));
  g_now_ns += 100'000'000;  // the loop has not written for 0.1 s (> wrench_timeout_s)
  EXPECT_TRUE(WaitUntil([&] { return fake.Last().force.z == 0.0; }));
  EXPECT_GT(d.status().stale_wrenches, 0u);
}

TEST_F(ForceDimensionTest, TheLoopsCallsAndTheIoThreadAllocateNothing) {
  ForceDimensionDevice d(FakeConfig());
  d.Open();
  DeviceState st;
  ASSERT_TRUE(WaitUntil([&] { return d.ReadState(g_now_ns.load(), st); }));
  const std::uint64_t exchanges_before = d.status().exchanges;
  const long before = testing_support::Allocations();
  // Ticks of the loop while the I/O thread runs its exchanges.
  for (int i = 0; i < 200; ++i) {
    d.ReadState(g_now_ns.load(), st);
    d.WriteWrench({{0.0, 0.0, 0.001 * i}, {}}, g_now_ns.load());
    std::this_thread::sleep_for(100us);
  }
  const std::uint64_t exchanges_after = d.status().exchanges;
  EXPECT_EQ(testing_support::Allocations() - before, 0);
  EXPECT_GT(exchanges_after, exchanges_before);  // the I/O thread ran in the window
}

}  // namespace
}  // namespace ht::force_dimension
