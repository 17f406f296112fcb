// SpaceMouse backend: the HID descriptor parser and the report parser fed the real descriptors and
// report bytes of ../shared/data/spacemouse (located through HT_SHARED_DATA, else
// ../shared/data relative to the working directory, the project root; skipped with a message
// when absent), shaping (dead zone, hold then decay), pose mapping, the device table against the
// CSV it came from, random bytes into both parsers, and Open() without a device.

#include "master_station/spacemouse.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <vector>

namespace ht {
namespace {

namespace fs = std::filesystem;
using Bytes = std::vector<std::uint8_t>;

// ---- test data --------------------------------------------------------------------------------

fs::path SpaceMouseDataDir() {
  if (const char* env = std::getenv("HT_SHARED_DATA"); env != nullptr && *env != '\0') {
    return fs::path(env) / "spacemouse";
  }
  return fs::path("../shared/data/spacemouse");
}

#define REQUIRE_SPACEMOUSE_DATA()                                                           \
  do {                                                                                      \
    if (!fs::is_directory(SpaceMouseDataDir())) {                                           \
      GTEST_SKIP() << "SpaceMouse test data not found at " << SpaceMouseDataDir()           \
                   << ": set HT_SHARED_DATA to the shared data directory (the one holding " \
                      "spacemouse/), or run from the project root where ../shared/data "    \
                      "exists";                                                             \
    }                                                                                       \
  } while (0)

Bytes ReadBinary(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  EXPECT_TRUE(in) << "cannot read " << p;
  return Bytes(std::istreambuf_iterator<char>(in), {});
}

Bytes ParseHex(const std::string& text) {
  Bytes out;
  std::istringstream in(text);
  std::string tok;
  while (in >> tok) out.push_back(static_cast<std::uint8_t>(std::stoul(tok, nullptr, 16)));
  return out;
}

Bytes ReadHexFile(const fs::path& p) {
  std::ifstream in(p);
  EXPECT_TRUE(in) << "cannot read " << p;
  std::stringstream ss;
  ss << in.rdbuf();
  return ParseHex(ss.str());
}

Bytes Descriptor(const std::string& name) { return ReadBinary(SpaceMouseDataDir() / name); }

// Splits one CSV line, honouring double quotes.
std::vector<std::string> SplitCsv(const std::string& line) {
  std::vector<std::string> out(1);
  bool quoted = false;
  for (char c : line) {
    if (c == '"') {
      quoted = !quoted;
    } else if (c == ',' && !quoted) {
      out.emplace_back();
    } else {
      out.back().push_back(c);
    }
  }
  return out;
}

std::vector<std::vector<std::string>> ReadCsv(const fs::path& p) {
  std::ifstream in(p);
  EXPECT_TRUE(in) << "cannot read " << p;
  std::vector<std::vector<std::string>> rows;
  std::string line;
  bool header = true;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    if (header) {  // first non-comment line names the columns
      header = false;
      continue;
    }
    rows.push_back(SplitCsv(line));
  }
  return rows;
}

// Packs values LSB-first into bytes: an encoder independent of HidFieldValue.
Bytes PackBits(const std::vector<std::pair<std::int64_t, int>>& values_and_bits) {
  Bytes out;
  std::size_t bit = 0;
  for (const auto& [v, n] : values_and_bits) {
    for (int b = 0; b < n; ++b, ++bit) {
      if (bit / 8 >= out.size()) out.push_back(0);
      if ((static_cast<std::uint64_t>(v) >> b) & 1u) {
        out[bit / 8] = static_cast<std::uint8_t>(out[bit / 8] | (1u << (bit % 8)));
      }
    }
  }
  return out;
}

// A report: id byte then 16-bit little-endian values.
Bytes Report16(std::uint8_t id, const std::vector<int>& values) {
  Bytes r{id};
  for (int v : values) {
    r.push_back(static_cast<std::uint8_t>(v & 0xFF));
    r.push_back(static_cast<std::uint8_t>((v >> 8) & 0xFF));
  }
  return r;
}

void ExpectFieldsInside(const HidReportDescriptor& d) {
  for (const HidInputReport& r : d.input_reports) {
    EXPECT_LE(r.size_bits, 4096u * 8u);
    for (const HidField& f : r.fields) {
      EXPECT_GE(f.bit_size, 1u);
      EXPECT_LE(f.bit_size, 32u);
      EXPECT_LE(std::uint64_t{f.bit_offset} + f.bit_size, r.size_bits);
    }
  }
}

std::vector<unsigned> InputIds(const HidReportDescriptor& d) {
  std::vector<unsigned> ids;
  for (const HidInputReport& r : d.input_reports) ids.push_back(r.report_id);
  return ids;
}

void ExpectAxisFields(const HidInputReport& r, std::uint16_t first_usage, int count,
                      bool relative) {
  ASSERT_EQ(r.fields.size(), static_cast<std::size_t>(count));
  EXPECT_EQ(r.size_bits, static_cast<std::uint32_t>(16 * count));
  for (int i = 0; i < count; ++i) {
    const HidField& f = r.fields[i];
    EXPECT_EQ(f.usage_page, kHidPageGenericDesktop);
    EXPECT_EQ(f.usage, first_usage + i);
    EXPECT_EQ(f.bit_offset, static_cast<std::uint32_t>(16 * i));
    EXPECT_EQ(f.bit_size, 16u);
    EXPECT_EQ(f.logical_min, -350);
    EXPECT_EQ(f.logical_max, 350);
    EXPECT_EQ(f.relative, relative);
    EXPECT_FALSE(f.array);
  }
}

bool SameField(const HidField& a, const HidField& b) {
  return a.bit_offset == b.bit_offset && a.bit_size == b.bit_size &&
         a.logical_min == b.logical_min && a.logical_max == b.logical_max &&
         a.usage_page == b.usage_page && a.usage == b.usage && a.usage_max == b.usage_max &&
         a.relative == b.relative && a.array == b.array;
}

constexpr double kFull = 350.0;  // the real descriptors' logical maximum

// ---- 1. descriptor parser on the real descriptors ---------------------------------------------

TEST(HidDescriptor, SpaceNavigator217HasSplitRelativeAxesOfPlusMinus350) {
  REQUIRE_SPACEMOUSE_DATA();
  const Bytes bytes = Descriptor("SpaceNavigator_046d_c626_rdesc_217.bin");
  ASSERT_EQ(bytes.size(), 217u);
  const HidReportDescriptor d = ParseHidReportDescriptor(bytes);
  EXPECT_TRUE(d.complete) << d.problem;
  EXPECT_EQ(d.bytes_parsed, 217u);
  EXPECT_TRUE(d.uses_report_ids);
  EXPECT_EQ(InputIds(d), (std::vector<unsigned>{1, 2, 3}));  // 4 is output, 5..0x13 feature
  ExpectAxisFields(*d.FindInput(1), kHidUsageX, 3, /*relative=*/true);
  ExpectAxisFields(*d.FindInput(2), kHidUsageX + 3, 3, /*relative=*/true);
  const HidInputReport& buttons = *d.FindInput(3);
  EXPECT_EQ(buttons.size_bits, 16u);  // 2 buttons + 14 bits of padding
  ASSERT_EQ(buttons.fields.size(), 2u);
  for (int i = 0; i < 2; ++i) {
    EXPECT_EQ(buttons.fields[i].usage_page, kHidPageButton);
    EXPECT_EQ(buttons.fields[i].usage, i + 1);
    EXPECT_EQ(buttons.fields[i].bit_offset, static_cast<std::uint32_t>(i));
    EXPECT_EQ(buttons.fields[i].bit_size, 1u);
  }
  ExpectFieldsInside(d);
}

TEST(HidDescriptor, SpaceNavigator228VariantHasTheSameInputReportsAs217) {
  REQUIRE_SPACEMOUSE_DATA();
  const Bytes b217 = Descriptor("SpaceNavigator_046d_c626_rdesc_217.bin");
  const Bytes b228 = Descriptor("SpaceNavigator_046d_c626_rdesc_228.bin");
  ASSERT_EQ(b228.size(), 228u);
  // The .hex transcription and the .bin agree (two routes to the same bytes).
  EXPECT_EQ(ReadHexFile(SpaceMouseDataDir() / "SpaceNavigator_046d_c626_rdesc_228.hex"), b228);
  const HidReportDescriptor d217 = ParseHidReportDescriptor(b217);
  const HidReportDescriptor d228 = ParseHidReportDescriptor(b228);
  EXPECT_TRUE(d228.complete) << d228.problem;
  EXPECT_EQ(d228.bytes_parsed, 228u);
  ASSERT_EQ(InputIds(d228), InputIds(d217));
  for (std::size_t i = 0; i < d217.input_reports.size(); ++i) {
    const HidInputReport& a = d217.input_reports[i];
    const HidInputReport& b = d228.input_reports[i];
    EXPECT_EQ(a.size_bits, b.size_bits);
    ASSERT_EQ(a.fields.size(), b.fields.size());
    for (std::size_t k = 0; k < a.fields.size(); ++k)
      EXPECT_TRUE(SameField(a.fields[k], b.fields[k]));
  }
}

TEST(HidDescriptor, SpaceMouseWireless270HasOneAbsoluteSixAxisReportAndABatteryReport) {
  REQUIRE_SPACEMOUSE_DATA();
  const Bytes bytes = Descriptor("SpaceMouseWireless_256f_c62e_rdesc_270.bin");
  ASSERT_EQ(bytes.size(), 270u);
  const HidReportDescriptor d = ParseHidReportDescriptor(bytes);
  EXPECT_TRUE(d.complete) << d.problem;
  EXPECT_EQ(d.bytes_parsed, 270u);
  EXPECT_EQ(InputIds(d), (std::vector<unsigned>{1, 3, 0x17}));
  const HidInputReport& axes = *d.FindInput(1);
  EXPECT_EQ(axes.payload_bytes(), 12u);
  ExpectAxisFields(axes, kHidUsageX, 6, /*relative=*/false);
  EXPECT_EQ(d.FindInput(3)->size_bits, 16u);
  // Report 0x17: Battery Strength (page 0x06, usage 0x20) 0..100 in 8 bits, a vendor bit, padding.
  const HidInputReport& battery = *d.FindInput(0x17);
  EXPECT_EQ(battery.size_bits, 16u);
  ASSERT_EQ(battery.fields.size(), 2u);
  EXPECT_EQ(battery.fields[0].usage_page, 0x06);
  EXPECT_EQ(battery.fields[0].usage, 0x20);
  EXPECT_EQ(battery.fields[0].bit_size, 8u);
  EXPECT_EQ(battery.fields[0].logical_min, 0);
  EXPECT_EQ(battery.fields[0].logical_max, 100);
  EXPECT_EQ(battery.fields[1].usage_page, 0xFF00);
  EXPECT_EQ(battery.fields[1].usage, 0x27);
  EXPECT_EQ(battery.fields[1].bit_offset, 8u);
  EXPECT_EQ(battery.fields[1].bit_size, 1u);
  ExpectFieldsInside(d);
}

TEST(HidDescriptor, TruncatedEnterpriseDescriptorSaysTruncatedAndKeepsWhatCameBefore) {
  REQUIRE_SPACEMOUSE_DATA();
  const Bytes bytes =
      ReadHexFile(SpaceMouseDataDir() / "SpaceMouseEnterprise_256f_c633_rdesc_TRUNCATED.hex");
  ASSERT_EQ(bytes.size(), 326u);
  const HidReportDescriptor d = ParseHidReportDescriptor(bytes);
  EXPECT_FALSE(d.complete);
  EXPECT_NE(d.problem.find("truncated"), std::string::npos) << d.problem;
  EXPECT_NE(d.problem.find("byte 325"), std::string::npos) << d.problem;  // the cut 0x81 item
  EXPECT_NE(d.problem.find("Input"), std::string::npos) << d.problem;
  EXPECT_EQ(d.bytes_parsed, 325u);
  // Report 0x1D was being described when the text ends: it has no complete Input item.
  EXPECT_EQ(InputIds(d), (std::vector<unsigned>{1, 3, 0x1C}));
  ExpectAxisFields(*d.FindInput(1), kHidUsageX, 6, /*relative=*/false);
  const HidInputReport& buttons = *d.FindInput(3);
  EXPECT_EQ(buttons.fields.size(), 31u);
  EXPECT_EQ(buttons.size_bits, 32u);
  EXPECT_EQ(buttons.fields[30].usage, 31);
  const HidInputReport& array = *d.FindInput(0x1C);
  ASSERT_EQ(array.fields.size(), 6u);
  EXPECT_TRUE(array.fields[0].array);
  EXPECT_EQ(array.fields[0].usage_page, kHidPageButton);
  EXPECT_EQ(array.fields[0].usage, 0);
  EXPECT_EQ(array.fields[0].usage_max, 255);
  EXPECT_EQ(array.fields[0].logical_max, 255);
  // What survives is enough to drive the device: six axes in report 1.
  SpaceMouseReportParser parser(d);
  EXPECT_TRUE(parser.Feed(Report16(1, {100, 0, 0, 0, 0, -200}), 1));
  EXPECT_EQ(parser.raw_axes()[0], 100);
  EXPECT_EQ(parser.raw_axes()[5], -200);
  // Array report 0x1C lists pressed buttons by number: 5 and 12.
  EXPECT_TRUE(parser.Feed(Report16(0x1C, {5, 12, 0, 0, 0, 0}), 2));
  EXPECT_EQ(parser.sample().buttons, (1u << 4) | (1u << 11));
}

TEST(HidDescriptor, EveryStrictPrefixOfARealDescriptorIsFlaggedIncomplete) {
  REQUIRE_SPACEMOUSE_DATA();
  for (const char* name :
       {"SpaceNavigator_046d_c626_rdesc_217.bin", "SpaceNavigator_046d_c626_rdesc_228.bin",
        "SpaceMouseWireless_256f_c62e_rdesc_270.bin"}) {
    const Bytes bytes = Descriptor(name);
    for (std::size_t n = 0; n < bytes.size(); ++n) {
      const HidReportDescriptor d =
          ParseHidReportDescriptor(std::span<const std::uint8_t>(bytes.data(), n));
      // `05 01 09 08` (bytes 0..3) is whole on its own; from byte 4 on, an item is cut or the
      // application collection is open.
      if (n > 4 || n % 2 == 1) {
        EXPECT_FALSE(d.complete) << name << " cut at " << n;
        EXPECT_FALSE(d.problem.empty());
      }
      EXPECT_LE(d.bytes_parsed, n);
      ExpectFieldsInside(d);
    }
  }
}

// ---- 1b. descriptor parser on hand-made descriptors -------------------------------------------

TEST(HidDescriptor, MalformedItemsStopWithAMessageNamingTheByte) {
  struct Case {
    Bytes bytes;
    const char* expect;
  };
  const std::vector<Case> cases = {
      {{0x05, 0x01, 0xB4}, "Pop without Push"},
      {{0x05, 0x01, 0x85, 0x00}, "Report ID 0"},
      {{0xC0}, "End Collection without Collection"},
      {{0x75, 0x40, 0x95, 0x01, 0x81, 0x02}, "Report Size 64"},
      {{0x96, 0x01, 0x20}, "Report Count 8193"},
      {{0x0C}, "reserved item type"},
      {{0xFE, 0x05, 0x00, 0x01}, "long item"},
      {{0x75, 0x08, 0x95, 0x01, 0x81, 0x02, 0x85, 0x01}, "Report ID after input items"},
      {{0x26, 0xFF}, "truncated"},
      {{0xA1, 0x01}, "not closed"},
  };
  for (const Case& c : cases) {
    const HidReportDescriptor d = ParseHidReportDescriptor(c.bytes);
    EXPECT_FALSE(d.complete);
    EXPECT_NE(d.problem.find(c.expect), std::string::npos)
        << "expected '" << c.expect << "' in '" << d.problem << "'";
    EXPECT_NE(d.problem.find("byte"), std::string::npos) << d.problem;
  }
}

TEST(HidDescriptor, LogicalMaximumIsUnsignedWhenTheMinimumIsNotNegative) {
  // 15 00 25 FF: 0..255 (one-byte 0xFF read unsigned); 15 80 25 7F: -128..127.
  const Bytes a = {0x15, 0x00, 0x25, 0xFF, 0x75, 0x08, 0x95, 0x01, 0x09, 0x30, 0x81, 0x02};
  const Bytes b = {0x15, 0x80, 0x25, 0x7F, 0x75, 0x08, 0x95, 0x01, 0x09, 0x30, 0x81, 0x02};
  const HidReportDescriptor da = ParseHidReportDescriptor(a);
  const HidReportDescriptor db = ParseHidReportDescriptor(b);
  ASSERT_TRUE(da.complete && db.complete);
  EXPECT_EQ(da.input_reports[0].fields[0].logical_min, 0);
  EXPECT_EQ(da.input_reports[0].fields[0].logical_max, 255);
  EXPECT_EQ(db.input_reports[0].fields[0].logical_min, -128);
  EXPECT_EQ(db.input_reports[0].fields[0].logical_max, 127);
  // Values read back: 0xFF is 255 unsigned, -1 signed.
  EXPECT_EQ(HidFieldValue(da.input_reports[0].fields[0], Bytes{0xFF}), 255);
  EXPECT_EQ(HidFieldValue(db.input_reports[0].fields[0], Bytes{0xFF}), -1);
}

TEST(HidDescriptor, PushPopLongItemsAndExtendedUsages) {
  // Push, change the size, Pop: the field after Pop has the pushed size. A long item in between
  // is skipped. The 4-byte usage 0x0001_0031 is Generic Desktop Y although the page is Button.
  const Bytes bytes = {0x05, 0x09, 0x15, 0x00, 0x25,
                       0x01, 0x75, 0x08, 0x95, 0x01,  // page Button, 8-bit
                       0xA4,                          // Push
                       0x75, 0x04,                    // size 4
                       0xFE, 0x02, 0x10, 0xAA, 0xBB,  // long item, 2 data bytes
                       0xB4,                          // Pop: size 8 again
                       0x0B, 0x31, 0x00, 0x01, 0x00,  // Usage 0x00010031
                       0x81, 0x02};
  const HidReportDescriptor d = ParseHidReportDescriptor(bytes);
  ASSERT_TRUE(d.complete) << d.problem;
  ASSERT_EQ(d.input_reports.size(), 1u);
  const HidField& f = d.input_reports[0].fields.at(0);
  EXPECT_EQ(f.bit_size, 8u);
  EXPECT_EQ(f.usage_page, kHidPageGenericDesktop);
  EXPECT_EQ(f.usage, 0x31);
}

TEST(HidDescriptor, BuiltInDescriptorsGiveTheRealDescriptorsAxisLayout) {
  REQUIRE_SPACEMOUSE_DATA();
  const HidReportDescriptor split =
      ParseHidReportDescriptor(BuiltInSpaceMouseDescriptor(SpaceMouseReportStyle::kSplit));
  const HidReportDescriptor six =
      ParseHidReportDescriptor(BuiltInSpaceMouseDescriptor(SpaceMouseReportStyle::kSixAxis));
  ASSERT_TRUE(split.complete) << split.problem;
  ASSERT_TRUE(six.complete) << six.problem;
  EXPECT_TRUE(BuiltInSpaceMouseDescriptor(SpaceMouseReportStyle::kNone).empty());
  const HidReportDescriptor nav =
      ParseHidReportDescriptor(Descriptor("SpaceNavigator_046d_c626_rdesc_217.bin"));
  const HidReportDescriptor wireless =
      ParseHidReportDescriptor(Descriptor("SpaceMouseWireless_256f_c62e_rdesc_270.bin"));
  auto same_report = [](const HidInputReport& a, const HidInputReport& b, std::size_t n) {
    ASSERT_GE(a.fields.size(), n);
    ASSERT_GE(b.fields.size(), n);
    for (std::size_t k = 0; k < n; ++k) EXPECT_TRUE(SameField(a.fields[k], b.fields[k])) << k;
  };
  same_report(*split.FindInput(1), *nav.FindInput(1), 3);
  same_report(*split.FindInput(2), *nav.FindInput(2), 3);
  same_report(*split.FindInput(3), *nav.FindInput(3), 2);  // the real one has 2 buttons
  same_report(*six.FindInput(1), *wireless.FindInput(1), 6);
  same_report(*six.FindInput(3), *wireless.FindInput(3), 2);
}

// ---- 2. report parser -------------------------------------------------------------------------

// Every input row of observed_input_reports.csv gives the decoded meaning stated there.
TEST(SpaceMouseReports, ObservedReportsDecodeToTheirStatedMeaning) {
  REQUIRE_SPACEMOUSE_DATA();
  const std::map<std::string, Bytes> descriptor_of_pid = {
      {"c626", Descriptor("SpaceNavigator_046d_c626_rdesc_217.bin")},
      {"c62e", Descriptor("SpaceMouseWireless_256f_c62e_rdesc_270.bin")}};
  const std::regex axis_re(R"(\b(X|Y|Z|Rx|Ry|Rz)=(-?\d+))");
  const std::regex buttons_re(R"(buttons? ([0-9+]+) pressed)");
  const std::map<std::string, int> axis_index = {{"X", 0},  {"Y", 1},  {"Z", 2},
                                                 {"Rx", 3}, {"Ry", 4}, {"Rz", 5}};
  int checked_in = 0;
  int checked_out = 0;
  for (const auto& row : ReadCsv(SpaceMouseDataDir() / "observed_input_reports.csv")) {
    ASSERT_GE(row.size(), 7u);
    const std::string& pid = row[2];
    const std::string& direction = row[3];
    const Bytes report = ParseHex(row[4]);
    const std::string& meaning = row[5];
    SCOPED_TRACE(row[4] + " = " + meaning);
    ASSERT_TRUE(descriptor_of_pid.count(pid)) << "no descriptor for pid " << pid;
    const HidReportDescriptor d = ParseHidReportDescriptor(descriptor_of_pid.at(pid));
    SpaceMouseReportParser parser(d);
    if (direction == "out") {
      // Output reports (LED) are not input reports: fed as input they are counted and dropped.
      EXPECT_FALSE(parser.Feed(report, 1));
      EXPECT_EQ(parser.sample().counts.unknown_report_id, 1u);
      ++checked_out;
      continue;
    }
    ASSERT_EQ(direction, "in");
    ASSERT_TRUE(parser.Feed(report, 1));
    int facts = 0;
    for (auto it = std::sregex_iterator(meaning.begin(), meaning.end(), axis_re);
         it != std::sregex_iterator(); ++it) {
      const int a = axis_index.at((*it)[1]);
      const int value = std::stoi((*it)[2]);
      EXPECT_EQ(parser.raw_axes()[a], value) << (*it)[0];
      // Normalized by the descriptor's range and mapped D → M: (x, -y, -z, rx, -ry, -rz).
      const double sign = (a == 0 || a == 3) ? 1.0 : -1.0;
      EXPECT_DOUBLE_EQ(parser.sample().axes[a], sign * value / kFull) << (*it)[0];
      ++facts;
    }
    std::smatch m;
    if (meaning.find("all released") != std::string::npos) {
      EXPECT_EQ(parser.sample().buttons, 0u);
      ++facts;
    } else if (std::regex_search(meaning, m, buttons_re)) {
      std::uint32_t expected = 0;
      std::stringstream list(m[1].str());
      std::string n;
      while (std::getline(list, n, '+')) expected |= 1u << (std::stoi(n) - 1);
      EXPECT_EQ(parser.sample().buttons, expected);
      ++facts;
    }
    if (std::regex_search(meaning, m, std::regex(R"(strength=(\d+), vendor bit=(\d+))"))) {
      const HidInputReport& r = *d.FindInput(report[0]);
      const std::span<const std::uint8_t> payload(report.data() + 1, report.size() - 1);
      EXPECT_EQ(HidFieldValue(r.fields[0], payload), std::stoi(m[1].str()));
      EXPECT_EQ(HidFieldValue(r.fields[1], payload), std::stoi(m[2].str()));
      ++facts;
    }
    EXPECT_GT(facts, 0) << "meaning not understood by the test";
    EXPECT_EQ(parser.sample().counts.accepted, 1u);
    ++checked_in;
  }
  EXPECT_EQ(checked_in, 8);
  EXPECT_EQ(checked_out, 2);
}

TEST(SpaceMouseReports, SplitAndSixAxisStylesGiveTheSameDeflection) {
  REQUIRE_SPACEMOUSE_DATA();
  const std::vector<int> v = {118, -20, -6, 30, -350, 175};
  SpaceMouseReportParser split(
      ParseHidReportDescriptor(Descriptor("SpaceNavigator_046d_c626_rdesc_217.bin")));
  SpaceMouseReportParser six(
      ParseHidReportDescriptor(Descriptor("SpaceMouseWireless_256f_c62e_rdesc_270.bin")));
  EXPECT_TRUE(split.Feed(Report16(1, {v[0], v[1], v[2]}), 10));
  EXPECT_TRUE(split.Feed(Report16(2, {v[3], v[4], v[5]}), 20));
  EXPECT_TRUE(six.Feed(Report16(1, v), 20));
  for (int i = 0; i < 6; ++i) {
    EXPECT_EQ(split.raw_axes()[i], v[i]);
    EXPECT_EQ(six.raw_axes()[i], v[i]);
    EXPECT_DOUBLE_EQ(split.sample().axes[i], six.sample().axes[i]);
  }
  // Each axis carries the time of the report that set it.
  EXPECT_EQ(split.sample().axis_time_ns[kTx], 10);
  EXPECT_EQ(split.sample().axis_time_ns[kRz], 20);
  // A six-axis report into the split parser has the wrong length: counted and dropped.
  EXPECT_FALSE(split.Feed(Report16(1, v), 30));
  EXPECT_EQ(split.sample().counts.wrong_length, 1u);
  EXPECT_EQ(split.raw_axes()[0], v[0]);
}

TEST(SpaceMouseReports, NormalizationUsesTheDescriptorsRangeNotAnAssumed350) {
  // No report ids; six 10-bit axes 0..1023 (centre 511.5) then 4 bits of padding.
  const Bytes desc = {0x05, 0x01, 0x09, 0x08, 0xA1, 0x01, 0x15, 0x00, 0x26, 0xFF, 0x03, 0x09,
                      0x30, 0x09, 0x31, 0x09, 0x32, 0x09, 0x33, 0x09, 0x34, 0x09, 0x35, 0x75,
                      0x0A, 0x95, 0x06, 0x81, 0x02, 0x75, 0x04, 0x95, 0x01, 0x81, 0x03, 0xC0};
  const HidReportDescriptor d = ParseHidReportDescriptor(desc);
  ASSERT_TRUE(d.complete) << d.problem;
  EXPECT_FALSE(d.uses_report_ids);
  ASSERT_EQ(d.input_reports.at(0).payload_bytes(), 8u);
  SpaceMouseAxisMap identity;
  identity.sign = {1, 1, 1, 1, 1, 1};
  SpaceMouseReportParser parser(d, identity);
  const std::vector<std::int64_t> raw = {1023, 0, 511, 767, 256, 600};
  Bytes report = PackBits(
      {{raw[0], 10}, {raw[1], 10}, {raw[2], 10}, {raw[3], 10}, {raw[4], 10}, {raw[5], 10}, {0, 4}});
  ASSERT_TRUE(parser.Feed(report, 1));
  for (int i = 0; i < 6; ++i) {
    EXPECT_EQ(parser.raw_axes()[i], raw[i]);
    EXPECT_DOUBLE_EQ(parser.sample().axes[i], (static_cast<double>(raw[i]) - 511.5) / 511.5);
  }
}

TEST(SpaceMouseReports, UnknownIdsAndWrongLengthsAreCountedAndDropped) {
  REQUIRE_SPACEMOUSE_DATA();
  SpaceMouseReportParser parser(
      ParseHidReportDescriptor(Descriptor("SpaceNavigator_046d_c626_rdesc_217.bin")));
  EXPECT_TRUE(parser.Feed(Bytes{0x01, 0x76, 0x00, 0x00, 0x00, 0xfa, 0xff}, 1));
  EXPECT_FALSE(parser.Feed(Bytes{0x09, 0x00, 0x00}, 2));        // no such report
  EXPECT_FALSE(parser.Feed(Bytes{0x17, 0x64, 0x01}, 3));        // the Wireless's battery report
  EXPECT_FALSE(parser.Feed(Bytes{0x05, 0x00}, 4));              // a feature report id
  EXPECT_FALSE(parser.Feed(Bytes{0x01, 0x76, 0x00}, 5));        // short
  EXPECT_FALSE(parser.Feed(Bytes{0x03, 0x01, 0x00, 0x00}, 6));  // long
  EXPECT_FALSE(parser.Feed(Bytes{}, 7));                        // empty
  const SpaceMouseReportCounts& c = parser.sample().counts;
  EXPECT_EQ(c.accepted, 1u);
  EXPECT_EQ(c.unknown_report_id, 3u);
  EXPECT_EQ(c.wrong_length, 3u);
  EXPECT_EQ(parser.raw_axes()[0], 118);  // the dropped reports changed nothing
  EXPECT_EQ(parser.sample().axis_time_ns[kTx], 1);
  EXPECT_EQ(parser.sample().buttons, 0u);
}

TEST(SpaceMouseReports, BuiltInDescriptorAcceptsLongerButtonReports) {
  SpaceMouseReportParser parser(
      ParseHidReportDescriptor(BuiltInSpaceMouseDescriptor(SpaceMouseReportStyle::kSixAxis)), {},
      /*accept_longer_reports=*/true);
  // A SpaceMouse Pro style button report: 4 bytes; the built-in one knows the first 16 buttons.
  EXPECT_TRUE(parser.Feed(Bytes{0x03, 0x01, 0x80, 0xFF, 0xFF}, 1));
  EXPECT_EQ(parser.sample().buttons, (1u << 0) | (1u << 15));
  EXPECT_FALSE(parser.Feed(Bytes{0x03, 0x01}, 2));  // shorter is still dropped
  EXPECT_EQ(parser.sample().counts.wrong_length, 1u);
}

TEST(SpaceMouseReports, ADescriptorWithoutSixAxesIsRejectedByName) {
  // X, Y, Z only.
  const Bytes desc = {0x05, 0x01, 0x16, 0xA2, 0xFE, 0x26, 0x5E, 0x01, 0x09, 0x30,
                      0x09, 0x31, 0x09, 0x32, 0x75, 0x10, 0x95, 0x03, 0x81, 0x02};
  try {
    SpaceMouseReportParser parser(ParseHidReportDescriptor(desc));
    FAIL() << "expected std::invalid_argument";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("no Rx axis"), std::string::npos) << e.what();
  }
  SpaceMouseAxisMap bad;
  bad.source = {0, 0, 2, 3, 4, 5};
  const HidReportDescriptor split =
      ParseHidReportDescriptor(BuiltInSpaceMouseDescriptor(SpaceMouseReportStyle::kSplit));
  EXPECT_THROW((SpaceMouseReportParser{split, bad}), std::invalid_argument);
}

