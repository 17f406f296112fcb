#pragma once
// 3D Systems (formerly SensAble) devices: Touch, Touch X, Phantom Omni/Desktop/Premium, through
// OpenHaptics' HD API library (libHD.so), loaded with dlopen at Open, or the path given with
// --device-library. Nothing of OpenHaptics is needed to build.
//
// HD calls used (hd.h, hdDevice.h, hdScheduler.h, hdDefines.h of OpenHaptics 3.x; signatures and
// values as those headers and CHAI3D's hdPhantom wrapper use them): hdInitDevice
// (HD_DEFAULT_DEVICE or a configuration name), hdMakeCurrentDevice, hdEnable(HD_FORCE_OUTPUT),
// hdGetDoublev / hdGetIntegerv / hdGetString for what the device can do (HD_NOMINAL_MAX_FORCE N,
// HD_NOMINAL_MAX_STIFFNESS N/mm, HD_NOMINAL_MAX_DAMPING N·s/mm, HD_USABLE_WORKSPACE_DIMENSIONS mm,
// HD_INPUT_DOF, HD_OUTPUT_DOF, HD_DEVICE_MODEL_TYPE; for 6-DoF output HD_NOMINAL_MAX_TORQUE_FORCE
// and HD_NOMINAL_MAX_TORQUE_STIFFNESS, taken as mN·m and mN·m/rad), hdScheduleAsynchronous with
// a servo callback at HD_MAX_SCHEDULER_PRIORITY, hdStartScheduler; in the callback hdBeginFrame,
// hdGetDoublev(HD_CURRENT_TRANSFORM mm / HD_CURRENT_VELOCITY mm/s / HD_CURRENT_ANGULAR_VELOCITY
// rad/s), hdGetIntegerv(HD_CURRENT_BUTTONS), hdSetDoublev(HD_CURRENT_FORCE N; HD_CURRENT_TORQUE
// mN·m on 6-DoF output devices), hdEndFrame, hdGetError; at Close hdScheduleSynchronous (a zero
// frame), hdStopScheduler, hdUnschedule, hdDisableDevice; hdGetErrorString for messages.
//
// OpenHaptics runs its own servo loop (about 1 kHz, a thread of its own). The callback and the
// haptic loop hand the pose and the wrench to each other through wait-free triple buffers
// (lock_free.h): neither side locks or waits for the other.
//
// Frames. P: OpenHaptics' base, +x right, +y up, +z towards the operator (mm), origin set by the
// device's calibration. M: the station's device base, +x right, +y away from the operator, +z up,
// origin at the centre of HD_USABLE_WORKSPACE_DIMENSIONS: p_M = kR_MP (p_P - c_P), that is
// (x, -z, y) about the centre. S: the stylus frame whose pose HD_CURRENT_TRANSFORM gives as the
// column-major 4x4 X_PS (identity rotation at the device's zero orientation). H: S with M's axes
// at the zero orientation, R_MH = kR_MP R_PS kR_MP^T.

#include <atomic>
#include <cstdint>
#include <glm/mat3x3.hpp>
#include <memory>
#include <string>

#include "master_station/haptic_device.h"
#include "master_station/lock_free.h"

namespace ht {

class VendorLibrary;

namespace openhaptics {

/// R_MP: OpenHaptics' base P (+x right, +y up, +z towards the operator) turned into M (+x
/// right, +y away from the operator, +z up). Columns: P's axes expressed in M.
inline const glm::dmat3 kR_MP{glm::dvec3(1.0, 0.0, 0.0), glm::dvec3(0.0, 0.0, 1.0),
                              glm::dvec3(0.0, -1.0, 0.0)};

struct OpenHapticsConfig {
  /// The HD library to load (`--device-library PATH`); empty = libHD.so, libHD.so.3.4,
  /// libHD.so.3 through the dynamic loader's search.
  std::string library_path;
  /// hdInitDevice's configuration name (as set up with Touch_Setup); empty = HD_DEFAULT_DEVICE.
  std::string device_name;
  /// A wrench older than this is not rendered any more (s): the loop has stalled.
  double wrench_timeout_s = 0.05;
  /// A reading older than this makes ReadState fail (s): the servo loop has stalled.
  double stale_after_s = 0.02;
  /// The clock the servo callback stamps readings and checks wrench freshness with (ns,
  /// steady); null = SteadyNowNs. Tests pass a clock of their own.
  std::int64_t (*clock_ns)() noexcept = nullptr;
};

/// What the servo callback has seen (counters since Open).
struct OpenHapticsStatus {
  bool running = false;
  std::uint64_t frames = 0;              ///< Servo frames run.
  std::uint64_t device_errors = 0;       ///< Frames after which hdGetError reported an error.
  std::uint32_t last_error_code = 0;     ///< HDErrorInfo::errorCode of the newest error.
  std::uint64_t saturated_commands = 0;  ///< Wrenches scaled down to the device's limits.
  std::uint64_t stale_wrenches = 0;      ///< Frames that rendered zero for want of a wrench.
};

/// An OpenHaptics device as a HapticDevice. Open loads the HD library, initialises the device,
/// reads what it can do, enables force output, and schedules the servo callback, which each
/// servo tick reads the stylus, publishes it and renders the newest wrench, clamped to the
/// device's limits. A frame with a device error (hdGetError) publishes no valid reading and the
/// device gets zero until a frame passes without one.
class OpenHapticsDevice final : public HapticDevice {
 public:
  /// Throws std::invalid_argument for a non-positive timeout or staleness.
  explicit OpenHapticsDevice(OpenHapticsConfig config);
  ~OpenHapticsDevice() override;
  OpenHapticsDevice(const OpenHapticsDevice&) = delete;
  OpenHapticsDevice& operator=(const OpenHapticsDevice&) = delete;

