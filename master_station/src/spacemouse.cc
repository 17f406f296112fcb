#include "master_station/spacemouse.h"

#include <hidapi.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <glm/common.hpp>
#include <numbers>
#include <optional>
#include <stdexcept>
#include <utility>

// hid_get_report_descriptor arrived in hidapi 0.14.0; Debian 12 ships 0.13.1.
#if defined(HID_API_VERSION) && defined(HID_API_MAKE_VERSION)
#if HID_API_VERSION >= HID_API_MAKE_VERSION(0, 14, 0)
#define HT_HIDAPI_HAS_GET_REPORT_DESCRIPTOR 1
#endif
#endif

namespace ht {

// ------------------------------------------------------------------------------------------------
// 1. HID report descriptor
// ------------------------------------------------------------------------------------------------

namespace {

constexpr std::size_t kMaxReportBytes = 4096;
constexpr std::uint32_t kMaxReportCount = 4096;
constexpr std::size_t kMaxFields = 4096;
constexpr std::size_t kMaxUsages = 1024;
constexpr std::size_t kMaxPushDepth = 16;
constexpr int kMaxCollectionDepth = 64;

// Item types (HID 1.11 §6.2.2.2) and tags (§6.2.2.4, §6.2.2.7, §6.2.2.8).
enum ItemType : std::uint8_t { kMain = 0, kGlobal = 1, kLocal = 2, kReserved = 3 };
enum MainTag : std::uint8_t {
  kInput = 0x8,
  kOutput = 0x9,
  kCollection = 0xA,
  kFeature = 0xB,
  kEndCollection = 0xC
};
enum GlobalTag : std::uint8_t {
  kUsagePage = 0x0,
  kLogicalMinimum = 0x1,
  kLogicalMaximum = 0x2,
  kReportSize = 0x7,
  kReportId = 0x8,
  kReportCount = 0x9,
  kPush = 0xA,
  kPop = 0xB
};
enum LocalTag : std::uint8_t { kUsage = 0x0, kUsageMinimum = 0x1, kUsageMaximum = 0x2 };

const char* ItemName(std::uint8_t type, std::uint8_t tag) {
  static constexpr const char* kMainNames[16] = {
      "reserved main",  "reserved main", "reserved main", "reserved main",
      "reserved main",  "reserved main", "reserved main", "reserved main",
      "Input",          "Output",        "Collection",    "Feature",
      "End Collection", "reserved main", "reserved main", "reserved main"};
  static constexpr const char* kGlobalNames[16] = {"Usage Page",
                                                   "Logical Minimum",
                                                   "Logical Maximum",
                                                   "Physical Minimum",
                                                   "Physical Maximum",
                                                   "Unit Exponent",
                                                   "Unit",
                                                   "Report Size",
                                                   "Report ID",
                                                   "Report Count",
                                                   "Push",
                                                   "Pop",
                                                   "reserved global",
                                                   "reserved global",
                                                   "reserved global",
                                                   "reserved global"};
  static constexpr const char* kLocalNames[16] = {"Usage",
                                                  "Usage Minimum",
                                                  "Usage Maximum",
                                                  "Designator Index",
                                                  "Designator Minimum",
                                                  "Designator Maximum",
                                                  "reserved local",
                                                  "String Index",
                                                  "String Minimum",
                                                  "String Maximum",
                                                  "Delimiter",
                                                  "reserved local",
                                                  "reserved local",
                                                  "reserved local",
                                                  "reserved local",
                                                  "reserved local"};
  switch (type) {
    case kMain:
      return kMainNames[tag & 0xF];
    case kGlobal:
      return kGlobalNames[tag & 0xF];
    case kLocal:
      return kLocalNames[tag & 0xF];
    default:
      return "reserved";
  }
}

std::string Format(const char* fmt, auto... args) {
  char buf[256];
  std::snprintf(buf, sizeof buf, fmt, args...);
  return buf;
}

struct GlobalState {
  std::uint16_t usage_page = 0;
  std::int64_t logical_min = 0;
  std::int64_t logical_max = 0;
  std::uint32_t logical_max_raw = 0;  // re-read signed/unsigned once the minimum is known
  std::uint8_t logical_max_size = 0;
  std::uint32_t report_size = 0;
  std::uint32_t report_count = 0;
  std::uint8_t report_id = 0;
};

// A usage or a usage range; `extended` when the item was 4 bytes (page in the high 16 bits).
struct UsageEntry {
  std::uint32_t first = 0;
  std::uint32_t last = 0;
  bool extended = false;
};

std::int64_t SignExtend(std::uint32_t v, std::size_t size_bytes) {
  switch (size_bytes) {
    case 1:
      return static_cast<std::int8_t>(v & 0xFFu);
    case 2:
      return static_cast<std::int16_t>(v & 0xFFFFu);
    case 4:
      return static_cast<std::int32_t>(v);
    default:
      return 0;
  }
}

class DescriptorParser {
 public:
  explicit DescriptorParser(std::span<const std::uint8_t> d) : d_(d) {}