// ---- 3. device table --------------------------------------------------------------------------

TEST(SpaceMouseTable, MatchesSpacenavdsTableRowForRow) {
  REQUIRE_SPACEMOUSE_DATA();
  std::set<std::pair<unsigned, unsigned>> seen;
  for (const auto& row : ReadCsv(SpaceMouseDataDir() / "spacenavd_usb_device_table.csv")) {
    ASSERT_GE(row.size(), 7u);
    const auto vid = static_cast<std::uint16_t>(std::stoul(row[0], nullptr, 16));
    const auto pid = static_cast<std::uint16_t>(std::stoul(row[1], nullptr, 16));
    const SpaceMouseModel* m = FindSpaceMouseModel(vid, pid);
    ASSERT_NE(m, nullptr) << row[0] << ":" << row[1];
    EXPECT_EQ(m->name, row[2]);
    EXPECT_EQ(m->six_dof, row[6] == "yes") << row[2];
    EXPECT_EQ(m->style == SpaceMouseReportStyle::kNone, !m->six_dof) << row[2];
    seen.insert({vid, pid});
  }
  EXPECT_EQ(seen.size(), 33u);
  // The table has each VID/PID once; the only extra row is PySpaceMouse's Universal Receiver.
  std::set<std::pair<unsigned, unsigned>> table;
  for (const SpaceMouseModel& m : kSpaceMouseModels) {
    EXPECT_TRUE(table.insert({m.vendor_id, m.product_id}).second) << m.name;
    if (!seen.count({m.vendor_id, m.product_id})) {
      EXPECT_EQ(m.product_id, 0xc652);
    }
  }
}

