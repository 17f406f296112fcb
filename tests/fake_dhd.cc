// A stand-in for Force Dimension's DHD library (libdhd.so), built as a shared library for
// force_dimension_test: the C functions the backend resolves, with dhdc.h's signatures (written
// here from the SDK's header as documented, independently of the backend's declarations), playing
// a scripted handle and recording what the backend commands. The test loads the same file with
// dlopen and drives it through the fake_dhd_* functions. Built a second time with
// FAKE_DHD_INCOMPLETE, without dhdSetForceAndTorque, for the missing-symbol message.
//
// Thread-safe (the backend's I/O thread calls while the test reads); allocates nothing.

#include <cstring>
#include <mutex>

namespace {

struct State {
  std::mutex mutex;
  bool present = true;          // dhdOpen finds a device
  int system_type = 104;        // DHD_DEVICE_SIGMA7_RIGHT
  bool has_wrist = true;        // dhdHasWrist
  bool active_wrist = true;     // dhdHasActiveWrist
  bool active_gripper = false;  // dhdHasActiveGripper
  double max_force = -1.0;      // dhdGetMaxForce: negative = no limit set
  double max_torque = -1.0;
  bool fail_reads = false;  // dhdGetPosition fails
  bool opened = false;
  bool force_enabled = false;

  double p[3] = {0.0, 0.0, 0.0};
  double R[3][3] = {{1.0, 0.0, 0.0}, {0.0, 1.0, 0.0}, {0.0, 0.0, 1.0}};
  double v[3] = {0.0, 0.0, 0.0};
  double w[3] = {0.0, 0.0, 0.0};
  unsigned int buttons = 0;

  double last[7] = {};          // newest fx fy fz tx ty tz fg commanded
  double before_stop[7] = {};   // the wrench commanded last before dhdStop
  long sets = 0;                // dhdSetForceAndTorque calls
  long gripper_sets = 0;        // dhdSetForceAndTorqueAndGripperForce calls
  long sets_since_mark = 0;     // either, since fake_dhd_mark
  long nonzero_since_mark = 0;  // of those, commands that were not all zero
  long reads = 0;               // dhdGetPosition calls
  char log[512] = {};           // lifecycle calls in order, comma-separated
  const char* error = "";
};

State& S() {
  static State s;
  return s;
}

void Log(State& s, const char* what) {
  if (s.log[0]) std::strncat(s.log, ",", sizeof s.log - std::strlen(s.log) - 1);
  std::strncat(s.log, what, sizeof s.log - std::strlen(s.log) - 1);
}

int Command(State& s, char id, const double (&w)[7]) {
  if (!s.opened || id != 0) {
    s.error = "device not open";
    return -1;
  }
  bool nonzero = false;
  for (int i = 0; i < 7; ++i) {
    s.last[i] = w[i];
    nonzero = nonzero || w[i] != 0.0;
  }
  ++s.sets_since_mark;
  if (nonzero) ++s.nonzero_since_mark;
  return 0;
}

}  // namespace

