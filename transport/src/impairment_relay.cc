// The impairment relay (transport/impairment_relay.h): datagram classification and the
// per-direction statistics, the bounded time-ordered queue of scheduled datagrams, and the relay
// loop that receives on both sockets, applies each direction's ImpairmentModel and sends each
// datagram at its departure time.

#include "transport/impairment_relay.h"

#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <limits>
#include <optional>
#include <stdexcept>
#include <vector>

#include "haptic_core/byte_order.h"
#include "haptic_core/steady_clock.h"
#include "impairment_internal.h"
#include "transport/impairment.h"
#include "transport/messages.h"
#include "transport/protocol.h"

namespace ht {

// ---------------------------------------------------------------------------------------------
// Classification and statistics.

std::uint8_t ClassifyDatagram(std::span<const std::uint8_t> bytes) noexcept {
  return static_cast<std::uint8_t>(wire::DatagramType(bytes));
}

std::string MessageTypeName(std::uint8_t type) {
  if (type == 0) return "other";
  if (type <= wire::kMaxMessageType) return wire::ToString(static_cast<wire::MessageType>(type));
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

using impairment_internal::kNsPerMs;
using impairment_internal::kNsPerS;

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

// Room for the largest datagram either side sends, plus one byte to detect longer ones.
constexpr std::size_t kSlotBytes = wire::kMaxDatagramBytes + 1;
// Datagrams taken from one socket before the due ones are sent again (bounds the lateness that
// a flood on one side can cause).
constexpr int kReceiveBatch = 64;
// Longest single wait, so a stop signal that lands just before ppoll is seen soon. Unit: ns.
constexpr std::int64_t kMaxWaitNs = 100 * kNsPerMs;
// Send buffer asked for on both sockets (the receive buffer is UdpSocket's 4 MiB): room for
// bursts while the relay is busy sending (best effort). Unit: bytes.
constexpr int kSendBufferBytes = 4 << 20;

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
        listen_socket(c.listen_address, kSendBufferBytes),
        server_socket(AnyAddressLike(c.forward_address), kSendBufferBytes),
        up(c.up, c.queue_slots),
        down(c.down, c.queue_slots) {}

  RelayConfig config;
  UdpSocket listen_socket;  // client side
  UdpSocket server_socket;  // server side
  Direction up;             // client → server
  Direction down;           // server → client
  SocketAddress client_address;
  bool have_client = false;
  std::array<std::uint8_t, kSlotBytes> scratch{};  // receive buffer when the queue is full
  double elapsed_s = 0.0;
  bool final_stats = false;

  // Takes one datagram from `socket` if one is waiting; returns false when none was.
  bool ReceiveOne(UdpSocket& socket, bool from_client) noexcept;
  // Sends every datagram of `dir` due at or before `now_ns`.
  void SendDue(Direction& dir, bool to_server, std::int64_t now_ns) noexcept;
};

bool ImpairmentRelay::State::ReceiveOne(UdpSocket& socket, bool from_client) noexcept {
  Direction& dir = from_client ? up : down;
  const std::int64_t index = dir.queue.Acquire();
  std::span<std::uint8_t> buffer =
      index >= 0 ? std::span<std::uint8_t>(dir.queue.slot(static_cast<std::size_t>(index)).bytes)
                 : std::span<std::uint8_t>(scratch);
  SocketAddress from;
  const std::optional<std::size_t> received = socket.ReceiveFrom(buffer, from);
  const std::int64_t arrival_ns = SteadyNowNs();
  auto release = [&] {
    if (index >= 0) dir.queue.Release(static_cast<std::size_t>(index));
  };
  if (!received) {
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
  const std::size_t size = *received;
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
    UdpSocket& socket = to_server ? server_socket : listen_socket;
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
  const std::int64_t start_ns = SteadyNowNs();
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

  pollfd fds[2] = {{s.listen_socket.native_handle(), POLLIN, 0},
                   {s.server_socket.native_handle(), POLLIN, 0}};
  while (!stop.load(std::memory_order_relaxed)) {
    // 1. Take what has arrived (a bounded batch per socket), stamping each on arrival.
    bool more_waiting = false;
    for (int side = 0; side < 2; ++side) {
      UdpSocket& socket = side == 0 ? s.listen_socket : s.server_socket;
      int taken = 0;
      while (taken < kReceiveBatch && s.ReceiveOne(socket, side == 0)) ++taken;
      if (taken == kReceiveBatch) more_waiting = true;
    }
    // 2. Send what is due.
    std::int64_t now_ns = SteadyNowNs();
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
    now_ns = SteadyNowNs();
    const std::int64_t wait_ns = more_waiting ? 0 : std::max<std::int64_t>(0, wake_ns - now_ns);
    const timespec timeout{static_cast<time_t>(wait_ns / kNsPerS),
                           static_cast<long>(wait_ns % kNsPerS)};
    ::ppoll(fds, 2, &timeout, nullptr);  // EINTR (a signal) just loops back to the stop check
  }
  s.elapsed_s = static_cast<double>(SteadyNowNs() - start_ns) * 1e-9;
  s.final_stats = true;
  if (!s.config.stats_file.empty()) {
    WriteFileAtomically(s.config.stats_file, StatsJson().dump(2) + "\n");
  }
}

}  // namespace ht