TEST(SpaceMouseTable, ReportStylesAgreeWithPySpaceMouseDevices) {
  REQUIRE_SPACEMOUSE_DATA();
  // [Name] … hid_id = [0xVID, 0xPID] … mappings.pitch = [channel, …]: channel 2 = split, 1 = six.
  std::ifstream in(SpaceMouseDataDir() / "pyspacemouse_devices.toml");
  ASSERT_TRUE(in);
  const std::regex hid_re(R"(hid_id = \[0x([0-9A-Fa-f]+), 0x([0-9A-Fa-f]+)\])");
  const std::regex pitch_re(R"(mappings\.pitch\s*=\s*\[(\d+),)");
  std::string line;
  unsigned vid = 0, pid = 0;
  int compared = 0;
  while (std::getline(in, line)) {
    std::smatch m;
    if (std::regex_search(line, m, hid_re)) {
      vid = static_cast<unsigned>(std::stoul(m[1].str(), nullptr, 16));
      pid = static_cast<unsigned>(std::stoul(m[2].str(), nullptr, 16));
    } else if (std::regex_search(line, m, pitch_re)) {
      const SpaceMouseModel* model =
          FindSpaceMouseModel(static_cast<std::uint16_t>(vid), static_cast<std::uint16_t>(pid));
      ASSERT_NE(model, nullptr) << std::hex << vid << ":" << pid;
      if (!model->six_dof) continue;  // 256f:c641, blacklisted by spacenavd (see the header)
      EXPECT_TRUE(model->style_listed) << model->name;
      EXPECT_EQ(model->style,
                m[1].str() == "2" ? SpaceMouseReportStyle::kSplit : SpaceMouseReportStyle::kSixAxis)
          << model->name;
      ++compared;
    }
  }
  EXPECT_EQ(compared, 12);
}

