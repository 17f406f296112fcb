// OpenHaptics devices through the HD library loaded at Open (openhaptics.h): Open with the
// library's checks, the servo callback, Close, and the wait-free hand-offs with the haptic loop.

#include "master_station/openhaptics.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>

#include "device_limits.h"
#include "haptic_core/steady_clock.h"
#include "master_station/vendor_exchange.h"
#include "master_station/vendor_library.h"

namespace ht::openhaptics {
namespace {

// hdDefines.h / hdScheduler.h (OpenHaptics 3.x): types and values.
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

constexpr HDerror kHdSuccess = 0x0000;
constexpr HHD kHdInvalidHandle = 0xFFFFFFFF;
constexpr HDCallbackCode kHdCallbackDone = 0;
constexpr HDCallbackCode kHdCallbackContinue = 1;
constexpr unsigned short kHdMaxSchedulerPriority = 0xFFFF;  // USHRT_MAX
constexpr unsigned short kHdMinSchedulerPriority = 0;

constexpr HDenum kHdCurrentButtons = 0x2000;
constexpr HDenum kHdCurrentVelocity = 0x2051;
constexpr HDenum kHdCurrentTransform = 0x2052;
constexpr HDenum kHdCurrentAngularVelocity = 0x2053;
constexpr HDenum kHdDeviceModelType = 0x2501;
constexpr HDenum kHdUsableWorkspaceDimensions = 0x2551;
constexpr HDenum kHdInputDof = 0x2553;
constexpr HDenum kHdOutputDof = 0x2554;
constexpr HDenum kHdNominalMaxStiffness = 0x2602;
constexpr HDenum kHdNominalMaxForce = 0x2603;
constexpr HDenum kHdNominalMaxDamping = 0x2609;
constexpr HDenum kHdNominalMaxTorqueStiffness = 0x2620;
constexpr HDenum kHdNominalMaxTorqueForce = 0x2622;
constexpr HDenum kHdCurrentForce = 0x2700;
constexpr HDenum kHdCurrentTorque = 0x2701;
constexpr HDenum kHdForceOutput = 0x4000;

// CHAI3D's cPhantomDevice: the Phantom Premium 1.5/3.0 6DOF's torque (N·m), for a 6-DoF output
// device that reports none.
constexpr double kPremium6DofTorqueNm = 0.188;

// The most errors one frame's drain pops off HD's error stack.
constexpr int kMaxErrorsDrained = 16;

// Room for the longest answer of any hdGet* used here (HD_CURRENT_TRANSFORM: 16).
constexpr int kGetBuffer = 16;

const VendorLibrarySpec& LibrarySpec() {
  static const VendorLibrarySpec spec{
      "OpenHaptics",
      {"libHD.so", "libHD.so.3.4", "libHD.so.3"},
      "Install OpenHaptics for Linux and the device driver (3D Systems: the Touch / Touch X "
      "device driver and OpenHaptics Developer Edition), check the device with Touch_Setup and "
      "Touch_Diagnostic, and put libHD.so on LD_LIBRARY_PATH or give it with --device-library "
      "PATH/libHD.so"};
  return spec;
}

std::string Hex(unsigned int code) {
  char text[16];
  std::snprintf(text, sizeof text, "0x%04X", code);
  return text;
}

}  // namespace

// The HD functions, with hd.h's signatures.
struct OpenHapticsDevice::Api {
  HHD (*init_device)(const char*) = nullptr;             // hdInitDevice
  void (*disable_device)(HHD) = nullptr;                 // hdDisableDevice
  void (*make_current_device)(HHD) = nullptr;            // hdMakeCurrentDevice
  void (*begin_frame)(HHD) = nullptr;                    // hdBeginFrame
  void (*end_frame)(HHD) = nullptr;                      // hdEndFrame
  void (*enable)(HDenum) = nullptr;                      // hdEnable
  void (*get_doublev)(HDenum, double*) = nullptr;        // hdGetDoublev
  void (*get_integerv)(HDenum, int*) = nullptr;          // hdGetIntegerv
  const char* (*get_string)(HDenum) = nullptr;           // hdGetString
  void (*set_doublev)(HDenum, const double*) = nullptr;  // hdSetDoublev
  HDErrorInfo (*get_error)() = nullptr;                  // hdGetError
  const char* (*get_error_string)(HDerror) = nullptr;    // hdGetErrorString
  void (*start_scheduler)() = nullptr;                   // hdStartScheduler
  void (*stop_scheduler)() = nullptr;                    // hdStopScheduler
  HDSchedulerHandle (*schedule_asynchronous)(HDSchedulerCallback, void*,
                                             unsigned short) = nullptr;  // hdScheduleAsynchronous
  void (*schedule_synchronous)(HDSchedulerCallback, void*,
                               unsigned short) = nullptr;  // hdScheduleSynchronous
  void (*unschedule)(HDSchedulerHandle) = nullptr;         // hdUnschedule

