#pragma once
// Scene updates over UDP: objects (Draco meshes, the scene graph, texture images: SceneObjectKind
// in protocol.h) cut into MTU-sized fragments, reassembled on the operator side, repaired by
// negative acknowledgement (NACK), with a newer version of an object superseding an older one (an
// unfinished one is dropped at once; a finished one is replaced when the first fragment of the
// newer arrives). Both ends are plain state machines (no sockets): the remote node and the
// operator station drive them from their network loops.

#include <cstdint>
#include <deque>
#include <map>
#include <optional>
#include <span>
#include <vector>

#include "transport/messages.h"

namespace ht {

/// One scene object as the remote node holds it.
struct SceneObject {
  std::uint32_t object_id = 0;
  std::uint32_t version = 0;  ///< starts at 1; bumped by SceneSender::Update
  wire::SceneObjectKind kind = wire::SceneObjectKind::kDracoMesh;
  std::vector<std::uint8_t> bytes;
  std::array<std::uint8_t, wire::kSceneDigestBytes> digest{};
  std::uint16_t fragment_count = 0;
};

/// Remote side: what to send next. Fragments go out in a queue paced by the caller's byte budget;
/// a new session queues every fragment, a NACK queues the fragments it names.
class SceneSender {
 public:
  /// `mtu`: largest datagram (bytes), kMinMtuBytes..kMaxDatagramBytes. Throws
  /// std::invalid_argument outside that range.
  explicit SceneSender(std::size_t mtu);

  /// Adds an object, or replaces its bytes with a new version (queued fragments of the old one are
  /// skipped). Throws std::invalid_argument when the bytes are empty, exceed kMaxSceneObjectBytes
  /// or need more than 65535 fragments at this MTU, or `kind` is not a SceneObjectKind. Returns the
  /// object's version.
  std::uint32_t Update(std::uint32_t object_id, std::vector<std::uint8_t> bytes,
                       wire::SceneObjectKind kind = wire::SceneObjectKind::kDracoMesh);
  /// Changes the MTU (a new session negotiated another); every object is re-cut.
  void SetMtu(std::size_t mtu);
  /// Forgets the queue and queues every fragment of every object (a new session).
  void QueueAll();
  /// Queues the fragments a NACK names (all of them when its count is 0). Returns false (nothing
  /// queued) when it names an unknown object, an old version or an index out of range.
  bool OnNack(const wire::SceneNackMessage& nack);
  /// The next fragment to send, or false when the queue is empty. `payload` points into the
  /// object's bytes (valid until the next Update).
  bool Next(wire::SceneFragmentMessage& fragment);
  /// Fragments waiting.
  std::size_t queued() const noexcept { return queue_.size(); }
  /// Manifest datagram bodies covering all objects (ceil(#objects / kMaxManifestEntries) of them).
  std::vector<wire::SceneManifestMessage> Manifest() const;
  const std::vector<SceneObject>& objects() const noexcept { return objects_; }
  std::size_t payload_bytes() const noexcept { return payload_; }

 private:
  struct Pending {
    std::uint32_t object_index;
    std::uint32_t version;
    std::uint16_t fragment;
  };
  std::size_t payload_;
  std::vector<SceneObject> objects_;
  std::deque<Pending> queue_;
  std::vector<std::vector<bool>> queued_;  ///< per object, per fragment: already in the queue
};

/// Times the operator sends each NACK (back to back, each with its own sequence number). A NACK is
/// small (a body of at most kSceneNackFixedBytes + 2 * kMaxNackIndices bytes) and a lost one costs
/// a whole repeat period (a round trip plus the gap); a copy that arrives with the first finds its
/// fragments still queued and queues nothing more (SceneSender::OnNack). Measured in
/// `SceneStream.RepairsOverALongLossyLinkAreTimelyAndRarelyDuplicate` (150 ms each way, 20 % loss):
/// the slowest of 40 transfers took 4.1 s with one copy, 2.1 s with two.
inline constexpr int kSceneNackCopies = 2;

/// Limits on the operator side's reassembly memory.
struct ReassemblyLimits {
  std::size_t max_object_bytes = 16u << 20;  ///< larger objects are refused (counted)
  std::size_t max_total_bytes = 64u << 20;   ///< unfinished + finished objects, all together
  std::size_t max_objects = 256;             ///< distinct object ids kept
};

/// Counters of the reassembler (since construction; Reset keeps them).
struct ReassemblyStats {
  std::uint64_t fragments_accepted = 0;
  std::uint64_t fragments_duplicate = 0;
  std::uint64_t fragments_stale = 0;         ///< for a version older than one already seen
  std::uint64_t fragments_inconsistent = 0;  ///< size/count disagreeing with the object's others
  std::uint64_t fragments_over_limit = 0;    ///< fragments or manifest entries refused by limits
  std::uint64_t objects_completed = 0;
  std::uint64_t objects_superseded = 0;  ///< unfinished versions dropped for a newer one
  std::uint64_t digest_mismatches = 0;   ///< completed, but not the manifest's content
  std::uint64_t nacks_sent = 0;
  std::uint64_t fragments_nacked = 0;
};

/// Operator side: collects fragments into objects, checks them against the manifest, and says
/// which fragments to ask for again. Memory is bounded by ReassemblyLimits.
class SceneReassembler {
 public:
  /// `mtu` as negotiated (fixes the payload size per fragment).
  SceneReassembler(std::size_t mtu, ReassemblyLimits limits = {});

