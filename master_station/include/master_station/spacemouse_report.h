#pragma once
// 3Dconnexion SpaceMouse, report parser: raw input reports (first byte = report id) -> the latest
// six axes in frame M, normalized to [-1, 1] by the descriptor's logical range, and the buttons.
// The same code parses bytes from hid_read_timeout and bytes from the tests. Stage 2 of the
// SpaceMouse pipeline (spacemouse.h).
//
// Frames. The HID axes (usages X, Y, Z, Rx, Ry, Rz) are in the device's own frame D: x to the
// right, y towards the user, z down, right-handed (PySpaceMouse negates y and z to get "forward"
// and "up"). Frame M of this project is x right, y forward (away from the user), z up: the proper
// rotation by pi about x, so that M = (x, -y, -z) for the translations and, being a proper
// rotation, also (rx, -ry, -rz) for the rotation vector. spacenavd's SWAPYZ|INVYZ, (x, -z, -y) for
// both, is a reflection (det = -1): it yields its own left-handed frame and is not used here.
// Every device in the table uses the same D (PySpaceMouse lists identical signs for all 13 of its
// devices), so one SpaceMouseAxisMap serves all; it is configurable in case a firmware differs.

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "master_station/hid_descriptor.h"

namespace ht {

// ------------------------------------------------------------------------------------------------
// 2. Report parser
// ------------------------------------------------------------------------------------------------

/// Axis order used for deflections throughout: translations then rotations.
enum SpaceMouseAxis : int { kTx = 0, kTy, kTz, kRx, kRy, kRz };

/// From the HID axes (frame D, order X Y Z Rx Ry Rz) to frame M: m[i] = sign[i] * d[source[i]].
/// The default is the rotation by pi about x described at the top of this file.
struct SpaceMouseAxisMap {
  std::array<int, 6> source{0, 1, 2, 3, 4, 5};
  std::array<double, 6> sign{1.0, -1.0, -1.0, 1.0, -1.0, -1.0};
};

/// Counts of what the report parser did with the reports it was fed.
struct SpaceMouseReportCounts {
  std::uint64_t accepted = 0;           ///< Parsed (known id, right length).
  std::uint64_t unknown_report_id = 0;  ///< Dropped: no such input report in the descriptor.
  std::uint64_t wrong_length = 0;       ///< Dropped: empty, or not the descriptor's length.
};

/// The latest state of the cap and the buttons. Trivially copyable (crosses threads).
struct SpaceMouseSample {
  /// Cap deflection in frame M, order SpaceMouseAxis, each in [-1, 1] (full scale of the
  /// descriptor's logical range). Translation deflections push the handle along +x right,
  /// +y forward, +z up; rotation deflections are a rotation vector direction in M.
  std::array<double, 6> axes{};
  /// steady-clock time (ns) of the report that last set each axis; 0 = never set.
  std::array<std::int64_t, 6> axis_time_ns{};
  std::uint32_t buttons = 0;  ///< Bit k set = HID button usage k + 1 pressed (usages 1..32).
  SpaceMouseReportCounts counts;
};

/// Parses raw input reports with the layout a report descriptor gives. Handles both report styles
/// of the family: translation (id 1) and rotation (id 2) in separate reports, or all six axes in
/// one report (id 1, 12 bytes of payload), and any other layout the descriptor describes.
/// Axis values are normalized by the descriptor's logical range: (v - centre) / half-range,
/// clamped to [-1, 1]. The Relative flag is ignored: 3Dconnexion firmwares flag the axes Relative
/// but send absolute deflections (the reason for the Linux hid-lg rel→abs fixup).
class SpaceMouseReportParser {
 public:
  /// Throws std::invalid_argument when no input report carries one of the six axes
  /// (Generic Desktop X..Rz) as a variable field, naming the missing axis. With
  /// `accept_longer_reports`, reports longer than the descriptor says are parsed and their extra
  /// bytes ignored (used with the built-in descriptors, whose button reports may be shorter than
  /// the real device's); shorter ones are always dropped.
  explicit SpaceMouseReportParser(const HidReportDescriptor& descriptor,
                                  const SpaceMouseAxisMap& axis_map = {},
                                  bool accept_longer_reports = false);

  /// Feeds one raw input report: report-id byte first when the descriptor uses report ids, then
  /// the payload. `now_ns` (steady clock) stamps the axes it sets. Returns false and counts the
  /// report when it is dropped (unknown id, wrong length). No allocation.
  bool Feed(std::span<const std::uint8_t> report, std::int64_t now_ns) noexcept;

  /// The state after the reports fed so far.
  const SpaceMouseSample& sample() const noexcept { return sample_; }
  /// The last raw HID axis values in logical units, HID order X Y Z Rx Ry Rz (frame D).
  const std::array<std::int64_t, 6>& raw_axes() const noexcept { return raw_axes_; }

 private:
  struct AxisBinding {
    HidField field;
    int hid_axis = 0;  // 0..5 = X..Rz
  };
  struct ButtonBinding {
    HidField field;
  };
  struct Layout {
    std::uint8_t report_id = 0;
    std::size_t payload_bytes = 0;
    std::vector<AxisBinding> axes;
    std::vector<ButtonBinding> buttons;
    bool has_buttons = false;
    std::uint32_t button_mask = 0;  // buttons currently pressed according to this report
  };

  std::vector<Layout> layouts_;
  std::array<std::int16_t, 256> layout_of_id_{};  // -1 = unknown id
  bool uses_report_ids_ = false;
  bool accept_longer_reports_ = false;
  SpaceMouseAxisMap axis_map_;
  std::array<int, 6> m_axis_of_hid_axis_{};  // inverse of axis_map_.source
  SpaceMouseSample sample_;
  std::array<std::int64_t, 6> raw_axes_{};
};

}  // namespace ht
