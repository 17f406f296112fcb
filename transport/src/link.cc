#include "transport/link.h"

#include <algorithm>

namespace ht {

bool ClockSync::AddSample(std::int64_t t1, std::int64_t t2, std::int64_t t3,
                          std::int64_t t4) noexcept {
  if (t4 < t1 || (t3 < t2 && t2 - t3 > 1000)) return false;
  t3 = std::max(t3, t2);  // the header's send time is whole µs
  Sample s;
  s.rtt_ns = (t4 - t1) - (t3 - t2);
  if (s.rtt_ns < 0) s.rtt_ns = 0;
  s.offset_ns = ((t2 - t1) + (t3 - t4)) / 2;
  samples_[static_cast<std::size_t>(next_)] = s;
  next_ = (next_ + 1) % kSamples;
  count_ = std::min(count_ + 1, kSamples);
  if (rtt_ms_.size() < rtt_ms_.capacity()) rtt_ms_.push_back(static_cast<double>(s.rtt_ns) * 1e-6);
  return true;
}

std::int64_t ClockSync::offset_ns() const noexcept {
  if (count_ == 0) return 0;
  const auto best =
      std::min_element(samples_.begin(), samples_.begin() + count_,
                       [](const Sample& a, const Sample& b) { return a.rtt_ns < b.rtt_ns; });
  return best->offset_ns;
}

std::int64_t ClockSync::rtt_ns() const noexcept {
  if (count_ == 0) return 0;
  const auto best =
      std::min_element(samples_.begin(), samples_.begin() + count_,
                       [](const Sample& a, const Sample& b) { return a.rtt_ns < b.rtt_ns; });
  return best->rtt_ns;
}

bool Accepts(LinkRole role, wire::MessageType type) noexcept {
  using T = wire::MessageType;
  if (role == LinkRole::kRemote) {
    return type == T::kToolState || type == T::kCompactToolState || type == T::kHello ||
           type == T::kPing || type == T::kSceneNack || type == T::kDepthFieldNack ||
           type == T::kGoodbye;
  }
  return type == T::kContactModel || type == T::kCompactContactModel || type == T::kWelcome ||
         type == T::kReject || type == T::kPong || type == T::kSceneFragment ||
         type == T::kSceneManifest || type == T::kNodePoses || type == T::kDepthFieldFragment ||
         type == T::kGoodbye;
}

SecureLink::SecureLink(UdpSocket& socket, const MacKey& key, LinkRole role)
    : socket_(socket), key_(key), role_(role) {}

wire::Header SecureLink::NextHeader(wire::MessageType type, std::uint32_t session_id) noexcept {
  wire::Header h;
  h.type = type;
  h.session_id = session_id;
  std::uint64_t& next = next_sequence_[static_cast<int>(type)];
  if (next < wire::kMaxSequence) ++next;
  h.sequence = next;
  h.send_time_ns = SteadyNowNs();
  return h;
}

bool SecureLink::SequencesNearlyUsedUp() const noexcept {
  return std::any_of(next_sequence_.begin(), next_sequence_.end(),
                     [](std::uint64_t s) { return s >= wire::kSequenceRenewAt; });
}

void SecureLink::StartSequencesAt(std::uint64_t last_sent) noexcept {
  next_sequence_.fill(std::min(last_sent, wire::kMaxSequence));
}

bool SecureLink::Send(const wire::Datagram& d, const SocketAddress& to) noexcept {
  const int type = wire::DatagramType(d.view());
  StreamStats& s = stats_[static_cast<std::size_t>(type < kTypes ? type : 0)];
  if (socket_.SendTo(d.view(), to)) {
    ++s.sent;
    s.bytes_sent += d.size;
    return true;
  }
  ++s.send_failed;
  return false;
}

void SecureLink::CountRejected(const wire::Header* header, wire::DecodeStatus status) noexcept {
  ++rejected_total_;
  ++rejected_by_reason_[static_cast<int>(status)];
  if (header) ++stats_[static_cast<int>(header->type)].rejected;
}

void SecureLink::CountBodyRejected(wire::MessageType type, wire::DecodeStatus status) noexcept {
  ++rejected_total_;
  ++rejected_by_reason_[static_cast<int>(status)];
  StreamStats& s = stats_[static_cast<int>(type)];
  ++s.rejected;
  // It was counted as received when it opened; it is not (its sequence number stays consumed, so
  // it is neither received nor lost: it is rejected).
  if (s.received > 0) --s.received;
  s.bytes_received -= std::min(s.bytes_received, last_open_bytes_);
}

wire::DecodeStatus SecureLink::Open(std::span<const std::uint8_t> datagram,
                                    std::uint32_t session_id, wire::Header& header,
                                    std::span<const std::uint8_t>& body, bool& late) noexcept {
  using wire::DecodeStatus;
  late = false;
  wire::Header h;
  DecodeStatus s = wire::PeekHeader(datagram, h);
  if (s == DecodeStatus::kOk && datagram.size() < wire::kHeaderBytes + wire::kMacBytes) {
    s = DecodeStatus::kTooShort;
  }
  if (s != DecodeStatus::kOk) {
    CountRejected(nullptr, s);
    return s;
  }
  if (!Accepts(role_, h.type)) {
    CountRejected(&h, DecodeStatus::kUnexpected);
    return DecodeStatus::kUnexpected;
  }
  const bool handshake = h.type == wire::MessageType::kHello ||
                         h.type == wire::MessageType::kWelcome ||
                         h.type == wire::MessageType::kReject;
  const int t = static_cast<int>(h.type);
  // The MAC first: only authenticated datagrams are classified further, so that a forgery always
  // counts as bad_mac (never as a duplicate or another session) and never touches a window.
  s = wire::OpenDatagram(datagram, key_, header, body);
  if (s != DecodeStatus::kOk) {
    CountRejected(&h, s);
    return s;
  }
  if (!handshake && (session_id == 0 || header.session_id != session_id)) {
    CountRejected(&h, DecodeStatus::kWrongSession);
    return DecodeStatus::kWrongSession;
  }
  if (!handshake) {
    const auto v = windows_[t].Accept(header.sequence);
    if (v == ReplayWindow::Verdict::kDuplicate || v == ReplayWindow::Verdict::kTooOld ||
        v == ReplayWindow::Verdict::kZero) {
      ++stats_[t].duplicate;
      CountRejected(&h, DecodeStatus::kReplayed);
      return DecodeStatus::kReplayed;
    }
    late = v == ReplayWindow::Verdict::kLate;
    if (late) ++stats_[t].late;
    ++unique_in_session_[t];
    // Only in-session traffic proves the peer alive: a replayed handshake datagram must not.
    last_authenticated_ns_ = SteadyNowNs();
  }
  ++stats_[t].received;
  stats_[t].bytes_received += datagram.size();
  last_open_bytes_ = datagram.size();
  return DecodeStatus::kOk;
}

void SecureLink::ResetSession() noexcept {
  for (int t = 0; t < kTypes; ++t) {
    const std::uint64_t highest = windows_[t].highest();
    if (highest > unique_in_session_[t]) stats_[t].lost += highest - unique_in_session_[t];
    windows_[t].Reset();
    unique_in_session_[t] = 0;
    next_sequence_[t] = 0;
  }
}

const StreamStats& SecureLink::stats(wire::MessageType type) const noexcept {
  return stats_[static_cast<int>(type)];
}

nlohmann::json SecureLink::StatsJson() const {
  nlohmann::json streams = nlohmann::json::object();
  for (int t = 1; t < kTypes; ++t) {
    StreamStats s = stats_[t];
    const std::uint64_t highest = windows_[t].highest();
    if (highest > unique_in_session_[t]) s.lost += highest - unique_in_session_[t];
    if (s.sent + s.send_failed + s.received + s.rejected + s.duplicate == 0) continue;
    streams[wire::ToString(static_cast<wire::MessageType>(t))] = {
        {"sent", s.sent},
        {"send_failed", s.send_failed},
        {"bytes_sent", s.bytes_sent},
        {"received", s.received},
        {"bytes_received", s.bytes_received},
        {"lost", s.lost},
        {"late", s.late},
        {"duplicate", s.duplicate},
        {"rejected", s.rejected}};
  }
  nlohmann::json reasons = nlohmann::json::object();
  for (int i = 1; i < wire::kDecodeStatusCount; ++i) {
    if (rejected_by_reason_[i]) {
      reasons[wire::ToString(static_cast<wire::DecodeStatus>(i))] = rejected_by_reason_[i];
    }
  }
  return {
      {"streams", streams}, {"rejected_total", rejected_total_}, {"rejected_by_reason", reasons}};
}

}  // namespace ht