  HidReportDescriptor Run() {
    std::size_t pos = 0;
    while (pos < d_.size() && out_.problem.empty()) {
      const std::uint8_t prefix = d_[pos];
      if (prefix == 0xFE) {  // long item: bDataSize, bLongItemTag, data (§6.2.2.3)
        if (pos + 3 > d_.size()) {
          Fail(Format("truncated: long item at byte %zu needs a 3-byte header, %zu byte(s) left",
                      pos, d_.size() - pos));
          break;
        }
        const std::size_t len = d_[pos + 1];
        if (pos + 3 + len > d_.size()) {
          Fail(Format("truncated: long item at byte %zu needs %zu data byte(s), %zu left", pos, len,
                      d_.size() - pos - 3));
          break;
        }
        pos += 3 + len;
        out_.bytes_parsed = pos;
        continue;
      }
      const std::size_t size = (prefix & 3u) == 3u ? 4u : (prefix & 3u);
      const auto type = static_cast<std::uint8_t>((prefix >> 2) & 3u);
      const auto tag = static_cast<std::uint8_t>(prefix >> 4);
      if (pos + 1 + size > d_.size()) {
        Fail(Format("truncated: item 0x%02X (%s) at byte %zu needs %zu data byte(s), %zu left",
                    prefix, ItemName(type, tag), pos, size, d_.size() - pos - 1));
        break;
      }
      std::uint32_t udata = 0;
      for (std::size_t i = 0; i < size; ++i) {
        udata |= static_cast<std::uint32_t>(d_[pos + 1 + i]) << (8 * i);
      }
      item_pos_ = pos;
      item_prefix_ = prefix;
      switch (type) {
        case kMain:
          Main(tag, udata);
          break;
        case kGlobal:
          Global(tag, udata, size);
          break;
        case kLocal:
          Local(tag, udata, size);
          break;
        default:
          Fail(Format("reserved item type 3 (prefix 0x%02X) at byte %zu", prefix, pos));
          break;
      }
      if (!out_.problem.empty()) break;
      pos += 1 + size;
      out_.bytes_parsed = pos;
    }
    if (collection_depth_ > 0) {
      const std::string open =
          Format("%d collection(s) not closed at the end (byte %zu)", collection_depth_, d_.size());
      out_.problem = out_.problem.empty() ? open : out_.problem + "; " + open;
    }
    out_.complete = out_.problem.empty();
    return std::move(out_);
  }

 private:
  void Fail(std::string what) {
    if (out_.problem.empty()) out_.problem = std::move(what);
  }
  std::string Where() const {
    return Format("item 0x%02X (%s) at byte %zu", item_prefix_,
                  ItemName(static_cast<std::uint8_t>((item_prefix_ >> 2) & 3u),
                           static_cast<std::uint8_t>(item_prefix_ >> 4)),
                  item_pos_);
  }

  void Global(std::uint8_t tag, std::uint32_t udata, std::size_t size) {
    switch (tag) {
      case kUsagePage:
        g_.usage_page = static_cast<std::uint16_t>(udata & 0xFFFFu);
        break;
      case kLogicalMinimum:
        g_.logical_min = SignExtend(udata, size);
        ResolveLogicalMax();
        break;
      case kLogicalMaximum:
        g_.logical_max_raw = udata;
        g_.logical_max_size = static_cast<std::uint8_t>(size);
        ResolveLogicalMax();
        break;
      case kReportSize:
        g_.report_size = udata;
        break;
      case kReportCount:
        if (udata > kMaxReportCount) {
          Fail(Format("Report Count %u > %u: ", udata, kMaxReportCount) + Where());
        }
        g_.report_count = udata;
        break;
      case kReportId:
        if (udata == 0 || udata > 0xFF) {
          Fail(Format("Report ID %u is not in 1..255: ", udata) + Where());
          break;
        }
        if (!out_.uses_report_ids && !out_.input_reports.empty()) {
          Fail("Report ID after input items without one: " + Where());
          break;
        }
        out_.uses_report_ids = true;
        g_.report_id = static_cast<std::uint8_t>(udata);
        break;
      case kPush:
        if (stack_.size() >= kMaxPushDepth) {
          Fail(Format("Push deeper than %zu: ", kMaxPushDepth) + Where());
          break;
        }
        stack_.push_back(g_);
        break;
      case kPop:
        if (stack_.empty()) {
          Fail("Pop without Push: " + Where());
          break;
        }
        g_ = stack_.back();
        stack_.pop_back();
        break;
      default:  // physical range, unit, unit exponent, reserved: not needed here
        break;
    }
  }