  /// What happened to one fragment.
  enum class Outcome : std::uint8_t {
    kAccepted,
    kCompleted,
    kDuplicate,
    kStale,
    kInconsistent,
    kOverLimit
  };
  /// Adds a fragment received at `now_ns` (operator clock).
  Outcome Add(const wire::SceneFragmentMessage& fragment, std::int64_t now_ns);
  /// Records the remote node's current objects (from a manifest datagram).
  void OnManifest(const wire::SceneManifestMessage& manifest, std::int64_t now_ns);
  /// When repairs are asked for (operator clock, ns).
  struct RepairTiming {
    /// Round trip to the remote node: a repeated NACK waits this long plus `gap_ns` for the
    /// answer to the previous one. 0 when not yet measured.
    std::int64_t rtt_ns = 0;
    /// Silence after a burst that marks its missing fragments as lost rather than still on their
    /// way (covers reordering and the sender's pacing between objects).
    std::int64_t gap_ns = 30000000;
  };
  /// Calls `send(nack)` for each object that needs repair:
  /// - an object of which fragments are missing and none has arrived for `gap_ns`: its missing
  ///   fragments (at most kMaxNackIndices), at most once per `rtt_ns + gap_ns`;
  /// - a manifest object nothing of which (at the manifest's version) has arrived, once the whole
  ///   stream has been silent for `gap_ns` and the manifest is `rtt_ns + gap_ns` old: all of it
  ///   (count 0), at most once per `rtt_ns + gap_ns`.
  /// A NACK repeated sooner than the round trip would fetch again fragments already on their way;
  /// one delayed much longer leaves the scene incomplete for long on a lossy link (a lost
  /// fragment costs one repeat period, and at 20 % loss each way 36 % of the round trips fail).
  template <typename Send>
  void CollectNacks(std::int64_t now_ns, const RepairTiming& timing, Send&& send);
  /// True when every manifest object is complete at the manifest's version and its digest matches.
  bool SceneComplete() const noexcept;
  /// Number of objects the manifest announced (0 before any manifest).
  std::size_t manifest_objects() const noexcept { return manifest_.size(); }
  /// Completed objects whose digest matches the manifest.
  std::size_t verified_objects() const noexcept;
  /// The complete bytes of an object (empty when it is not complete).
  std::span<const std::uint8_t> CompletedBytes(std::uint32_t object_id) const noexcept;
  /// What the manifest says the object is; nullopt for an object no manifest has announced.
  std::optional<wire::SceneObjectKind> ObjectKind(std::uint32_t object_id) const noexcept;
  /// Version of the object's complete bytes (those CompletedBytes gives); 0 when it is not
  /// complete (nothing yet, a newer version under way, or dropped on a digest mismatch). Watch it
  /// to see a new version of a mesh, the scene graph or an image arrive.
  std::uint32_t CompletedVersion(std::uint32_t object_id) const noexcept;
  /// Bytes held (unfinished and finished).
  std::size_t bytes_held() const noexcept { return bytes_held_; }
  const ReassemblyStats& stats() const noexcept { return stats_; }
  /// Forgets everything (a new session).
  void Reset(std::size_t mtu);

 private:
  struct Object {
    std::uint32_t version = 0;  ///< newest version seen (in progress or complete)
    std::uint32_t object_bytes = 0;
    std::uint16_t fragment_count = 0;
    std::vector<std::uint8_t> bytes;
    std::vector<bool> have;
    std::uint32_t have_count = 0;
    bool complete = false;
    std::array<std::uint8_t, wire::kSceneDigestBytes> digest{};
    std::int64_t last_fragment_ns = 0;
    std::int64_t last_nack_ns = 0;
  };
  struct Announced {
    wire::ManifestEntry entry;
    std::int64_t first_seen_ns = 0;
    std::int64_t last_nack_ns = 0;
  };
  void Release(Object& o);
  void BuildNacks(std::int64_t now_ns, const RepairTiming& timing,
                  std::vector<wire::SceneNackMessage>& out);

  std::size_t payload_;
  ReassemblyLimits limits_;
  std::map<std::uint32_t, Object> objects_;
  std::map<std::uint32_t, Announced> manifest_;
  std::size_t manifest_total_ = 0;
  std::size_t bytes_held_ = 0;
  std::int64_t last_any_fragment_ns_ = 0;  ///< newest fragment of any object (any outcome)
  ReassemblyStats stats_;
  std::vector<wire::SceneNackMessage> nack_scratch_;
};

template <typename Send>
void SceneReassembler::CollectNacks(std::int64_t now_ns, const RepairTiming& timing, Send&& send) {
  nack_scratch_.clear();
  BuildNacks(now_ns, timing, nack_scratch_);
  for (const wire::SceneNackMessage& n : nack_scratch_) send(n);
}

}  // namespace ht
