// Force Dimension devices through the DHD library loaded at Open (force_dimension.h): the model
// figures, Open with the library's checks, the I/O thread, and the wait-free hand-offs with the
// haptic loop.

#include "master_station/force_dimension.h"

#include <chrono>
#include <cmath>
#include <stdexcept>
#include <thread>

#include "device_limits.h"
#include "haptic_core/steady_clock.h"
#include "master_station/vendor_exchange.h"
#include "master_station/vendor_library.h"

namespace ht::force_dimension {
namespace {

// dhdc.h (Force Dimension Haptic SDK 3.x): device types and the on/off value.
constexpr int kDeviceDelta3 = 63;
constexpr int kDeviceOmega3 = 33;
constexpr int kDeviceOmega6Right = 34;
constexpr int kDeviceOmega6Left = 36;
constexpr int kDeviceOmega7Right = 35;
constexpr int kDeviceOmega7Left = 37;
constexpr int kDeviceSigma7Right = 104;
constexpr int kDeviceSigma7Left = 105;
constexpr int kDeviceLambda7Right = 108;
constexpr int kDeviceLambda7Left = 109;
constexpr int kDeviceFalcon = 60;
constexpr unsigned char kDhdOn = 1;

const VendorLibrarySpec& LibrarySpec() {
  static const VendorLibrarySpec spec{
      "Force Dimension",
      {"libdhd.so", "libdhd.so.3", "libdrd.so", "libdrd.so.3"},
      "Install the Force Dimension SDK (forcedimension.com, Software: the Haptic SDK for Linux) "
      "and put its lib folder on LD_LIBRARY_PATH, or give the library with --device-library "
      "PATH/libdhd.so"};
  return spec;
}

}  // namespace

// The DHD functions, with dhdc.h's signatures (the trailing `char ID` is the device: dhdOpen's
// answer).
struct ForceDimensionDevice::Api {
  int (*open)() = nullptr;                                         // dhdOpen
  int (*close)(char) = nullptr;                                    // dhdClose
  int (*stop)(char) = nullptr;                                     // dhdStop
  int (*get_system_type)(char) = nullptr;                          // dhdGetSystemType
  const char* (*get_system_name)(char) = nullptr;                  // dhdGetSystemName (optional)
  int (*enable_force)(unsigned char, char) = nullptr;              // dhdEnableForce
  int (*get_position)(double*, double*, double*, char) = nullptr;  // dhdGetPosition
  int (*get_orientation_frame)(double[3][3], char) = nullptr;      // (optional)
  int (*get_linear_velocity)(double*, double*, double*, char) = nullptr;  // dhdGetLinearVelocity
  int (*get_angular_velocity_rad)(double*, double*, double*, char) = nullptr;  // (optional)
  unsigned int (*get_button_mask)(char) = nullptr;                             // dhdGetButtonMask
  int (*set_force_and_torque)(double, double, double, double, double, double, char) = nullptr;
  int (*set_force_and_torque_and_gripper_force)(double, double, double, double, double, double,
                                                double, char) = nullptr;  // (optional)
  bool (*has_wrist)(char) = nullptr;                                      // (optional)
  bool (*has_active_wrist)(char) = nullptr;                               // (optional)
  bool (*has_active_gripper)(char) = nullptr;                             // (optional)
  double (*get_max_force)(char) = nullptr;                                // (optional, SDK 3.9+)
  double (*get_max_torque)(char) = nullptr;                               // (optional)
  const char* (*error_get_last_str)() = nullptr;                          // dhdErrorGetLastStr