  // Linux hid-core reads the maximum signed when the minimum is negative and unsigned otherwise,
  // so that `15 00 26 FF 00` is 0..255 and `15 00 25 FF` is 0..255 too.
  void ResolveLogicalMax() {
    if (g_.logical_max_size == 0) {
      g_.logical_max = 0;
    } else if (g_.logical_min < 0) {
      g_.logical_max = SignExtend(g_.logical_max_raw, g_.logical_max_size);
    } else {
      g_.logical_max = g_.logical_max_raw;
    }
  }

  void Local(std::uint8_t tag, std::uint32_t udata, std::size_t size) {
    const bool extended = size == 4;
    switch (tag) {
      case kUsage:
        if (usages_.size() < kMaxUsages) usages_.push_back({udata, udata, extended});
        break;
      case kUsageMinimum:
        usage_min_ = udata;
        has_usage_min_ = true;
        usage_min_extended_ = extended;
        AddRangeIfComplete();
        break;
      case kUsageMaximum:
        usage_max_ = udata;
        has_usage_max_ = true;
        AddRangeIfComplete();
        break;
      default:  // designators, strings, delimiters
        break;
    }
  }

  void AddRangeIfComplete() {
    if (!has_usage_min_ || !has_usage_max_) return;
    if (usages_.size() < kMaxUsages) {
      usages_.push_back({usage_min_, std::max(usage_min_, usage_max_), usage_min_extended_});
    }
    has_usage_min_ = has_usage_max_ = false;
  }

  void ClearLocals() {
    usages_.clear();
    has_usage_min_ = has_usage_max_ = false;
  }

  // Page and id of the i-th usage of the local list (the last one repeats, HID §6.2.2.8).
  std::pair<std::uint16_t, std::uint16_t> UsageAt(std::uint32_t i) const {
    if (usages_.empty()) return {g_.usage_page, 0};
    std::uint64_t k = i;
    const UsageEntry* e = &usages_.back();
    std::uint32_t value = e->last;
    for (const UsageEntry& u : usages_) {
      const std::uint64_t n = static_cast<std::uint64_t>(u.last) - u.first + 1;
      if (k < n) {
        e = &u;
        value = static_cast<std::uint32_t>(u.first + k);
        break;
      }
      k -= n;
    }
    const std::uint16_t page =
        e->extended ? static_cast<std::uint16_t>(value >> 16) : g_.usage_page;
    return {page, static_cast<std::uint16_t>(value & 0xFFFFu)};
  }

  void Main(std::uint8_t tag, std::uint32_t udata) {
    switch (tag) {
      case kInput:
        Input(udata);
        break;
      case kOutput:
      case kFeature:
        break;  // not input: their bits are counted in other reports
      case kCollection:
        if (++collection_depth_ > kMaxCollectionDepth) {
          Fail(Format("collections nested deeper than %d: ", kMaxCollectionDepth) + Where());
        }
        break;
      case kEndCollection:
        if (collection_depth_ == 0) {
          Fail("End Collection without Collection: " + Where());
        } else {
          --collection_depth_;
        }
        break;
      default:
        Fail("reserved main item: " + Where());
        break;
    }
    ClearLocals();
  }

