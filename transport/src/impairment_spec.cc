// The impairment spec (transport/impairment_spec.h): parsing the "delay=75ms,loss=10%" text,
// checking the ranges, and printing the canonical form back.

#include "transport/impairment_spec.h"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <limits>
#include <stdexcept>
#include <string_view>
#include <vector>

#include "impairment_internal.h"

namespace ht {
namespace {

using impairment_internal::kNsPerMs;
using impairment_internal::kNsPerS;
using impairment_internal::kNsPerUs;

constexpr double kMaxTimeS = 3600.0;  // longest delay, jitter or reorder gap accepted
constexpr std::size_t kMaxLimitPackets = 1'000'000;
constexpr double kMaxBurstPackets = 1e9;
constexpr std::int64_t kDefaultReorderGapNs = 5 * kNsPerMs;

constexpr const char* kTimeForm = "a time like 50ms (units us, ms, s; a bare number is ms)";
constexpr const char* kFractionForm = "a percentage like 5% (0..100%) or a fraction 0..1";
constexpr const char* kRateForm =
    "a rate like 20mbit (units bit, kbit, mbit, gbit per second; a bare number is bit/s), > 0";

// ---------------------------------------------------------------------------------------------
// Spec parsing and printing.

std::string_view Trim(std::string_view s) {
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.front()))) s.remove_prefix(1);
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.back()))) s.remove_suffix(1);
  return s;
}

std::string Lower(std::string_view s) {
  std::string out(s);
  for (char& c : out) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return out;
}

[[noreturn]] void ThrowBad(std::string_view key, std::string_view value, const std::string& why,
                           const char* form) {
  throw std::invalid_argument("impairment spec: " + std::string(key) + "='" + std::string(value) +
                              "': " + why + "; expected " + form);
}

// A finite number followed by an optional unit (the rest of the text).
struct NumberAndUnit {
  double number = 0.0;
  std::string unit;  // lower case
};

NumberAndUnit SplitNumber(std::string_view key, std::string_view value, const char* form) {
  NumberAndUnit out;
  const char* begin = value.data();
  const char* end = value.data() + value.size();
  const auto [ptr, ec] = std::from_chars(begin, end, out.number);
  if (ec != std::errc() || value.empty()) ThrowBad(key, value, "not a number", form);
  if (!std::isfinite(out.number)) ThrowBad(key, value, "not a finite number", form);
  out.unit = Lower(Trim(std::string_view(ptr, static_cast<std::size_t>(end - ptr))));
  return out;
}

std::int64_t ParseTimeNs(std::string_view key, std::string_view value) {
  const NumberAndUnit nu = SplitNumber(key, value, kTimeForm);
  double scale_ns = 0.0;
  if (nu.unit.empty() || nu.unit == "ms") {
    scale_ns = static_cast<double>(kNsPerMs);
  } else if (nu.unit == "us") {
    scale_ns = static_cast<double>(kNsPerUs);
  } else if (nu.unit == "s") {
    scale_ns = static_cast<double>(kNsPerS);
  } else {
    ThrowBad(key, value, "bad unit '" + nu.unit + "'", kTimeForm);
  }
  const double ns = nu.number * scale_ns;
  if (!(ns >= 0.0) || ns > kMaxTimeS * static_cast<double>(kNsPerS)) {
    ThrowBad(key, value, "out of range 0..3600s", kTimeForm);
  }
  return std::llround(ns);
}

double ParseFraction(std::string_view key, std::string_view value) {
  const NumberAndUnit nu = SplitNumber(key, value, kFractionForm);
  double fraction = 0.0;
  if (nu.unit == "%") {
    fraction = nu.number / 100.0;
  } else if (nu.unit.empty()) {
    fraction = nu.number;
  } else {
    ThrowBad(key, value, "bad unit '" + nu.unit + "'", kFractionForm);
  }
  if (!(fraction >= 0.0 && fraction <= 1.0)) ThrowBad(key, value, "out of range", kFractionForm);
  return fraction;
}

double ParseRateBps(std::string_view key, std::string_view value) {
  const NumberAndUnit nu = SplitNumber(key, value, kRateForm);
  double scale = 0.0;
  if (nu.unit.empty() || nu.unit == "bit") {
    scale = 1.0;
  } else if (nu.unit == "kbit") {
    scale = 1e3;
  } else if (nu.unit == "mbit") {
    scale = 1e6;
  } else if (nu.unit == "gbit") {
    scale = 1e9;
  } else {
    ThrowBad(key, value, "bad unit '" + nu.unit + "'", kRateForm);
  }
  const double bps = nu.number * scale;
  if (!(bps > 0.0) || !std::isfinite(bps)) ThrowBad(key, value, "out of range", kRateForm);
  return bps;
}

