// 3Dconnexion SpaceMouse, report parser: input reports -> normalized axes in frame M and buttons.

#include "master_station/spacemouse_report.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <utility>

#include "spacemouse_internal.h"

namespace ht {

// ------------------------------------------------------------------------------------------------
// 2. Report parser
// ------------------------------------------------------------------------------------------------

namespace detail {

void ValidateAxisMap(const SpaceMouseAxisMap& map) {
  std::array<bool, 6> used{};
  for (int m = 0; m < 6; ++m) {
    const int s = map.source[m];
    if (s < 0 || s > 5 || used[s]) {
      throw std::invalid_argument(Format(
          "spacemouse: axis_map.source must be a permutation of 0..5; entry %d is %d", m, s));
    }
    used[s] = true;
    if (!std::isfinite(map.sign[m]) || map.sign[m] == 0.0) {
      throw std::invalid_argument(Format(
          "spacemouse: axis_map.sign[%d] must be finite and non-zero, got %g", m, map.sign[m]));
    }
  }
}

}  // namespace detail

namespace {

using detail::Format;
using detail::ValidateAxisMap;

constexpr const char* kHidAxisNames[6] = {"X", "Y", "Z", "Rx", "Ry", "Rz"};

}  // namespace

SpaceMouseReportParser::SpaceMouseReportParser(const HidReportDescriptor& descriptor,
                                               const SpaceMouseAxisMap& axis_map,
                                               bool accept_longer_reports)
    : uses_report_ids_(descriptor.uses_report_ids),
      accept_longer_reports_(accept_longer_reports),
      axis_map_(axis_map) {
  ValidateAxisMap(axis_map);
  for (int m = 0; m < 6; ++m) m_axis_of_hid_axis_[axis_map.source[m]] = m;
  layout_of_id_.fill(-1);
  std::array<bool, 6> seen{};
  for (const HidInputReport& r : descriptor.input_reports) {
    Layout layout;
    layout.report_id = r.report_id;
    layout.payload_bytes = r.payload_bytes();
    for (const HidField& f : r.fields) {
      if (f.usage_page == kHidPageGenericDesktop && !f.array && f.usage >= kHidUsageX &&
          f.usage <= kHidUsageX + 5 && f.logical_max > f.logical_min) {
        const int axis = f.usage - kHidUsageX;
        layout.axes.push_back({f, axis});
        seen[axis] = true;
      } else if (f.usage_page == kHidPageButton) {
        layout.buttons.push_back({f});
        layout.has_buttons = true;
      }
    }
    layout_of_id_[r.report_id] = static_cast<std::int16_t>(layouts_.size());
    layouts_.push_back(std::move(layout));
  }
  for (int a = 0; a < 6; ++a) {
    if (!seen[a]) {
      throw std::invalid_argument(Format(
          "spacemouse: the report descriptor has no %s axis (Generic Desktop usage 0x%02X, a "
          "variable Input field with a logical range) in any input report: not a 6-DoF device%s",
          kHidAxisNames[a], kHidUsageX + a,
          descriptor.complete ? "" : " (the descriptor is incomplete)"));
    }
  }
}

bool SpaceMouseReportParser::Feed(std::span<const std::uint8_t> report,
                                  std::int64_t now_ns) noexcept {
  if (report.empty()) {
    ++sample_.counts.wrong_length;
    return false;
  }
  std::uint8_t id = 0;
  std::span<const std::uint8_t> payload = report;
  if (uses_report_ids_) {
    id = report[0];
    payload = report.subspan(1);
  }
  const int index = layout_of_id_[id];
  if (index < 0) {
    ++sample_.counts.unknown_report_id;
    return false;
  }
  Layout& layout = layouts_[static_cast<std::size_t>(index)];
  if (payload.size() < layout.payload_bytes ||
      (payload.size() > layout.payload_bytes && !accept_longer_reports_)) {
    ++sample_.counts.wrong_length;
    return false;
  }
  payload = payload.first(layout.payload_bytes);
  for (const AxisBinding& a : layout.axes) {
    const std::int64_t raw = HidFieldValue(a.field, payload);
    raw_axes_[a.hid_axis] = raw;
    const double centre =
        0.5 * (static_cast<double>(a.field.logical_min) + static_cast<double>(a.field.logical_max));
    const double half =
        0.5 * (static_cast<double>(a.field.logical_max) - static_cast<double>(a.field.logical_min));
    const double n = std::clamp((static_cast<double>(raw) - centre) / half, -1.0, 1.0);
    const int m = m_axis_of_hid_axis_[a.hid_axis];
    sample_.axes[m] = axis_map_.sign[m] * n;
    sample_.axis_time_ns[m] = now_ns;
  }
  if (layout.has_buttons) {
    std::uint32_t mask = 0;
    for (const ButtonBinding& b : layout.buttons) {
      const HidField& f = b.field;
      const std::int64_t v = HidFieldValue(f, payload);
      std::int64_t usage = -1;
      if (!f.array) {
        if (v != 0) usage = f.usage;
      } else if (v >= f.logical_min && v <= f.logical_max) {
        usage = f.usage + (v - f.logical_min);
        if (usage > f.usage_max) usage = -1;
      }
      if (usage >= 1 && usage <= 32) mask |= std::uint32_t{1} << (usage - 1);
    }
    layout.button_mask = mask;
    std::uint32_t all = 0;
    for (const Layout& l : layouts_) all |= l.button_mask;
    sample_.buttons = all;
  }
  ++sample_.counts.accepted;
  return true;
}

}  // namespace ht
