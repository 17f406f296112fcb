#include "transport/impairment.h"

#include <fcntl.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <limits>
#include <stdexcept>
#include <string_view>

#include "haptic_core/steady_clock.h"
#include "transport/protocol.h"

namespace ht {
namespace {

constexpr std::int64_t kNsPerUs = 1'000;
constexpr std::int64_t kNsPerMs = 1'000'000;
constexpr std::int64_t kNsPerS = 1'000'000'000;
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

// Throws when the spec's fields are outside the ranges Parse accepts, or the loss and burst do
// not make a valid Gilbert–Elliott chain.
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

std::int64_t NowNs() noexcept { return SteadyNowNs(); }

void WriteFileAtomically(const std::string& path, const std::string& text) {
  const std::string tmp = path + ".tmp";
  {
    std::ofstream f(tmp);
    f << text;
    if (!f) throw std::runtime_error("cannot write " + tmp);
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    throw std::runtime_error("cannot rename " + tmp + " to " + path + ": " + std::strerror(errno));
  }
}

}  // namespace

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
    Validate(spec);
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

// ---------------------------------------------------------------------------------------------
// The model.

ImpairmentModel::ImpairmentModel(const ImpairmentSpec& spec) : spec_(spec), rng_(spec.seed) {
  Validate(spec_);
  if (spec_.burst_packets != 0.0) {
    p_bad_to_good_ = 1.0 / spec_.burst_packets;
    p_good_to_bad_ = spec_.loss * p_bad_to_good_ / (1.0 - spec_.loss);
  }
  if (spec_.rate_bps > 0.0) queue_tx_end_ns_.assign(spec_.limit_packets, 0);
}

double ImpairmentModel::Uniform01() noexcept {
  // The top 53 bits of the raw 64-bit output, scaled by 2^-53: exactly representable, in [0, 1).
  return static_cast<double>(rng_() >> 11) * 0x1.0p-53;
}

PacketDecision ImpairmentModel::Decide(std::int64_t arrival_ns, std::size_t size_bytes) noexcept {
  // Always four draws, in this order, whatever the packet's fate.
  const double u_loss = Uniform01();
  const double u_jitter = Uniform01();
  const double u_reorder = Uniform01();
  const double u_dup = Uniform01();

  PacketDecision d;
  bool lost = false;
  if (spec_.burst_packets != 0.0) {
    // Gilbert–Elliott: move the chain one step, then the packet is lost iff the state is Bad.
    if (bad_) {
      if (u_loss < p_bad_to_good_) bad_ = false;
    } else if (u_loss < p_good_to_bad_) {
      bad_ = true;
    }
    lost = bad_;
  } else {
    lost = u_loss < spec_.loss;
  }
  if (lost) {
    d.fate = PacketFate::kDroppedLoss;
    return d;
  }

  std::int64_t tx_end_ns = arrival_ns;
  if (spec_.rate_bps > 0.0) {
    const std::size_t capacity = queue_tx_end_ns_.size();
    while (queue_count_ > 0 && queue_tx_end_ns_[queue_head_] <= arrival_ns) {
      queue_head_ = (queue_head_ + 1) % capacity;
      --queue_count_;
    }
    if (queue_count_ >= capacity) {
      d.fate = PacketFate::kDroppedQueue;
      return d;
    }
    const std::int64_t tx_start_ns = std::max(arrival_ns, link_free_ns_);
    const std::int64_t tx_ns =
        std::llround(static_cast<double>(size_bytes) * 8.0 * 1e9 / spec_.rate_bps);
    tx_end_ns = tx_start_ns + tx_ns;
    link_free_ns_ = tx_end_ns;
    queue_tx_end_ns_[(queue_head_ + queue_count_) % capacity] = tx_end_ns;
    ++queue_count_;
  }

  std::int64_t delay_ns = spec_.delay_ns;
  if (spec_.jitter_ns > 0) {
    // Uniform over the 2J + 1 integers in [-J, +J].
    const std::int64_t span = 2 * spec_.jitter_ns + 1;
    auto k = static_cast<std::int64_t>(u_jitter * static_cast<double>(span));
    k = std::min(k, span - 1);
    delay_ns = std::max<std::int64_t>(0, delay_ns + k - spec_.jitter_ns);
  }
  d.reordered = u_reorder < spec_.reorder;
  if (d.reordered) delay_ns += spec_.reorder_gap_ns;
  d.deliver_ns = tx_end_ns + delay_ns;
  d.copies = u_dup < spec_.dup ? 2 : 1;
  return d;
}

// ---------------------------------------------------------------------------------------------
// Classification and statistics.

std::uint8_t ClassifyDatagram(std::span<const std::uint8_t> bytes) noexcept {
  if (bytes.size() < 7) return 0;
  const std::uint32_t magic =
      static_cast<std::uint32_t>(bytes[0]) | static_cast<std::uint32_t>(bytes[1]) << 8 |
      static_cast<std::uint32_t>(bytes[2]) << 16 | static_cast<std::uint32_t>(bytes[3]) << 24;
  if (magic != wire::kMagic) return 0;
  return bytes[6];
}

std::string MessageTypeName(std::uint8_t type) {
  static constexpr const char* kNames[] = {
      "other",  "tool_state", "contact_model", "goodbye",        "hello",      "welcome",
      "reject", "ping",       "pong",          "scene_fragment", "scene_nack", "scene_manifest"};
  if (type < std::size(kNames)) return kNames[type];
  return "type_" + std::to_string(type);
}

nlohmann::json TrafficCounters::ToJson() const {
  return {{"received", received},
          {"dropped_loss", dropped_loss},
          {"dropped_queue", dropped_queue},
          {"dropped_oversize", dropped_oversize},
          {"duplicated", duplicated},
          {"reordered", reordered},
          {"forwarded", forwarded},
          {"send_errors", send_errors},
          {"bytes_in", bytes_in},
          {"bytes_out", bytes_out},
          {"in_flight_at_exit", in_flight_at_exit}};
}

TrafficCounters& TrafficCounters::operator+=(const TrafficCounters& o) noexcept {
  received += o.received;
  dropped_loss += o.dropped_loss;
  dropped_queue += o.dropped_queue;
  dropped_oversize += o.dropped_oversize;
  duplicated += o.duplicated;
  reordered += o.reordered;
  forwarded += o.forwarded;
  send_errors += o.send_errors;
  bytes_in += o.bytes_in;
  bytes_out += o.bytes_out;
  in_flight_at_exit += o.in_flight_at_exit;
  return *this;
}

TrafficCounters DirectionStats::Total() const noexcept {
  TrafficCounters total;
  for (const TrafficCounters& c : by_type) total += c;
  return total;
}

nlohmann::json DirectionStats::ToJson() const {
  nlohmann::json j = Total().ToJson();
  for (std::size_t t = 0; t < by_type.size(); ++t) {
    if (by_type[t].received > 0) {
      j[MessageTypeName(static_cast<std::uint8_t>(t))] = by_type[t].ToJson();
    }
  }
  j["dropped_unknown_source"] = dropped_unknown_source;
  return j;
}

// ---------------------------------------------------------------------------------------------
// The relay.

namespace {

// Room for the largest datagram either side sends, plus one byte to detect longer ones.
constexpr std::size_t kSlotBytes = wire::kMaxDatagramBytes + 1;
// Datagrams taken from one socket before the due ones are sent again (bounds the lateness that
// a flood on one side can cause).
constexpr int kReceiveBatch = 64;
// Longest single wait, so a stop signal that lands just before ppoll is seen soon. Unit: ns.
constexpr std::int64_t kMaxWaitNs = 100 * kNsPerMs;

// A bound, non-blocking UDP socket whose descriptor can be polled together with another one
// (ht::UdpSocket keeps its descriptor private and waits on one socket only).
class PollableUdpSocket {
 public:
  explicit PollableUdpSocket(const SocketAddress& local) {
    fd_ = ::socket(local.storage.ss_family, SOCK_DGRAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
    if (fd_ < 0) throw std::runtime_error(std::string("socket(): ") + std::strerror(errno));
    // Best effort: room for bursts while the relay is busy sending (4 MiB each way).
    const int buffer_bytes = 4 << 20;
    ::setsockopt(fd_, SOL_SOCKET, SO_RCVBUF, &buffer_bytes, sizeof(buffer_bytes));
    ::setsockopt(fd_, SOL_SOCKET, SO_SNDBUF, &buffer_bytes, sizeof(buffer_bytes));
    if (::bind(fd_, reinterpret_cast<const sockaddr*>(&local.storage), local.length) != 0) {
      const std::string why = std::strerror(errno);
      ::close(fd_);
      throw std::runtime_error("cannot bind UDP " + local.ToString() + ": " + why);
    }
  }
  ~PollableUdpSocket() { ::close(fd_); }
  PollableUdpSocket(const PollableUdpSocket&) = delete;
  PollableUdpSocket& operator=(const PollableUdpSocket&) = delete;

  int fd() const noexcept { return fd_; }

  SocketAddress local_address() const {
    SocketAddress a;
    a.length = sizeof(a.storage);
    ::getsockname(fd_, reinterpret_cast<sockaddr*>(&a.storage), &a.length);
    return a;
  }

  // The datagram's full length (MSG_TRUNC), or -1 when none is waiting.
  std::int64_t ReceiveFrom(std::span<std::uint8_t> buffer, SocketAddress& from) noexcept {
    from.length = sizeof(from.storage);
    return ::recvfrom(fd_, buffer.data(), buffer.size(), MSG_DONTWAIT | MSG_TRUNC,
                      reinterpret_cast<sockaddr*>(&from.storage), &from.length);
  }

  bool SendTo(std::span<const std::uint8_t> bytes, const SocketAddress& to) noexcept {
    const ssize_t n = ::sendto(fd_, bytes.data(), bytes.size(), MSG_DONTWAIT,
                               reinterpret_cast<const sockaddr*>(&to.storage), to.length);
    return n == static_cast<ssize_t>(bytes.size());
  }

 private:
  int fd_ = -1;
};

// Same family, host and port (ignores sin6_flowinfo and padding).
bool SameEndpoint(const SocketAddress& a, const SocketAddress& b) noexcept {
  if (a.storage.ss_family != b.storage.ss_family) return false;
  if (a.storage.ss_family == AF_INET) {
    const auto* x = reinterpret_cast<const sockaddr_in*>(&a.storage);
    const auto* y = reinterpret_cast<const sockaddr_in*>(&b.storage);
    return x->sin_port == y->sin_port && x->sin_addr.s_addr == y->sin_addr.s_addr;
  }
  if (a.storage.ss_family == AF_INET6) {
    const auto* x = reinterpret_cast<const sockaddr_in6*>(&a.storage);
    const auto* y = reinterpret_cast<const sockaddr_in6*>(&b.storage);
    return x->sin6_port == y->sin6_port &&
           std::memcmp(&x->sin6_addr, &y->sin6_addr, sizeof(x->sin6_addr)) == 0;
  }
  return a == b;
}

SocketAddress AnyAddressLike(const SocketAddress& peer) {
  return SocketAddress::Parse(peer.storage.ss_family == AF_INET6 ? "[::]:0" : "0.0.0.0:0");
}

// One scheduled datagram.
struct Slot {
  std::int64_t deliver_ns = 0;
  std::uint64_t order = 0;  // arrival order, breaks ties so equal times leave first-in first-out
  std::uint32_t size = 0;
  std::uint8_t copies = 0;  // copies still to send
  std::uint8_t type = 0;    // ClassifyDatagram()
  std::array<std::uint8_t, kSlotBytes> bytes{};
};

// A bounded time-ordered queue: preallocated slots, a free list, and a binary min-heap of slot
// indices on (deliver_ns, order). No allocation after construction.
class ScheduleQueue {
 public:
  explicit ScheduleQueue(std::size_t capacity) : slots_(capacity) {
    free_.reserve(capacity);
    heap_.reserve(capacity);
    for (std::size_t i = capacity; i-- > 0;) free_.push_back(static_cast<std::uint32_t>(i));
  }