TEST(SpaceMouseTable, UdevRulesCoverEverySixDofModel) {
  const fs::path rules = "deploy/udev/70-haptic-spacemouse.rules";
  if (!fs::exists(rules)) GTEST_SKIP() << rules << " not found (run from the project root)";
  std::ifstream in(rules);
  std::stringstream ss;
  ss << in.rdbuf();
  const std::string text = ss.str();
  for (const SpaceMouseModel& m : kSpaceMouseModels) {
    char key[32];
    std::snprintf(key, sizeof key, "*:%04X:%04X.*", static_cast<unsigned>(m.vendor_id),
                  static_cast<unsigned>(m.product_id));
    EXPECT_EQ(text.find(key) != std::string::npos, m.six_dof) << m.name << " " << key;
  }
}

// ---- 4. shaping and mapping -------------------------------------------------------------------

constexpr std::int64_t kMs = 1'000'000;

SpaceMouseSample SampleWith(int axis, double value, std::int64_t t_ns) {
  SpaceMouseSample s;
  s.axes[axis] = value;
  s.axis_time_ns[axis] = t_ns;
  return s;
}

TEST(SpaceMouseShaping, DeadZoneZeroesSmallDeflectionsAndStaysContinuous) {
  EXPECT_EQ(ApplySpaceMouseDeadZone(0.049, 0.05), 0.0);
  EXPECT_EQ(ApplySpaceMouseDeadZone(-0.05, 0.05), 0.0);
  EXPECT_DOUBLE_EQ(ApplySpaceMouseDeadZone(1.0, 0.05), 1.0);
  EXPECT_DOUBLE_EQ(ApplySpaceMouseDeadZone(-1.0, 0.05), -1.0);
  EXPECT_NEAR(ApplySpaceMouseDeadZone(0.05 + 1e-9, 0.05), 0.0, 1e-8);
  EXPECT_DOUBLE_EQ(ApplySpaceMouseDeadZone(0.525, 0.05), 0.5);
  EXPECT_DOUBLE_EQ(ApplySpaceMouseDeadZone(-0.3, 0.05), -ApplySpaceMouseDeadZone(0.3, 0.05));
  EXPECT_EQ(ApplySpaceMouseDeadZone(std::nan(""), 0.05), 0.0);
  // Through the report parser with the default 5 %: 10/350 = 2.9 % reads 0; 175/350 reads
  // (0.5 - 0.05) / 0.95.
  SpaceMouseReportParser parser(
      ParseHidReportDescriptor(BuiltInSpaceMouseDescriptor(SpaceMouseReportStyle::kSplit)));
  ASSERT_TRUE(parser.Feed(Report16(1, {10, 0, 0}), kMs));
  const SpaceMouseConfig config;
  EXPECT_EQ(ShapeSpaceMouseAxes(parser.sample(), kMs, config)[kTx], 0.0);
  ASSERT_TRUE(parser.Feed(Report16(1, {175, 0, 0}), kMs));
  EXPECT_DOUBLE_EQ(ShapeSpaceMouseAxes(parser.sample(), kMs, config)[kTx], 0.45 / 0.95);
}

