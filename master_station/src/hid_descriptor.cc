// HID report descriptor parser (HID 1.11 §6.2.2) and field reader.

#include "master_station/hid_descriptor.h"

#include <algorithm>
#include <cstdio>
#include <utility>

#include "spacemouse_internal.h"

namespace ht {

// ------------------------------------------------------------------------------------------------
// 1. HID report descriptor
// ------------------------------------------------------------------------------------------------

namespace {

using detail::Format;

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

}  // namespace ht
