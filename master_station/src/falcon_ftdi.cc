// Novint Falcon, USB transport: the FT232 baud divisor and LibusbFalconTransport (libusb-1.0
// set-up of the FTDI chip, bulk transfers with the FTDI status bytes stripped).

#include "master_station/falcon_ftdi.h"

#include <libusb.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <stdexcept>
#include <string>

#include "falcon_internal.h"

namespace ht::falcon {
namespace detail {

int MsUntil(Clock::time_point deadline) noexcept {
  const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now());
  return static_cast<int>(left.count());
}

}  // namespace detail

namespace {

using detail::Clock;
using detail::kControlTimeoutMs;
using detail::MsUntil;

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

const char* const kUdevHint =
    "for access without root install deploy/udev/70-haptic-falcon.rules (see the comment in "
    "it) and replug the Falcon";

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

}  // namespace ht::falcon
