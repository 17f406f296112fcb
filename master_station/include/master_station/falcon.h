#pragma once
// Novint Falcon through libusb-1.0: 3-DoF position in, 3-DoF force out.
//
// The pipeline, in the order the bytes travel, one header (and source) per stage:
//   falcon_ftdi.h        FalconTransport: byte pipe to the Falcon's FTDI FT232 (control set-up,
//                        bulk in/out);
//   falcon_protocol.h    FalconProtocol: boot-loader firmware load, then 16-byte request/response
//                        frames;
//   falcon_kinematics.h  encoder counts -> motor angles -> handle position (forward solution of
//                        the Falcon's delta mechanism) and Jacobian transpose force -> torques;
//   falcon.h             FalconDevice: HapticDevice with its own I/O thread (one exchange per ms),
//                        handing state and wrench to and from the haptic loop through wait-free
//                        buffers.
// This header includes the other three, so that including it gives the whole backend.
//
// Facts about the device are taken from libnifalcon (github.com/libnifalcon/libnifalcon, BSD),
// read, not copied; each constant names its source. The mechanism model is R. E. Stamper's,
// "A Three Degree of Freedom Parallel Manipulator with Only Translational Degrees of Freedom",
// PhD thesis, Univ. of Maryland, 1997 (ISR PhD 97-4), as parameterised in libnifalcon.
//
// Frames K (the Falcon's kinematic frame), D (K moved to the workspace centre), M (the device base
// the loop sees: D turned so that +z is up, +y away from the user; kR_MD) and H (the handle): see
// falcon_kinematics.h. Orientation is not sensed: R_MH is the identity.

#include <atomic>
#include <cstdint>
#include <functional>
#include <glm/vec3.hpp>
#include <memory>
#include <string>
#include <thread>

#include "master_station/falcon_ftdi.h"
#include "master_station/falcon_kinematics.h"
#include "master_station/falcon_protocol.h"
#include "master_station/haptic_device.h"
#include "master_station/lock_free.h"

namespace ht::falcon {

// ---------------------------------------------------------------------------------------------
// Device
// ---------------------------------------------------------------------------------------------

/// Makes the transport at Open; the default opens the libusb transport at the configured
/// bus/address.
using FalconTransportFactory = std::function<std::unique_ptr<FalconTransport>()>;

struct FalconConfig {
  /// Firmware image (`--falcon-firmware FILE`). Required: Open throws when it is empty.
  std::string firmware_path;
  int usb_bus = -1;                 ///< With usb_address: which Falcon; -1 = the first one found.
  int usb_address = -1;             ///< USB device address on `usb_bus`.
  double exchange_period_s = 1e-3;  ///< I/O thread period (s).
  int exchange_timeout_ms = 5;      ///< Wait for one response (ms).
  int max_motor_command = kDefaultMaxMotorCommand;  ///< Per-motor clamp, firmware units.
  /// A wrench older than this is not rendered any more (s): the loop has stalled.
  double wrench_timeout_s = 0.05;
  /// A reading older than this makes ReadState fail (s): the device has stalled.
  double stale_after_s = 0.02;
  double velocity_cutoff_hz = 100.0;  ///< First-order low-pass on the differentiated position.
  int start_timeout_ms = 1000;  ///< Open waits this long for the first response after the load.
  /// The clock the I/O thread stamps readings and checks wrench freshness with (ns, steady);
  /// null = std::chrono::steady_clock (SteadyNowNs). Tests pass a simulated clock so that what
  /// the velocity filter sees does not depend on how the machine schedules threads.
  std::int64_t (*clock_ns)() noexcept = nullptr;
};

/// What the I/O thread has seen (counters since Open).
struct FalconStatus {
  bool running = false;
  bool homed = false;           ///< All three axes homed; until then no force and no state.
  std::uint8_t homed_mask = 0;  ///< Bit i: axis i homed.
  std::uint64_t exchanges = 0;  ///< Responses received.
  std::uint64_t malformed_frames = 0;
  std::uint64_t io_errors = 0;           ///< Failed bulk writes or reads.
  std::uint64_t read_timeouts = 0;       ///< Requests that got no response in time.
  std::uint64_t kinematics_faults = 0;   ///< Readings whose forward kinematics failed.
  std::uint64_t saturated_commands = 0;  ///< Requests whose motor commands were scaled down.
};

/// The Novint Falcon as a HapticDevice: position in (dof_in 3), force out (dof_out 3).
/// Open loads the firmware and starts an I/O thread that exchanges one frame per
/// exchange_period_s: it turns the newest wrench into motor commands at the newest position and
/// publishes each reading. Until all three axes report homed it asks the firmware for homing
/// mode (red LED), commands zero and ReadState fails; the operator homes the Falcon by pulling
/// the handle all the way out and pushing it back in. Then the LED turns green.
class FalconDevice final : public HapticDevice {
 public:
  explicit FalconDevice(FalconConfig config, FalconTransportFactory factory = {});
  ~FalconDevice() override;
  FalconDevice(const FalconDevice&) = delete;
  FalconDevice& operator=(const FalconDevice&) = delete;

