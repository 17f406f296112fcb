// A stand-in for OpenHaptics' HD library (libHD.so), built as a shared library for
// openhaptics_test: the C functions the backend resolves, with hd.h's signatures and
// hdDefines.h's values (written here from OpenHaptics' headers as documented, independently of the
// backend's declarations), playing a scripted stylus and recording what the backend sets. It has
// no servo thread: the test runs one servo tick at a time with fake_hd_tick, which calls the
// scheduled callbacks as OpenHaptics' scheduler would. Built a second time with
// FAKE_HD_INCOMPLETE, without hdScheduleAsynchronous, for the missing-symbol message.
//
// Allocates nothing.

#include <cstring>
#include <mutex>

namespace {

using HHD = unsigned int;
using HDenum = unsigned int;
using HDerror = unsigned int;
struct HDErrorInfo {
  HDerror errorCode;
  int internalErrorCode;
  HHD hHD;
};
using HDCallbackCode = unsigned int;
using HDSchedulerHandle = unsigned long;
using HDSchedulerCallback = HDCallbackCode (*)(void*);

constexpr HDerror HD_SUCCESS = 0x0000;
constexpr HDerror HD_INVALID_ENUM = 0x0100;
constexpr HDerror HD_COMM_ERROR = 0x0302;
constexpr HDerror HD_ILLEGAL_BEGIN = 0x0400;
constexpr HHD HD_INVALID_HANDLE = 0xFFFFFFFF;
constexpr HDCallbackCode HD_CALLBACK_CONTINUE = 1;

constexpr HDenum HD_CURRENT_BUTTONS = 0x2000;
constexpr HDenum HD_CURRENT_VELOCITY = 0x2051;
constexpr HDenum HD_CURRENT_TRANSFORM = 0x2052;
constexpr HDenum HD_CURRENT_ANGULAR_VELOCITY = 0x2053;
constexpr HDenum HD_DEVICE_MODEL_TYPE = 0x2501;
constexpr HDenum HD_USABLE_WORKSPACE_DIMENSIONS = 0x2551;
constexpr HDenum HD_INPUT_DOF = 0x2553;
constexpr HDenum HD_OUTPUT_DOF = 0x2554;
constexpr HDenum HD_NOMINAL_MAX_STIFFNESS = 0x2602;
constexpr HDenum HD_NOMINAL_MAX_FORCE = 0x2603;
constexpr HDenum HD_NOMINAL_MAX_DAMPING = 0x2609;
constexpr HDenum HD_NOMINAL_MAX_TORQUE_STIFFNESS = 0x2620;
constexpr HDenum HD_NOMINAL_MAX_TORQUE_FORCE = 0x2622;
constexpr HDenum HD_CURRENT_FORCE = 0x2700;
constexpr HDenum HD_CURRENT_TORQUE = 0x2701;
constexpr HDenum HD_FORCE_OUTPUT = 0x4000;

constexpr HHD kHandle = 7;
constexpr int kMaxCallbacks = 8;
constexpr int kMaxErrors = 8;

struct Callback {
  HDSchedulerCallback cb = nullptr;
  void* data = nullptr;
  unsigned short priority = 0;
  bool active = false;
};

struct State {
  std::recursive_mutex mutex;  // a tick holds it while the callbacks call back in
  bool present = true;
  int input_dof = 6;
  int output_dof = 3;
  double max_force_n = 3.3;
  double max_torque_mNm[3] = {0.0, 0.0, 0.0};
  double stiffness_n_per_mm = 0.75;
  double damping_ns_per_mm = 0.004;
  // Usable workspace: min x, y, z, max x, y, z (mm); centre (0, 20, 10).
  double workspace_mm[6] = {-80.0, -40.0, -30.0, 80.0, 80.0, 50.0};

