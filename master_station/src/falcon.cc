#include "master_station/falcon.h"

#include <libusb.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <stdexcept>

#include "haptic_core/steady_clock.h"

namespace ht::falcon {
namespace {

using Clock = std::chrono::steady_clock;

std::int64_t NowNs() noexcept { return SteadyNowNs(); }

int MsUntil(Clock::time_point deadline) noexcept {
  const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now());
  return static_cast<int>(left.count());
}

std::string Hex(unsigned value, int digits) {
  char buf[16];
  std::snprintf(buf, sizeof buf, "0x%0*X", digits, value);
  return buf;
}

// ---- FTDI vendor requests (libftdi ftdi.h SIO_* values; libnifalcon FalconCommLibUSB.cpp) ----
constexpr std::uint8_t kFtdiRequestType = 0x40;  // vendor, host to device, device recipient
constexpr std::uint8_t kSioReset = 0;            // value 1: purge RX, 2: purge TX
constexpr std::uint8_t kSioModemControl = 1;     // value: DTR bit 0, RTS bit 1; mask in bits 8, 9
constexpr std::uint8_t kSioSetFlowControl = 2;   // value 0: none
constexpr std::uint8_t kSioSetBaudRate = 3;
constexpr std::uint8_t kSioSetData = 4;  // value: data bits | parity << 8 | stop bits << 11
constexpr std::uint8_t kSioSetLatencyTimer = 9;
constexpr std::uint16_t kSioPurgeRx = 1;
constexpr std::uint16_t kSioPurgeTx = 2;
constexpr unsigned char kEndpointOut = 0x02;
constexpr unsigned char kEndpointIn = 0x81;
constexpr std::size_t kFtdiPacketSize = 64;  // full-speed bulk packet
constexpr std::size_t kFtdiStatusBytes = 2;  // modem and line status at the head of each packet
constexpr int kControlTimeoutMs = 1000;

const char* const kUdevHint =
    "for access without root install deploy/udev/70-haptic-falcon.rules (see the comment in "
    "it) and replug the Falcon";

// ---- Mechanism (libnifalcon core/FalconGeometry.h, after Stamper 1997, fig. p. 30) ----
constexpr double kA = 0.060;         // leg base to knee (m)
constexpr double kB = 0.1025;        // parallelogram (shin) side (m)
constexpr double kC = 0.014;         // shin joint to effector centre, u component (m)
constexpr double kD = 0.01125;       // shin to effector joint (m)
constexpr double kE = kD;            // knee to shin joint (m)
constexpr double kF = -0.025;        // shin joint to effector centre, v component (m)
constexpr double kR = 0.037233758;   // frame origin to leg base, u component (m)
constexpr double kS = -0.027330909;  // frame origin to leg base, v component (m)
// Leg directions about z: 90°, -30°, -150°, each turned by the 15° tilt of the device.
constexpr double kPi = std::numbers::pi;
constexpr std::array<double, 3> kPhi = {kPi / 2 + kPi / 12, -kPi / 6 + kPi / 12,
                                        -5 * kPi / 6 + kPi / 12};
// Encoder: 320 slots in quadrature on a 14.25 mm shaft, 110 mm arm capstan, 35° at 0 counts.
constexpr double kCountsPerMotorTurn = 4.0 * 320.0;
constexpr double kShaftDiameter_m = 0.01425;
constexpr double kArmDiameter_m = 0.110;
constexpr double kRadPerCount =
    2.0 * kPi * kShaftDiameter_m / (kCountsPerMotorTurn * kArmDiameter_m);
constexpr double kAngleAtZero_rad = 35.0 * kPi / 180.0;

struct LegTrig {
  double c, s;
};
const std::array<LegTrig, 3>& LegTrigs() noexcept {
  static const std::array<LegTrig, 3> trig = {LegTrig{std::cos(kPhi[0]), std::sin(kPhi[0])},
                                              LegTrig{std::cos(kPhi[1]), std::sin(kPhi[1])},
                                              LegTrig{std::cos(kPhi[2]), std::sin(kPhi[2])}};
  return trig;
}

glm::dvec3 ToK(const glm::dvec3& p_MH) noexcept {
  return {p_MH.x, p_MH.y, p_MH.z + kWorkspaceCentreZ_m};
}

// One leg's closure equation and its derivatives at handle point p_K for motor angle theta:
//   C(p, θ) = (u + c - a cos θ)² + (w - a sin θ)² - (d + e + sqrt(b² - (v + f)²))² = 0,
// with (u, v, w) the point in the leg's frame: the knee (end of the arm a) lies on the circle of
// radius d + e + b sin θ3 around the effector-side joint, b cos θ3 = v + f.
struct LegClosure {
  double value = 0.0;
  glm::dvec3 grad_p{0.0};  // ∂C/∂p_K
  double d_theta = 0.0;    // ∂C/∂θ
  bool ok = false;
};

LegClosure EvaluateLeg(int i, const glm::dvec3& p_K, double theta) noexcept {
  LegClosure out;
  const LegTrig& t = LegTrigs()[i];
  const double u = t.c * p_K.x + t.s * p_K.y - kR;
  const double v = -t.s * p_K.x + t.c * p_K.y - kS;
  const double w = p_K.z;
  const double q = v + kF;
  const double s2 = kB * kB - q * q;
  if (!(s2 > 1e-12)) return out;
  const double root = std::sqrt(s2);
  const double L = kD + kE + root;
  const double U = u + kC - kA * std::cos(theta);
  const double W = w - kA * std::sin(theta);
  out.value = U * U + W * W - L * L;
  const double dC_du = 2.0 * U;
  const double dC_dv = 2.0 * L * q / root;
  const double dC_dw = 2.0 * W;
  out.grad_p = {dC_du * t.c - dC_dv * t.s, dC_du * t.s + dC_dv * t.c, dC_dw};
  out.d_theta = 2.0 * kA * (U * std::sin(theta) - W * std::cos(theta));
  out.ok = std::isfinite(out.value);
  return out;
}

glm::dmat3 FromRows(const glm::dvec3& r0, const glm::dvec3& r1, const glm::dvec3& r2) noexcept {
  return glm::transpose(glm::dmat3(r0, r1, r2));
}

std::uint8_t NibbleByte(unsigned value, int shift) noexcept {
  return static_cast<std::uint8_t>(kNibbleOffset + ((value >> shift) & 0xF));
}

void EncodeValues(const std::array<std::int16_t, 3>& values,
                  std::span<std::uint8_t, kFrameSize> out) noexcept {
  for (int i = 0; i < 3; ++i) {
    const unsigned bits = static_cast<std::uint16_t>(values[i]);
    for (int k = 0; k < 4; ++k) out[1 + 4 * i + k] = NibbleByte(bits, 4 * k);
  }
}

// Parses bytes 1..12; false when a nibble byte is outside 0x41..0x50.
bool DecodeValues(std::span<const std::uint8_t> frame,
                  std::array<std::int16_t, 3>& values) noexcept {
  for (int i = 0; i < 3; ++i) {
    unsigned bits = 0;
    for (int k = 0; k < 4; ++k) {
      const int nibble = frame[1 + 4 * i + k] - kNibbleOffset;
      if (nibble < 0 || nibble > 0xF) return false;
      bits |= static_cast<unsigned>(nibble) << (4 * k);
    }
    values[i] = static_cast<std::int16_t>(static_cast<std::uint16_t>(bits));
  }
  return true;
}

bool MarkersOk(std::span<const std::uint8_t> frame) noexcept {
  return frame.size() == kFrameSize && frame[0] == kFrameStart &&
         frame[kFrameSize - 1] == kFrameEnd;
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// FTDI baud divisor (AN232B-05)
// ---------------------------------------------------------------------------------------------

FtdiBaudSetting FtdiBaudDivisor(int baud) {
  constexpr int kBaseClock = 3000000;
  if (baud < 183 || baud > kBaseClock) {
    throw std::invalid_argument("FTDI baud rate " + std::to_string(baud) +
                                " outside 183 .. 3000000");
  }
  // Divisor in eighths, rounded to the nearest.
  long eighths = std::lround(8.0 * kBaseClock / baud);
  FtdiBaudSetting s;
  if (eighths < 10) {  // nearest to 1: the 3 MHz code
    s.value = 0;
    s.actual_baud = kBaseClock;
    return s;
  }
  if (eighths < 14) {  // nearest to 1.5: the 2 MHz code
    s.value = 1;
    s.actual_baud = 2000000;
    return s;
  }
  eighths = std::clamp(eighths, 16L, 131071L);  // 2 .. 16383.875
  // Sub-integer eighths -> the chip's 3-bit code (AN232B-05 table: 0, 1/8, 1/4, 3/8, 1/2, 5/8,
  // 3/4, 7/8 -> 0, 3, 2, 4, 1, 5, 6, 7).
  static constexpr std::array<unsigned, 8> kFractionCode = {0, 3, 2, 4, 1, 5, 6, 7};
  const unsigned code = kFractionCode[static_cast<std::size_t>(eighths & 7)];
  s.value = static_cast<std::uint16_t>((eighths >> 3) | ((code & 3u) << 14));
  s.index = static_cast<std::uint16_t>(code >> 2);
  s.actual_baud = static_cast<int>(std::lround(8.0 * kBaseClock / static_cast<double>(eighths)));
  return s;
}

// ---------------------------------------------------------------------------------------------
// libusb transport
// ---------------------------------------------------------------------------------------------

LibusbFalconTransport::LibusbFalconTransport(int bus, int address) {
  int rc = libusb_init(&context_);
  if (rc != 0) {
    context_ = nullptr;
    throw std::runtime_error(
        std::string("Novint Falcon: libusb could not start (") + libusb_error_name(rc) +
        "), so no Falcon (USB 0403:cb48) can be found on this machine; " + kUdevHint);
  }
  libusb_device** list = nullptr;
  const ssize_t n = libusb_get_device_list(context_, &list);
  if (n < 0) {
    libusb_exit(context_);
    context_ = nullptr;
    throw std::runtime_error(std::string("Novint Falcon: cannot list USB devices (") +
                             libusb_error_name(static_cast<int>(n)) + ")");
  }
  libusb_device* found = nullptr;
  for (ssize_t k = 0; k < n && found == nullptr; ++k) {
    libusb_device_descriptor desc{};
    if (libusb_get_device_descriptor(list[k], &desc) != 0) continue;
    if (desc.idVendor != kUsbVendorId || desc.idProduct != kUsbProductId) continue;
    if (bus < 0 ||
        (libusb_get_bus_number(list[k]) == bus && libusb_get_device_address(list[k]) == address)) {
      found = list[k];
    }
  }
  if (found == nullptr) {
    libusb_free_device_list(list, 1);
    libusb_exit(context_);
    context_ = nullptr;
    const std::string where =
        bus < 0 ? std::string()
                : " at bus " + std::to_string(bus) + " address " + std::to_string(address);
    throw std::runtime_error("Novint Falcon: no Falcon (USB 0403:cb48) found" + where +
                             "; check that it is plugged in and its power supply is on "
                             "(`lsusb -d 0403:cb48`); " +
                             kUdevHint);
  }
  const int found_bus = libusb_get_bus_number(found);
  const int found_address = libusb_get_device_address(found);
  rc = libusb_open(found, &handle_);
  libusb_free_device_list(list, 1);
  if (rc != 0) {
    handle_ = nullptr;
    libusb_exit(context_);
    context_ = nullptr;
    const std::string at =
        " at bus " + std::to_string(found_bus) + " address " + std::to_string(found_address);
    if (rc == LIBUSB_ERROR_ACCESS) {
      throw std::runtime_error("Novint Falcon: permission denied opening the Falcon" + at + "; " +
                               kUdevHint);
    }
    throw std::runtime_error("Novint Falcon: cannot open the Falcon" + at + " (" +
                             libusb_error_name(rc) + ")");
  }
  // Let libusb move a kernel serial driver out of the way where the platform has one bound.
  libusb_set_auto_detach_kernel_driver(handle_, 1);
  rc = libusb_claim_interface(handle_, 0);
  if (rc != 0) {
    libusb_close(handle_);
    handle_ = nullptr;
    libusb_exit(context_);
    context_ = nullptr;
    if (rc == LIBUSB_ERROR_BUSY) {
      throw std::runtime_error(
          "Novint Falcon: its USB interface is held by another program (another master_station "
          "or a libnifalcon tool?); close it and retry");
    }
    if (rc == LIBUSB_ERROR_ACCESS) {
      throw std::runtime_error(std::string("Novint Falcon: permission denied claiming the "
                                           "Falcon's interface; ") +
                               kUdevHint);
    }
    throw std::runtime_error(std::string("Novint Falcon: cannot claim its USB interface (") +
                             libusb_error_name(rc) + ")");
  }
}

LibusbFalconTransport::~LibusbFalconTransport() {
  if (handle_ != nullptr) {
    libusb_release_interface(handle_, 0);
    libusb_close(handle_);
  }
  if (context_ != nullptr) libusb_exit(context_);
}

void LibusbFalconTransport::Control(std::uint8_t request, std::uint16_t value, std::uint16_t index,
                                    const char* what) {
  const int rc = libusb_control_transfer(handle_, kFtdiRequestType, request, value, index, nullptr,
                                         0, kControlTimeoutMs);
  if (rc < 0) {
    throw std::runtime_error(std::string("Novint Falcon: FTDI ") + what + " failed (" +
                             libusb_error_name(rc) + ")");
  }
}

void LibusbFalconTransport::PurgeBuffers() {
  Control(kSioReset, kSioPurgeRx, 0, "purge of the receive buffer");
  Control(kSioReset, kSioPurgeTx, 0, "purge of the transmit buffer");
  pending_begin_ = pending_end_ = 0;
}

void LibusbFalconTransport::SetBaudRate(int baud) {
  const FtdiBaudSetting s = FtdiBaudDivisor(baud);
  Control(kSioSetBaudRate, s.value, s.index, "baud rate");
}

void LibusbFalconTransport::SetLineFormat8N1NoFlowControl() {
  Control(kSioSetData, 8 /* data bits */ | (0 << 8) /* no parity */ | (0 << 11) /* 1 stop */, 0,
          "line format 8N1");
  Control(kSioSetFlowControl, 0, 0, "flow control off");
}

void LibusbFalconTransport::SetLatencyTimer(int latency_ms) {
  if (latency_ms < 1 || latency_ms > 255) {
    throw std::invalid_argument("FTDI latency timer " + std::to_string(latency_ms) +
                                " ms outside 1..255");
  }
  Control(kSioSetLatencyTimer, static_cast<std::uint16_t>(latency_ms), 0, "latency timer");
}

void LibusbFalconTransport::SetDtr(bool high) {
  Control(kSioModemControl, static_cast<std::uint16_t>(0x0100 | (high ? 0x1 : 0x0)), 0, "DTR");
}

void LibusbFalconTransport::SetRts(bool high) {
  Control(kSioModemControl, static_cast<std::uint16_t>(0x0200 | (high ? 0x2 : 0x0)), 0, "RTS");
}

int LibusbFalconTransport::Write(std::span<const std::uint8_t> bytes, int timeout_ms) noexcept {
  if (handle_ == nullptr) return -1;
  int sent = 0;
  // libusb takes a non-const buffer for both directions; an OUT transfer only reads it.
  const int rc = libusb_bulk_transfer(
      handle_, kEndpointOut, const_cast<std::uint8_t*>(bytes.data()),
      static_cast<int>(bytes.size()), &sent, static_cast<unsigned>(std::max(1, timeout_ms)));
  return rc == 0 ? sent : -1;
}

int LibusbFalconTransport::Read(std::span<std::uint8_t> out, int timeout_ms) noexcept {
  if (handle_ == nullptr) return -1;
  if (out.empty()) return 0;
  if (pending_begin_ == pending_end_) {
    pending_begin_ = pending_end_ = 0;
    const auto deadline = Clock::now() + std::chrono::milliseconds(std::max(1, timeout_ms));
    while (pending_end_ == 0) {
      const int left_ms = MsUntil(deadline);
      if (left_ms < 1) return 0;
      int got = 0;
      const int rc =
          libusb_bulk_transfer(handle_, kEndpointIn, raw_.data(), static_cast<int>(raw_.size()),
                               &got, static_cast<unsigned>(left_ms));
      if (rc != 0 && rc != LIBUSB_ERROR_TIMEOUT) return -1;
      // Every 64-byte packet of the transfer starts with the two FTDI status bytes.
      for (std::size_t off = 0; off < static_cast<std::size_t>(got); off += kFtdiPacketSize) {
        const std::size_t packet = std::min(kFtdiPacketSize, static_cast<std::size_t>(got) - off);
        if (packet <= kFtdiStatusBytes) continue;
        const std::size_t payload = packet - kFtdiStatusBytes;
        std::memcpy(pending_.data() + pending_end_, raw_.data() + off + kFtdiStatusBytes, payload);
        pending_end_ += payload;
      }
      if (rc == LIBUSB_ERROR_TIMEOUT && pending_end_ == 0) return 0;
    }
  }
  const std::size_t n = std::min(out.size(), pending_end_ - pending_begin_);
  std::memcpy(out.data(), pending_.data() + pending_begin_, n);
  pending_begin_ += n;
  return static_cast<int>(n);
}

// ---------------------------------------------------------------------------------------------
// Frames
// ---------------------------------------------------------------------------------------------

void EncodeRequest(const FalconRequest& request, std::span<std::uint8_t, kFrameSize> out) noexcept {
  out[0] = kFrameStart;
  EncodeValues(request.motor_command, out);
  const unsigned flags = (request.leds & (kLedGreen | kLedBlue | kLedRed)) |
                         (request.homing_mode ? kRequestHomingMode : 0);
  out[13] = static_cast<std::uint8_t>(kNibbleOffset + flags);
  out[14] = kNibbleOffset;
  out[15] = kFrameEnd;
}

bool DecodeRequest(std::span<const std::uint8_t> frame, FalconRequest& request) noexcept {
  if (!MarkersOk(frame)) return false;
  FalconRequest r;
  if (!DecodeValues(frame, r.motor_command)) return false;
  const int flags = frame[13] - kNibbleOffset;
  if (flags < 0 || flags > 0xF || frame[14] != kNibbleOffset) return false;
  r.homing_mode = (flags & kRequestHomingMode) != 0;
  r.leds = static_cast<std::uint8_t>(flags & (kLedGreen | kLedBlue | kLedRed));
  request = r;
  return true;
}

void EncodeResponse(const FalconResponse& response,
                    std::span<std::uint8_t, kFrameSize> out) noexcept {
  out[0] = kFrameStart;
  EncodeValues(response.encoder, out);
  const unsigned flags = (response.buttons & 0x0Fu) | ((response.homed_mask & kAllAxesHomed) << 4);
  out[13] = static_cast<std::uint8_t>(kNibbleOffset + flags);
  out[14] = kNibbleOffset;
  out[15] = kFrameEnd;
}

bool DecodeResponse(std::span<const std::uint8_t> frame, FalconResponse& response) noexcept {
  if (!MarkersOk(frame)) return false;
  FalconResponse r;
  if (!DecodeValues(frame, r.encoder)) return false;
  const int flags = frame[13] - kNibbleOffset;
  if (flags < 0 || flags > 0x7F) return false;
  r.buttons = static_cast<std::uint8_t>(flags & 0x0F);
  r.homed_mask = static_cast<std::uint8_t>((flags >> 4) & kAllAxesHomed);
  response = r;
  return true;
}

bool ResponseAssembler::Push(std::span<const std::uint8_t> bytes, FalconResponse& newest) noexcept {
  bool completed = false;
  for (const std::uint8_t byte : bytes) {
    if (size_ == 0 && byte != kFrameStart) continue;  // between frames: skip to a start marker
    buffer_[size_++] = byte;
    if (size_ < kFrameSize) continue;
    if (DecodeResponse(buffer_, newest)) {
      completed = true;
      size_ = 0;
      continue;
    }
    ++malformed_;
    // Resynchronise on the next start marker inside the rejected candidate.
    std::size_t next = 1;
    while (next < kFrameSize && buffer_[next] != kFrameStart) ++next;
    std::memmove(buffer_.data(), buffer_.data() + next, kFrameSize - next);
    size_ = kFrameSize - next;
  }
  return completed;
}

// ---------------------------------------------------------------------------------------------
// Firmware
// ---------------------------------------------------------------------------------------------

void CheckFirmwareImage(std::span<const std::uint8_t> image, const std::string& what) {
  const std::string known = " (libnifalcon knows the nVent driver's image, " +
                            std::to_string(kNventFirmwareSize) + " bytes, and its test firmware, " +
                            std::to_string(kTestFirmwareSize) + " bytes)";
  if (image.empty()) throw std::runtime_error("Novint Falcon: firmware " + what + " is empty");
  if (image.size() > kMaxFirmwareSize) {
    throw std::runtime_error("Novint Falcon: firmware " + what + " has " +
                             std::to_string(image.size()) + " bytes, more than the " +
                             std::to_string(kMaxFirmwareSize) + " a Falcon image can have" + known);
  }
  // TMS320 boot data stream, 8-bit mode, 16-bit words least significant byte first: key 0x08AA,
  // 8 reserved words, entry point (2 words), then blocks.
  constexpr std::size_t kHeaderBytes = 2 + 8 * 2 + 2 * 2;
  if (image.size() < kHeaderBytes + 2 || image[0] != 0xAA || image[1] != 0x08) {
    throw std::runtime_error("Novint Falcon: " + what +
                             " is not a Falcon firmware image: it does not start with the "
                             "TMS320 boot key 0x08AA (bytes AA 08)" +
                             known);
  }
  std::size_t pos = kHeaderBytes;
  for (int block = 0;; ++block) {
    if (pos + 2 > image.size()) {
      throw std::runtime_error("Novint Falcon: firmware " + what + " is truncated: boot block " +
                               std::to_string(block) + " starts past its end (" +
                               std::to_string(image.size()) + " bytes)" + known);
    }
    const std::size_t words = image[pos] | (static_cast<std::size_t>(image[pos + 1]) << 8);
    pos += 2;
    if (words == 0) break;  // end of the table
    pos += 4 + 2 * words;   // destination address, data
    if (pos > image.size()) {
      throw std::runtime_error("Novint Falcon: firmware " + what + " is truncated: boot block " +
                               std::to_string(block) + " runs past its end (" +
                               std::to_string(image.size()) + " bytes)" + known);
    }
  }
}

std::vector<std::uint8_t> ReadFirmwareFile(const std::string& path) {
  if (path.empty()) {
    throw std::runtime_error(
        "Novint Falcon: no firmware given. The Falcon runs firmware loaded over USB at every "
        "start; pass --falcon-firmware FILE with Novint's image (e.g. from the Novint/nVent "
        "driver, 8492 bytes, or libnifalcon's test_firmware.bin, 7324 bytes). It is not shipped "
        "with this project.");
  }
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) {
    throw std::runtime_error("Novint Falcon: firmware file '" + path +
                             "' not found (--falcon-firmware); the Falcon cannot run without it");
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error("Novint Falcon: cannot read firmware file '" + path + "'");
  const auto size = std::filesystem::file_size(path, ec);
  if (ec || size > kMaxFirmwareSize) {
    throw std::runtime_error("Novint Falcon: firmware file '" + path + "' has " +
                             std::to_string(size) + " bytes, more than the " +
                             std::to_string(kMaxFirmwareSize) + " a Falcon image can have");
  }
  std::vector<std::uint8_t> bytes(static_cast<std::size_t>(size));
  in.read(reinterpret_cast<char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  if (static_cast<std::size_t>(in.gcount()) != bytes.size()) {
    throw std::runtime_error("Novint Falcon: cannot read all of firmware file '" + path + "'");
  }
  CheckFirmwareImage(bytes, "file '" + path + "'");
  return bytes;
}

// ---------------------------------------------------------------------------------------------
// Protocol
// ---------------------------------------------------------------------------------------------

void FalconProtocol::ReadExactly(std::span<std::uint8_t> out, int timeout_ms, const char* what) {
  const auto deadline = Clock::now() + std::chrono::milliseconds(timeout_ms);
  std::size_t got = 0;
  while (got < out.size()) {
    const int left_ms = MsUntil(deadline);
    const int n = left_ms < 1 ? 0 : transport_.Read(out.subspan(got), left_ms);
    if (n < 0) {
      throw std::runtime_error(std::string("Novint Falcon: USB read failed while waiting for ") +
                               what);
    }
    if (n == 0 && MsUntil(deadline) < 1) {
      throw std::runtime_error(std::string("Novint Falcon: timed out waiting for ") + what + " (" +
                               std::to_string(got) + " of " + std::to_string(out.size()) +
                               " bytes); power-cycle the Falcon and retry");
    }
    got += static_cast<std::size_t>(n);
  }
}

void FalconProtocol::LoadFirmware(std::span<const std::uint8_t> image) {
  FalconTransport& t = transport_;
  t.PurgeBuffers();
  t.SetLatencyTimer(kBootLatencyMs);
  t.SetBaudRate(kHandshakeBaud);
  t.SetLineFormat8N1NoFlowControl();
  t.SetRts(false);
  t.SetDtr(false);
  t.SetDtr(true);

  // Handshake: the DSP's boot loader answers {0x0A,0x43,0x0D} with {0x0A,0x44,0x2C,0x0D}, with
  // or without a leading 0x00 depending on the host (libnifalcon setFirmwareMode).
  static constexpr std::array<std::uint8_t, 3> kHello = {0x0A, 0x43, 0x0D};
  static constexpr std::array<std::uint8_t, 4> kHelloReply = {0x0A, 0x44, 0x2C, 0x0D};
  constexpr int kHandshakeTries = 100;
  constexpr int kHandshakeWaitMs = 200;
  bool answered = false;
  for (int attempt = 0; attempt < kHandshakeTries && !answered; ++attempt) {
    if (t.Write(kHello, kControlTimeoutMs) != static_cast<int>(kHello.size())) {
      throw std::runtime_error("Novint Falcon: cannot write the boot-loader handshake");
    }
    std::array<std::uint8_t, 64> reply{};
    std::size_t got = 0;
    const auto deadline = Clock::now() + std::chrono::milliseconds(kHandshakeWaitMs);
    while (got < 5) {
      const int left_ms = MsUntil(deadline);
      if (left_ms < 1) break;
      const int n = t.Read(std::span(reply).subspan(got, 5 - got), left_ms);
      if (n < 0) throw std::runtime_error("Novint Falcon: USB read failed during the handshake");
      if (n == 0) break;
      got += static_cast<std::size_t>(n);
      if (got >= 4 && std::equal(kHelloReply.begin(), kHelloReply.end(), reply.begin() + got - 4))
        break;
    }
    answered = got >= 4 && (got == 4 || reply[0] == 0x00) &&
               std::equal(kHelloReply.begin(), kHelloReply.end(), reply.begin() + got - 4);
  }
  if (!answered) {
    throw std::runtime_error(
        "Novint Falcon: the boot loader did not answer the handshake; is the Falcon's power "
        "supply plugged in? Unplug USB and power, replug, and retry");
  }

  // Autobaud at the load rate: the boot loader echoes 'A'.
  t.SetDtr(false);
  t.SetBaudRate(kFirmwareBaud);
  static constexpr std::array<std::uint8_t, 1> kAutobaud = {'A'};
  if (t.Write(kAutobaud, kControlTimeoutMs) != 1) {
    throw std::runtime_error("Novint Falcon: cannot write the autobaud character");
  }
  std::array<std::uint8_t, 1> echo{};
  ReadExactly(echo, kControlTimeoutMs, "the boot loader's autobaud echo");
  if (echo[0] != 'A') {
    throw std::runtime_error("Novint Falcon: the boot loader echoed " + Hex(echo[0], 2) +
                             " for the autobaud character 'A'");
  }

  // The image, each byte echoed back.
  std::array<std::uint8_t, kFirmwareChunkBytes> back{};
  for (std::size_t pos = 0; pos < image.size(); pos += kFirmwareChunkBytes) {
    const std::size_t n = std::min<std::size_t>(kFirmwareChunkBytes, image.size() - pos);
    const auto chunk = image.subspan(pos, n);
    if (t.Write(chunk, kControlTimeoutMs) != static_cast<int>(n)) {
      throw std::runtime_error("Novint Falcon: USB write failed at firmware byte " +
                               std::to_string(pos));
    }
    ReadExactly(std::span(back).first(n), kControlTimeoutMs, "the firmware echo");
    for (std::size_t k = 0; k < n; ++k) {
      if (back[k] != chunk[k]) {
        throw std::runtime_error("Novint Falcon: firmware echo mismatch at byte " +
                                 std::to_string(pos + k) + " (sent " + Hex(chunk[k], 2) + ", got " +
                                 Hex(back[k], 2) +
                                 "); the load failed: power-cycle the Falcon and retry");
      }
    }
  }

  // Running mode.
  t.SetLatencyTimer(kRunningLatencyMs);
  t.SetBaudRate(kRunningBaud);
  t.PurgeBuffers();
  assembler_.Reset();
}

ExchangeResult FalconProtocol::Exchange(const FalconRequest& request, FalconResponse& response,
                                        int timeout_ms) noexcept {
  std::array<std::uint8_t, kFrameSize> tx{};
  EncodeRequest(request, tx);
  if (transport_.Write(tx, std::max(1, timeout_ms)) != static_cast<int>(kFrameSize)) {
    return ExchangeResult::kWriteFailed;
  }
  const auto deadline = Clock::now() + std::chrono::milliseconds(std::max(1, timeout_ms));
  std::array<std::uint8_t, 64> rx{};
  for (;;) {
    const int left_ms = MsUntil(deadline);
    if (left_ms < 1) return ExchangeResult::kTimeout;
    const int n = transport_.Read(rx, left_ms);
    if (n < 0) return ExchangeResult::kReadFailed;
    if (n == 0) return ExchangeResult::kTimeout;
    if (assembler_.Push(std::span(rx).first(static_cast<std::size_t>(n)), response)) {
      return ExchangeResult::kOk;
    }
  }
}

// ---------------------------------------------------------------------------------------------
// Kinematics
// ---------------------------------------------------------------------------------------------

double EncoderToMotorAngle(double counts) noexcept {
  return counts * kRadPerCount + kAngleAtZero_rad;
}

double MotorAngleToEncoder(double angle_rad) noexcept {
  return (angle_rad - kAngleAtZero_rad) / kRadPerCount;
}

bool InverseKinematics(const glm::dvec3& p_MH, MotorAngles& theta) noexcept {
  const glm::dvec3 p_K = ToK(p_MH);
  MotorAngles out{};
  for (int i = 0; i < 3; ++i) {
    const LegTrig& t = LegTrigs()[i];
    const double u = t.c * p_K.x + t.s * p_K.y - kR;
    const double v = -t.s * p_K.x + t.c * p_K.y - kS;
    const double w = p_K.z;
    const double q = v + kF;  // b cos θ3
    if (!(std::abs(q) < kB)) return false;
    const double L = kD + kE + std::sqrt(kB * kB - q * q);  // d + e + b sin θ3
    // Knee circle: (X - a cos θ)² + (w - a sin θ)² = L², X = u + c, i.e.
    // X cos θ + w sin θ = (X² + w² + a² - L²) / (2a) = ρ cos(θ - atan2(w, X)).
    const double X = u + kC;
    const double rho = std::hypot(X, w);
    if (!(rho > 1e-9)) return false;
    const double k = (X * X + w * w + kA * kA - L * L) / (2.0 * kA * rho);
    if (!(std::abs(k) <= 1.0)) return false;
    out[i] = std::atan2(w, X) - std::acos(k);
  }
  theta = out;
  return true;
}

bool ForwardKinematics(const MotorAngles& theta, glm::dvec3& p_MH) noexcept {
  for (double th : theta) {
    if (!std::isfinite(th)) return false;
  }
  glm::dvec3 p_K = ToK(p_MH);
  if (!(std::isfinite(p_K.x) && std::isfinite(p_K.y) && std::isfinite(p_K.z))) {
    p_K = ToK(glm::dvec3(0.0));
  }
  constexpr int kMaxIterations = 30;
  constexpr double kMaxStep_m = 0.02;
  bool converged = false;
  for (int it = 0; it < kMaxIterations && !converged; ++it) {
    std::array<LegClosure, 3> leg;
    for (int i = 0; i < 3; ++i) {
      leg[i] = EvaluateLeg(i, p_K, theta[i]);
      if (!leg[i].ok) return false;
    }
    const glm::dmat3 G = FromRows(leg[0].grad_p, leg[1].grad_p, leg[2].grad_p);
    const double det = glm::determinant(G);
    if (!(std::abs(det) > 1e-18)) return false;
    glm::dvec3 step = glm::inverse(G) * -glm::dvec3(leg[0].value, leg[1].value, leg[2].value);
    const double len = glm::length(step);
    if (!std::isfinite(len)) return false;
    if (len > kMaxStep_m) step *= kMaxStep_m / len;
    p_K += step;
    converged = len < 1e-13;
  }
  // The closure equations hold on both knee branches; keep only the one IK returns.
  const glm::dvec3 p = {p_K.x, p_K.y, p_K.z - kWorkspaceCentreZ_m};
  MotorAngles check{};
  if (!InverseKinematics(p, check)) return false;
  for (int i = 0; i < 3; ++i) {
    if (!(std::abs(check[i] - theta[i]) < 1e-7)) return false;
  }
  p_MH = p;
  return true;
}

bool HandleJacobian(const glm::dvec3& p_MH, glm::dmat3& J) noexcept {
  MotorAngles theta{};
  if (!InverseKinematics(p_MH, theta)) return false;
  const glm::dvec3 p_K = ToK(p_MH);
  // C_i(p, θ_i) = 0 along any motion: ∇C_i · ṗ + ∂C_i/∂θ_i θ̇_i = 0, so row i of ∂θ/∂p is
  // -∇C_i / (∂C_i/∂θ_i), and J = ∂p/∂θ is its inverse.
  std::array<glm::dvec3, 3> rows;
  for (int i = 0; i < 3; ++i) {
    const LegClosure leg = EvaluateLeg(i, p_K, theta[i]);
    if (!leg.ok || !(std::abs(leg.d_theta) > 1e-12)) return false;
    rows[i] = -leg.grad_p / leg.d_theta;
  }
  const glm::dmat3 dtheta_dp = FromRows(rows[0], rows[1], rows[2]);
  if (!(std::abs(glm::determinant(dtheta_dp)) > 1e-9)) return false;
  J = glm::inverse(dtheta_dp);
  return true;
}

MotorCommands TorquesToMotorCommands(const MotorTorques& tau_nm, int max_command) noexcept {
  MotorCommands out;
  const double limit = std::clamp(max_command, 1, 32767);
  glm::dvec3 c = -kMotorCommandPerNm * tau_nm;
  if (!(std::isfinite(c.x) && std::isfinite(c.y) && std::isfinite(c.z))) return out;
  const double largest = std::max({std::abs(c.x), std::abs(c.y), std::abs(c.z)});
  if (largest > limit) {
    c *= limit / largest;
    out.saturated = true;
  }
  for (int i = 0; i < 3; ++i) {
    out.command[i] = static_cast<std::int16_t>(std::clamp(std::round(c[i]), -limit, limit));
  }
  return out;
}

// ---------------------------------------------------------------------------------------------
// Device
// ---------------------------------------------------------------------------------------------

FalconDevice::FalconDevice(FalconConfig config, FalconTransportFactory factory)
    : config_(std::move(config)), factory_(std::move(factory)) {
  if (config_.max_motor_command < 1 || config_.max_motor_command > 32767) {
    throw std::invalid_argument("Novint Falcon: max_motor_command " +
                                std::to_string(config_.max_motor_command) + " outside 1..32767");
  }
  if (!(config_.exchange_period_s > 0.0) || !(config_.exchange_period_s <= 0.1)) {
    throw std::invalid_argument("Novint Falcon: exchange period " +
                                std::to_string(config_.exchange_period_s) + " s outside (0, 0.1]");
  }
  if (config_.exchange_timeout_ms < 1 || config_.start_timeout_ms < 1 ||
      !(config_.wrench_timeout_s > 0.0) || !(config_.stale_after_s > 0.0) ||
      !(config_.velocity_cutoff_hz > 0.0)) {
    throw std::invalid_argument(
        "Novint Falcon: timeouts, staleness and velocity cut-off must be positive");
  }
  if (!factory_) {
    factory_ = [bus = config_.usb_bus, address = config_.usb_address] {
      return std::unique_ptr<FalconTransport>(new LibusbFalconTransport(bus, address));
    };
  }
}

FalconDevice::~FalconDevice() { Close(); }

DeviceCapabilities FalconDevice::capabilities() const {
  DeviceCapabilities c;
  c.name = "Novint Falcon (libusb)";
  c.max_force_n = 8.9;  // Novint: "force capabilities > 8.9 N" (H3DAPI wiki, Novint Falcon)
  c.max_torque_nm = 0.0;
  c.max_stiffness_n_per_m = 3000.0;  // CHAI3D cFalconDevice m_maxForceStiffness
  c.max_rotational_stiffness_nm_per_rad = 0.0;
  c.max_damping_ns_per_m = 20.0;  // CHAI3D cFalconDevice m_maxLinearDamping
  c.rated_loop_rate_hz = 1.0 / config_.exchange_period_s;
  // Novint: 4" x 4" x 4" 3D touch workspace (H3DAPI wiki): ±2" = ±0.0508 m about M's origin.
  c.workspace_half_extents_m = {0.0508, 0.0508, 0.0508};
  c.dof_in = 3;
  c.dof_out = 3;
  return c;
}

void FalconDevice::Open() {
  if (open_.load()) return;
  std::vector<std::uint8_t> image = ReadFirmwareFile(config_.firmware_path);
  try {
    transport_ = factory_();
    if (!transport_) throw std::runtime_error("Novint Falcon: no transport was made");
    protocol_ = std::make_unique<FalconProtocol>(*transport_);
    protocol_->LoadFirmware(image);
    // The firmware answers every request once it runs (libnifalcon isFirmwareLoaded).
    FalconRequest hello;
    hello.homing_mode = true;
    hello.leds = kLedRed;
    FalconResponse first;
    bool answered = false;
    const auto deadline = Clock::now() + std::chrono::milliseconds(config_.start_timeout_ms);
    while (!answered && Clock::now() < deadline) {
      answered =
          protocol_->Exchange(hello, first, config_.exchange_timeout_ms) == ExchangeResult::kOk;
      if (!answered) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    if (!answered) {
      throw std::runtime_error(
          "Novint Falcon: the firmware was loaded but the Falcon does not answer; is its power "
          "supply plugged in? Power-cycle it and retry");
    }
  } catch (...) {
    protocol_.reset();
    transport_.reset();
    throw;
  }
  Sample drained;
  while (samples_.Read(drained)) {
  }
  have_sample_ = false;
  homed_ = false;
  homed_mask_ = 0;
  exchanges_ = 0;
  malformed_ = 0;
  io_errors_ = 0;
  timeouts_ = 0;
  kinematics_faults_ = 0;
  saturated_ = 0;
  commands_.Write(ForceCommand{});
  stop_ = false;
  io_thread_ = std::thread([this] { IoLoop(); });
  open_ = true;
}

void FalconDevice::Close() noexcept {
  open_ = false;
  stop_ = true;
  if (io_thread_.joinable()) io_thread_.join();  // the loop's last request commands zero
  protocol_.reset();
  transport_.reset();
}

void FalconDevice::IoLoop() noexcept {
  const auto period = std::chrono::nanoseconds(
      static_cast<std::int64_t>(std::llround(config_.exchange_period_s * 1e9)));
  const auto wrench_timeout_ns = static_cast<std::int64_t>(config_.wrench_timeout_s * 1e9);
  const double tau_filter_s = 1.0 / (2.0 * kPi * config_.velocity_cutoff_hz);
  ForceCommand force;
  glm::dvec3 p_MH{0.0};
  glm::dvec3 v_MH_M{0.0};
  bool have_position = false;
  std::int64_t t_position_ns = 0;
  bool homed = false;
  auto next = Clock::now();
  // The clock is passed in (FalconConfig::clock_ns): readings and freshness use it.
  const auto clock_ns = [this]() noexcept {
    return config_.clock_ns ? config_.clock_ns() : NowNs();
  };

  while (!stop_.load(std::memory_order_relaxed)) {
    ForceCommand newest;
    if (commands_.Read(newest)) force = newest;
    const std::int64_t now_ns = clock_ns();

    FalconRequest request;
    request.homing_mode = !homed;
    request.leds = homed ? kLedGreen : kLedRed;
    const bool fresh = force.valid && std::abs(now_ns - force.t_ns) <= wrench_timeout_ns;
    if (homed && have_position && fresh) {
      glm::dmat3 J;
      if (HandleJacobian(p_MH, J)) {
        const MotorCommands mc =
            TorquesToMotorCommands(TorquesForForce(J, force.F_H_M), config_.max_motor_command);
        request.motor_command = mc.command;
        if (mc.saturated) saturated_.fetch_add(1, std::memory_order_relaxed);
      } else {
        kinematics_faults_.fetch_add(1, std::memory_order_relaxed);
      }
    }

    FalconResponse response;
    const ExchangeResult result =
        protocol_->Exchange(request, response, config_.exchange_timeout_ms);
    malformed_.store(protocol_->malformed_frames(), std::memory_order_relaxed);
    if (result == ExchangeResult::kOk) {
      const std::int64_t t_ns = clock_ns();
      exchanges_.fetch_add(1, std::memory_order_relaxed);
      homed_mask_.store(response.homed_mask, std::memory_order_relaxed);
      homed = (response.homed_mask & kAllAxesHomed) == kAllAxesHomed;
      homed_.store(homed, std::memory_order_relaxed);
      Sample sample;
      sample.homed = homed;
      sample.buttons = response.buttons;
      sample.t_ns = t_ns;
      if (homed) {
        const MotorAngles theta = {EncoderToMotorAngle(response.encoder[0]),
                                   EncoderToMotorAngle(response.encoder[1]),
                                   EncoderToMotorAngle(response.encoder[2])};
        glm::dvec3 p = have_position ? p_MH : glm::dvec3(0.0);
        if (ForwardKinematics(theta, p)) {
          if (have_position) {
            const double dt = static_cast<double>(t_ns - t_position_ns) * 1e-9;
            if (dt > 0.0) {
              const double alpha = dt / (dt + tau_filter_s);
              v_MH_M += alpha * ((p - p_MH) / dt - v_MH_M);
            }
          } else {
            v_MH_M = glm::dvec3(0.0);
          }
          p_MH = p;
          t_position_ns = t_ns;
          have_position = true;
        } else {
          kinematics_faults_.fetch_add(1, std::memory_order_relaxed);
        }
      } else {
        have_position = false;
      }
      sample.p_MH = p_MH;
      sample.v_MH_M = v_MH_M;
      // A reading whose kinematics failed is not published as new.
      if (!homed || t_position_ns == t_ns) samples_.Write(sample);
    } else if (result == ExchangeResult::kTimeout) {
      timeouts_.fetch_add(1, std::memory_order_relaxed);
    } else {
      io_errors_.fetch_add(1, std::memory_order_relaxed);
    }

    next += period;
    const auto now = Clock::now();
    if (next < now) next = now;
    std::this_thread::sleep_until(next);
  }

  // Leave the motors unpowered and the LEDs off.
  FalconRequest zero;
  FalconResponse ignored;
  protocol_->Exchange(zero, ignored, config_.exchange_timeout_ms);
}

bool FalconDevice::ReadState(std::int64_t now_ns, DeviceState& state) noexcept {
  if (!open_.load(std::memory_order_acquire)) return false;
  Sample s;
  if (samples_.Read(s)) {
    last_sample_ = s;
    have_sample_ = true;
  }
  if (!have_sample_ || !last_sample_.homed) return false;
  if (now_ns - last_sample_.t_ns > static_cast<std::int64_t>(config_.stale_after_s * 1e9)) {
    return false;
  }
  state.X_MH = RigidTransform{last_sample_.p_MH, glm::dquat(1.0, 0.0, 0.0, 0.0)};
  state.V_MH_M = Twist{last_sample_.v_MH_M, glm::dvec3(0.0)};
  state.buttons = last_sample_.buttons;
  state.timestamp_ns = last_sample_.t_ns;
  return true;
}

bool FalconDevice::WriteWrench(const Wrench& F_H_M, std::int64_t now_ns) noexcept {
  if (!open_.load(std::memory_order_acquire)) return false;
  ForceCommand command;
  command.t_ns = now_ns;
  if (!IsFinite(F_H_M)) {
    command.valid = true;  // render zero
    commands_.Write(command);
    return false;
  }
  command.F_H_M = F_H_M.force;
  command.valid = true;
  commands_.Write(command);
  return true;
}

FalconStatus FalconDevice::status() const noexcept {
  FalconStatus s;
  s.running = open_.load();
  s.homed = homed_.load();
  s.homed_mask = homed_mask_.load();
  s.exchanges = exchanges_.load();
  s.malformed_frames = malformed_.load();
  s.io_errors = io_errors_.load();
  s.read_timeouts = timeouts_.load();
  s.kinematics_faults = kinematics_faults_.load();
  s.saturated_commands = saturated_.load();
  return s;
}

}  // namespace ht::falcon
