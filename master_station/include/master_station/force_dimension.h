#pragma once
// Force Dimension devices (delta.3/.6, omega.3/.6/.7, sigma.3/.7, lambda.7, and a Novint Falcon
// run by Force Dimension's library) through the vendor's DHD library (Haptic SDK), loaded with
// dlopen at Open: libdhd.so / libdhd.so.3, or libdrd.so (the Robotic SDK, which contains DHD), or
// the path given with --device-library. Nothing of the SDK is needed to build.
//
// DHD calls used (dhdc.h, Force Dimension Haptic SDK 3.x; signatures as CHAI3D's cDeltaDevice
// resolves them): dhdOpen, dhdClose, dhdStop, dhdGetSystemType, dhdEnableForce, dhdGetPosition,
// dhdGetLinearVelocity, dhdGetButtonMask, dhdSetForceAndTorque, dhdErrorGetLastStr; where the
// library has them, dhdGetSystemName, dhdHasWrist, dhdHasActiveWrist, dhdHasActiveGripper,
// dhdGetOrientationFrame, dhdGetAngularVelocityRad, dhdGetMaxForce, dhdGetMaxTorque and
// dhdSetForceAndTorqueAndGripperForce. Every device call returns < 0 on an error (DHD_TIMEGUARD 1
// and DHD_MOTOR_SATURATED 2 are not errors).
//
// Frames. D: the device's base as DHD reports it, origin at the workspace centre, +x towards the
// operator, +y to the operator's right, +z up (CHAI3D's convention, which cDeltaDevice passes on
// unchanged). M: the station's device base, the same origin, +x right, +y away from the operator,
// +z up. kR_MD turns D into M (a -90 degree turn about z): p_M = (p_D.y, -p_D.x, p_D.z). S: the
// end-effector frame whose orientation dhdGetOrientationFrame gives as R_DS (row i, column j =
// matrix[i][j]; the identity at the device's zero orientation). H: S with M's axes at the zero
// orientation, R_MH = kR_MD R_DS kR_MD^T, so that turning the wrist about D's +z turns H about
// M's +z. Units: DHD gives metres, m/s, rad/s and takes N and N·m, like the station.

#include <atomic>
#include <cstdint>
#include <glm/mat3x3.hpp>
#include <memory>
#include <string>
#include <thread>

#include "master_station/haptic_device.h"
#include "master_station/lock_free.h"

namespace ht {

class VendorLibrary;

namespace force_dimension {

/// R_MD: DHD's base D (+x towards the operator, +y right, +z up) turned into M (+x right, +y away
/// from the operator, +z up). Columns: D's axes expressed in M.
inline const glm::dmat3 kR_MD{glm::dvec3(0.0, -1.0, 0.0), glm::dvec3(1.0, 0.0, 0.0),
                              glm::dvec3(0.0, 0.0, 1.0)};

/// Published figures of one Force Dimension model, by dhdGetSystemType's answer (DHD_DEVICE_*).
struct ModelFigures {
  int system_type = 0;
  const char* name = "";
  double max_force_n = 0.0;            ///< Largest force (N).
  double max_torque_nm = 0.0;          ///< Largest torque (N·m); 0 = the wrist is passive.
  double max_stiffness_n_per_m = 0.0;  ///< Largest stable stiffness (N/m).
  double max_rotational_stiffness_nm_per_rad = 0.0;
  double max_damping_ns_per_m = 0.0;  ///< Largest stable damping (N·s/m).
  double workspace_radius_m = 0.0;    ///< Radius of a sphere about the origin the handle reaches.
  bool sensed_rotation = false;       ///< Has a wrist whose orientation is read.
  bool actuated_rotation = false;     ///< Has an active wrist (renders torque).
};

/// The figures for `system_type`, from CHAI3D's cDeltaDevice::open (src/devices/
/// CDeltaDevices.cpp, CHAI3D 3.3, BSD), which lists Force Dimension's own numbers per model; an
/// unknown type gets that file's default (12 N, no torque, 0.075 m, no wrist), and the library's
/// own answers (dhdHasWrist, dhdHasActiveWrist, dhdGetMaxForce...) refine it at Open.
ModelFigures FiguresForSystemType(int system_type) noexcept;

struct ForceDimensionConfig {
  /// The DHD library to load (`--device-library PATH`); empty = libdhd.so, libdhd.so.3,
  /// libdrd.so, libdrd.so.3 through the dynamic loader's search.
  std::string library_path;
  double io_period_s = 1e-3;  ///< Period of the I/O thread's exchange with the device (s).
  /// A wrench older than this is not rendered any more (s): the loop has stalled.
  double wrench_timeout_s = 0.05;
  /// A reading older than this makes ReadState fail (s): the I/O thread has stalled.
  double stale_after_s = 0.02;
  /// The clock the I/O thread stamps readings and checks wrench freshness with (ns, steady);
  /// null = SteadyNowNs. Tests pass a clock of their own.
  std::int64_t (*clock_ns)() noexcept = nullptr;
};

/// What the I/O thread has seen (counters since Open).
struct ForceDimensionStatus {
  bool running = false;
  std::uint64_t exchanges = 0;           ///< Periods whose reading and command both succeeded.
  std::uint64_t read_faults = 0;         ///< Periods whose reading failed (zero was commanded).
  std::uint64_t write_faults = 0;        ///< dhdSetForceAndTorque... calls that failed.
  std::uint64_t saturated_commands = 0;  ///< Wrenches scaled down to the device's limits.
  std::uint64_t stale_wrenches = 0;      ///< Periods that rendered zero for want of a wrench.
};

/// A Force Dimension device as a HapticDevice. Open loads the DHD library, opens the first device
/// (dhdOpen), reads what it can do, enables forces and starts an I/O thread that, once per
/// io_period_s, reads the handle (position, orientation, velocities, buttons) and commands the
/// newest wrench, clamped to the device's limits. The haptic loop's ReadState and WriteWrench only
/// touch wait-free buffers (lock_free.h): the DHD calls, which may block on USB, stay on the I/O
/// thread.
class ForceDimensionDevice final : public HapticDevice {
 public:
  /// Throws std::invalid_argument for a non-positive period, timeout or staleness.
  explicit ForceDimensionDevice(ForceDimensionConfig config);
  ~ForceDimensionDevice() override;
  ForceDimensionDevice(const ForceDimensionDevice&) = delete;
  ForceDimensionDevice& operator=(const ForceDimensionDevice&) = delete;

