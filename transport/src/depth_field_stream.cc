#include "transport/depth_field_stream.h"

#include <algorithm>
#include <stdexcept>
#include <string>

namespace ht {
namespace {

std::size_t PayloadFor(std::size_t mtu) {
  if (mtu < wire::kMinMtuBytes || mtu > wire::kMaxDatagramBytes) {
    throw std::invalid_argument("depth-field stream: MTU " + std::to_string(mtu) + " outside [" +
                                std::to_string(wire::kMinMtuBytes) + ", " +
                                std::to_string(wire::kMaxDatagramBytes) + "]");
  }
  static_assert(wire::kDepthFieldFragmentFixedBytes == wire::kSceneFragmentFixedBytes);
  return wire::FragmentPayloadBytes(mtu);
}

}  // namespace

DepthFieldSender::DepthFieldSender(std::size_t mtu, std::size_t keep)
    : payload_(PayloadFor(mtu)), keep_(keep) {
  if (keep == 0) throw std::invalid_argument("depth-field stream: keep must be at least 1");
  fields_.reserve(keep);
}

void DepthFieldSender::Reset(std::size_t mtu) {
  payload_ = PayloadFor(mtu);
  fields_.clear();
  queue_.clear();
}

DepthFieldSender::Field* DepthFieldSender::Find(std::uint32_t id) noexcept {
  for (Field& f : fields_) {
    if (f.id == id) return &f;
  }
  return nullptr;
}

bool DepthFieldSender::Named(std::uint32_t id) noexcept {
  Field* f = id != 0 ? Find(id) : nullptr;
  if (f == nullptr) return false;
  f->named_at = ++clock_;
  return true;
}

void DepthFieldSender::Add(std::uint32_t id, std::vector<std::uint8_t> bytes) {
  if (id == 0) throw std::invalid_argument("depth-field stream: field id 0");
  if (Find(id) != nullptr) {
    throw std::invalid_argument("depth-field stream: field " + std::to_string(id) + " added twice");
  }
  if (bytes.empty() || bytes.size() > wire::kMaxDepthFieldBytes) {
    throw std::invalid_argument("depth-field stream: field of " + std::to_string(bytes.size()) +
                                " bytes (1.." + std::to_string(wire::kMaxDepthFieldBytes) + ")");
  }
  const std::size_t count = (bytes.size() + payload_ - 1) / payload_;  // ≤ 2¹⁰ at any MTU
  if (fields_.size() >= keep_) {
    // The least recently named goes; its queued fragments are skipped by Next.
    const auto oldest =
        std::min_element(fields_.begin(), fields_.end(),
                         [](const Field& a, const Field& b) { return a.named_at < b.named_at; });
    fields_.erase(oldest);
  }
  Field f;
  f.id = id;
  f.bytes = std::move(bytes);
  f.fragment_count = static_cast<std::uint16_t>(count);
  f.queued.assign(count, true);
  f.named_at = ++clock_;
  for (std::size_t k = 0; k < count; ++k) queue_.emplace_back(id, static_cast<std::uint16_t>(k));
  fields_.push_back(std::move(f));
  ++fields_added_;
}

bool DepthFieldSender::OnNack(const wire::SceneNackMessage& nack) {
  Field* f = nack.version == wire::kDepthFieldVersion ? Find(nack.object_id) : nullptr;
  bool ok = f != nullptr;
  for (int i = 0; ok && i < nack.count; ++i) ok = nack.missing[i] < f->fragment_count;
  if (!ok) {
    ++nacks_refused_;
    return false;
  }
  ++nacks_answered_;
  const auto queue = [&](std::uint16_t k) {
    if (f->queued[k]) return;
    f->queued[k] = true;
    queue_.emplace_back(f->id, k);
  };
  if (nack.count == 0) {
    for (std::uint16_t k = 0; k < f->fragment_count; ++k) queue(k);
  } else {
    for (int i = 0; i < nack.count; ++i) queue(nack.missing[i]);
  }
  return true;
}

bool DepthFieldSender::QueueAgain(std::uint32_t id) {
  Field* f = id != 0 ? Find(id) : nullptr;
  if (f == nullptr) return false;
  for (std::uint16_t k = 0; k < f->fragment_count; ++k) {
    if (f->queued[k]) continue;
    f->queued[k] = true;
    queue_.emplace_back(id, k);
  }
  return true;
}

bool DepthFieldSender::Next(wire::SceneFragmentMessage& out) {
  while (!queue_.empty()) {
    const auto [id, k] = queue_.front();
    queue_.pop_front();
    Field* f = Find(id);
    if (f == nullptr || k >= f->fragment_count) continue;  // dropped since it was queued
    f->queued[k] = false;
    const std::size_t begin = static_cast<std::size_t>(k) * payload_;
    const std::size_t end = std::min(begin + payload_, f->bytes.size());
    out.object_id = id;
    out.version = wire::kDepthFieldVersion;
    out.object_bytes = static_cast<std::uint32_t>(f->bytes.size());
    out.fragment_index = k;
    out.fragment_count = f->fragment_count;
    out.payload = {f->bytes.data() + begin, end - begin};
    ++fragments_sent_;
    bytes_sent_ += end - begin;
    return true;
  }
  return false;
}

DepthFieldReassembler::DepthFieldReassembler(std::size_t mtu, std::size_t slots)
    : payload_(PayloadFor(mtu)), partials_(slots), held_(kHeldIds, 0) {
  if (slots == 0) throw std::invalid_argument("depth-field reassembly: slots must be at least 1");
  wants_.reserve(64);
}

void DepthFieldReassembler::Reset(std::size_t mtu) {
  payload_ = PayloadFor(mtu);
  for (Partial& p : partials_) p.id = 0;
  std::fill(held_.begin(), held_.end(), 0u);
  held_next_ = 0;
  wants_.clear();
  completed_.clear();
  completed_id_ = 0;
}

bool DepthFieldReassembler::IsHeld(std::uint32_t id) const noexcept {
  return id != 0 && std::find(held_.begin(), held_.end(), id) != held_.end();
}

void DepthFieldReassembler::Held(std::uint32_t id) noexcept {
  if (id == 0 || IsHeld(id)) return;
  held_[held_next_] = id;
  held_next_ = (held_next_ + 1) % held_.size();
  std::erase_if(wants_, [id](const Want& w) { return w.id == id; });
}

DepthFieldReassembler::Outcome DepthFieldReassembler::Add(const wire::SceneFragmentMessage& f,
                                                          std::int64_t now_ns) {
  if (IsHeld(f.object_id)) {
    ++stats_.fragments_duplicate;
    return Outcome::kDuplicate;
  }
  // A fragment consistent with the MTU's cut: its count, and its payload's length.
  const std::size_t count = (static_cast<std::size_t>(f.object_bytes) + payload_ - 1) / payload_;
  const std::size_t begin = static_cast<std::size_t>(f.fragment_index) * payload_;
  const std::size_t expected =
      begin < f.object_bytes ? std::min(payload_, f.object_bytes - begin) : 0;
  if (f.object_id == 0 || f.object_bytes == 0 || f.object_bytes > wire::kMaxDepthFieldBytes ||
      f.fragment_count != count || f.fragment_index >= count || f.payload.size() != expected) {
    ++stats_.fragments_inconsistent;
    return Outcome::kInconsistent;
  }
  Partial* slot = nullptr;
  for (Partial& p : partials_) {
    if (p.id == f.object_id) slot = &p;
  }
  if (slot != nullptr &&
      (slot->field_bytes != f.object_bytes || slot->fragment_count != f.fragment_count)) {
    ++stats_.fragments_inconsistent;
    return Outcome::kInconsistent;
  }
  if (slot == nullptr) {
    // A free slot, else the one whose last fragment is oldest (abandoned).
    slot = &*std::min_element(partials_.begin(), partials_.end(),
                              [](const Partial& a, const Partial& b) {
                                if ((a.id == 0) != (b.id == 0)) return a.id == 0;
                                return a.last_fragment_ns < b.last_fragment_ns;
                              });
    if (slot->id != 0) ++stats_.fields_abandoned;
    slot->id = f.object_id;
    slot->field_bytes = f.object_bytes;
    slot->fragment_count = f.fragment_count;
    slot->bytes.resize(f.object_bytes);
    slot->have.assign(count, false);
    slot->have_count = 0;
  }
  slot->last_fragment_ns = now_ns;
  if (slot->have[f.fragment_index]) {
    ++stats_.fragments_duplicate;
    return Outcome::kDuplicate;
  }
  std::copy(f.payload.begin(), f.payload.end(),
            slot->bytes.begin() + static_cast<std::ptrdiff_t>(begin));
  slot->have[f.fragment_index] = true;
  ++stats_.fragments_accepted;
  if (++slot->have_count < slot->fragment_count) return Outcome::kAccepted;
  completed_.swap(slot->bytes);
  completed_id_ = slot->id;
  slot->id = 0;
  ++stats_.fields_completed;
  return Outcome::kCompleted;
}

void DepthFieldReassembler::Lost(std::uint32_t id, std::int64_t now_ns) {
  if (id == 0) return;
  std::replace(held_.begin(), held_.end(), id, 0u);
  Wanted(id, now_ns);
}

void DepthFieldReassembler::Wanted(std::uint32_t id, std::int64_t now_ns) {
  if (id == 0 || IsHeld(id)) return;
  for (Want& w : wants_) {
    if (w.id == id) {
      w.last_named_ns = now_ns;
      return;
    }
  }
  if (wants_.size() >= 64) {  // the least recently named makes room
    wants_.erase(std::min_element(wants_.begin(), wants_.end(), [](const Want& a, const Want& b) {
      return a.last_named_ns < b.last_named_ns;
    }));
  }
  wants_.push_back({id, now_ns, now_ns, 0});
}

void DepthFieldReassembler::BuildNacks(std::int64_t now_ns, const RepairTiming& timing,
                                       std::vector<wire::SceneNackMessage>& out) {
  constexpr std::int64_t kNamedWithinNs = 1'000'000'000;
  std::erase_if(wants_, [&](const Want& w) { return now_ns - w.last_named_ns > kNamedWithinNs; });
  for (Want& w : wants_) {
    if (now_ns - w.first_ns < timing.gap_ns) continue;
    if (w.last_nack_ns != 0 && now_ns - w.last_nack_ns < timing.rtt_ns + timing.gap_ns) continue;
    const Partial* p = nullptr;
    for (const Partial& q : partials_) {
      if (q.id == w.id) p = &q;
    }
    // A field still arriving (a fragment within the gap) is left to finish.
    if (p != nullptr && now_ns - p->last_fragment_ns < timing.gap_ns) continue;
    wire::SceneNackMessage nack;
    nack.object_id = w.id;
    nack.version = wire::kDepthFieldVersion;
    nack.count = 0;
    if (p != nullptr) {
      for (std::uint16_t k = 0; k < p->fragment_count && nack.count < wire::kMaxNackIndices; ++k) {
        if (!p->have[k]) nack.missing[nack.count++] = k;
      }
    }
    w.last_nack_ns = now_ns;
    ++stats_.nacks_sent;
    stats_.fragments_nacked += nack.count;
    out.push_back(nack);
  }
}

}  // namespace ht