template <typename Int>
Int ParseInteger(std::string_view key, std::string_view value, Int min, Int max, const char* form) {
  Int out{};
  const auto [ptr, ec] = std::from_chars(value.data(), value.data() + value.size(), out);
  if (ec == std::errc::result_out_of_range) ThrowBad(key, value, "out of range", form);
  if (ec != std::errc() || value.empty() || ptr != value.data() + value.size()) {
    ThrowBad(key, value, "not an integer", form);
  }
  if (out < min || out > max) ThrowBad(key, value, "out of range", form);
  return out;
}

std::string Shortest(double v) {
  char buf[64];
  const auto [ptr, ec] = std::to_chars(buf, buf + sizeof(buf), v);
  return ec == std::errc() ? std::string(buf, ptr) : std::to_string(v);
}

std::string FormatTime(std::int64_t ns) {
  if (ns % kNsPerS == 0 && ns != 0) return std::to_string(ns / kNsPerS) + "s";
  if (ns % kNsPerMs == 0) return std::to_string(ns / kNsPerMs) + "ms";
  if (ns % kNsPerUs == 0) return std::to_string(ns / kNsPerUs) + "us";
  char buf[48];
  std::snprintf(buf, sizeof(buf), "%lld.%03lldus", static_cast<long long>(ns / kNsPerUs),
                static_cast<long long>(ns % kNsPerUs));
  return buf;
}

std::string FormatFraction(std::string_view key, double fraction) {
  const std::string percent = Shortest(fraction * 100.0) + "%";
  if (ParseFraction(key, percent) == fraction) return percent;
  return Shortest(fraction);
}

std::string FormatRate(double bps) {
  if (bps == std::floor(bps) && bps < 9e15) {
    const auto bits = static_cast<std::int64_t>(bps);
    if (bits % 1'000'000'000 == 0) return std::to_string(bits / 1'000'000'000) + "gbit";
    if (bits % 1'000'000 == 0) return std::to_string(bits / 1'000'000) + "mbit";
    if (bits % 1'000 == 0) return std::to_string(bits / 1'000) + "kbit";
    return std::to_string(bits) + "bit";
  }
  return Shortest(bps) + "bit";
}

}  // namespace

namespace impairment_internal {

void Validate(const ImpairmentSpec& s) {
  auto bad = [](const std::string& what) {
    throw std::invalid_argument("impairment spec: " + what);
  };
  const std::int64_t max_ns = static_cast<std::int64_t>(kMaxTimeS) * kNsPerS;
  if (s.delay_ns < 0 || s.delay_ns > max_ns) bad("delay out of range 0..3600s");
  if (s.jitter_ns < 0 || s.jitter_ns > max_ns) bad("jitter out of range 0..3600s");
  if (s.reorder_gap_ns < 0 || s.reorder_gap_ns > max_ns) bad("reorder-gap out of range 0..3600s");
  if (!(s.loss >= 0.0 && s.loss <= 1.0)) bad("loss out of range 0..1");
  if (!(s.reorder >= 0.0 && s.reorder <= 1.0)) bad("reorder out of range 0..1");
  if (!(s.dup >= 0.0 && s.dup <= 1.0)) bad("dup out of range 0..1");
  if (!(s.rate_bps >= 0.0) || !std::isfinite(s.rate_bps)) bad("rate must be > 0 (or 0: none)");
  if (s.limit_packets < 1 || s.limit_packets > kMaxLimitPackets) {
    bad("limit out of range 1..1000000");
  }
  if (s.burst_packets != 0.0) {
    if (!(s.burst_packets >= 1.0 && s.burst_packets <= kMaxBurstPackets)) {
      bad("burst must be a mean burst length >= 1 packet");
    }
    if (!(s.loss < 1.0)) bad("loss must be below 100% with burst (Gilbert-Elliott loss)");
    const double r = 1.0 / s.burst_packets;
    const double p = s.loss * r / (1.0 - s.loss);
    if (p > 1.0) {
      char text[200];
      std::snprintf(text, sizeof(text),
                    "loss=%g%% with burst=%g needs p(Good->Bad) = %g > 1; with burst=B, loss must "
                    "be at most B/(B+1) = %g%%",
                    s.loss * 100.0, s.burst_packets, p,
                    100.0 * s.burst_packets / (s.burst_packets + 1.0));
      bad(text);
    }
  }
}

}  // namespace impairment_internal