  void Input(std::uint32_t flags) {
    const bool constant = (flags & 0x1u) != 0;
    const bool variable = (flags & 0x2u) != 0;
    const bool relative = (flags & 0x4u) != 0;
    if (out_.uses_report_ids && g_.report_id == 0) {
      Fail("Input item without a Report ID in a descriptor that uses them: " + Where());
      return;
    }
    if (!constant && g_.report_size > 32) {
      Fail(Format("Report Size %u > 32 on a data Input item: ", g_.report_size) + Where());
      return;
    }
    HidInputReport* report = nullptr;
    for (HidInputReport& r : out_.input_reports) {
      if (r.report_id == g_.report_id) report = &r;
    }
    if (report == nullptr) {
      out_.input_reports.push_back({});
      report = &out_.input_reports.back();
      report->report_id = g_.report_id;
    }
    const std::uint64_t bits = static_cast<std::uint64_t>(g_.report_size) * g_.report_count;
    if (report->size_bits + bits > kMaxReportBytes * 8) {
      Fail(Format("input report %u longer than %zu bytes: ", static_cast<unsigned>(g_.report_id),
                  kMaxReportBytes) +
           Where());
      return;
    }
    if (!constant && g_.report_size > 0) {
      if (field_count_ + g_.report_count > kMaxFields) {
        Fail(Format("more than %zu input fields: ", kMaxFields) + Where());
        return;
      }
      for (std::uint32_t i = 0; i < g_.report_count; ++i) {
        HidField f;
        f.bit_offset = report->size_bits + i * g_.report_size;
        f.bit_size = g_.report_size;
        f.logical_min = g_.logical_min;
        f.logical_max = g_.logical_max;
        f.relative = relative;
        f.array = !variable;
        if (variable) {
          const auto [page, usage] = UsageAt(i);
          f.usage_page = page;
          f.usage = f.usage_max = usage;
        } else {
          const auto [page, first] = UsageAt(0);
          f.usage_page = page;
          f.usage = first;
          f.usage_max =
              usages_.empty() ? first : static_cast<std::uint16_t>(usages_.back().last & 0xFFFFu);
        }
        report->fields.push_back(f);
      }
      field_count_ += g_.report_count;
    }
    report->size_bits += static_cast<std::uint32_t>(bits);
  }