  /// Novint's published figures (H3DAPI wiki "Novint Falcon": force > 8.9 N, 4" x 4" x 4"
  /// workspace = ±0.0508 m) and CHAI3D's cFalconDevice for the stiffness and damping it renders
  /// stably at 1 kHz (m_maxForceStiffness 3000 N/m, m_maxLinearDamping 20 N·s/m).
  DeviceCapabilities capabilities() const override;
  /// Checks the firmware file, opens the transport, loads the firmware, waits for the first
  /// response and starts the I/O thread. Throws std::runtime_error saying what is missing.
  void Open() override;
  /// Commands zero force, stops the I/O thread and releases the transport.
  void Close() noexcept override;
  /// Newest reading: p_DH (orientation identity), V_MH_M (angular zero), grip buttons. False
  /// before Open, until homed, or when the newest reading is older than stale_after_s.
  bool ReadState(std::int64_t now_ns, DeviceState& state) noexcept override;
  /// Hands F_H_M.force (N, in M), turned into D, to the I/O thread (the torque is not rendered:
  /// 3-DoF). Zero is rendered until homed. False before Open or for a non-finite wrench (zero is
  /// then commanded).
  bool WriteWrench(const Wrench& F_H_M, std::int64_t now_ns) noexcept override;

  /// Counters and homing state of the I/O thread.
  FalconStatus status() const noexcept;

 private:
  struct Sample {
    glm::dvec3 p_DH{0.0};
    glm::dvec3 v_DH_D{0.0};
    std::uint32_t buttons = 0;
    bool homed = false;
    std::int64_t t_ns = 0;
  };
  struct ForceCommand {
    glm::dvec3 F_H_D{0.0};
    std::int64_t t_ns = 0;
    bool valid = false;
  };

  void IoLoop() noexcept;

  FalconConfig config_;
  FalconTransportFactory factory_;
  std::unique_ptr<FalconTransport> transport_;
  std::unique_ptr<FalconProtocol> protocol_;
  std::thread io_thread_;
  std::atomic<bool> stop_{false};
  std::atomic<bool> open_{false};

  TripleBuffer<Sample> samples_;         // I/O thread -> loop
  TripleBuffer<ForceCommand> commands_;  // loop -> I/O thread
  Sample last_sample_;                   // loop side
  bool have_sample_ = false;             // loop side

  std::atomic<bool> homed_{false};
  std::atomic<std::uint8_t> homed_mask_{0};
  std::atomic<std::uint64_t> exchanges_{0};
  std::atomic<std::uint64_t> malformed_{0};
  std::atomic<std::uint64_t> io_errors_{0};
  std::atomic<std::uint64_t> timeouts_{0};
  std::atomic<std::uint64_t> kinematics_faults_{0};
  std::atomic<std::uint64_t> saturated_{0};
};

}  // namespace ht::falcon