  std::string LastError() const {
    const char* s = error_get_last_str ? error_get_last_str() : nullptr;
    return s && *s ? s : "no error text";
  }
};

ModelFigures FiguresForSystemType(int system_type) noexcept {
  // CHAI3D's cDeltaDevice::open: its default, then one entry per model.
  ModelFigures f{system_type, "Force Dimension device", 12.0, 0.0, 5000.0, 0.0, 30.0, 0.075, false,
                 false};
  switch (system_type) {
    case kDeviceDelta3:
      f = {system_type, "delta.3", 20.0, 0.0, 5000.0, 0.0, 30.0, 0.15, false, false};
      break;
    case kDeviceOmega3:
      f = {system_type, "omega.3", 12.0, 0.0, 5000.0, 0.0, 30.0, 0.075, false, false};
      break;
    case kDeviceOmega6Right:
    case kDeviceOmega6Left:
      f = {system_type, "omega.6", 12.0, 0.0, 5000.0, 0.0, 30.0, 0.075, true, false};
      break;
    case kDeviceOmega7Right:
    case kDeviceOmega7Left:
      f = {system_type, "omega.7", 12.0, 0.0, 5000.0, 0.0, 30.0, 0.075, true, false};
      break;
    case kDeviceSigma7Right:
    case kDeviceSigma7Left:
      f = {system_type, "sigma.7", 12.0, 0.2, 4000.0, 1.0, 30.0, 0.075, true, true};
      break;
    case kDeviceLambda7Right:
    case kDeviceLambda7Left:
      f = {system_type, "lambda.7", 12.0, 0.2, 8000.0, 1.0, 30.0, 0.1125, true, true};
      break;
    case kDeviceFalcon:
      f = {system_type, "Novint Falcon (DHD)", 8.0, 0.0, 3000.0, 0.0, 20.0, 0.04, false, false};
      break;
    default:
      break;
  }
  return f;
}

ForceDimensionDevice::ForceDimensionDevice(ForceDimensionConfig config)
    : config_(std::move(config)) {
  if (!(config_.io_period_s > 0.0) || !(config_.io_period_s <= 0.1)) {
    throw std::invalid_argument("Force Dimension: I/O period " +
                                std::to_string(config_.io_period_s) + " s outside (0, 0.1]");
  }
  if (!(config_.wrench_timeout_s > 0.0) || !(config_.stale_after_s > 0.0)) {
    throw std::invalid_argument("Force Dimension: wrench timeout and staleness must be positive");
  }
  caps_.name = "Force Dimension (DHD library, not opened)";
  caps_.rated_loop_rate_hz = 1.0 / config_.io_period_s;
  caps_.dof_in = 3;
  caps_.dof_out = 3;
}

ForceDimensionDevice::~ForceDimensionDevice() { Close(); }

DeviceCapabilities ForceDimensionDevice::capabilities() const { return caps_; }

std::int64_t ForceDimensionDevice::NowNs() const noexcept {
  return config_.clock_ns ? config_.clock_ns() : SteadyNowNs();
}

void ForceDimensionDevice::Open() {
  if (open_.load()) return;
  auto library = std::make_unique<VendorLibrary>(LibrarySpec(), config_.library_path);
  auto api = std::make_unique<Api>();
  {
    const VendorLibrary& l = *library;
    Api& a = *api;
    a.open = l.Require<decltype(a.open)>("dhdOpen");
    a.close = l.Require<decltype(a.close)>("dhdClose");
    a.stop = l.Require<decltype(a.stop)>("dhdStop");
    a.get_system_type = l.Require<decltype(a.get_system_type)>("dhdGetSystemType");
    a.get_system_name = l.Find<decltype(a.get_system_name)>("dhdGetSystemName");
    a.enable_force = l.Require<decltype(a.enable_force)>("dhdEnableForce");
    a.get_position = l.Require<decltype(a.get_position)>("dhdGetPosition");
    a.get_orientation_frame = l.Find<decltype(a.get_orientation_frame)>("dhdGetOrientationFrame");
    a.get_linear_velocity = l.Require<decltype(a.get_linear_velocity)>("dhdGetLinearVelocity");
    a.get_angular_velocity_rad =
        l.Find<decltype(a.get_angular_velocity_rad)>("dhdGetAngularVelocityRad");
    a.get_button_mask = l.Require<decltype(a.get_button_mask)>("dhdGetButtonMask");
    a.set_force_and_torque = l.Require<decltype(a.set_force_and_torque)>("dhdSetForceAndTorque");
    a.set_force_and_torque_and_gripper_force =
        l.Find<decltype(a.set_force_and_torque_and_gripper_force)>(
            "dhdSetForceAndTorqueAndGripperForce");
    a.has_wrist = l.Find<decltype(a.has_wrist)>("dhdHasWrist");
    a.has_active_wrist = l.Find<decltype(a.has_active_wrist)>("dhdHasActiveWrist");
    a.has_active_gripper = l.Find<decltype(a.has_active_gripper)>("dhdHasActiveGripper");
    a.get_max_force = l.Find<decltype(a.get_max_force)>("dhdGetMaxForce");
    a.get_max_torque = l.Find<decltype(a.get_max_torque)>("dhdGetMaxTorque");
    a.error_get_last_str = l.Require<decltype(a.error_get_last_str)>("dhdErrorGetLastStr");
  }

  const int id = api->open();
  if (id < 0) {
    throw std::runtime_error(
        "Force Dimension: dhdOpen found no device (" + api->LastError() + ", library " +
        library->file() +
        "). Is it plugged in, powered and calibrated, and may this user open it (the SDK's "
        "doc/linux udev rule)?");
  }
  const char c_id = static_cast<char>(id);
  try {
    const int type = api->get_system_type(c_id);
    if (type < 0) {
      throw std::runtime_error("Force Dimension: dhdGetSystemType failed: " + api->LastError());
    }
    const ModelFigures figures = FiguresForSystemType(type);
    sensed_rotation_ = figures.sensed_rotation;
    actuated_rotation_ = figures.actuated_rotation;
    if (api->has_wrist) sensed_rotation_ = api->has_wrist(c_id);
    if (api->has_active_wrist) actuated_rotation_ = api->has_active_wrist(c_id);
    if (!api->get_orientation_frame) sensed_rotation_ = false;
    active_gripper_ = api->set_force_and_torque_and_gripper_force && api->has_active_gripper &&
                      api->has_active_gripper(c_id);

    DeviceCapabilities c;
    const char* system_name = api->get_system_name ? api->get_system_name(c_id) : nullptr;
    c.name = std::string("Force Dimension ") +
             (system_name && *system_name ? system_name : figures.name) + " (DHD)";
    c.max_force_n = figures.max_force_n;
    // dhdGetMaxForce/Torque: the limit set on the device (N, N·m); negative = none set.
    if (api->get_max_force) {
      const double limit = api->get_max_force(c_id);
      if (limit > 0.0 && limit < c.max_force_n) c.max_force_n = limit;
    }
    c.max_torque_nm = actuated_rotation_ ? figures.max_torque_nm : 0.0;
    if (api->get_max_torque && c.max_torque_nm > 0.0) {
      const double limit = api->get_max_torque(c_id);
      if (limit > 0.0 && limit < c.max_torque_nm) c.max_torque_nm = limit;
    }
    c.max_stiffness_n_per_m = figures.max_stiffness_n_per_m;
    c.max_rotational_stiffness_nm_per_rad =
        actuated_rotation_ ? figures.max_rotational_stiffness_nm_per_rad : 0.0;
    c.max_damping_ns_per_m = figures.max_damping_ns_per_m;
    c.rated_loop_rate_hz = 1.0 / config_.io_period_s;
    c.workspace_half_extents_m = glm::dvec3(figures.workspace_radius_m / std::sqrt(3.0));
    c.dof_in = sensed_rotation_ ? 6 : 3;
    c.dof_out = c.max_torque_nm > 0.0 ? 6 : 3;

    if (api->enable_force(kDhdOn, c_id) < 0) {
      throw std::runtime_error("Force Dimension: dhdEnableForce failed: " + api->LastError());
    }
    if (api->set_force_and_torque(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, c_id) < 0) {
      throw std::runtime_error("Force Dimension: the first zero wrench failed: " +
                               api->LastError());
    }
    caps_ = c;
  } catch (...) {
    api->stop(c_id);
    api->close(c_id);
    throw;
  }

  library_ = std::move(library);
  api_ = std::move(api);
  id_ = c_id;
  Sample drained;
  while (samples_.Read(drained)) {
  }
  have_sample_ = false;
  exchanges_ = 0;
  read_faults_ = 0;
  write_faults_ = 0;
  saturated_ = 0;
  stale_ = 0;
  commands_.Write(Command{});
  stop_ = false;
  io_thread_ = std::thread([this] { IoLoop(); });
  open_ = true;
}

void ForceDimensionDevice::Close() noexcept {
  open_ = false;
  stop_ = true;
  if (io_thread_.joinable()) io_thread_.join();  // its last exchange commands zero
  if (api_) {
    api_->stop(id_);  // forces off, brakes on
    api_->close(id_);
  }
  api_.reset();
  library_.reset();
}

bool ForceDimensionDevice::Send(const Wrench& F_H_D) noexcept {
  const glm::dvec3& f = F_H_D.force;
  const glm::dvec3 t = actuated_rotation_ ? F_H_D.torque : glm::dvec3(0.0);
  const int rc = active_gripper_ ? api_->set_force_and_torque_and_gripper_force(f.x, f.y, f.z, t.x,
                                                                                t.y, t.z, 0.0, id_)
                                 : api_->set_force_and_torque(f.x, f.y, f.z, t.x, t.y, t.z, id_);
  if (rc < 0) {
    write_faults_.fetch_add(1, std::memory_order_relaxed);
    return false;
  }
  return true;
}

void ForceDimensionDevice::Exchange(const Command& command, std::int64_t now_ns) noexcept {
  Sample sample;
  double px = 0.0, py = 0.0, pz = 0.0, vx = 0.0, vy = 0.0, vz = 0.0;
  bool ok = api_->get_position(&px, &py, &pz, id_) >= 0 &&
            api_->get_linear_velocity(&vx, &vy, &vz, id_) >= 0;
  glm::dmat3 R_DS(1.0);
  glm::dvec3 w_DS_D(0.0);
  if (ok && sensed_rotation_) {
    double m[3][3] = {{1.0, 0.0, 0.0}, {0.0, 1.0, 0.0}, {0.0, 0.0, 1.0}};
    ok = api_->get_orientation_frame(m, id_) >= 0;
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) R_DS[j][i] = m[i][j];  // glm: [column][row]
    }
    if (ok && api_->get_angular_velocity_rad) {
      ok = api_->get_angular_velocity_rad(&w_DS_D.x, &w_DS_D.y, &w_DS_D.z, id_) >= 0;
    }
  }
  sample.t_ns = now_ns;
  if (ok) {
    const glm::dmat3 R_MH = kR_MD * R_DS * glm::transpose(kR_MD);
    sample.X_MH = RigidTransform{kR_MD * glm::dvec3(px, py, pz), glm::quat_cast(R_MH)};
    sample.V_MH_M = Twist{kR_MD * glm::dvec3(vx, vy, vz), kR_MD * w_DS_D};
    sample.buttons = api_->get_button_mask(id_);
    sample.valid = IsFinite(sample.X_MH) && IsFinite(sample.V_MH_M);
  }
  samples_.Write(sample);
  if (!sample.valid) {
    // No trustworthy reading: the device gets zero.
    read_faults_.fetch_add(1, std::memory_order_relaxed);
    Send(Wrench{});
    return;
  }
  const bool fresh = command.valid && std::abs(now_ns - command.t_ns) <=
                                          static_cast<std::int64_t>(config_.wrench_timeout_s * 1e9);
  Wrench F_H_D{};
  if (fresh) {
    bool saturated = false;
    F_H_D = detail::ClampToDeviceLimits(command.F_H_D, caps_.max_force_n, caps_.max_torque_nm,
                                        saturated);
    if (saturated) saturated_.fetch_add(1, std::memory_order_relaxed);
  } else {
    stale_.fetch_add(1, std::memory_order_relaxed);
  }
  if (Send(F_H_D)) exchanges_.fetch_add(1, std::memory_order_relaxed);
}

