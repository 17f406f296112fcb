#pragma once
// Novint Falcon through libusb-1.0: 3-DoF position in, 3-DoF force out.
//
// The pipeline, in the order the bytes travel:
//   FalconTransport     byte pipe to the Falcon's FTDI FT232 (control set-up, bulk in/out);
//   FalconProtocol      boot-loader firmware load, then 16-byte request/response frames;
//   kinematics          encoder counts -> motor angles -> handle position (forward solution of
//                       the Falcon's delta mechanism) and Jacobian transpose force -> torques;
//   FalconDevice        HapticDevice with its own I/O thread (one exchange per ms), handing state
//                       and wrench to and from the haptic loop through wait-free buffers.
//
// Facts about the device are taken from libnifalcon (github.com/libnifalcon/libnifalcon, BSD),
// read, not copied; each constant names its source. The mechanism model is R. E. Stamper's,
// "A Three Degree of Freedom Parallel Manipulator with Only Translational Degrees of Freedom",
// PhD thesis, Univ. of Maryland, 1997 (ISR PhD 97-4), as parameterised in libnifalcon.
//
// Frames. K is libnifalcon's kinematic frame of the Falcon (z out of the device towards the
// user, the legs at 105°, -15° and -135° about z). M, the device base frame used everywhere
// outside this file, has K's axes and its origin at the centre of the workspace, 0.11 m out
// along z (libnifalcon examples/falcon_test_cli/FalconSphereTest.cpp centres its sphere there).
// H is the handle (the grip centre). Orientation is not sensed: R_MH is the identity.

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <glm/mat3x3.hpp>
#include <glm/matrix.hpp>
#include <memory>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include "master_station/haptic_device.h"
#include "master_station/lock_free.h"

struct libusb_context;
struct libusb_device_handle;

namespace ht::falcon {

// ---------------------------------------------------------------------------------------------
// USB identity and FTDI set-up
// ---------------------------------------------------------------------------------------------

/// FTDI's vendor id; the Falcon's product id (libnifalcon FalconComm.h FALCON_VENDOR_ID and
/// FALCON_PRODUCT_ID; linux/40-novint-falcon-udev.rules).
inline constexpr std::uint16_t kUsbVendorId = 0x0403;
inline constexpr std::uint16_t kUsbProductId = 0xCB48;

/// One FT232 baud-rate setting: the control transfer's wValue and wIndex and the rate it gives.
struct FtdiBaudSetting {
  std::uint16_t value = 0;
  std::uint16_t index = 0;
  int actual_baud = 0;
};

/// The FT232B/R divisor encoding for `baud` (baud/s): 3 MHz divided by an integer plus eighths,
/// with 3 MHz and 2 MHz as special codes (FTDI application note AN232B-05, "Configuring FT232R,
/// FT2232 and FT232B Baud Rates"). Throws std::invalid_argument outside 183 .. 3,000,000 baud.
/// Examples: 9600 -> 0x4138 (the literal libnifalcon sends), 142857 -> 0x0015, 1.5 M -> 0x0002.
FtdiBaudSetting FtdiBaudDivisor(int baud);

/// The byte pipe to the FTDI chip in the Falcon: the control operations the Falcon's set-up
/// needs, named by what they do, and bulk transfers. The set-up calls run in Open (outside the
/// haptic loop) and throw std::runtime_error; Write/Read run on the I/O thread and never throw.
class FalconTransport {
 public:
  virtual ~FalconTransport() = default;
  /// Discards whatever the chip holds in its receive and transmit buffers.
  virtual void PurgeBuffers() = 0;
  /// Sets the serial rate (baud/s) between the FTDI chip and the Falcon's DSP.
  virtual void SetBaudRate(int baud) = 0;
  /// 8 data bits, no parity, 1 stop bit, no flow control.
  virtual void SetLineFormat8N1NoFlowControl() = 0;
  /// How long (ms, 1..255) the chip holds a partly filled packet before sending it to the host.
  virtual void SetLatencyTimer(int latency_ms) = 0;
  /// Drives the DTR line (high = true); the Falcon's boot loader is entered by toggling it.
  virtual void SetDtr(bool high) = 0;
  /// Drives the RTS line (high = true).
  virtual void SetRts(bool high) = 0;
  /// Writes all of `bytes`; returns the number written, or -1 on an error. Blocks at most
  /// `timeout_ms` (>= 1).
  virtual int Write(std::span<const std::uint8_t> bytes, int timeout_ms) noexcept = 0;
  /// Reads up to out.size() payload bytes (the FTDI status bytes already removed); returns the
  /// number read, 0 when nothing arrived within `timeout_ms` (>= 1), or -1 on an error.
  virtual int Read(std::span<std::uint8_t> out, int timeout_ms) noexcept = 0;
};

/// FalconTransport over libusb-1.0: interface 0, bulk OUT 0x02, bulk IN 0x81 (libnifalcon
/// FalconCommLibUSB.cpp). Each 64-byte bulk IN packet of an FTDI chip starts with two modem
/// status bytes; Read strips them. Not thread-safe: set-up and then one I/O thread.
class LibusbFalconTransport final : public FalconTransport {
 public:
  /// Opens the first Falcon (USB 0403:cb48) when `bus` < 0, else the one at `bus`/`address`.
  /// Throws std::runtime_error when libusb cannot start, no Falcon is present, access is denied
  /// (install deploy/udev/70-haptic-falcon.rules) or the interface is held by another program.
  explicit LibusbFalconTransport(int bus = -1, int address = -1);
  ~LibusbFalconTransport() override;
  LibusbFalconTransport(const LibusbFalconTransport&) = delete;
  LibusbFalconTransport& operator=(const LibusbFalconTransport&) = delete;