  /// Before Open: the name only (no force). After Open: the device's own figures (header
  /// comment), the workspace's half sizes turned into M, dof_out 6 only when HD_OUTPUT_DOF is 6;
  /// a 6-DoF output device that reports no torque limit gets the Phantom Premium 6DOF's 0.188
  /// N·m (CHAI3D's cPhantomDevice); rated at HD's nominal 1000 Hz.
  DeviceCapabilities capabilities() const override;
  /// Loads the library, resolves its symbols, initialises the device, enables forces and starts
  /// the servo callback. Throws std::runtime_error naming what is missing: the library (with
  /// what to install), a symbol, or the device (with hdGetErrorString's text and the code).
  void Open() override;
  /// Renders zero (the servo callback and a last synchronous frame), stops the scheduler,
  /// disables the device and unloads the library.
  void Close() noexcept override;
  /// Newest reading: X_MH, V_MH_M (frames above), buttons (HD_CURRENT_BUTTONS). False before
  /// Open, after a frame with a device error, or when the newest reading is older than
  /// stale_after_s.
  bool ReadState(std::int64_t now_ns, DeviceState& state) noexcept override;
  /// Hands F_H_M (N, N·m, in M), turned into P, to the servo callback, which clamps its force and
  /// torque magnitudes to the device's limits keeping their directions and renders torque only on
  /// 6-DoF output devices. False before Open or for a non-finite wrench (zero is then rendered).
  bool WriteWrench(const Wrench& F_H_M, std::int64_t now_ns) noexcept override;

  OpenHapticsStatus status() const noexcept;

 private:
  struct Api;  // the resolved HD functions
  struct Sample {
    RigidTransform X_MH;
    Twist V_MH_M;
    std::uint32_t buttons = 0;
    bool valid = false;
    std::int64_t t_ns = 0;
  };
  struct Command {
    Wrench F_H_P;
    std::int64_t t_ns = 0;
    bool valid = false;
  };

  // The servo callbacks (HDSchedulerCallback: HDCallbackCode (*)(void*), `user` = this).
  static unsigned int ServoCallback(void* user) noexcept;
  static unsigned int ZeroFrameCallback(void* user) noexcept;
  unsigned int Servo() noexcept;
  // Sets HD_CURRENT_FORCE (and HD_CURRENT_TORQUE on 6-DoF output) to F_H_P inside a frame.
  void Render(const Wrench& F_H_P) noexcept;
  // Pops HD's error stack (at most 16); returns the newest error's code (0 = HD_SUCCESS: none).
  unsigned int DrainErrors() noexcept;
  std::int64_t NowNs() const noexcept;

  OpenHapticsConfig config_;
  DeviceCapabilities caps_;
  std::unique_ptr<VendorLibrary> library_;
  std::unique_ptr<Api> api_;
  unsigned int hhd_ = 0;
  unsigned long servo_handle_ = 0;
  glm::dvec3 c_P_m_{0.0};  // workspace centre in P (m)
  bool sensed_rotation_ = false;
  bool torque_out_ = false;

  std::atomic<bool> open_{false};
  std::atomic<bool> closing_{false};
  TripleBuffer<Sample> samples_;    // servo callback -> loop
  TripleBuffer<Command> commands_;  // loop -> servo callback
  Sample last_sample_;              // loop side
  bool have_sample_ = false;        // loop side
  Command command_;                 // servo side
  bool zero_next_frame_ = false;    // servo side: the previous frame ended with an error

  std::atomic<std::uint64_t> frames_{0};
  std::atomic<std::uint64_t> errors_{0};
  std::atomic<std::uint32_t> last_error_{0};
  std::atomic<std::uint64_t> saturated_{0};
  std::atomic<std::uint64_t> stale_{0};
};

}  // namespace openhaptics
}  // namespace ht