TEST(SpaceMouseShaping, StaleAxesHoldThenDecayToZero) {
  SpaceMouseConfig config;
  config.dead_zone = 0.0;
  config.hold_s = 0.5;
  config.decay_s = 0.2;
  SpaceMouseReportParser parser(
      ParseHidReportDescriptor(BuiltInSpaceMouseDescriptor(SpaceMouseReportStyle::kSplit)));
  const std::int64_t t0 = 1000 * kMs;
  ASSERT_TRUE(parser.Feed(Report16(1, {350, 0, 0}), t0));               // translation at t0
  ASSERT_TRUE(parser.Feed(Report16(2, {0, 0, -350}), t0 + 300 * kMs));  // rotation 0.3 s later
  auto at = [&](std::int64_t dt_ms) {
    return ShapeSpaceMouseAxes(parser.sample(), t0 + dt_ms * kMs, config);
  };
  EXPECT_DOUBLE_EQ(at(0)[kTx], 1.0);
  EXPECT_DOUBLE_EQ(at(500)[kTx], 1.0);    // end of the hold
  EXPECT_NEAR(at(600)[kTx], 0.5, 1e-12);  // half way down the ramp
  EXPECT_EQ(at(700)[kTx], 0.0);           // decayed
  EXPECT_EQ(at(5000)[kTx], 0.0);
  EXPECT_DOUBLE_EQ(at(700)[kRz], 1.0);  // rotation is younger: still held (D→M: -rz)
  EXPECT_NEAR(at(900)[kRz], 0.5, 1e-12);
  // A fresh report restores the axis at once.
  ASSERT_TRUE(parser.Feed(Report16(1, {175, 0, 0}), t0 + 5000 * kMs));
  EXPECT_DOUBLE_EQ(at(5000)[kTx], 0.5);
  EXPECT_EQ(SpaceMouseStalenessGain(0.6, 0.5, 0.0), 0.0);
  // Never-set axes read 0 whatever their stored value.
  SpaceMouseSample never;
  never.axes[kTy] = 1.0;
  EXPECT_EQ(ShapeSpaceMouseAxes(never, t0, config)[kTy], 0.0);
}