  void PurgeBuffers() override;
  void SetBaudRate(int baud) override;
  void SetLineFormat8N1NoFlowControl() override;
  void SetLatencyTimer(int latency_ms) override;
  void SetDtr(bool high) override;
  void SetRts(bool high) override;
  int Write(std::span<const std::uint8_t> bytes, int timeout_ms) noexcept override;
  int Read(std::span<std::uint8_t> out, int timeout_ms) noexcept override;

 private:
  void Control(std::uint8_t request, std::uint16_t value, std::uint16_t index, const char* what);

  libusb_context* context_ = nullptr;
  libusb_device_handle* handle_ = nullptr;
  std::array<std::uint8_t, 512> raw_{};      // one bulk IN transfer, status bytes included
  std::array<std::uint8_t, 512> pending_{};  // payload received but not yet handed out
  std::size_t pending_begin_ = 0;
  std::size_t pending_end_ = 0;
};

// ---------------------------------------------------------------------------------------------
// Wire format of the running firmware (libnifalcon FalconFirmwareNovintSDK.cpp formatInput /
// formatOutput; nifalcon_test_fw.h for the flag bits)
// ---------------------------------------------------------------------------------------------
//
// Both directions carry 16-byte frames:
//   byte 0        '<' (0x3C)
//   bytes 1..12   three signed 16-bit values, motor/axis i in bytes 1+4i .. 4+4i, one nibble per
//                 byte, least significant nibble first, each nibble sent as 0x41 + nibble
//   byte 13       0x41 + flags. Request: bit 0 homing mode, bits 1..3 LEDs green/blue/red.
//                 Response: bits 0..3 grip buttons, bits 4..6 axis 1..3 homed.
//   byte 14       request: 0x41 (unused); response: not documented, ignored
//   byte 15       '>' (0x3E)
// Request values are motor commands (firmware units, see kMotorCommandPerNm); response values
// are encoder counts.

inline constexpr std::size_t kFrameSize = 16;
inline constexpr std::uint8_t kFrameStart = '<';
inline constexpr std::uint8_t kFrameEnd = '>';
inline constexpr std::uint8_t kNibbleOffset = 0x41;

inline constexpr std::uint8_t kRequestHomingMode = 0x01;
inline constexpr std::uint8_t kLedGreen = 0x02;
inline constexpr std::uint8_t kLedBlue = 0x04;
inline constexpr std::uint8_t kLedRed = 0x08;
inline constexpr std::uint8_t kAllAxesHomed = 0x07;

/// Host -> Falcon.
struct FalconRequest {
  std::array<std::int16_t, 3> motor_command{};  ///< Per motor, firmware units.
  std::uint8_t leds = 0;                        ///< kLedGreen | kLedBlue | kLedRed.
  bool homing_mode = false;                     ///< Ask the firmware to find the home switches.
};

/// Falcon -> host.
struct FalconResponse {
  std::array<std::int16_t, 3> encoder{};  ///< Per motor, quadrature counts.
  std::uint8_t homed_mask = 0;            ///< Bit i: axis i has passed its home switch.
  std::uint8_t buttons = 0;               ///< Grip buttons, bits 0..3.
};

/// Serializes `request` into exactly kFrameSize bytes.
void EncodeRequest(const FalconRequest& request, std::span<std::uint8_t, kFrameSize> out) noexcept;
/// Parses a request frame (what the device side reads). False, `request` untouched, when the
/// length is not kFrameSize, a marker is wrong or a field byte is out of its range.
bool DecodeRequest(std::span<const std::uint8_t> frame, FalconRequest& request) noexcept;
/// Serializes `response` into exactly kFrameSize bytes (byte 14 written as 0x41).
void EncodeResponse(const FalconResponse& response,
                    std::span<std::uint8_t, kFrameSize> out) noexcept;
/// Parses a response frame. False, `response` untouched, on a wrong length, a wrong marker, a
/// nibble byte outside 0x41..0x50 or a flag byte outside 0x41..0xC0.
bool DecodeResponse(std::span<const std::uint8_t> frame, FalconResponse& response) noexcept;

/// Reassembles response frames from a byte stream that may split, join or corrupt them: bytes
/// before a '<' are skipped; a 16-byte candidate that does not decode is counted and dropped,
/// resynchronising on the next '<' inside it.
class ResponseAssembler {
 public:
  /// Feeds `bytes`; returns true when at least one whole response was completed, the newest in
  /// `newest`.
  bool Push(std::span<const std::uint8_t> bytes, FalconResponse& newest) noexcept;
  std::uint64_t malformed_frames() const noexcept { return malformed_; }
  void Reset() noexcept { size_ = 0; }

