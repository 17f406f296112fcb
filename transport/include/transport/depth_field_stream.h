#pragma once
// The depth fields of a session's contact models over UDP (protocol.h: DepthFieldFragment,
// DepthFieldNack): each encoded field (codecs/depth_field_codec.h) cut into MTU-sized fragments
// that the remote node sends before the first contact model naming it, reassembled on the
// operator side, repaired by negative acknowledgement when a model names a field that has not
// arrived whole. Both ends are plain state machines (no sockets, no threads): the remote node's
// session and the operator station's network worker drive them.

#include <cstdint>
#include <deque>
#include <span>
#include <vector>

#include "transport/messages.h"

namespace ht {

/// Remote side: the encoded depth fields the operator may still ask for, and the fragments to
/// send next.
class DepthFieldSender {
 public:
  /// `mtu`: largest datagram (bytes), kMinMtuBytes..kMaxDatagramBytes; `keep`: fields kept for
  /// repairs (≥ 1; the least recently named goes first). Throws std::invalid_argument outside
  /// those ranges.
  DepthFieldSender(std::size_t mtu, std::size_t keep);

  /// Forgets every field and the queue, and cuts fragments for `mtu` from now on (a new
  /// session). Throws std::invalid_argument for an MTU out of range.
  void Reset(std::size_t mtu);
  /// Whether field `id` is kept (it was added in this session and not dropped since). Marks it
  /// named now (it is kept over fields not named for longer).
  bool Named(std::uint32_t id) noexcept;
  /// Adds the encoded field `id` and queues all its fragments. Throws std::invalid_argument for
  /// an id 0 or one already kept, empty bytes or more than kMaxDepthFieldBytes.
  void Add(std::uint32_t id, std::vector<std::uint8_t> bytes);
  /// Queues the fragments a DepthFieldNack names (all of them when its count is 0) that are not
  /// queued already. Returns false (nothing queued) for a field not kept or an index out of
  /// range.
  bool OnNack(const wire::SceneNackMessage& nack);
  /// Queues every fragment of kept field `id` that is not queued already (a second copy of a
  /// field just sent, for a link that loses datagrams). Returns false for a field not kept.
  bool QueueAgain(std::uint32_t id);
  /// The next fragment to send, or false when the queue is empty. `payload` points into the
  /// field's bytes (valid until the next Add or Reset).
  bool Next(wire::SceneFragmentMessage& fragment);
  std::size_t queued() const noexcept { return queue_.size(); }
  std::size_t kept() const noexcept { return fields_.size(); }
  /// Fields added, fragments handed out by Next, and NACKs answered / refused, since
  /// construction.
  std::uint64_t fields_added() const noexcept { return fields_added_; }
  std::uint64_t fragments_sent() const noexcept { return fragments_sent_; }
  std::uint64_t bytes_sent() const noexcept { return bytes_sent_; }
  std::uint64_t nacks_answered() const noexcept { return nacks_answered_; }
  std::uint64_t nacks_refused() const noexcept { return nacks_refused_; }

 private:
  struct Field {
    std::uint32_t id = 0;
    std::vector<std::uint8_t> bytes;
    std::uint16_t fragment_count = 0;
    std::vector<bool> queued;  ///< per fragment: in the queue
    std::uint64_t named_at = 0;
  };
  Field* Find(std::uint32_t id) noexcept;
  std::size_t payload_ = 0, keep_ = 1;
  std::vector<Field> fields_;
  std::deque<std::pair<std::uint32_t, std::uint16_t>> queue_;  ///< field id, fragment
  std::uint64_t clock_ = 0;
  std::uint64_t fields_added_ = 0, fragments_sent_ = 0, bytes_sent_ = 0;
  std::uint64_t nacks_answered_ = 0, nacks_refused_ = 0;
};

/// Counters of the operator side (since construction; Reset keeps them).
struct DepthFieldReassemblyStats {
  std::uint64_t fragments_accepted = 0;
  std::uint64_t fragments_duplicate = 0;     ///< of a fragment or a field already whole
  std::uint64_t fragments_inconsistent = 0;  ///< size or count disagreeing with the field's others
  std::uint64_t fields_completed = 0;
  std::uint64_t fields_abandoned = 0;  ///< unfinished, dropped for a newer field's room
  std::uint64_t nacks_sent = 0;
  std::uint64_t fragments_nacked = 0;
};

/// Operator side: collects DepthFieldFragments into encoded fields, remembers which fields it
/// holds, and says which to ask for again. Memory: `slots` unfinished fields of at most
/// kMaxDepthFieldBytes each (allocated as they grow), and the ids of the last kHeldIds fields
/// handed on.
class DepthFieldReassembler {
 public:
  static constexpr std::size_t kHeldIds = 128;
  /// `mtu` as negotiated (fixes the payload per fragment); `slots` ≥ 1 fields in progress at
  /// once. Throws std::invalid_argument outside those ranges.
  DepthFieldReassembler(std::size_t mtu, std::size_t slots = 16);