SpaceMouseConfig RateConfig() {
  SpaceMouseConfig c;
  c.dead_zone = 0.0;
  c.v_max_m_per_s = 0.2;
  c.w_max_rad_per_s = 1.0;
  c.workspace_half_extents_m = {0.1, 0.05, 0.1};
  c.max_rotation_rad = 0.5;
  return c;
}

// Drives a mapper with a deflection that is refreshed at every step, through `times_ns`.
DeviceState RunMapper(SpaceMousePoseMapper& mapper, int axis, double value,
                      const std::vector<std::int64_t>& times_ns) {
  DeviceState state;
  for (std::int64_t t : times_ns) mapper.Step(SampleWith(axis, value, t), t, state);
  return state;
}

TEST(SpaceMouseMapping, RateControlIntegratesWithTheRealDt) {
  const SpaceMouseConfig config = RateConfig();
  const std::int64_t t0 = 5000 * kMs;
  const std::int64_t t_end = t0 + 300 * kMs;
  std::vector<std::int64_t> uniform;
  for (std::int64_t t = t0; t <= t_end; t += kMs) uniform.push_back(t);
  std::vector<std::int64_t> irregular{t0};
  std::mt19937 rng(7);
  std::uniform_int_distribution<std::int64_t> step(100'000, 20 * kMs);
  while (irregular.back() < t_end)
    irregular.push_back(std::min(t_end, irregular.back() + step(rng)));
  SpaceMousePoseMapper a(config);
  SpaceMousePoseMapper b(config);
  const DeviceState sa = RunMapper(a, kTx, 0.5, uniform);
  const DeviceState sb = RunMapper(b, kTx, 0.5, irregular);
  // x = v_max * d * T = 0.2 * 0.5 * 0.3 s whatever the step pattern.
  EXPECT_NEAR(sa.X_MH.translation.x, 0.03, 1e-12);
  EXPECT_NEAR(sb.X_MH.translation.x, 0.03, 1e-12);
  EXPECT_NEAR(sa.V_MH_M.linear.x, 0.1, 1e-9);
  EXPECT_NEAR(sb.V_MH_M.linear.x, 0.1, 1e-9);
  EXPECT_EQ(sa.X_MH.translation.y, 0.0);
  EXPECT_EQ(sa.timestamp_ns, t_end);
  // Rotation: w = 1 rad/s * 0.5 about z for 0.3 s → rotation vector (0, 0, 0.15).
  SpaceMousePoseMapper r(config);
  const DeviceState sr = RunMapper(r, kRz, 0.5, uniform);
  const glm::dvec3 theta = RotationVectorFromQuaternion(sr.X_MH.rotation);
  EXPECT_NEAR(theta.z, 0.15, 1e-9);
  EXPECT_NEAR(glm::length(theta), 0.15, 1e-9);
  EXPECT_NEAR(sr.V_MH_M.angular.z, 0.5, 1e-6);
}

TEST(SpaceMouseMapping, RateControlIsClampedToTheWorkspaceAndRotationLimit) {
  const SpaceMouseConfig config = RateConfig();
  std::vector<std::int64_t> times;
  for (std::int64_t t = kMs; t <= 3000 * kMs; t += kMs) times.push_back(t);
  SpaceMousePoseMapper up(config);
  DeviceState s = RunMapper(up, kTy, 1.0, times);  // 0.2 m/s for 3 s ≫ 0.05 m
  EXPECT_EQ(s.X_MH.translation.y, 0.05);
  EXPECT_EQ(s.V_MH_M.linear.y, 0.0);  // clamped: it does not move any more
  SpaceMousePoseMapper down(config);
  s = RunMapper(down, kTz, -1.0, times);
  EXPECT_EQ(s.X_MH.translation.z, -0.1);
  SpaceMousePoseMapper tilt(config);
  s = RunMapper(tilt, kRx, 1.0, times);  // 1 rad/s for 3 s ≫ 0.5 rad
  EXPECT_NEAR(glm::length(RotationVectorFromQuaternion(s.X_MH.rotation)), 0.5, 1e-9);
  EXPECT_NEAR(glm::length(s.V_MH_M.angular), 0.0, 1e-9);
  // A stall integrates at most max_step_s (0.05 s): 0.2 * 0.05 = 0.01 m.
  SpaceMousePoseMapper stall(config);
  s = RunMapper(stall, kTx, 1.0, {kMs, kMs + 1000 * kMs});
  EXPECT_NEAR(s.X_MH.translation.x, 0.01, 1e-15);
  // Time going backwards integrates nothing.
  const double x = s.X_MH.translation.x;
  stall.Step(SampleWith(kTx, 1.0, kMs), kMs, s);
  EXPECT_EQ(s.X_MH.translation.x, x);
}

TEST(SpaceMouseMapping, PositionControlMapsDeflectionToAnOffsetFromTheCentre) {
  SpaceMouseConfig config = RateConfig();
  config.mode = SpaceMouseControlMode::kPosition;
  SpaceMousePoseMapper mapper(config);
  DeviceState s;
  SpaceMouseSample sample;
  sample.axes = {0.5, -1.0, 0.25, 0.0, 0.0, 1.0};
  sample.axis_time_ns.fill(kMs);
  mapper.Step(sample, kMs, s);
  EXPECT_DOUBLE_EQ(s.X_MH.translation.x, 0.05);
  EXPECT_DOUBLE_EQ(s.X_MH.translation.y, -0.05);
  EXPECT_DOUBLE_EQ(s.X_MH.translation.z, 0.025);
  EXPECT_NEAR(RotationVectorFromQuaternion(s.X_MH.rotation).z, 0.5, 1e-12);
  // Released (the all-zero report): back to the centre, with the velocity of that return.
  sample.axes = {};
  sample.axis_time_ns.fill(11 * kMs);
  mapper.Step(sample, 11 * kMs, s);
  EXPECT_EQ(s.X_MH.translation, glm::dvec3(0.0));
  EXPECT_NEAR(s.V_MH_M.linear.x, -0.05 / 0.01, 1e-9);
}

TEST(SpaceMouseMapping, ConfigValidationNamesTheBadValue) {
  auto message = [](SpaceMouseConfig c) -> std::string {
    try {
      ValidateSpaceMouseConfig(c);
    } catch (const std::invalid_argument& e) {
      return e.what();
    }
    return "";
  };
  SpaceMouseConfig c;
  EXPECT_EQ(message(c), "");
  c.dead_zone = 1.0;
  EXPECT_NE(message(c).find("dead_zone"), std::string::npos);
  c = {};
  c.v_max_m_per_s = std::nan("");
  EXPECT_NE(message(c).find("v_max_m_per_s"), std::string::npos);
  c = {};
  c.workspace_half_extents_m.y = 0.0;
  EXPECT_NE(message(c).find("workspace_half_extents_m"), std::string::npos);
  c = {};
  c.max_rotation_rad = 4.0;
  EXPECT_NE(message(c).find("max_rotation_rad"), std::string::npos);
  EXPECT_THROW(SpaceMouseDevice{c}, std::invalid_argument);
}

// ---- 5. the device ----------------------------------------------------------------------------

TEST(SpaceMouseOpen, IsAnInputOnlyDevice) {
  SpaceMouseConfig config;
  config.workspace_half_extents_m = {0.2, 0.1, 0.05};
  SpaceMouseDevice device(config);
  const DeviceCapabilities c = device.capabilities();
  EXPECT_EQ(c.dof_in, 6);
  EXPECT_EQ(c.dof_out, 0);
  EXPECT_EQ(c.max_force_n, 0.0);
  EXPECT_EQ(c.max_torque_nm, 0.0);
  EXPECT_EQ(c.max_stiffness_n_per_m, 0.0);
  EXPECT_EQ(c.workspace_half_extents_m, config.workspace_half_extents_m);
  DeviceState state;
  EXPECT_FALSE(device.ReadState(1, state));                                // not open
  EXPECT_TRUE(device.WriteWrench({{1.0, 2.0, 3.0}, {0.1, 0.2, 0.3}}, 1));  // accepted, ignored
  device.Close();                                                          // harmless
}

TEST(SpaceMouseOpen, OpenWithoutADeviceThrowsAClearMessage) {
  SpaceMouseDevice device;
  try {
    device.Open();
  } catch (const std::runtime_error& e) {
    const std::string what = e.what();
    // Either nothing is plugged in, or something is but hidraw does not let us open it.
    const bool none = what.find("no 3Dconnexion device found (looked for 046d:c603") == 0;
    const bool denied = what.find("could not open") != std::string::npos;
    EXPECT_TRUE(none || denied) << what;
    if (none) {
      EXPECT_NE(what.find("256f:c652"), std::string::npos) << what;
      EXPECT_EQ(what.find("256f:c650"), std::string::npos) << what;  // CadMouse: not 6-DoF
    }
    EXPECT_NE(what.find("/dev/hidraw"), std::string::npos) << what;
    EXPECT_NE(what.find("deploy/udev/70-haptic-spacemouse.rules"), std::string::npos) << what;
    return;
  }
  device.Close();
  GTEST_SKIP() << "a 3Dconnexion device is present and opened (" << device.model_name()
               << "); the no-device message cannot be checked here";
}

TEST(SpaceMouseOpen, OpenWithAMissingPathNamesThePath) {
  SpaceMouseConfig config;
  config.path = "/dev/hidraw-does-not-exist";
  SpaceMouseDevice device(config);
  try {
    device.Open();
    FAIL() << "expected std::runtime_error";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("/dev/hidraw-does-not-exist"), std::string::npos)
        << e.what();
    EXPECT_NE(std::string(e.what()).find("deploy/udev"), std::string::npos) << e.what();
  }
  DeviceState state;
  EXPECT_FALSE(device.ReadState(1, state));
}