  // Throws when hdGetError reports an error, naming `what` and the error.
  void Check(const std::string& what) const {
    const HDErrorInfo e = get_error();
    if (e.errorCode == kHdSuccess) return;
    const char* text = get_error_string(e.errorCode);
    throw std::runtime_error("OpenHaptics: " + what +
                             " failed: " + (text && *text ? text : "no error text") +
                             " (HD error " + Hex(e.errorCode) + ", device code " +
                             std::to_string(e.internalErrorCode) + ")");
  }
};

OpenHapticsDevice::OpenHapticsDevice(OpenHapticsConfig config) : config_(std::move(config)) {
  if (!(config_.wrench_timeout_s > 0.0) || !(config_.stale_after_s > 0.0)) {
    throw std::invalid_argument("OpenHaptics: wrench timeout and staleness must be positive");
  }
  caps_.name = "OpenHaptics (HD library, not opened)";
  caps_.dof_in = 6;
  caps_.dof_out = 3;
}

OpenHapticsDevice::~OpenHapticsDevice() { Close(); }

DeviceCapabilities OpenHapticsDevice::capabilities() const { return caps_; }

std::int64_t OpenHapticsDevice::NowNs() const noexcept {
  return config_.clock_ns ? config_.clock_ns() : SteadyNowNs();
}

void OpenHapticsDevice::Open() {
  if (open_.load()) return;
  auto library = std::make_unique<VendorLibrary>(LibrarySpec(), config_.library_path);
  auto api = std::make_unique<Api>();
  {
    const VendorLibrary& l = *library;
    Api& a = *api;
    a.init_device = l.Require<decltype(a.init_device)>("hdInitDevice");
    a.disable_device = l.Require<decltype(a.disable_device)>("hdDisableDevice");
    a.make_current_device = l.Require<decltype(a.make_current_device)>("hdMakeCurrentDevice");
    a.begin_frame = l.Require<decltype(a.begin_frame)>("hdBeginFrame");
    a.end_frame = l.Require<decltype(a.end_frame)>("hdEndFrame");
    a.enable = l.Require<decltype(a.enable)>("hdEnable");
    a.get_doublev = l.Require<decltype(a.get_doublev)>("hdGetDoublev");
    a.get_integerv = l.Require<decltype(a.get_integerv)>("hdGetIntegerv");
    a.get_string = l.Require<decltype(a.get_string)>("hdGetString");
    a.set_doublev = l.Require<decltype(a.set_doublev)>("hdSetDoublev");
    a.get_error = l.Require<decltype(a.get_error)>("hdGetError");
    a.get_error_string = l.Require<decltype(a.get_error_string)>("hdGetErrorString");
    a.start_scheduler = l.Require<decltype(a.start_scheduler)>("hdStartScheduler");
    a.stop_scheduler = l.Require<decltype(a.stop_scheduler)>("hdStopScheduler");
    a.schedule_asynchronous =
        l.Require<decltype(a.schedule_asynchronous)>("hdScheduleAsynchronous");
    a.schedule_synchronous = l.Require<decltype(a.schedule_synchronous)>("hdScheduleSynchronous");
    a.unschedule = l.Require<decltype(a.unschedule)>("hdUnschedule");
  }

  const HHD hhd =
      api->init_device(config_.device_name.empty() ? nullptr : config_.device_name.c_str());
  const std::string which = config_.device_name.empty()
                                ? std::string("hdInitDevice(HD_DEFAULT_DEVICE)")
                                : "hdInitDevice(\"" + config_.device_name + "\")";
  try {
    api->Check(which);
  } catch (const std::runtime_error& e) {
    if (hhd != kHdInvalidHandle) api->disable_device(hhd);
    throw std::runtime_error(std::string(e.what()) +
                             ". Is the device plugged in and powered, and set up with Touch_Setup "
                             "(Touch_Diagnostic shows it)?");
  }
  if (hhd == kHdInvalidHandle) {
    throw std::runtime_error("OpenHaptics: " + which + " gave no device");
  }
  try {
    api->make_current_device(hhd);
    DeviceCapabilities c;
    double v[kGetBuffer] = {};
    api->get_doublev(kHdNominalMaxForce, v);
    c.max_force_n = v[0];
    std::fill(v, v + kGetBuffer, 0.0);
    api->get_doublev(kHdNominalMaxStiffness, v);
    c.max_stiffness_n_per_m = v[0] * 1e3;  // N/mm
    std::fill(v, v + kGetBuffer, 0.0);
    api->get_doublev(kHdNominalMaxDamping, v);
    c.max_damping_ns_per_m = v[0] * 1e3;  // N·s/mm
    std::fill(v, v + kGetBuffer, 0.0);
    api->get_doublev(kHdUsableWorkspaceDimensions, v);  // min x, y, z, max x, y, z (mm)
    const glm::dvec3 min_P(v[0], v[1], v[2]), max_P(v[3], v[4], v[5]);
    int n[kGetBuffer] = {};
    api->get_integerv(kHdInputDof, n);
    const int dof_in = n[0];
    n[0] = 0;
    api->get_integerv(kHdOutputDof, n);
    const int dof_out = n[0];
    const char* model = api->get_string(kHdDeviceModelType);
    api->Check("reading the device's figures (hdGetDoublev, hdGetIntegerv, hdGetString)");
    if (!(c.max_force_n > 0.0) || !std::isfinite(c.max_force_n)) {
      throw std::runtime_error("OpenHaptics: the device reports HD_NOMINAL_MAX_FORCE " +
                               std::to_string(c.max_force_n) + " N; expected a positive force");
    }
    const glm::dvec3 half_P = 0.5e-3 * (max_P - min_P);
    if (!(half_P.x > 0.0 && half_P.y > 0.0 && half_P.z > 0.0) || !std::isfinite(half_P.x) ||
        !std::isfinite(half_P.y) || !std::isfinite(half_P.z)) {
      throw std::runtime_error("OpenHaptics: the device reports an empty usable workspace");
    }
    c_P_m_ = 0.5e-3 * (max_P + min_P);
    c.workspace_half_extents_m = {half_P.x, half_P.z, half_P.y};  // turned into M
    sensed_rotation_ = dof_in >= 6;
    torque_out_ = dof_out >= 6;
    c.dof_in = sensed_rotation_ ? 6 : 3;
    c.dof_out = torque_out_ ? 6 : 3;
    if (torque_out_) {
      // Per gimbal axis, in mN·m and mN·m/rad: the smallest bounds every direction.
      std::fill(v, v + kGetBuffer, 0.0);
      api->get_doublev(kHdNominalMaxTorqueForce, v);
      const double t = std::min({v[0], v[1], v[2]});
      c.max_torque_nm = t > 0.0 && std::isfinite(t) ? t * 1e-3 : kPremium6DofTorqueNm;
      std::fill(v, v + kGetBuffer, 0.0);
      api->get_doublev(kHdNominalMaxTorqueStiffness, v);
      const double k = std::min({v[0], v[1], v[2]});
      c.max_rotational_stiffness_nm_per_rad = k > 0.0 && std::isfinite(k) ? k * 1e-3 : 0.0;
      // A device without these figures answers with an error, not a throw: the defaults stand.
      for (int i = 0; i < kMaxErrorsDrained && api->get_error().errorCode != kHdSuccess; ++i) {
      }
    }
    c.rated_loop_rate_hz = 1000.0;
    c.name = std::string("OpenHaptics ") + (model && *model ? model : "device") + " (HD)";

    api->enable(kHdForceOutput);
    api->Check("hdEnable(HD_FORCE_OUTPUT)");
    caps_ = c;
  } catch (...) {
    api->disable_device(hhd);
    throw;
  }

  library_ = std::move(library);
  api_ = std::move(api);
  hhd_ = hhd;
  Sample drained;
  while (samples_.Read(drained)) {
  }
  have_sample_ = false;
  command_ = Command{};
  zero_next_frame_ = false;
  frames_ = 0;
  errors_ = 0;
  last_error_ = 0;
  saturated_ = 0;
  stale_ = 0;
  commands_.Write(Command{});
  closing_ = false;
  servo_handle_ =
      api_->schedule_asynchronous(&OpenHapticsDevice::ServoCallback, this, kHdMaxSchedulerPriority);
  api_->start_scheduler();
  try {
    api_->Check("starting the servo loop (hdScheduleAsynchronous, hdStartScheduler)");
  } catch (...) {
    api_->stop_scheduler();
    api_->unschedule(servo_handle_);
    api_->disable_device(hhd_);
    api_.reset();
    library_.reset();
    throw;
  }
  open_ = true;
}

void OpenHapticsDevice::Close() noexcept {
  if (!api_) return;
  open_ = false;
  closing_ = true;  // the servo callback renders zero from its next frame on
  // One more frame, after the servo callback's (lowest priority), that renders zero.
  api_->schedule_synchronous(&OpenHapticsDevice::ZeroFrameCallback, this, kHdMinSchedulerPriority);
  api_->stop_scheduler();
  api_->unschedule(servo_handle_);
  api_->disable_device(hhd_);
  DrainErrors();
  api_.reset();
  library_.reset();
}

unsigned int OpenHapticsDevice::DrainErrors() noexcept {
  unsigned int newest = kHdSuccess;
  for (int i = 0; i < kMaxErrorsDrained; ++i) {
    const HDerror code = api_->get_error().errorCode;
    if (code == kHdSuccess) break;
    if (newest == kHdSuccess) newest = code;
  }
  return newest;
}

void OpenHapticsDevice::Render(const Wrench& F_H_P) noexcept {
  const double f[3] = {F_H_P.force.x, F_H_P.force.y, F_H_P.force.z};
  api_->set_doublev(kHdCurrentForce, f);
  if (torque_out_) {
    const double t_mNm[3] = {F_H_P.torque.x * 1e3, F_H_P.torque.y * 1e3, F_H_P.torque.z * 1e3};
    api_->set_doublev(kHdCurrentTorque, t_mNm);
  }
}

unsigned int OpenHapticsDevice::ServoCallback(void* user) noexcept {
  return static_cast<OpenHapticsDevice*>(user)->Servo();
}

unsigned int OpenHapticsDevice::ZeroFrameCallback(void* user) noexcept {
  auto* self = static_cast<OpenHapticsDevice*>(user);
  self->api_->make_current_device(self->hhd_);
  self->api_->begin_frame(self->hhd_);
  self->Render(Wrench{});
  self->api_->end_frame(self->hhd_);
  return kHdCallbackDone;
}

unsigned int OpenHapticsDevice::Servo() noexcept {
  const Api& a = *api_;
  a.make_current_device(hhd_);
  a.begin_frame(hhd_);
  if (closing_.load(std::memory_order_acquire)) {
    Render(Wrench{});
    a.end_frame(hhd_);
    DrainErrors();
    return kHdCallbackContinue;
  }
  double T[kGetBuffer] = {}, v[kGetBuffer] = {}, w[kGetBuffer] = {};
  int buttons[kGetBuffer] = {};
  a.get_doublev(kHdCurrentTransform, T);                              // X_PS, column-major, mm
  a.get_doublev(kHdCurrentVelocity, v);                               // mm/s
  if (sensed_rotation_) a.get_doublev(kHdCurrentAngularVelocity, w);  // rad/s
  a.get_integerv(kHdCurrentButtons, buttons);
  const std::int64_t now_ns = NowNs();

  Sample sample;
  sample.t_ns = now_ns;
  unsigned int error = DrainErrors();
  bool fault = error != kHdSuccess || zero_next_frame_;
  zero_next_frame_ = false;
  if (!fault) {
    const glm::dvec3 p_PS = 1e-3 * glm::dvec3(T[12], T[13], T[14]);
    glm::dmat3 R_PS(1.0);
    if (sensed_rotation_) {
      R_PS = glm::dmat3(glm::dvec3(T[0], T[1], T[2]), glm::dvec3(T[4], T[5], T[6]),
                        glm::dvec3(T[8], T[9], T[10]));
    }
    const glm::dmat3 R_MH = kR_MP * R_PS * glm::transpose(kR_MP);
    sample.X_MH = RigidTransform{kR_MP * (p_PS - c_P_m_), glm::quat_cast(R_MH)};
    sample.V_MH_M =
        Twist{kR_MP * (1e-3 * glm::dvec3(v[0], v[1], v[2])), kR_MP * glm::dvec3(w[0], w[1], w[2])};
    sample.buttons = static_cast<std::uint32_t>(buttons[0]);
    sample.valid = IsFinite(sample.X_MH) && IsFinite(sample.V_MH_M);
  }

  Command newest;
  if (commands_.Read(newest)) command_ = newest;
  Wrench F_H_P{};
  if (sample.valid) {
    const bool fresh =
        command_.valid && std::abs(now_ns - command_.t_ns) <=
                              static_cast<std::int64_t>(config_.wrench_timeout_s * 1e9);
    if (fresh) {
      bool saturated = false;
      F_H_P = detail::ClampToDeviceLimits(command_.F_H_P, caps_.max_force_n, caps_.max_torque_nm,
                                          saturated);
      if (saturated) saturated_.fetch_add(1, std::memory_order_relaxed);
    } else {
      stale_.fetch_add(1, std::memory_order_relaxed);
    }
  }
  Render(F_H_P);
  a.end_frame(hhd_);
  const unsigned int end_error = DrainErrors();
  if (end_error != kHdSuccess) {
    error = end_error;
    zero_next_frame_ = true;  // what this frame sent may be wrong: the next one renders zero
    sample.valid = false;
  }
  if (error != kHdSuccess) {
    errors_.fetch_add(1, std::memory_order_relaxed);
    last_error_.store(error, std::memory_order_relaxed);
  }
  samples_.Write(sample);
  frames_.fetch_add(1, std::memory_order_relaxed);
  return kHdCallbackContinue;
}

bool OpenHapticsDevice::ReadState(std::int64_t now_ns, DeviceState& state) noexcept {
  if (!open_.load(std::memory_order_acquire)) return false;
  return ReadFreshSample(samples_, last_sample_, have_sample_, now_ns, config_.stale_after_s,
                         state);
}

bool OpenHapticsDevice::WriteWrench(const Wrench& F_H_M, std::int64_t now_ns) noexcept {
  if (!open_.load(std::memory_order_acquire)) return false;
  return WriteVendorWrench(commands_, &Command::F_H_P, glm::transpose(kR_MP), F_H_M, now_ns);
}

OpenHapticsStatus OpenHapticsDevice::status() const noexcept {
  OpenHapticsStatus s;
  s.running = open_.load();
  s.frames = frames_.load();
  s.device_errors = errors_.load();
  s.last_error_code = last_error_.load();
  s.saturated_commands = saturated_.load();
  s.stale_wrenches = stale_.load();
  return s;
}

}  // namespace ht::openhaptics
