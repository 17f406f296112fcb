#pragma once
// Novint Falcon, frame protocol: the running firmware's 16-byte request/response frames (encode,
// decode, reassembly from a byte stream), the checks on the firmware image, and FalconProtocol
// (boot-loader firmware load, then one request/response exchange at a time over a
// FalconTransport). Part of the Falcon backend; falcon.h describes the whole pipeline.

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "master_station/falcon_ftdi.h"

namespace ht::falcon {

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

}  // namespace ht::falcon