extern "C" {

// ------------------------------------------------------------------------------------------
// dhdc.h
// ------------------------------------------------------------------------------------------

int dhdOpen() {
  State& s = S();
  std::lock_guard lock(s.mutex);
  Log(s, "open");
  if (!s.present) {
    s.error = "fake: no device found";
    return -1;
  }
  s.opened = true;
  return 0;
}

int dhdClose(char id) {
  State& s = S();
  std::lock_guard lock(s.mutex);
  Log(s, "close");
  if (id != 0) return -1;
  s.opened = false;
  return 0;
}

int dhdStop(char id) {
  State& s = S();
  std::lock_guard lock(s.mutex);
  Log(s, "stop");
  std::memcpy(s.before_stop, s.last, sizeof s.last);
  s.force_enabled = false;
  return id == 0 ? 0 : -1;
}

int dhdGetSystemType(char) {
  State& s = S();
  std::lock_guard lock(s.mutex);
  return s.system_type;
}

const char* dhdGetSystemName(char) { return "fake.7"; }

int dhdEnableForce(unsigned char val, char) {
  State& s = S();
  std::lock_guard lock(s.mutex);
  Log(s, val ? "enable_force" : "disable_force");
  s.force_enabled = val != 0;
  return 0;
}

bool dhdHasWrist(char) {
  State& s = S();
  std::lock_guard lock(s.mutex);
  return s.has_wrist;
}

bool dhdHasActiveWrist(char) {
  State& s = S();
  std::lock_guard lock(s.mutex);
  return s.active_wrist;
}

bool dhdHasActiveGripper(char) {
  State& s = S();
  std::lock_guard lock(s.mutex);
  return s.active_gripper;
}

double dhdGetMaxForce(char) {
  State& s = S();
  std::lock_guard lock(s.mutex);
  return s.max_force;
}

double dhdGetMaxTorque(char) {
  State& s = S();
  std::lock_guard lock(s.mutex);
  return s.max_torque;
}

int dhdGetPosition(double* px, double* py, double* pz, char) {
  State& s = S();
  std::lock_guard lock(s.mutex);
  ++s.reads;
  if (s.fail_reads || !s.opened) {
    s.error = "fake: communication error";
    return -1;
  }
  *px = s.p[0];
  *py = s.p[1];
  *pz = s.p[2];
  return 0;
}

int dhdGetOrientationFrame(double matrix[3][3], char) {
  State& s = S();
  std::lock_guard lock(s.mutex);
  std::memcpy(matrix, s.R, sizeof s.R);
  return 0;
}

int dhdGetLinearVelocity(double* vx, double* vy, double* vz, char) {
  State& s = S();
  std::lock_guard lock(s.mutex);
  *vx = s.v[0];
  *vy = s.v[1];
  *vz = s.v[2];
  return 0;
}

int dhdGetAngularVelocityRad(double* wx, double* wy, double* wz, char) {
  State& s = S();
  std::lock_guard lock(s.mutex);
  *wx = s.w[0];
  *wy = s.w[1];
  *wz = s.w[2];
  return 0;
}

unsigned int dhdGetButtonMask(char) {
  State& s = S();
  std::lock_guard lock(s.mutex);
  return s.buttons;
}

#ifndef FAKE_DHD_INCOMPLETE
int dhdSetForceAndTorque(double fx, double fy, double fz, double tx, double ty, double tz,
                         char id) {
  State& s = S();
  std::lock_guard lock(s.mutex);
  ++s.sets;
  return Command(s, id, {fx, fy, fz, tx, ty, tz, 0.0});
}
#endif

int dhdSetForceAndTorqueAndGripperForce(double fx, double fy, double fz, double tx, double ty,
                                        double tz, double fg, char id) {
  State& s = S();
  std::lock_guard lock(s.mutex);
  ++s.gripper_sets;
  return Command(s, id, {fx, fy, fz, tx, ty, tz, fg});
}

const char* dhdErrorGetLastStr() {
  State& s = S();
  std::lock_guard lock(s.mutex);
  return s.error;
}

// ------------------------------------------------------------------------------------------
// Test controls
// ------------------------------------------------------------------------------------------

/// Back to a fresh device of `system_type` (DHD_DEVICE_*); `present` = 0: dhdOpen finds none.
void fake_dhd_reset(int present, int system_type, int has_wrist, int active_wrist,
                    int active_gripper) {
  State& s = S();
  std::lock_guard lock(s.mutex);
  s.present = present != 0;
  s.system_type = system_type;
  s.has_wrist = has_wrist != 0;
  s.active_wrist = active_wrist != 0;
  s.active_gripper = active_gripper != 0;
  s.max_force = -1.0;
  s.max_torque = -1.0;
  s.fail_reads = false;
  s.opened = false;
  s.force_enabled = false;
  std::memset(s.p, 0, sizeof s.p);
  std::memset(s.v, 0, sizeof s.v);
  std::memset(s.w, 0, sizeof s.w);
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) s.R[i][j] = i == j ? 1.0 : 0.0;
  }
  s.buttons = 0;
  std::memset(s.last, 0, sizeof s.last);
  std::memset(s.before_stop, 0, sizeof s.before_stop);
  s.sets = s.gripper_sets = s.sets_since_mark = s.nonzero_since_mark = s.reads = 0;
  s.log[0] = '\0';
  s.error = "";
}

/// The limits dhdGetMaxForce / dhdGetMaxTorque report (negative: none set).
void fake_dhd_set_limits(double max_force, double max_torque) {
  State& s = S();
  std::lock_guard lock(s.mutex);
  s.max_force = max_force;
  s.max_torque = max_torque;
}

/// The handle: position (m), orientation frame (row-major, matrix[i][j] = R[3 i + j]), linear
/// (m/s) and angular (rad/s) velocity, all in DHD's base frame, and the button mask.
void fake_dhd_set_handle(const double p[3], const double R[9], const double v[3], const double w[3],
                         unsigned int buttons) {
  State& s = S();
  std::lock_guard lock(s.mutex);
  for (int i = 0; i < 3; ++i) {
    s.p[i] = p[i];
    s.v[i] = v[i];
    s.w[i] = w[i];
    for (int j = 0; j < 3; ++j) s.R[i][j] = R[3 * i + j];
  }
  s.buttons = buttons;
}

/// From now on dhdGetPosition fails (non-zero) or works again (zero).
void fake_dhd_fail_reads(int fail) {
  State& s = S();
  std::lock_guard lock(s.mutex);
  s.fail_reads = fail != 0;
}

/// Starts counting commands afresh (fake_dhd_since_mark).
void fake_dhd_mark() {
  State& s = S();
  std::lock_guard lock(s.mutex);
  s.sets_since_mark = s.nonzero_since_mark = 0;
}

/// Commands since fake_dhd_mark, and of those the ones that were not all zero.
void fake_dhd_since_mark(long* commands, long* nonzero) {
  State& s = S();
  std::lock_guard lock(s.mutex);
  *commands = s.sets_since_mark;
  *nonzero = s.nonzero_since_mark;
}

/// The newest wrench commanded (fx fy fz N, tx ty tz N·m, gripper N) and the one commanded
/// last before dhdStop.
void fake_dhd_wrenches(double last[7], double before_stop[7]) {
  State& s = S();
  std::lock_guard lock(s.mutex);
  std::memcpy(last, s.last, sizeof s.last);
  std::memcpy(before_stop, s.before_stop, sizeof s.before_stop);
}

/// Calls of dhdSetForceAndTorque and of dhdSetForceAndTorqueAndGripperForce.
void fake_dhd_set_counts(long* sets, long* gripper_sets) {
  State& s = S();
  std::lock_guard lock(s.mutex);
  *sets = s.sets;
  *gripper_sets = s.gripper_sets;
}

/// Copies the lifecycle log ("open,enable_force,stop,close", ...) into `out` (`size` bytes).
void fake_dhd_log(char* out, int size) {
  State& s = S();
  std::lock_guard lock(s.mutex);
  std::strncpy(out, s.log, static_cast<std::size_t>(size) - 1);
  out[size - 1] = '\0';
}

}  // extern "C"