  std::span<const std::uint8_t> d_;
  HidReportDescriptor out_;
  GlobalState g_;
  std::vector<GlobalState> stack_;
  std::vector<UsageEntry> usages_;
  std::uint32_t usage_min_ = 0;
  std::uint32_t usage_max_ = 0;
  bool has_usage_min_ = false;
  bool has_usage_max_ = false;
  bool usage_min_extended_ = false;
  int collection_depth_ = 0;
  std::size_t field_count_ = 0;
  std::size_t item_pos_ = 0;
  std::uint8_t item_prefix_ = 0;
};

}  // namespace

const HidInputReport* HidReportDescriptor::FindInput(std::uint8_t report_id) const noexcept {
  for (const HidInputReport& r : input_reports) {
    if (r.report_id == report_id) return &r;
  }
  return nullptr;
}

HidReportDescriptor ParseHidReportDescriptor(std::span<const std::uint8_t> descriptor) {
  return DescriptorParser(descriptor).Run();
}

std::int64_t HidFieldValue(const HidField& field, std::span<const std::uint8_t> payload) noexcept {
  if (field.bit_size == 0 || field.bit_size > 32) return 0;
  const std::uint64_t end_bit = static_cast<std::uint64_t>(field.bit_offset) + field.bit_size;
  if (end_bit > static_cast<std::uint64_t>(payload.size()) * 8) return 0;
  std::uint64_t v = 0;
  for (std::uint32_t b = 0; b < field.bit_size; ++b) {
    const std::uint64_t bit = static_cast<std::uint64_t>(field.bit_offset) + b;
    if ((payload[bit >> 3] >> (bit & 7u)) & 1u) v |= std::uint64_t{1} << b;
  }
  if (field.logical_min < 0 && ((v >> (field.bit_size - 1)) & 1u)) {
    v |= ~std::uint64_t{0} << field.bit_size;  // sign-extend
  }
  return static_cast<std::int64_t>(v);
}

// ------------------------------------------------------------------------------------------------
// 2. Report parser
// ------------------------------------------------------------------------------------------------

namespace {

constexpr const char* kHidAxisNames[6] = {"X", "Y", "Z", "Rx", "Ry", "Rz"};

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

// ------------------------------------------------------------------------------------------------
// 3. Device table
// ------------------------------------------------------------------------------------------------

const SpaceMouseModel* FindSpaceMouseModel(std::uint16_t vendor_id,
                                           std::uint16_t product_id) noexcept {
  for (const SpaceMouseModel& m : kSpaceMouseModels) {
    if (m.vendor_id == vendor_id && m.product_id == product_id) return &m;
  }
  return nullptr;
}

namespace {

// Written from the layout facts (HID usages, 16-bit little-endian axes with logical range
// -350..350, buttons in report 3), keeping each family's Input flags: the split (Logitech-era)
// firmwares flag the axes Relative (0x06), the six-axis ones Absolute (0x02).
// clang-format off
constexpr std::uint8_t kSplitDescriptor[] = {
    0x05, 0x01, 0x09, 0x08, 0xA1, 0x01,              // Generic Desktop, Multi-axis Controller
    0xA1, 0x00, 0x85, 0x01,                          //   report 1: translation
    0x16, 0xA2, 0xFE, 0x26, 0x5E, 0x01,              //   logical -350..350
    0x09, 0x30, 0x09, 0x31, 0x09, 0x32,              //   X Y Z
    0x75, 0x10, 0x95, 0x03, 0x81, 0x06, 0xC0,        //   3 x 16 bits, Data Var Rel
    0xA1, 0x00, 0x85, 0x02,                          //   report 2: rotation
    0x09, 0x33, 0x09, 0x34, 0x09, 0x35,              //   Rx Ry Rz
    0x75, 0x10, 0x95, 0x03, 0x81, 0x06, 0xC0,
    0xA1, 0x02, 0x85, 0x03, 0x05, 0x09,              //   report 3: buttons 1..16
    0x19, 0x01, 0x29, 0x10, 0x15, 0x00, 0x25, 0x01,
    0x75, 0x01, 0x95, 0x10, 0x81, 0x02, 0xC0,
    0xC0};
constexpr std::uint8_t kSixAxisDescriptor[] = {
    0x05, 0x01, 0x09, 0x08, 0xA1, 0x01,              // Generic Desktop, Multi-axis Controller
    0xA1, 0x00, 0x85, 0x01,                          //   report 1: all six axes
    0x16, 0xA2, 0xFE, 0x26, 0x5E, 0x01,              //   logical -350..350
    0x09, 0x30, 0x09, 0x31, 0x09, 0x32,              //   X Y Z
    0x09, 0x33, 0x09, 0x34, 0x09, 0x35,              //   Rx Ry Rz
    0x75, 0x10, 0x95, 0x06, 0x81, 0x02, 0xC0,        //   6 x 16 bits, Data Var Abs
    0xA1, 0x02, 0x85, 0x03, 0x05, 0x09,              //   report 3: buttons 1..16
    0x19, 0x01, 0x29, 0x10, 0x15, 0x00, 0x25, 0x01,
    0x75, 0x01, 0x95, 0x10, 0x81, 0x02, 0xC0,
    0xC0};
// clang-format on

}  // namespace

std::span<const std::uint8_t> BuiltInSpaceMouseDescriptor(SpaceMouseReportStyle style) noexcept {
  switch (style) {
    case SpaceMouseReportStyle::kSplit:
      return kSplitDescriptor;
    case SpaceMouseReportStyle::kSixAxis:
      return kSixAxisDescriptor;
    default:
      return {};
  }
}

// ------------------------------------------------------------------------------------------------
// 4. Shaping and mapping
// ------------------------------------------------------------------------------------------------

void ValidateSpaceMouseConfig(const SpaceMouseConfig& c) {
  auto bad = [](const char* what, double v) {
    throw std::invalid_argument(Format("spacemouse: %s, got %g", what, v));
  };
  if (!(c.dead_zone >= 0.0 && c.dead_zone < 1.0)) bad("dead_zone must be in [0, 1)", c.dead_zone);
  if (!(c.hold_s >= 0.0 && std::isfinite(c.hold_s))) bad("hold_s must be >= 0", c.hold_s);
  if (!(c.decay_s >= 0.0 && std::isfinite(c.decay_s))) bad("decay_s must be >= 0", c.decay_s);
  if (!(c.v_max_m_per_s > 0.0 && std::isfinite(c.v_max_m_per_s))) {
    bad("v_max_m_per_s must be > 0", c.v_max_m_per_s);
  }
  if (!(c.w_max_rad_per_s > 0.0 && std::isfinite(c.w_max_rad_per_s))) {
    bad("w_max_rad_per_s must be > 0", c.w_max_rad_per_s);
  }
  if (!(c.max_rotation_rad > 0.0 && c.max_rotation_rad <= std::numbers::pi)) {
    bad("max_rotation_rad must be in (0, pi]", c.max_rotation_rad);
  }
  for (int i = 0; i < 3; ++i) {
    const double h = c.workspace_half_extents_m[i];
    if (!(h > 0.0 && std::isfinite(h))) bad("workspace_half_extents_m must be > 0", h);
  }
  if (!(c.max_step_s > 0.0 && std::isfinite(c.max_step_s))) {
    bad("max_step_s must be > 0", c.max_step_s);
  }
  if (!(c.read_timeout_ms > 0 && c.read_timeout_ms <= 1000)) {
    bad("read_timeout_ms must be in (0, 1000]", c.read_timeout_ms);
  }
  if (c.mode != SpaceMouseControlMode::kRate && c.mode != SpaceMouseControlMode::kPosition) {
    bad("mode must be kRate or kPosition", static_cast<int>(c.mode));
  }
  ValidateAxisMap(c.axis_map);
}

double ApplySpaceMouseDeadZone(double v, double dead_zone) noexcept {
  const double a = std::min(std::abs(v), 1.0);
  if (!(a > dead_zone)) return 0.0;  // NaN reads 0
  return std::copysign((a - dead_zone) / (1.0 - dead_zone), v);
}

double SpaceMouseStalenessGain(double age_s, double hold_s, double decay_s) noexcept {
  if (!(age_s > hold_s)) return 1.0;
  if (!(decay_s > 0.0)) return 0.0;
  return std::clamp(1.0 - (age_s - hold_s) / decay_s, 0.0, 1.0);
}

std::array<double, 6> ShapeSpaceMouseAxes(const SpaceMouseSample& sample, std::int64_t now_ns,
                                          const SpaceMouseConfig& config) noexcept {
  std::array<double, 6> d{};
  for (int i = 0; i < 6; ++i) {
    if (sample.axis_time_ns[i] == 0) continue;
    const double age_s =
        std::max<double>(0.0, static_cast<double>(now_ns - sample.axis_time_ns[i]) * 1e-9);
    d[i] = SpaceMouseStalenessGain(age_s, config.hold_s, config.decay_s) *
           ApplySpaceMouseDeadZone(sample.axes[i], config.dead_zone);
  }
  return d;
}

SpaceMousePoseMapper::SpaceMousePoseMapper(const SpaceMouseConfig& config) : config_(config) {
  ValidateSpaceMouseConfig(config);
}

void SpaceMousePoseMapper::Reset() noexcept {
  X_MH_ = RigidTransform::Identity();
  started_ = false;
  last_ns_ = 0;
}

void SpaceMousePoseMapper::Step(const SpaceMouseSample& sample, std::int64_t now_ns,
                                DeviceState& state) noexcept {
  if (!started_) {
    started_ = true;
    last_ns_ = now_ns;
  }
  double dt = 0.0;
  if (now_ns > last_ns_) {
    dt = std::min(static_cast<double>(now_ns - last_ns_) * 1e-9, config_.max_step_s);
    last_ns_ = now_ns;
  }
  const std::array<double, 6> d = ShapeSpaceMouseAxes(sample, now_ns, config_);
  const glm::dvec3 d_t{d[kTx], d[kTy], d[kTz]};
  glm::dvec3 d_r{d[kRx], d[kRy], d[kRz]};
  const glm::dvec3& h = config_.workspace_half_extents_m;
  const RigidTransform X_prev = X_MH_;
  if (config_.mode == SpaceMouseControlMode::kRate) {
    const Twist delta{(config_.v_max_m_per_s * dt) * d_t, (config_.w_max_rad_per_s * dt) * d_r};
    RigidTransform X = Displace(X_MH_, delta);
    X.translation = glm::clamp(X.translation, -h, h);
    X.rotation = glm::normalize(X.rotation);
    const glm::dvec3 theta = RotationVectorFromQuaternion(X.rotation);
    const double angle = glm::length(theta);
    if (angle > config_.max_rotation_rad) {
      X.rotation = QuaternionFromRotationVector(theta * (config_.max_rotation_rad / angle));
    }
    X_MH_ = X;
  } else {
    const double n = glm::length(d_r);
    if (n > 1.0) d_r /= n;
    X_MH_.translation = d_t * h;
    X_MH_.rotation = QuaternionFromRotationVector(config_.max_rotation_rad * d_r);
  }
  Twist V;
  if (dt > 0.0) {
    const Twist change = PoseDifference(X_MH_, X_prev);
    V = {change.linear / dt, change.angular / dt};
  }
  state.X_MH = X_MH_;
  state.V_MH_M = V;
  state.buttons = sample.buttons;
  state.timestamp_ns = now_ns;
}

// ------------------------------------------------------------------------------------------------
// 5. The device
// ------------------------------------------------------------------------------------------------

namespace {

constexpr const char* kUdevHint = "see deploy/udev/70-haptic-spacemouse.rules";

std::string Narrow(const wchar_t* w) {
  if (w == nullptr) return "no error text";
  std::string s;
  for (; *w != L'\0'; ++w) {
    s.push_back(*w > 0 && *w < 128 ? static_cast<char>(*w) : '?');
  }
  return s;
}

std::string LookedFor() {
  std::string s;
  for (const SpaceMouseModel& m : kSpaceMouseModels) {
    if (!m.six_dof) continue;
    if (!s.empty()) s += ", ";
    s += Format("%04x:%04x", static_cast<unsigned>(m.vendor_id),
                static_cast<unsigned>(m.product_id));
  }
  return s;
}

struct Candidate {
  std::string path;
  const SpaceMouseModel* model = nullptr;
  bool multi_axis_interface = false;  // usage page 1, usage 8 (or unknown)
};

// hidraw: /dev/hidrawN → /sys/class/hidraw/hidrawN/device/report_descriptor.
std::vector<std::uint8_t> ReadSysfsDescriptor(const std::string& path) {
  const std::string prefix = "/dev/";
  if (path.rfind(prefix + "hidraw", 0) != 0) return {};
  const std::string node = path.substr(prefix.size());
  std::ifstream in("/sys/class/hidraw/" + node + "/device/report_descriptor", std::ios::binary);
  if (!in) return {};
  std::vector<std::uint8_t> bytes(4096);
  in.read(reinterpret_cast<char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  bytes.resize(static_cast<std::size_t>(std::max<std::streamsize>(0, in.gcount())));
  return bytes;
}

}  // namespace

SpaceMouseDevice::SpaceMouseDevice(const SpaceMouseConfig& config)
    : config_(config), mapper_(config) {}

SpaceMouseDevice::~SpaceMouseDevice() { Close(); }

DeviceCapabilities SpaceMouseDevice::capabilities() const {
  DeviceCapabilities c;
  c.name = "3Dconnexion " + (model_name_.empty() ? std::string("SpaceMouse") : model_name_) +
           " (hidapi, input only)";
  c.max_force_n = 0.0;
  c.max_torque_nm = 0.0;
  c.max_stiffness_n_per_m = 0.0;
  c.max_rotational_stiffness_nm_per_rad = 0.0;
  c.max_damping_ns_per_m = 0.0;
  c.rated_loop_rate_hz = 1000.0;
  c.workspace_half_extents_m = config_.workspace_half_extents_m;
  c.dof_in = 6;
  c.dof_out = 0;
  return c;
}

void SpaceMouseDevice::Open() {
  Close();
  if (hid_init() != 0) {
    throw std::runtime_error("spacemouse: hid_init failed: " + Narrow(hid_error(nullptr)));
  }
  // Find the device: the table's 6-DoF models on both vendor ids, or the path given.
  std::vector<Candidate> found;
  const bool by_path = !config_.path.empty();
  auto scan = [&](unsigned short vendor_id) {
    hid_device_info* list = hid_enumerate(vendor_id, 0);
    for (hid_device_info* i = list; i != nullptr; i = i->next) {
      if (i->path == nullptr) continue;
      const SpaceMouseModel* model = FindSpaceMouseModel(i->vendor_id, i->product_id);
      if (by_path) {
        if (config_.path == i->path) found.push_back({i->path, model, true});
        continue;
      }
      if (model == nullptr || !model->six_dof) continue;
      const bool multi_axis = i->usage_page == 0 || (i->usage_page == kHidPageGenericDesktop &&
                                                     i->usage == kHidUsageMultiAxisController);
      found.push_back({i->path, model, multi_axis});
    }
    hid_free_enumeration(list);
  };
  if (by_path) {
    scan(0);
  } else {
    scan(0x046d);
    scan(0x256f);
  }
  // Prefer the multi-axis interface of a device that exposes several.
  std::stable_sort(found.begin(), found.end(), [](const Candidate& a, const Candidate& b) {
    return a.multi_axis_interface && !b.multi_axis_interface;
  });
  Candidate chosen;
  if (!found.empty()) {
    chosen = found.front();
  } else if (by_path) {
    chosen.path = config_.path;  // not enumerated (e.g. a path outside udev): try it anyway
  } else {
    throw std::runtime_error("no 3Dconnexion device found (looked for " + LookedFor() +
                             "); is it plugged in, and does /dev/hidraw* allow you to read it? " +
                             kUdevHint);
  }
  const std::string name =
      chosen.model != nullptr ? std::string(chosen.model->name) : std::string("HID device");
  hid_device* handle = hid_open_path(chosen.path.c_str());
  if (handle == nullptr) {
    throw std::runtime_error("spacemouse: could not open " + name + " at " + chosen.path + " (" +
                             Narrow(hid_error(nullptr)) +
                             "); is it plugged in, and does /dev/hidraw* allow you to read it? " +
                             kUdevHint);
  }
  // The report descriptor: from hidapi, else sysfs, else the built-in one of the model's style.
  std::vector<std::uint8_t> bytes;
  SpaceMouseDescriptorSource source = SpaceMouseDescriptorSource::kNone;
#ifdef HT_HIDAPI_HAS_GET_REPORT_DESCRIPTOR
  {
    std::vector<std::uint8_t> buf(HID_API_MAX_REPORT_DESCRIPTOR_SIZE);
    const int n = hid_get_report_descriptor(handle, buf.data(), buf.size());
    if (n > 0) {
      buf.resize(static_cast<std::size_t>(n));
      bytes = std::move(buf);
      source = SpaceMouseDescriptorSource::kHidapi;
    }
  }
#endif
  if (bytes.empty()) {
    bytes = ReadSysfsDescriptor(chosen.path);
    if (!bytes.empty()) source = SpaceMouseDescriptorSource::kSysfs;
  }
  bool accept_longer = false;
  if (bytes.empty()) {
    if (chosen.model == nullptr || chosen.model->style == SpaceMouseReportStyle::kNone) {
      hid_close(handle);
      throw std::runtime_error("spacemouse: cannot read the report descriptor of " + name + " at " +
                               chosen.path +
                               " (hidapi " HID_API_VERSION_STR
                               " has no hid_get_report_descriptor and sysfs has none) and it is "
                               "not a known 6-DoF model");
    }
    const auto builtin = BuiltInSpaceMouseDescriptor(chosen.model->style);
    bytes.assign(builtin.begin(), builtin.end());
    source = SpaceMouseDescriptorSource::kBuiltIn;
    accept_longer = true;
  }
  const HidReportDescriptor descriptor = ParseHidReportDescriptor(bytes);
  std::optional<SpaceMouseReportParser> parser;
  try {
    parser.emplace(descriptor, config_.axis_map, accept_longer);
  } catch (const std::invalid_argument& e) {
    hid_close(handle);
    throw std::runtime_error("spacemouse: " + name + " at " + chosen.path + ": " + e.what() +
                             (descriptor.complete ? "" : "; descriptor: " + descriptor.problem));
  }
  handle_ = handle;
  model_name_ = name;
  device_path_ = chosen.path;
  descriptor_source_ = source;
  descriptor_problem_ = descriptor.problem;
  mapper_.Reset();
  latest_ = {};
  SpaceMouseSample stale;
  while (handoff_.Read(stale)) {
  }
  stop_.store(false, std::memory_order_relaxed);
  lost_.store(false, std::memory_order_relaxed);
  read_errors_.store(0, std::memory_order_relaxed);
  reader_ = std::thread(&SpaceMouseDevice::ReaderLoop, this, std::move(*parser));
  open_ = true;
}

void SpaceMouseDevice::ReaderLoop(SpaceMouseReportParser parser) noexcept {
  std::array<std::uint8_t, 4097> buf{};  // the longest report the parser accepts, plus its id
  while (!stop_.load(std::memory_order_acquire)) {
    const int n = hid_read_timeout(handle_, buf.data(), buf.size(), config_.read_timeout_ms);
    if (n < 0) {  // unplugged or revoked: stop; ReadState reports the loss
      read_errors_.fetch_add(1, std::memory_order_relaxed);
      lost_.store(true, std::memory_order_release);
      return;
    }
    if (n == 0) continue;
    const std::int64_t now_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(
                                    std::chrono::steady_clock::now().time_since_epoch())
                                    .count();
    parser.Feed(std::span<const std::uint8_t>(buf.data(), static_cast<std::size_t>(n)), now_ns);
    handoff_.Write(parser.sample());
  }
}

void SpaceMouseDevice::Close() noexcept {
  stop_.store(true, std::memory_order_release);
  if (reader_.joinable()) reader_.join();
  if (handle_ != nullptr) {
    hid_close(handle_);
    handle_ = nullptr;
  }
  open_ = false;
}

bool SpaceMouseDevice::ReadState(std::int64_t now_ns, DeviceState& state) noexcept {
  if (!open_) return false;
  handoff_.Read(latest_);
  mapper_.Step(latest_, now_ns, state);
  return !lost_.load(std::memory_order_acquire) && IsFiniteRigidTransform(state.X_MH) &&
         IsFinite(state.V_MH_M);
}

bool SpaceMouseDevice::WriteWrench(const Wrench&, std::int64_t) noexcept { return true; }

}  // namespace ht
