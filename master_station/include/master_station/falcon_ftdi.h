#pragma once
// Novint Falcon, USB transport: the Falcon's USB identity, the FT232 baud-rate encoding, and the
// byte pipe to its FTDI chip (FalconTransport, and LibusbFalconTransport over libusb-1.0).
// Part of the Falcon backend; falcon.h describes the whole pipeline and includes this header.

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>

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

}  // namespace ht::falcon