  /// Before Open: the name only (no force). After Open: the model's figures
  /// (FiguresForSystemType), with max force and torque lowered to the library's limits where
  /// dhdGetMaxForce / dhdGetMaxTorque report one (> 0), torque 0 and dof_out 3 when the wrist is
  /// passive or the model has no torque figure (delta.6, sigma.3...), dof_in 3 without a wrist;
  /// workspace: the cube inscribed in the model's workspace sphere (half size r/sqrt(3)); rated at
  /// 1/io_period_s.
  DeviceCapabilities capabilities() const override;
  /// Loads the library, resolves its symbols, opens the device, enables forces with a zero
  /// wrench and starts the I/O thread. Throws std::runtime_error naming what is missing: the
  /// library (with what to install), a symbol, or the device (with the SDK's error text).
  void Open() override;
  /// Commands zero wrench, stops the I/O thread, then dhdStop (forces off, brakes on) and
  /// dhdClose, and unloads the library.
  void Close() noexcept override;
  /// Newest reading: X_MH, V_MH_M (frames above), buttons (dhdGetButtonMask). False before Open,
  /// after a failed reading, or when the newest reading is older than stale_after_s.
  bool ReadState(std::int64_t now_ns, DeviceState& state) noexcept override;
  /// Hands F_H_M (N, N·m, in M), turned into D, to the I/O thread, which clamps its force and
  /// torque magnitudes to the device's limits keeping their directions (no torque where the wrist
  /// is passive). False before Open or for a non-finite wrench (zero is then commanded).
  bool WriteWrench(const Wrench& F_H_M, std::int64_t now_ns) noexcept override;

  ForceDimensionStatus status() const noexcept;

 private:
  struct Api;  // the resolved DHD functions
  struct Sample {
    RigidTransform X_MH;
    Twist V_MH_M;
    std::uint32_t buttons = 0;
    bool valid = false;
    std::int64_t t_ns = 0;
  };
  struct Command {
    Wrench F_H_D;
    std::int64_t t_ns = 0;
    bool valid = false;
  };

  void IoLoop() noexcept;
  // One exchange: read the handle, publish the reading, command the wrench (zero after a failed
  // reading or without a fresh wrench).
  void Exchange(const Command& command, std::int64_t now_ns) noexcept;
  // Sends F_H_D to the device (zero torque unless the wrist is active). False on an error.
  bool Send(const Wrench& F_H_D) noexcept;
  std::int64_t NowNs() const noexcept;

  ForceDimensionConfig config_;
  DeviceCapabilities caps_;
  std::unique_ptr<VendorLibrary> library_;
  std::unique_ptr<Api> api_;
  char id_ = -1;
  bool sensed_rotation_ = false;
  bool actuated_rotation_ = false;
  bool active_gripper_ = false;

  std::thread io_thread_;
  std::atomic<bool> stop_{false};
  std::atomic<bool> open_{false};
  TripleBuffer<Sample> samples_;    // I/O thread -> loop
  TripleBuffer<Command> commands_;  // loop -> I/O thread
  Sample last_sample_;              // loop side
  bool have_sample_ = false;        // loop side

  std::atomic<std::uint64_t> exchanges_{0};
  std::atomic<std::uint64_t> read_faults_{0};
  std::atomic<std::uint64_t> write_faults_{0};
  std::atomic<std::uint64_t> saturated_{0};
  std::atomic<std::uint64_t> stale_{0};
};

}  // namespace force_dimension
}  // namespace ht