  double T[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
  double v[3] = {};
  double w[3] = {};
  int buttons = 0;

  bool initialised = false;
  bool force_enabled = false;
  bool scheduler_running = false;
  int frame_depth = 0;
  Callback callbacks[kMaxCallbacks];

  double force[3] = {};
  double torque_mNm[3] = {};
  double force_at_stop[3] = {};
  long force_sets = 0;
  long torque_sets = 0;
  long sets_outside_frame = 0;
  HDerror error_at_end_frame = HD_SUCCESS;  // pushed by the next hdEndFrame
  HDErrorInfo errors[kMaxErrors] = {};
  int error_count = 0;
  char log[512] = {};
};

State& S() {
  static State s;
  return s;
}

void Log(State& s, const char* what) {
  if (s.log[0]) std::strncat(s.log, ",", sizeof s.log - std::strlen(s.log) - 1);
  std::strncat(s.log, what, sizeof s.log - std::strlen(s.log) - 1);
}

void Push(State& s, HDerror code, int internal) {
  if (s.error_count < kMaxErrors) s.errors[s.error_count++] = {code, internal, kHandle};
}

void Copy(double* out, const double* in, int n) { std::memcpy(out, in, sizeof(double) * n); }

}  // namespace

extern "C" {

// ------------------------------------------------------------------------------------------
// hd.h
// ------------------------------------------------------------------------------------------

HHD hdInitDevice(const char* config_name) {
  State& s = S();
  std::lock_guard lock(s.mutex);
  Log(s, config_name ? "init_named" : "init_default");
  if (!s.present) {
    Push(s, HD_COMM_ERROR, -42);
    return HD_INVALID_HANDLE;
  }
  s.initialised = true;
  return kHandle;
}

void hdDisableDevice(HHD) {
  State& s = S();
  std::lock_guard lock(s.mutex);
  Log(s, "disable_device");
  s.initialised = false;
  s.force_enabled = false;
}

void hdMakeCurrentDevice(HHD h) {
  State& s = S();
  std::lock_guard lock(s.mutex);
  if (h != kHandle) Push(s, HD_INVALID_ENUM, 0);
}

void hdBeginFrame(HHD h) {
  State& s = S();
  std::lock_guard lock(s.mutex);
  if (h != kHandle || !s.initialised) Push(s, HD_ILLEGAL_BEGIN, 0);
  ++s.frame_depth;
}

void hdEndFrame(HHD) {
  State& s = S();
  std::lock_guard lock(s.mutex);
  --s.frame_depth;
  if (s.error_at_end_frame != HD_SUCCESS) {
    Push(s, s.error_at_end_frame, 7);
    s.error_at_end_frame = HD_SUCCESS;
  }
}

void hdEnable(HDenum cap) {
  State& s = S();
  std::lock_guard lock(s.mutex);
  if (cap == HD_FORCE_OUTPUT) {
    Log(s, "enable_force");
    s.force_enabled = true;
  } else {
    Push(s, HD_INVALID_ENUM, 0);
  }
}

void hdGetDoublev(HDenum name, double* out) {
  State& s = S();
  std::lock_guard lock(s.mutex);
  switch (name) {
    case HD_CURRENT_TRANSFORM:
      Copy(out, s.T, 16);
      break;
    case HD_CURRENT_VELOCITY:
      Copy(out, s.v, 3);
      break;
    case HD_CURRENT_ANGULAR_VELOCITY:
      Copy(out, s.w, 3);
      break;
    case HD_NOMINAL_MAX_FORCE:
      out[0] = s.max_force_n;
      break;
    case HD_NOMINAL_MAX_STIFFNESS:
      out[0] = s.stiffness_n_per_mm;
      break;
    case HD_NOMINAL_MAX_DAMPING:
      out[0] = s.damping_ns_per_mm;
      break;
    case HD_USABLE_WORKSPACE_DIMENSIONS:
      Copy(out, s.workspace_mm, 6);
      break;
    case HD_NOMINAL_MAX_TORQUE_FORCE:
      if (s.output_dof < 6) {
        Push(s, HD_INVALID_ENUM, 0);
      } else {
        Copy(out, s.max_torque_mNm, 3);
      }
      break;
    case HD_NOMINAL_MAX_TORQUE_STIFFNESS:
      for (int i = 0; i < 3; ++i) out[i] = 300.0;  // mN·m/rad
      break;
    default:
      Push(s, HD_INVALID_ENUM, 0);
      break;
  }
}

void hdGetIntegerv(HDenum name, int* out) {
  State& s = S();
  std::lock_guard lock(s.mutex);
  switch (name) {
    case HD_CURRENT_BUTTONS:
      out[0] = s.buttons;
      break;
    case HD_INPUT_DOF:
      out[0] = s.input_dof;
      break;
    case HD_OUTPUT_DOF:
      out[0] = s.output_dof;
      break;
    default:
      Push(s, HD_INVALID_ENUM, 0);
      break;
  }
}

const char* hdGetString(HDenum name) {
  State& s = S();
  std::lock_guard lock(s.mutex);
  if (name == HD_DEVICE_MODEL_TYPE) return s.output_dof >= 6 ? "Fake Premium 6DOF" : "Fake Touch";
  Push(s, HD_INVALID_ENUM, 0);
  return nullptr;
}

void hdSetDoublev(HDenum name, const double* in) {
  State& s = S();
  std::lock_guard lock(s.mutex);
  if (s.frame_depth <= 0) ++s.sets_outside_frame;
  if (name == HD_CURRENT_FORCE) {
    Copy(s.force, in, 3);
    ++s.force_sets;
  } else if (name == HD_CURRENT_TORQUE) {
    Copy(s.torque_mNm, in, 3);
    ++s.torque_sets;
  } else {
    Push(s, HD_INVALID_ENUM, 0);
  }
}

HDErrorInfo hdGetError() {
  State& s = S();
  std::lock_guard lock(s.mutex);
  if (s.error_count == 0) return {HD_SUCCESS, 0, kHandle};
  return s.errors[--s.error_count];  // newest first
}

const char* hdGetErrorString(HDerror code) {
  switch (code) {
    case HD_COMM_ERROR:
      return "fake: communication error";
    case HD_INVALID_ENUM:
      return "fake: invalid enum";
    default:
      return "fake: device error";
  }
}

void hdStartScheduler() {
  State& s = S();
  std::lock_guard lock(s.mutex);
  Log(s, "start_scheduler");
  s.scheduler_running = true;
}

void hdStopScheduler() {
  State& s = S();
  std::lock_guard lock(s.mutex);
  Log(s, "stop_scheduler");
  Copy(s.force_at_stop, s.force, 3);
  s.scheduler_running = false;
}

#ifndef FAKE_HD_INCOMPLETE
HDSchedulerHandle hdScheduleAsynchronous(HDSchedulerCallback cb, void* data,
                                         unsigned short priority) {
  State& s = S();
  std::lock_guard lock(s.mutex);
  Log(s, "schedule_async");
  for (int i = 0; i < kMaxCallbacks; ++i) {
    if (!s.callbacks[i].active) {
      s.callbacks[i] = {cb, data, priority, true};
      return static_cast<HDSchedulerHandle>(i + 1);
    }
  }
  return 0;
}
#endif

void hdScheduleSynchronous(HDSchedulerCallback cb, void* data, unsigned short) {
  State& s = S();
  std::lock_guard lock(s.mutex);
  Log(s, "schedule_sync");
  // As one servo tick: the asynchronous callbacks (higher priority first), then this one.
  for (Callback& c : s.callbacks) {
    if (c.active && c.cb(c.data) != HD_CALLBACK_CONTINUE) c.active = false;
  }
  cb(data);
}

void hdUnschedule(HDSchedulerHandle h) {
  State& s = S();
  std::lock_guard lock(s.mutex);
  Log(s, "unschedule");
  if (h >= 1 && h <= kMaxCallbacks) s.callbacks[h - 1].active = false;
}

// ------------------------------------------------------------------------------------------
// Test controls
// ------------------------------------------------------------------------------------------

/// Back to a fresh device: `present` = 0: hdInitDevice fails with HD_COMM_ERROR; DoF in and out;
/// HD_NOMINAL_MAX_FORCE (N); HD_NOMINAL_MAX_TORQUE_FORCE per gimbal axis (mN·m).
void fake_hd_reset(int present, int input_dof, int output_dof, double max_force_n,
                   const double max_torque_mNm[3]) {
  State& s = S();
  std::lock_guard lock(s.mutex);
  s.present = present != 0;
  s.input_dof = input_dof;
  s.output_dof = output_dof;
  s.max_force_n = max_force_n;
  Copy(s.max_torque_mNm, max_torque_mNm, 3);
  const double identity[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
  Copy(s.T, identity, 16);
  std::memset(s.v, 0, sizeof s.v);
  std::memset(s.w, 0, sizeof s.w);
  s.buttons = 0;
  s.initialised = s.force_enabled = s.scheduler_running = false;
  s.frame_depth = 0;
  for (Callback& c : s.callbacks) c = Callback{};
  std::memset(s.force, 0, sizeof s.force);
  std::memset(s.torque_mNm, 0, sizeof s.torque_mNm);
  std::memset(s.force_at_stop, 0, sizeof s.force_at_stop);
  s.force_sets = s.torque_sets = s.sets_outside_frame = 0;
  s.error_at_end_frame = HD_SUCCESS;
  s.error_count = 0;
  s.log[0] = '\0';
}

/// The stylus: X_PS as OpenHaptics' column-major 4x4 (translation in mm at 12..14), velocity
/// (mm/s), angular velocity (rad/s), buttons.
void fake_hd_set_stylus(const double T[16], const double v[3], const double w[3], int buttons) {
  State& s = S();
  std::lock_guard lock(s.mutex);
  Copy(s.T, T, 16);
  Copy(s.v, v, 3);
  Copy(s.w, w, 3);
  s.buttons = buttons;
}

/// One servo tick: runs the scheduled callbacks once (if the scheduler runs); returns how many.
int fake_hd_tick() {
  State& s = S();
  std::lock_guard lock(s.mutex);
  if (!s.scheduler_running) return 0;
  int ran = 0;
  for (Callback& c : s.callbacks) {
    if (!c.active) continue;
    ++ran;
    if (c.cb(c.data) != HD_CALLBACK_CONTINUE) c.active = false;
  }
  return ran;
}

/// An error on HD's error stack now (as a failed read in the frame to come would leave), or at
/// the end of the next frame (`at_end_frame` != 0).
void fake_hd_inject_error(unsigned int code, int at_end_frame) {
  State& s = S();
  std::lock_guard lock(s.mutex);
  if (at_end_frame) {
    s.error_at_end_frame = code;
  } else {
    Push(s, code, 3);
  }
}

/// The newest HD_CURRENT_FORCE (N) and HD_CURRENT_TORQUE (mN·m) set, the force set when the
/// scheduler was stopped, and the counts of sets (force, torque, outside a frame).
void fake_hd_outputs(double force[3], double torque_mNm[3], double force_at_stop[3],
                     long counts[3]) {
  State& s = S();
  std::lock_guard lock(s.mutex);
  Copy(force, s.force, 3);
  Copy(torque_mNm, s.torque_mNm, 3);
  Copy(force_at_stop, s.force_at_stop, 3);
  counts[0] = s.force_sets;
  counts[1] = s.torque_sets;
  counts[2] = s.sets_outside_frame;
}

/// Copies the lifecycle log ("init_default,enable_force,schedule_async,...") into `out`.
void fake_hd_log(char* out, int size) {
  State& s = S();
  std::lock_guard lock(s.mutex);
  std::strncpy(out, s.log, static_cast<std::size_t>(size) - 1);
  out[size - 1] = '\0';
}

}  // extern "C"