 private:
  std::array<std::uint8_t, kFrameSize> buffer_{};
  std::size_t size_ = 0;
  std::uint64_t malformed_ = 0;
};

// ---------------------------------------------------------------------------------------------
// Firmware
// ---------------------------------------------------------------------------------------------

/// Sizes of the two firmware images libnifalcon knows (bytes): the nVent driver's
/// (util/FalconFirmwareBinaryNvent.h, NOVINT_FALCON_NVENT_FIRMWARE_SIZE) and the test firmware
/// (util/FalconFirmwareBinaryTest.h, NOVINT_FALCON_TEST_FIRMWARE_SIZE). Others are accepted if
/// their boot table is well formed.
inline constexpr std::size_t kNventFirmwareSize = 8492;
inline constexpr std::size_t kTestFirmwareSize = 7324;
/// Largest image accepted (bytes): the TMS320F28xx's on-chip RAM the boot loader fills is far
/// smaller; this only rejects a wrong file early.
inline constexpr std::size_t kMaxFirmwareSize = 64 * 1024;

/// Reads the firmware the user supplies (`--falcon-firmware FILE`; it is Novint's and is not
/// shipped here) and checks that it is a TMS320 8-bit boot table (TI SPRU722, "Boot ROM
/// Reference Guide", boot data stream: key 0x08AA, 8 reserved words, a 32-bit entry point, then
/// blocks {size in 16-bit words, 32-bit address, data} ending with a zero size; libnifalcon
/// describes the image as the hex2000 memory layout of the TMS320 DSP). Throws
/// std::runtime_error naming the path and the fault: empty path, missing or unreadable file,
/// empty or oversized file, wrong key, or a block table that runs past the end of the file.
std::vector<std::uint8_t> ReadFirmwareFile(const std::string& path);

/// Same checks on bytes in memory; `what` names them in the message.
void CheckFirmwareImage(std::span<const std::uint8_t> image, const std::string& what);

// ---------------------------------------------------------------------------------------------
// Protocol
// ---------------------------------------------------------------------------------------------

/// Serial rates of the two phases (baud/s). Boot: 9600 for the handshake (libnifalcon
/// FalconCommLibUSB::setFirmwareMode, divisor literal 0x4138), then 3 MHz / 21 = 142857 for the
/// image ("140000 baud (0x15 clock ticks per signal)", ibid.). Running: 3 MHz / 2 = 1.5 M
/// (setNormalMode sends divisor 0x0002; the libftdi variant asks for 1456312, which rounds to
/// the same divisor).
inline constexpr int kHandshakeBaud = 9600;
inline constexpr int kFirmwareBaud = 142857;
inline constexpr int kRunningBaud = 1500000;
/// Latency timer during the boot (16 ms: "otherwise firmware checks tend to always fail") and
/// while running (1 ms: "if we do not reset latency to 1ms ... wait 16ms to get any data back"),
/// libnifalcon nifalcon_libftdi.c.
inline constexpr int kBootLatencyMs = 16;
inline constexpr int kRunningLatencyMs = 1;
/// Firmware bytes per bulk write during the load; each byte is echoed back by the boot loader
/// and compared (libnifalcon FalconFirmware.cpp READ_SIZE = 62: a 64-byte full-speed packet
/// less the FTDI's two status bytes).
inline constexpr int kFirmwareChunkBytes = 62;

/// Outcome of one request/response exchange.
enum class ExchangeResult { kOk, kWriteFailed, kReadFailed, kTimeout };

/// The Falcon's protocol over a FalconTransport: the boot-loader firmware load, then the
/// running exchange of 16-byte frames. The transport must outlive it.
class FalconProtocol {
 public:
  explicit FalconProtocol(FalconTransport& transport) noexcept : transport_(transport) {}

