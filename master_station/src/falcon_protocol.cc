// Novint Falcon, frame protocol: frame encode/decode and reassembly, firmware image checks, and
// FalconProtocol (firmware load through the boot loader, request/response exchange).

#include "master_station/falcon_protocol.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <string>

#include "falcon_internal.h"

namespace ht::falcon {
namespace {

using detail::Clock;
using detail::kControlTimeoutMs;
using detail::MsUntil;

std::string Hex(unsigned value, int digits) {
  char buf[16];
  std::snprintf(buf, sizeof buf, "0x%0*X", digits, value);
  return buf;
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

}  // namespace ht::falcon