  enum class Outcome : std::uint8_t { kAccepted, kCompleted, kDuplicate, kInconsistent };
  /// Adds a fragment received at `now_ns` (operator clock). On kCompleted, completed() holds the
  /// field's bytes until the next Add; the caller decodes them and calls Held() when the field
  /// was handed on (a field that did not decode, or found no room, is asked for again).
  Outcome Add(const wire::SceneFragmentMessage& fragment, std::int64_t now_ns);
  std::span<const std::uint8_t> completed() const noexcept { return completed_; }
  std::uint32_t completed_id() const noexcept { return completed_id_; }
  /// Field `id` was handed on: later fragments of it are duplicates and a model naming it needs
  /// no repair.
  void Held(std::uint32_t id) noexcept;
  /// Whether field `id` was handed on (among the last kHeldIds).
  bool IsHeld(std::uint32_t id) const noexcept;
  /// Field `id`, handed on, is not held where it went (evicted there): no longer held, and
  /// wanted from `now_ns` on (Wanted).
  void Lost(std::uint32_t id, std::int64_t now_ns);
  /// A contact model received at `now_ns` names field `id`: it will be asked for again if it is
  /// not held by the time CollectNacks finds the repair due.
  void Wanted(std::uint32_t id, std::int64_t now_ns);
  /// When repairs are asked for (operator clock, ns): a field named by a model and not held is
  /// asked for `gap_ns` after the model came (fragments go before their model: later than that
  /// they were lost), and again every `rtt_ns + gap_ns` while it is still named (a model in the
  /// last second named it) and not held. The NACK lists its missing fragments (at most
  /// kMaxNackIndices) or, when nothing of it came, asks for all (count 0).
  struct RepairTiming {
    std::int64_t rtt_ns = 0;
    std::int64_t gap_ns = 10'000'000;
  };
  template <typename Send>
  void CollectNacks(std::int64_t now_ns, const RepairTiming& timing, Send&& send) {
    nack_scratch_.clear();
    BuildNacks(now_ns, timing, nack_scratch_);
    for (const wire::SceneNackMessage& n : nack_scratch_) send(n);
  }
  const DepthFieldReassemblyStats& stats() const noexcept { return stats_; }
  /// Forgets every field (a new session; ids restart).
  void Reset(std::size_t mtu);

 private:
  struct Partial {
    std::uint32_t id = 0;  ///< 0: free
    std::uint32_t field_bytes = 0;
    std::uint16_t fragment_count = 0;
    std::vector<std::uint8_t> bytes;
    std::vector<bool> have;
    std::uint32_t have_count = 0;
    std::int64_t last_fragment_ns = 0;
  };
  struct Want {
    std::uint32_t id = 0;
    std::int64_t first_ns = 0, last_named_ns = 0, last_nack_ns = 0;
  };
  void BuildNacks(std::int64_t now_ns, const RepairTiming& timing,
                  std::vector<wire::SceneNackMessage>& out);
  std::size_t payload_ = 0;
  std::vector<Partial> partials_;
  std::vector<std::uint8_t> completed_;
  std::uint32_t completed_id_ = 0;
  std::vector<std::uint32_t> held_;  ///< ring of the last kHeldIds held ids
  std::size_t held_next_ = 0;
  std::vector<Want> wants_;
  DepthFieldReassemblyStats stats_;
  std::vector<wire::SceneNackMessage> nack_scratch_;
};

}  // namespace ht