  // A free slot's index, or -1 when all are in use. The slot is not queued until Push.
  std::int64_t Acquire() noexcept {
    if (free_.empty()) return -1;
    const std::uint32_t i = free_.back();
    free_.pop_back();
    return i;
  }
  void Release(std::size_t i) noexcept { free_.push_back(static_cast<std::uint32_t>(i)); }
  Slot& slot(std::size_t i) noexcept { return slots_[i]; }

  void Push(std::size_t i) noexcept {
    slots_[i].order = next_order_++;
    heap_.push_back(static_cast<std::uint32_t>(i));
    std::push_heap(heap_.begin(), heap_.end(), Later{&slots_});
  }
  bool empty() const noexcept { return heap_.empty(); }
  std::size_t size() const noexcept { return heap_.size(); }
  Slot& top() noexcept { return slots_[heap_.front()]; }
  const Slot& top() const noexcept { return slots_[heap_.front()]; }
  void Pop() noexcept {
    std::pop_heap(heap_.begin(), heap_.end(), Later{&slots_});
    free_.push_back(heap_.back());
    heap_.pop_back();
  }

 private:
  struct Later {
    const std::vector<Slot>* slots;
    bool operator()(std::uint32_t a, std::uint32_t b) const noexcept {
      const Slot& x = (*slots)[a];
      const Slot& y = (*slots)[b];
      return x.deliver_ns != y.deliver_ns ? x.deliver_ns > y.deliver_ns : x.order > y.order;
    }
  };
  std::vector<Slot> slots_;
  std::vector<std::uint32_t> free_;
  std::vector<std::uint32_t> heap_;
  std::uint64_t next_order_ = 0;
};

struct Direction {
  Direction(const ImpairmentSpec& spec, std::size_t slots) : model(spec), queue(slots) {}
  ImpairmentModel model;
  ScheduleQueue queue;
  DirectionStats stats;
};

}  // namespace

struct ImpairmentRelay::State {
  explicit State(const RelayConfig& c)
      : config(c),
        listen_socket(c.listen_address),
        server_socket(AnyAddressLike(c.forward_address)),
        up(c.up, c.queue_slots),
        down(c.down, c.queue_slots) {}