  /// Loads `image` (already checked) into the DSP and leaves the link in running mode:
  /// purge, latency 16 ms, 9600 8N1 without flow control, RTS low, DTR low then high (reset
  /// into the boot loader), handshake {0x0A,0x43,0x0D} answered by {[0x00,]0x0A,0x44,0x2C,0x0D}
  /// (up to 100 tries), DTR low, 142857 baud, autobaud character 'A' echoed, the image in
  /// 62-byte chunks each echoed byte for byte, then latency 1 ms, 1.5 Mbaud, purge
  /// (libnifalcon FalconCommLibUSB::setFirmwareMode, FalconFirmware::loadFirmware,
  /// setNormalMode). Throws std::runtime_error saying which step failed.
  void LoadFirmware(std::span<const std::uint8_t> image);

  /// Sends `request`, then reads until a whole response arrives or `timeout_ms` passes.
  ExchangeResult Exchange(const FalconRequest& request, FalconResponse& response,
                          int timeout_ms) noexcept;

  std::uint64_t malformed_frames() const noexcept { return assembler_.malformed_frames(); }

 private:
  /// Reads exactly out.size() bytes or throws, saying `what` was awaited.
  void ReadExactly(std::span<std::uint8_t> out, int timeout_ms, const char* what);

  FalconTransport& transport_;
  ResponseAssembler assembler_;
};

// ---------------------------------------------------------------------------------------------
// Kinematics
// ---------------------------------------------------------------------------------------------

/// Actuated angles θ1 of legs 1..3 (rad), Stamper's convention as in libnifalcon.
using MotorAngles = std::array<double, 3>;
/// Joint torques about the three actuated axes (N·m), positive in the direction of growing θ1.
using MotorTorques = glm::dvec3;

/// Position of the workspace centre in K (m): M's origin.
inline constexpr double kWorkspaceCentreZ_m = 0.11;

/// Motor angle θ1 (rad) for an encoder count: 320-slot wheel read in quadrature (1280 counts
/// per motor turn) on a 14.25 mm shaft driving a 110 mm arm capstan, 35° at count 0
/// (libnifalcon core/FalconGeometry.h WHEEL_SLOTS_NUMBER, SHAFT_DIAMETER, SMALL_ARM_DIAMETER,
/// THETA_OFFSET_ANGLE; core/FalconKinematic.h getTheta).
double EncoderToMotorAngle(double counts) noexcept;
/// Inverse of EncoderToMotorAngle (counts, not rounded).
double MotorAngleToEncoder(double angle_rad) noexcept;

/// Closed-form inverse kinematics: the motor angles that put the handle at p_MH (m, in M).
/// False when the point is outside the mechanism's reach. Per leg: the point in the leg's
/// (u,v,w) frame fixes the parallelogram's out-of-plane angle θ3 from v, and θ1 from the circle
/// the knee must lie on (Stamper 1997, ch. 3; libnifalcon FalconKinematicStamper::IK chooses
/// the same branch).
bool InverseKinematics(const glm::dvec3& p_MH, MotorAngles& theta) noexcept;

/// Forward kinematics: the handle position p_MH (m, in M) for motor angles `theta` (rad), by
/// Newton's method on the three leg-closure equations starting from the value `p_MH` holds
/// (pass the previous solution; the workspace centre, zero, when there is none). The result is
/// checked against InverseKinematics. False, `p_MH` untouched, when it does not converge within
/// 30 iterations or lands on the other knee branch.
bool ForwardKinematics(const MotorAngles& theta, glm::dvec3& p_MH) noexcept;

/// The Jacobian J = ∂p_MH/∂θ (m/rad; column j is the handle velocity per unit rate of motor j)
/// at handle position p_MH, from the implicit-function theorem on the leg-closure equations.
/// False near a singularity (|det| of ∂θ/∂p below 1e-9) or outside the reach.
bool HandleJacobian(const glm::dvec3& p_MH, glm::dmat3& J) noexcept;

/// Joint torques that render the force F_H_M (N, on the handle, in M) at the pose whose
/// Jacobian is J: τ = Jᵀ F (virtual work).
inline MotorTorques TorquesForForce(const glm::dmat3& J, const glm::dvec3& F_H_M) noexcept {
  return glm::transpose(J) * F_H_M;
}

/// Motor command units per N·m of joint torque, with the sign flip the firmware wants:
/// command = -kMotorCommandPerNm · τ (libnifalcon FalconKinematicStamper::getForces, "convert
/// torque to motor voltages": torque *= 10000; enc_force = -torque). An empirical scale, not a
/// calibrated one.
inline constexpr double kMotorCommandPerNm = 10000.0;
/// Default per-motor command limit: 10000 units = 1 N·m. libnifalcon documents no limit (it
/// clamps at a self-described "rather random" 30 N·m); 8.9 N at the workspace centre needs
/// about 0.54 N·m on the most loaded motor, so this leaves ~1.9x headroom inside the int16 field.
inline constexpr int kDefaultMaxMotorCommand = 10000;

/// Motor commands for joint torques τ (N·m): -kMotorCommandPerNm·τ, and when any motor would
/// exceed `max_command` (1..32767) the whole vector is scaled down so that the largest is at the
/// limit, which keeps the force direction. Non-finite torques give zero commands.
struct MotorCommands {
  std::array<std::int16_t, 3> command{};
  bool saturated = false;
};
MotorCommands TorquesToMotorCommands(const MotorTorques& tau_nm, int max_command) noexcept;

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
  /// Newest reading: p_MH (orientation identity), V_MH_M (angular zero), grip buttons. False
  /// before Open, until homed, or when the newest reading is older than stale_after_s.
  bool ReadState(std::int64_t now_ns, DeviceState& state) noexcept override;
  /// Hands F_H_M.force to the I/O thread (the torque is not rendered: 3-DoF). Zero is rendered
  /// until homed. False before Open or for a non-finite wrench (zero is then commanded).
  bool WriteWrench(const Wrench& F_H_M, std::int64_t now_ns) noexcept override;

  /// Counters and homing state of the I/O thread.
  FalconStatus status() const noexcept;

 private:
  struct Sample {
    glm::dvec3 p_MH{0.0};
    glm::dvec3 v_MH_M{0.0};
    std::uint32_t buttons = 0;
    bool homed = false;
    std::int64_t t_ns = 0;
  };
  struct ForceCommand {
    glm::dvec3 F_H_M{0.0};
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