ImpairmentSpec ImpairmentSpec::Parse(const std::string& text) {
  ImpairmentSpec spec;
  const std::string_view all = Trim(text);
  if (all.empty() || all == "none") return spec;
  std::vector<std::string> seen;
  std::size_t pos = 0;
  while (pos <= all.size()) {
    const std::size_t comma = std::min(all.find(',', pos), all.size());
    const std::string_view item = Trim(all.substr(pos, comma - pos));
    pos = comma + 1;
    const std::size_t eq = item.find('=');
    if (eq == std::string_view::npos) {
      throw std::invalid_argument(
          "impairment spec: item '" + std::string(item) +
          "' must be key=value (keys: delay, jitter, loss, burst, reorder, reorder-gap, dup, "
          "rate, limit, seed; or the whole spec 'none')");
    }
    const std::string key(Trim(item.substr(0, eq)));
    const std::string_view value = Trim(item.substr(eq + 1));
    if (std::find(seen.begin(), seen.end(), key) != seen.end()) {
      throw std::invalid_argument("impairment spec: key '" + key + "' given twice");
    }
    seen.push_back(key);
    if (key == "delay") {
      spec.delay_ns = ParseTimeNs(key, value);
    } else if (key == "jitter") {
      spec.jitter_ns = ParseTimeNs(key, value);
    } else if (key == "reorder-gap") {
      spec.reorder_gap_ns = ParseTimeNs(key, value);
    } else if (key == "loss") {
      spec.loss = ParseFraction(key, value);
    } else if (key == "reorder") {
      spec.reorder = ParseFraction(key, value);
    } else if (key == "dup") {
      spec.dup = ParseFraction(key, value);
    } else if (key == "burst") {
      constexpr const char* kBurstForm = "a mean burst length in packets >= 1, like 4";
      const NumberAndUnit nu = SplitNumber(key, value, kBurstForm);
      if (!nu.unit.empty()) ThrowBad(key, value, "bad unit '" + nu.unit + "'", kBurstForm);
      if (!(nu.number >= 1.0 && nu.number <= kMaxBurstPackets)) {
        ThrowBad(key, value, "out of range", kBurstForm);
      }
      spec.burst_packets = nu.number;
    } else if (key == "rate") {
      spec.rate_bps = ParseRateBps(key, value);
    } else if (key == "limit") {
      spec.limit_packets = ParseInteger<std::size_t>(key, value, 1, kMaxLimitPackets,
                                                     "a queue length in packets 1..1000000");
    } else if (key == "seed") {
      spec.seed = ParseInteger<std::uint64_t>(
          key, value, 0, std::numeric_limits<std::uint64_t>::max(), "an unsigned 64-bit integer");
    } else {
      throw std::invalid_argument(
          "impairment spec: unknown key '" + key + "' in '" + std::string(item) +
          "'; expected one of delay, jitter, loss, burst, reorder, reorder-gap, dup, rate, "
          "limit, seed");
    }
  }
  try {
    impairment_internal::Validate(spec);
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(std::string(e.what()) + " (in '" + std::string(all) + "')");
  }
  return spec;
}

std::string ImpairmentSpec::ToString() const {
  if (IsNone()) return "none";
  std::string out;
  auto add = [&out](const std::string& item) {
    if (!out.empty()) out += ',';
    out += item;
  };
  if (delay_ns != 0) add("delay=" + FormatTime(delay_ns));
  if (jitter_ns != 0) add("jitter=" + FormatTime(jitter_ns));
  if (loss != 0.0) add("loss=" + FormatFraction("loss", loss));
  if (burst_packets != 0.0) add("burst=" + Shortest(burst_packets));
  if (reorder != 0.0) add("reorder=" + FormatFraction("reorder", reorder));
  if (reorder_gap_ns != kDefaultReorderGapNs) add("reorder-gap=" + FormatTime(reorder_gap_ns));
  if (dup != 0.0) add("dup=" + FormatFraction("dup", dup));
  if (rate_bps != 0.0) add("rate=" + FormatRate(rate_bps));
  if (limit_packets != ImpairmentSpec{}.limit_packets) {
    add("limit=" + std::to_string(limit_packets));
  }
  add("seed=" + std::to_string(seed));
  return out;
}

bool ImpairmentSpec::IsNone() const noexcept {
  return delay_ns == 0 && jitter_ns == 0 && loss == 0.0 && reorder == 0.0 && dup == 0.0 &&
         rate_bps == 0.0;
}

}  // namespace ht
