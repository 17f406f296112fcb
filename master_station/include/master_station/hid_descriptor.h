#pragma once
// HID report descriptors: the item parser (HID 1.11 §6.2.2) that lists, per input report, the
// fields with bit offset, size, logical range, usage and the Relative flag, and the reading of one
// field from a report's payload. Stage 1 of the SpaceMouse pipeline (spacemouse.h); nothing here
// is specific to the SpaceMouse.

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace ht {

// ------------------------------------------------------------------------------------------------
// 1. HID report descriptor
// ------------------------------------------------------------------------------------------------

/// HID usage pages and usages used here (HID Usage Tables 1.12 §4, §12).
inline constexpr std::uint16_t kHidPageGenericDesktop = 0x01;
inline constexpr std::uint16_t kHidPageButton = 0x09;
inline constexpr std::uint16_t kHidUsageMultiAxisController = 0x08;
inline constexpr std::uint16_t kHidUsageX = 0x30;  ///< X, Y, Z, Rx, Ry, Rz are 0x30..0x35.

/// One data value of an input report as a report descriptor lays it out.
struct HidField {
  std::uint32_t bit_offset = 0;  ///< First bit after the report-id byte, LSB-first (HID §5.8).
  std::uint32_t bit_size = 0;    ///< Report Size, 1..32 bits.
  std::int64_t logical_min = 0;  ///< Logical Minimum; the value is signed when this is < 0.
  std::int64_t logical_max = 0;  ///< Logical Maximum.
  std::uint16_t usage_page = 0;
  /// Variable field: its usage. Array field: the usage that value `logical_min` selects.
  std::uint16_t usage = 0;
  std::uint16_t usage_max = 0;  ///< Array field: the last usage of its range; = usage otherwise.
  bool relative = false;        ///< Input item flag bit 2 (Relative) was set.
  bool array = false;           ///< Input item flag bit 1 clear: the value is a usage index.
};

/// One input report: its id and the fields in it.
struct HidInputReport {
  std::uint8_t report_id = 0;    ///< 0 when the descriptor declares no report ids.
  std::uint32_t size_bits = 0;   ///< Payload bits, padding included, report-id byte excluded.
  std::vector<HidField> fields;  ///< Data fields in bit order; constant (padding) items omitted.
  /// Payload bytes that follow the report-id byte.
  std::size_t payload_bytes() const noexcept { return (size_bits + 7u) / 8u; }
};

/// What ParseHidReportDescriptor found. Output and feature reports are parsed (their items change
/// the global state) but not listed.
struct HidReportDescriptor {
  bool uses_report_ids = false;               ///< Input reports then begin with a report-id byte.
  std::vector<HidInputReport> input_reports;  ///< In order of first appearance.
  /// False when parsing stopped early (truncated or malformed item) or collections were left
  /// open; `problem` then says what and at which byte offset. The reports parsed before the
  /// problem are kept, without the main item that was cut.
  bool complete = true;
  std::string problem;
  std::size_t bytes_parsed = 0;  ///< Bytes covered by whole items.
  /// The input report with that id, or nullptr.
  const HidInputReport* FindInput(std::uint8_t report_id) const noexcept;
};

/// Parses a HID report descriptor (HID 1.11 §6.2.2): short items of the main, global and local
/// types; Push/Pop; Report ID/Size/Count; Logical Minimum/Maximum (sign-extended; the maximum is
/// read unsigned when the minimum is not negative, as Linux hid-core does); Usage Page, Usage
/// (extended 32-bit usages too), Usage Minimum/Maximum; Input flags Constant/Array/Relative. Long
/// items are skipped. Never throws for bad content and never reads out of bounds: a truncated or
/// malformed descriptor gives a result with complete == false and a problem message. Bounds that
/// end parsing: Report Size > 32, Report Count > 4096, Report ID 0, Push deeper than 16, Pop or
/// End Collection without a match, a report longer than 4096 bytes, more than 4096 fields.
HidReportDescriptor ParseHidReportDescriptor(std::span<const std::uint8_t> descriptor);

/// Reads `field` from `payload` (the bytes after the report id), sign-extending when the field's
/// logical minimum is negative. Returns 0 when the field lies beyond the payload.
std::int64_t HidFieldValue(const HidField& field, std::span<const std::uint8_t> payload) noexcept;

}  // namespace ht