// ---- fuzz-ish ---------------------------------------------------------------------------------

TEST(SpaceMouseFuzz, RandomDescriptorsNeverCrashTheParser) {
  std::mt19937 rng(12345);
  std::uniform_int_distribution<int> byte(0, 255);
  std::uniform_int_distribution<int> len(0, 320);
  std::vector<Bytes> seeds = {
      Bytes(BuiltInSpaceMouseDescriptor(SpaceMouseReportStyle::kSplit).begin(),
            BuiltInSpaceMouseDescriptor(SpaceMouseReportStyle::kSplit).end()),
      Bytes(BuiltInSpaceMouseDescriptor(SpaceMouseReportStyle::kSixAxis).begin(),
            BuiltInSpaceMouseDescriptor(SpaceMouseReportStyle::kSixAxis).end())};
  if (fs::is_directory(SpaceMouseDataDir())) {
    seeds.push_back(Descriptor("SpaceNavigator_046d_c626_rdesc_217.bin"));
    seeds.push_back(Descriptor("SpaceMouseWireless_256f_c62e_rdesc_270.bin"));
  }
  int parsers_built = 0;
  for (int iter = 0; iter < 20000; ++iter) {
    Bytes d;
    if (iter % 2 == 0) {  // pure noise
      d.resize(static_cast<std::size_t>(len(rng)));
      for (auto& b : d) b = static_cast<std::uint8_t>(byte(rng));
    } else {  // a real descriptor with a few bytes changed and maybe cut
      d = seeds[static_cast<std::size_t>(iter) % seeds.size()];
      const int flips = 1 + byte(rng) % 4;
      for (int k = 0; k < flips; ++k) {
        d[static_cast<std::size_t>(byte(rng) * 7919) % d.size()] =
            static_cast<std::uint8_t>(byte(rng));
      }
      if (byte(rng) < 64) d.resize(static_cast<std::size_t>(byte(rng)) % (d.size() + 1));
    }
    const HidReportDescriptor parsed = ParseHidReportDescriptor(d);
    EXPECT_LE(parsed.bytes_parsed, d.size());
    EXPECT_EQ(parsed.complete, parsed.problem.empty());
    ExpectFieldsInside(parsed);
    try {
      SpaceMouseReportParser parser(parsed);
      ++parsers_built;
      for (int k = 0; k < 20; ++k) {
        Bytes r(static_cast<std::size_t>(byte(rng) % 16));
        for (auto& b : r) b = static_cast<std::uint8_t>(byte(rng));
        parser.Feed(r, k + 1);
        for (double a : parser.sample().axes) EXPECT_TRUE(a >= -1.0 && a <= 1.0);
      }
    } catch (const std::invalid_argument&) {
      // not six axes: rejected by name, which is the point
    }
  }
  EXPECT_GT(parsers_built, 0);
}