void ForceDimensionDevice::IoLoop() noexcept {
  const auto period =
      std::chrono::nanoseconds(static_cast<std::int64_t>(std::llround(config_.io_period_s * 1e9)));
  Command command;
  auto next = std::chrono::steady_clock::now();
  while (!stop_.load(std::memory_order_relaxed)) {
    Command newest;
    if (commands_.Read(newest)) command = newest;
    Exchange(command, NowNs());
    next += period;
    const auto now = std::chrono::steady_clock::now();
    if (next < now) next = now;
    std::this_thread::sleep_until(next);
  }
  Send(Wrench{});  // leave the device with zero wrench
}

bool ForceDimensionDevice::ReadState(std::int64_t now_ns, DeviceState& state) noexcept {
  if (!open_.load(std::memory_order_acquire)) return false;
  return ReadFreshSample(samples_, last_sample_, have_sample_, now_ns, config_.stale_after_s,
                         state);
}

bool ForceDimensionDevice::WriteWrench(const Wrench& F_H_M, std::int64_t now_ns) noexcept {
  if (!open_.load(std::memory_order_acquire)) return false;
  return WriteVendorWrench(commands_, &Command::F_H_D, glm::transpose(kR_MD), F_H_M, now_ns);
}

ForceDimensionStatus ForceDimensionDevice::status() const noexcept {
  ForceDimensionStatus s;
  s.running = open_.load();
  s.exchanges = exchanges_.load();
  s.read_faults = read_faults_.load();
  s.write_faults = write_faults_.load();
  s.saturated_commands = saturated_.load();
  s.stale_wrenches = stale_.load();
  return s;
}

}  // namespace ht::force_dimension
