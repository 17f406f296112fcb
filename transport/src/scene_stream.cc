#include "transport/scene_stream.h"

#include <algorithm>
#include <stdexcept>
#include <string>

namespace ht {
namespace {

std::size_t CheckedPayload(std::size_t mtu) {
  if (mtu < wire::kMinMtuBytes || mtu > wire::kMaxDatagramBytes) {
    throw std::invalid_argument("MTU must be within " + std::to_string(wire::kMinMtuBytes) + ".." +
                                std::to_string(wire::kMaxDatagramBytes) + " bytes, got " +
                                std::to_string(mtu));
  }
  return wire::FragmentPayloadBytes(mtu);
}

std::size_t FragmentCount(std::size_t bytes, std::size_t payload) {
  return (bytes + payload - 1) / payload;
}

}  // namespace

SceneSender::SceneSender(std::size_t mtu) : payload_(CheckedPayload(mtu)) {}

std::uint32_t SceneSender::Update(std::uint32_t object_id, std::vector<std::uint8_t> bytes,
                                  wire::SceneObjectKind kind) {
  if (const auto k = static_cast<int>(kind); k < 1 || k > wire::kMaxSceneObjectKind) {
    throw std::invalid_argument("scene object " + std::to_string(object_id) + " has kind " +
                                std::to_string(k) + ", not a SceneObjectKind");
  }
  if (bytes.empty())
    throw std::invalid_argument("scene object " + std::to_string(object_id) + " is empty");
  if (bytes.size() > wire::kMaxSceneObjectBytes) {
    throw std::invalid_argument("scene object " + std::to_string(object_id) + " has " +
                                std::to_string(bytes.size()) + " bytes; the limit is " +
                                std::to_string(wire::kMaxSceneObjectBytes));
  }
  const std::size_t count = FragmentCount(bytes.size(), payload_);
  if (count > 65535) {
    throw std::invalid_argument("scene object " + std::to_string(object_id) +
                                " needs more than 65535 fragments at this MTU");
  }
  auto it = std::find_if(objects_.begin(), objects_.end(),
                         [&](const SceneObject& o) { return o.object_id == object_id; });
  if (it == objects_.end()) {
    objects_.push_back({});
    queued_.emplace_back();
    it = objects_.end() - 1;
    it->object_id = object_id;
  }
  it->version += 1;
  it->kind = kind;
  it->bytes = std::move(bytes);
  it->digest = ContentDigest(it->bytes);
  it->fragment_count = static_cast<std::uint16_t>(count);
  const auto index = static_cast<std::size_t>(it - objects_.begin());
  queued_[index].assign(count, false);
  for (std::size_t f = 0; f < count; ++f) {
    queue_.push_back(
        {static_cast<std::uint32_t>(index), it->version, static_cast<std::uint16_t>(f)});
    queued_[index][f] = true;
  }
  return it->version;
}

void SceneSender::SetMtu(std::size_t mtu) {
  const std::size_t payload = CheckedPayload(mtu);
  if (payload == payload_) return;
  for (const SceneObject& o : objects_) {
    if (FragmentCount(o.bytes.size(), payload) > 65535) {
      throw std::invalid_argument("scene object " + std::to_string(o.object_id) +
                                  " needs more than 65535 fragments at MTU " + std::to_string(mtu));
    }
  }
  payload_ = payload;
  for (std::size_t i = 0; i < objects_.size(); ++i) {
    objects_[i].fragment_count =
        static_cast<std::uint16_t>(FragmentCount(objects_[i].bytes.size(), payload_));
  }
  QueueAll();
}

void SceneSender::QueueAll() {
  queue_.clear();
  for (std::size_t i = 0; i < objects_.size(); ++i) {
    queued_[i].assign(objects_[i].fragment_count, true);
    for (std::uint16_t f = 0; f < objects_[i].fragment_count; ++f) {
      queue_.push_back({static_cast<std::uint32_t>(i), objects_[i].version, f});
    }
  }
}

bool SceneSender::OnNack(const wire::SceneNackMessage& nack) {
  const auto it = std::find_if(objects_.begin(), objects_.end(),
                               [&](const SceneObject& o) { return o.object_id == nack.object_id; });
  if (it == objects_.end() || it->version != nack.version) return false;
  const auto index = static_cast<std::size_t>(it - objects_.begin());
  for (int i = 0; i < nack.count; ++i) {
    if (nack.missing[static_cast<std::size_t>(i)] >= it->fragment_count) return false;
  }
  const auto queue = [&](std::uint16_t f) {
    if (queued_[index][f]) return;
    queued_[index][f] = true;
    queue_.push_back({static_cast<std::uint32_t>(index), it->version, f});
  };
  if (nack.count == 0) {
    for (std::uint16_t f = 0; f < it->fragment_count; ++f) queue(f);
  } else {
    for (int i = 0; i < nack.count; ++i) queue(nack.missing[static_cast<std::size_t>(i)]);
  }
  return true;
}

bool SceneSender::Next(wire::SceneFragmentMessage& out) {
  while (!queue_.empty()) {
    const Pending p = queue_.front();
    queue_.pop_front();
    const SceneObject& o = objects_[p.object_index];
    if (p.version != o.version || p.fragment >= o.fragment_count) continue;  // superseded
    queued_[p.object_index][p.fragment] = false;
    const std::size_t begin = std::size_t{p.fragment} * payload_;
    const std::size_t end = std::min(begin + payload_, o.bytes.size());
    out.object_id = o.object_id;
    out.version = o.version;
    out.object_bytes = static_cast<std::uint32_t>(o.bytes.size());
    out.fragment_index = p.fragment;
    out.fragment_count = o.fragment_count;
    out.payload = std::span<const std::uint8_t>(o.bytes).subspan(begin, end - begin);
    return true;
  }
  return false;
}

std::vector<wire::SceneManifestMessage> SceneSender::Manifest() const {
  std::vector<wire::SceneManifestMessage> out;
  const std::size_t total = objects_.size();
  for (std::size_t first = 0; first < total; first += wire::kMaxManifestEntries) {
    wire::SceneManifestMessage m;
    m.total_objects = static_cast<std::uint16_t>(total);
    m.first_index = static_cast<std::uint16_t>(first);
    const std::size_t n = std::min<std::size_t>(wire::kMaxManifestEntries, total - first);
    m.count = static_cast<std::uint8_t>(n);
    for (std::size_t i = 0; i < n; ++i) {
      const SceneObject& o = objects_[first + i];
      m.entries[i] = {o.object_id,      o.version, static_cast<std::uint32_t>(o.bytes.size()),
                      o.fragment_count, o.kind,    o.digest};
    }
    out.push_back(m);
  }
  return out;
}

SceneReassembler::SceneReassembler(std::size_t mtu, ReassemblyLimits limits)
    : payload_(CheckedPayload(mtu)), limits_(limits) {}

void SceneReassembler::Reset(std::size_t mtu) {
  payload_ = CheckedPayload(mtu);
  objects_.clear();
  manifest_.clear();
  manifest_total_ = 0;
  bytes_held_ = 0;
  last_any_fragment_ns_ = 0;
}

void SceneReassembler::Release(Object& o) {
  bytes_held_ -= o.bytes.size();
  std::vector<std::uint8_t>().swap(o.bytes);
  std::vector<bool>().swap(o.have);
  o.have_count = 0;
  o.complete = false;
}

SceneReassembler::Outcome SceneReassembler::Add(const wire::SceneFragmentMessage& f,
                                                std::int64_t now_ns) {
  last_any_fragment_ns_ = now_ns;
  if (f.object_bytes > limits_.max_object_bytes) {
    ++stats_.fragments_over_limit;
    return Outcome::kOverLimit;
  }
  const std::size_t count = FragmentCount(f.object_bytes, payload_);
  const std::size_t begin = std::size_t{f.fragment_index} * payload_;
  if (count != f.fragment_count || f.fragment_index >= count ||
      f.payload.size() != std::min(payload_, f.object_bytes - begin)) {
    ++stats_.fragments_inconsistent;
    return Outcome::kInconsistent;
  }
  auto it = objects_.find(f.object_id);
  if (it == objects_.end()) {
    if (objects_.size() >= limits_.max_objects) {
      ++stats_.fragments_over_limit;
      return Outcome::kOverLimit;
    }
    it = objects_.emplace(f.object_id, Object{}).first;
  }
  Object& o = it->second;
  if (f.version < o.version) {
    ++stats_.fragments_stale;
    return Outcome::kStale;
  }
  if (f.version > o.version || o.bytes.empty()) {
    if (f.version > o.version && o.version != 0 && !o.complete) ++stats_.objects_superseded;
    if (f.version == o.version && o.complete) {  // completed earlier, then dropped on a mismatch
      ++stats_.fragments_duplicate;
      return Outcome::kDuplicate;
    }
    Release(o);
    if (bytes_held_ + f.object_bytes > limits_.max_total_bytes) {
      o.version = f.version;  // remember it, so that its other fragments count as refused too
      ++stats_.fragments_over_limit;
      return Outcome::kOverLimit;
    }
    o.version = f.version;
    o.object_bytes = f.object_bytes;
    o.fragment_count = f.fragment_count;
    o.bytes.assign(f.object_bytes, 0);
    o.have.assign(count, false);
    o.last_nack_ns = 0;
    bytes_held_ += f.object_bytes;
  } else if (o.object_bytes != f.object_bytes) {
    ++stats_.fragments_inconsistent;
    return Outcome::kInconsistent;
  }
  if (o.complete || o.have[f.fragment_index]) {
    ++stats_.fragments_duplicate;
    return Outcome::kDuplicate;
  }
  std::copy(f.payload.begin(), f.payload.end(),
            o.bytes.begin() + static_cast<std::ptrdiff_t>(begin));
  o.have[f.fragment_index] = true;
  ++o.have_count;
  o.last_fragment_ns = now_ns;
  ++stats_.fragments_accepted;
  if (o.have_count < o.fragment_count) return Outcome::kAccepted;
  o.complete = true;
  o.digest = ContentDigest(o.bytes);
  ++stats_.objects_completed;
  const auto m = manifest_.find(f.object_id);
  if (m != manifest_.end() && m->second.entry.version == o.version &&
      m->second.entry.digest != o.digest) {
    ++stats_.digest_mismatches;
    Release(o);  // ask for it again
  }
  return Outcome::kCompleted;
}

void SceneReassembler::OnManifest(const wire::SceneManifestMessage& m, std::int64_t now_ns) {
  manifest_total_ = m.total_objects;
  for (int i = 0; i < m.count; ++i) {
    const wire::ManifestEntry& e = m.entries[static_cast<std::size_t>(i)];
    if (manifest_.size() >= limits_.max_objects && !manifest_.contains(e.object_id)) {
      ++stats_.fragments_over_limit;  // a hostile manifest cannot grow memory
      continue;
    }
    auto [it, inserted] = manifest_.try_emplace(e.object_id);
    if (inserted || it->second.entry.version != e.version) {
      it->second.entry = e;
      it->second.first_seen_ns = now_ns;
      it->second.last_nack_ns = 0;
    }
    const auto o = objects_.find(e.object_id);
    if (o != objects_.end() && o->second.complete && o->second.version == e.version &&
        o->second.digest != e.digest) {
      ++stats_.digest_mismatches;
      Release(o->second);
    }
  }
}

void SceneReassembler::BuildNacks(std::int64_t now_ns, const RepairTiming& timing,
                                  std::vector<wire::SceneNackMessage>& out) {
  const std::int64_t gap = std::max<std::int64_t>(timing.gap_ns, 0);
  const std::int64_t repeat = std::max<std::int64_t>(timing.rtt_ns, 0) + gap;
  // Objects with fragments missing and nothing arriving.
  for (auto& [id, o] : objects_) {
    if (o.complete || o.bytes.empty()) continue;
    if (now_ns - o.last_fragment_ns < gap || now_ns - o.last_nack_ns < repeat) continue;
    const auto m = manifest_.find(id);
    if (m != manifest_.end() && m->second.entry.version > o.version) continue;  // superseded
    wire::SceneNackMessage n;
    n.object_id = id;
    n.version = o.version;
    for (std::uint16_t f = 0; f < o.fragment_count && n.count < wire::kMaxNackIndices; ++f) {
      if (!o.have[f]) n.missing[n.count++] = f;
    }
    o.last_nack_ns = now_ns;
    ++stats_.nacks_sent;
    stats_.fragments_nacked += n.count;
    out.push_back(n);
  }
  // Announced objects of which nothing (of that version) has arrived, or that failed their digest.
  for (auto& [id, a] : manifest_) {
    const auto o = objects_.find(id);
    const bool started = o != objects_.end() && o->second.version == a.entry.version &&
                         (o->second.complete || !o->second.bytes.empty());
    if (started) continue;
    // Never ask for what would be refused anyway (it would be re-sent for ever).
    if (a.entry.object_bytes > limits_.max_object_bytes ||
        bytes_held_ + a.entry.object_bytes > limits_.max_total_bytes) {
      continue;
    }
    // The sender streams its queue in order: while fragments still arrive, this object may be
    // behind them. The manifest travels ahead of the stream (with the Welcome), so its age must
    // cover a round trip before "nothing yet" means lost.
    if (now_ns - last_any_fragment_ns_ < gap || now_ns - a.first_seen_ns < repeat ||
        now_ns - a.last_nack_ns < repeat) {
      continue;
    }
    wire::SceneNackMessage n;
    n.object_id = id;
    n.version = a.entry.version;
    a.last_nack_ns = now_ns;
    a.first_seen_ns = std::min(a.first_seen_ns, now_ns);
    ++stats_.nacks_sent;
    stats_.fragments_nacked += a.entry.fragment_count;
    out.push_back(n);
  }
}

bool SceneReassembler::SceneComplete() const noexcept {
  return !manifest_.empty() && manifest_.size() == manifest_total_ &&
         verified_objects() == manifest_.size();
}

std::size_t SceneReassembler::verified_objects() const noexcept {
  std::size_t n = 0;
  for (const auto& [id, a] : manifest_) {
    const auto o = objects_.find(id);
    if (o != objects_.end() && o->second.complete && o->second.version == a.entry.version &&
        o->second.digest == a.entry.digest) {
      ++n;
    }
  }
  return n;
}

std::span<const std::uint8_t> SceneReassembler::CompletedBytes(
    std::uint32_t object_id) const noexcept {
  const auto o = objects_.find(object_id);
  if (o == objects_.end() || !o->second.complete) return {};
  return o->second.bytes;
}

std::optional<wire::SceneObjectKind> SceneReassembler::ObjectKind(
    std::uint32_t object_id) const noexcept {
  const auto a = manifest_.find(object_id);
  if (a == manifest_.end()) return std::nullopt;
  return a->second.entry.kind;
}

std::uint32_t SceneReassembler::CompletedVersion(std::uint32_t object_id) const noexcept {
  const auto o = objects_.find(object_id);
  if (o == objects_.end() || !o->second.complete) return 0;
  return o->second.version;
}

}  // namespace ht