TEST(SpaceMouseFuzz, RandomReportsNeverCrashTheReportParser) {
  REQUIRE_SPACEMOUSE_DATA();
  std::mt19937 rng(99);
  std::uniform_int_distribution<int> byte(0, 255);
  for (const HidReportDescriptor& d :
       {ParseHidReportDescriptor(Descriptor("SpaceNavigator_046d_c626_rdesc_217.bin")),
        ParseHidReportDescriptor(Descriptor("SpaceMouseWireless_256f_c62e_rdesc_270.bin")),
        ParseHidReportDescriptor(ReadHexFile(
            SpaceMouseDataDir() / "SpaceMouseEnterprise_256f_c633_rdesc_TRUNCATED.hex"))}) {
    SpaceMouseReportParser parser(d);
    std::uint64_t fed = 0;
    for (int k = 0; k < 50000; ++k) {
      Bytes r(static_cast<std::size_t>(byte(rng) % 20));
      for (auto& b : r) b = static_cast<std::uint8_t>(byte(rng));
      if (!r.empty() && k % 2 == 0) r[0] = static_cast<std::uint8_t>(1 + k % 3);  // real ids
      parser.Feed(r, k + 1);
      ++fed;
      for (double a : parser.sample().axes) ASSERT_TRUE(a >= -1.0 && a <= 1.0);
    }
    const SpaceMouseReportCounts& c = parser.sample().counts;
    EXPECT_EQ(c.accepted + c.unknown_report_id + c.wrong_length, fed);
    EXPECT_GT(c.accepted, 0u);
  }
}

}  // namespace
}  // namespace ht