  RelayConfig config;
  PollableUdpSocket listen_socket;  // client side
  PollableUdpSocket server_socket;  // server side
  Direction up;                     // client → server
  Direction down;                   // server → client
  SocketAddress client_address;
  bool have_client = false;
  std::array<std::uint8_t, kSlotBytes> scratch{};  // receive buffer when the queue is full
  double elapsed_s = 0.0;
  bool final_stats = false;

  // Takes one datagram from `socket` if one is waiting; returns false when none was.
  bool ReceiveOne(PollableUdpSocket& socket, bool from_client) noexcept;
  // Sends every datagram of `dir` due at or before `now_ns`.
  void SendDue(Direction& dir, bool to_server, std::int64_t now_ns) noexcept;
};

bool ImpairmentRelay::State::ReceiveOne(PollableUdpSocket& socket, bool from_client) noexcept {
  Direction& dir = from_client ? up : down;
  const std::int64_t index = dir.queue.Acquire();
  std::span<std::uint8_t> buffer =
      index >= 0 ? std::span<std::uint8_t>(dir.queue.slot(static_cast<std::size_t>(index)).bytes)
                 : std::span<std::uint8_t>(scratch);
  SocketAddress from;
  const std::int64_t n = socket.ReceiveFrom(buffer, from);
  const std::int64_t arrival_ns = NowNs();
  auto release = [&] {
    if (index >= 0) dir.queue.Release(static_cast<std::size_t>(index));
  };
  if (n < 0) {
    release();
    return false;
  }
  if (from_client) {
    client_address = from;
    have_client = true;
  } else if (!SameEndpoint(from, config.forward_address)) {
    ++dir.stats.dropped_unknown_source;
    release();
    return true;
  }
  const auto size = static_cast<std::size_t>(n);
  const std::uint8_t type = ClassifyDatagram(buffer.first(std::min(size, buffer.size())));
  TrafficCounters& c = dir.stats.by_type[type];
  ++c.received;
  c.bytes_in += size;
  if (size > wire::kMaxDatagramBytes) {
    ++c.dropped_oversize;
    release();
    return true;
  }
  if (index < 0) {
    ++c.dropped_queue;
    return true;
  }
  if (!from_client && !have_client) {  // nowhere to send it
    ++c.send_errors;
    release();
    return true;
  }
  const PacketDecision d = dir.model.Decide(arrival_ns, size);
  if (d.fate != PacketFate::kDelivered) {
    ++(d.fate == PacketFate::kDroppedLoss ? c.dropped_loss : c.dropped_queue);
    release();
    return true;
  }
  if (d.reordered) ++c.reordered;
  if (d.copies == 2) ++c.duplicated;
  c.in_flight_at_exit += static_cast<std::uint64_t>(d.copies);
  Slot& s = dir.queue.slot(static_cast<std::size_t>(index));
  s.deliver_ns = d.deliver_ns;
  s.size = static_cast<std::uint32_t>(size);
  s.copies = static_cast<std::uint8_t>(d.copies);
  s.type = type;
  dir.queue.Push(static_cast<std::size_t>(index));
  return true;
}

void ImpairmentRelay::State::SendDue(Direction& dir, bool to_server, std::int64_t now_ns) noexcept {
  while (!dir.queue.empty() && dir.queue.top().deliver_ns <= now_ns) {
    Slot& s = dir.queue.top();
    TrafficCounters& c = dir.stats.by_type[s.type];
    PollableUdpSocket& socket = to_server ? server_socket : listen_socket;
    const SocketAddress& to = to_server ? config.forward_address : client_address;
    for (; s.copies > 0; --s.copies) {
      --c.in_flight_at_exit;
      if (socket.SendTo(std::span<const std::uint8_t>(s.bytes.data(), s.size), to)) {
        ++c.forwarded;
        c.bytes_out += s.size;
      } else {
        ++c.send_errors;
      }
    }
    dir.queue.Pop();
  }
}

ImpairmentRelay::ImpairmentRelay(const RelayConfig& config) {
  if (config.queue_slots < 1 || config.queue_slots > (1u << 20)) {
    throw std::invalid_argument("relay: queue_slots " + std::to_string(config.queue_slots) +
                                " out of range 1..1048576");
  }
  if (!(config.stats_period_s > 0.0)) {
    throw std::invalid_argument("relay: stats period must be > 0 s");
  }
  if (!(config.progress_period_s >= 0.0) || !(config.duration_s >= 0.0)) {
    throw std::invalid_argument("relay: progress period and duration must be >= 0 s");
  }
  if (config.forward_address.length == 0 || config.forward_address.port() == 0) {
    throw std::invalid_argument("relay: forward address " + config.forward_address.ToString() +
                                " needs a port");
  }
  state_ = std::make_unique<State>(config);
  if (!config.port_file.empty()) {
    WriteFileAtomically(config.port_file, std::to_string(listen_address().port()) + "\n");
  }
}

ImpairmentRelay::~ImpairmentRelay() = default;

SocketAddress ImpairmentRelay::listen_address() const {
  return state_->listen_socket.local_address();
}

SocketAddress ImpairmentRelay::server_side_address() const {
  return state_->server_socket.local_address();
}

const DirectionStats& ImpairmentRelay::up_stats() const noexcept { return state_->up.stats; }
const DirectionStats& ImpairmentRelay::down_stats() const noexcept { return state_->down.stats; }

nlohmann::json ImpairmentRelay::StatsJson() const {
  const State& s = *state_;
  return {{"spec", {{"up", s.config.up.ToString()}, {"down", s.config.down.ToString()}}},
          {"listen", listen_address().ToString()},
          {"forward", s.config.forward_address.ToString()},
          {"elapsed_s", s.elapsed_s},
          {"final", s.final_stats},
          {"up", s.up.stats.ToJson()},
          {"down", s.down.stats.ToJson()}};
}

void ImpairmentRelay::Run(const std::atomic<bool>& stop) {
  State& s = *state_;
  const auto period_ns = [](double seconds) {
    return static_cast<std::int64_t>(std::llround(seconds * 1e9));
  };
  const std::int64_t start_ns = NowNs();
  const std::int64_t end_ns = s.config.duration_s > 0.0 ? start_ns + period_ns(s.config.duration_s)
                                                        : std::numeric_limits<std::int64_t>::max();
  const std::int64_t stats_period_ns = period_ns(s.config.stats_period_s);
  const std::int64_t progress_period_ns = period_ns(s.config.progress_period_s);
  std::int64_t next_stats_ns = start_ns + stats_period_ns;
  std::int64_t next_progress_ns = progress_period_ns > 0 ? start_ns + progress_period_ns
                                                         : std::numeric_limits<std::int64_t>::max();
  std::printf("[relay] listening on %s, forwarding to %s from %s; up: %s; down: %s\n",
              listen_address().ToString().c_str(), s.config.forward_address.ToString().c_str(),
              server_side_address().ToString().c_str(), s.config.up.ToString().c_str(),
              s.config.down.ToString().c_str());
  std::fflush(stdout);

  pollfd fds[2] = {{s.listen_socket.fd(), POLLIN, 0}, {s.server_socket.fd(), POLLIN, 0}};
  while (!stop.load(std::memory_order_relaxed)) {
    // 1. Take what has arrived (a bounded batch per socket), stamping each on arrival.
    bool more_waiting = false;
    for (int side = 0; side < 2; ++side) {
      PollableUdpSocket& socket = side == 0 ? s.listen_socket : s.server_socket;
      int taken = 0;
      while (taken < kReceiveBatch && s.ReceiveOne(socket, side == 0)) ++taken;
      if (taken == kReceiveBatch) more_waiting = true;
    }
    // 2. Send what is due.
    std::int64_t now_ns = NowNs();
    s.SendDue(s.up, /*to_server=*/true, now_ns);
    s.SendDue(s.down, /*to_server=*/false, now_ns);
    s.elapsed_s = static_cast<double>(now_ns - start_ns) * 1e-9;
    if (now_ns >= end_ns) break;
    // 3. Report.
    if (now_ns >= next_stats_ns) {
      if (!s.config.stats_file.empty()) {
        WriteFileAtomically(s.config.stats_file, StatsJson().dump(2) + "\n");
      }
      while (next_stats_ns <= now_ns) next_stats_ns += stats_period_ns;
    }
    if (now_ns >= next_progress_ns) {
      const TrafficCounters u = s.up.stats.Total();
      const TrafficCounters d = s.down.stats.Total();
      std::printf(
          "[relay] %.0f s  up: %llu in, %llu out, %llu lost, %llu queue-dropped  |  down: %llu "
          "in, %llu out, %llu lost, %llu queue-dropped  |  in flight %zu/%zu\n",
          s.elapsed_s, static_cast<unsigned long long>(u.received),
          static_cast<unsigned long long>(u.forwarded),
          static_cast<unsigned long long>(u.dropped_loss),
          static_cast<unsigned long long>(u.dropped_queue),
          static_cast<unsigned long long>(d.received), static_cast<unsigned long long>(d.forwarded),
          static_cast<unsigned long long>(d.dropped_loss),
          static_cast<unsigned long long>(d.dropped_queue), s.up.queue.size(), s.down.queue.size());
      std::fflush(stdout);
      while (next_progress_ns <= now_ns) next_progress_ns += progress_period_ns;
    }
    // 4. Wait for a datagram or the next departure / report / end, whichever is first.
    std::int64_t wake_ns = std::min({end_ns, next_stats_ns, next_progress_ns, now_ns + kMaxWaitNs});
    if (!s.up.queue.empty()) wake_ns = std::min(wake_ns, s.up.queue.top().deliver_ns);
    if (!s.down.queue.empty()) wake_ns = std::min(wake_ns, s.down.queue.top().deliver_ns);
    now_ns = NowNs();
    const std::int64_t wait_ns = more_waiting ? 0 : std::max<std::int64_t>(0, wake_ns - now_ns);
    const timespec timeout{static_cast<time_t>(wait_ns / kNsPerS),
                           static_cast<long>(wait_ns % kNsPerS)};
    ::ppoll(fds, 2, &timeout, nullptr);  // EINTR (a signal) just loops back to the stop check
  }
  s.elapsed_s = static_cast<double>(NowNs() - start_ns) * 1e-9;
  s.final_stats = true;
  if (!s.config.stats_file.empty()) {
    WriteFileAtomically(s.config.stats_file, StatsJson().dump(2) + "\n");
  }
}

}  // namespace ht
