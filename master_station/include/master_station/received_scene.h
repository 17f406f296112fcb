#pragma once
// The remote scene as the operator station has received it (protocol v5): the scene graph, its
// meshes decoded from Draco in their own frames, and the moving nodes' newest local poses. The
// network thread writes it; the display thread reads it. Neither is the haptic loop, so a mutex
// guards it; the loop never touches it.

#include <cstdint>
#include <glm/vec2.hpp>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "haptic_core/haptic_model.h"
#include "transport/messages.h"
#include "transport/scene_graph.h"

namespace ht {

/// One version of the received scene's content (immutable once published).
struct ReceivedSceneContent {
  /// The scene graph (transport/scene_graph.h); when the stream carried none, one root node per
  /// mesh at the identity (the remote world W).
  SceneGraphDescription graph;
  /// Version of the kSceneGraph object it came from (0 when synthesized).
  std::uint32_t graph_version = 0;
  /// A decoded kDracoMesh object: positions in the frame N of the nodes that show it (m).
  struct Mesh {
    std::uint32_t object_id = 0;
    std::uint32_t version = 0;
    TriangleMesh mesh_N;
    /// TEXCOORD_0 per vertex (glTF's convention: (0, 0) the image's top-left), or empty.
    std::vector<glm::dvec2> uv_N;
  };
  /// Every mesh object that decoded, by object id ascending.
  std::vector<Mesh> meshes;
  /// A kImage object: a base-colour texture's bytes as the file had them.
  struct Image {
    std::uint32_t object_id = 0;
    std::uint32_t version = 0;
    std::vector<std::uint8_t> bytes;
  };
  std::vector<Image> images;
  /// Objects that did not decode (object id and why).
  std::vector<std::pair<std::uint32_t, std::string>> errors;
};

/// Counters of NodePoses at the operator (since construction).
struct ReceivedPoseStats {
  std::uint64_t messages = 0;               ///< NodePoses datagrams handed to ApplyPoses
  std::uint64_t messages_before_scene = 0;  ///< arrived before the scene graph (dropped)
  std::uint64_t entries_applied = 0;        ///< node poses that became current
  std::uint64_t entries_dropped = 0;        ///< stale, another graph version or a bad node index
};

/// The first and the newest local pose a moving node received (for the run summary).
struct ReceivedNodeTrack {
  std::uint16_t node = 0;                        ///< index into the graph's nodes
  std::string name;                              ///< the node's name in the graph
  std::uint64_t updates = 0;                     ///< NodePoses entries applied to it
  double first_time_s = 0.0, last_time_s = 0.0;  ///< the remote scene's clock (s)
  /// The node's local pose X_PN in its parent frame P (m, unit quaternion R_PN, scale) at
  /// first_time_s and at last_time_s.
  SceneNodeTransform first, last;
};

/// Thread-safe holder of the received scene (see the file comment).
class ReceivedScene {
 public:
  /// Publishes a new content (a completed scene stream). The moving nodes restart at the new
  /// graph's rest poses, unless the graph is the same version as before (another object changed):
  /// then they keep the poses received. Bumps generation().
  void Set(std::shared_ptr<const ReceivedSceneContent> content);
  /// Applies a NodePoses message (newest wins per node, transport/scene_graph.h SceneNodePoses).
  /// Returns the entries applied; a message before any content is counted and dropped.
  std::size_t ApplyPoses(const wire::NodePosesMessage& message);
  /// The current content (null before the first Set) and its generation (0 before).
  std::shared_ptr<const ReceivedSceneContent> Content(std::uint64_t* generation) const;
  /// Copies the current local transform X_PN of every node of the current content's graph into
  /// `local` (#nodes; empty before the first Set; resized, so it allocates only when it grows).
  void CopyPoses(std::vector<SceneNodeTransform>* local) const;
  ReceivedPoseStats pose_stats() const;
  /// Per moving node of the current graph (ascending node index, at most kMaxTrackedNodes): the
  /// first and newest pose applied.
  std::vector<ReceivedNodeTrack> node_tracks() const;
  static constexpr std::size_t kMaxTrackedNodes = 64;

 private:
  mutable std::mutex mutex_;
  std::shared_ptr<const ReceivedSceneContent> content_;
  std::uint64_t generation_ = 0;
  std::optional<SceneNodePoses> poses_;
  ReceivedPoseStats stats_;
  std::map<std::uint16_t, ReceivedNodeTrack> tracks_;
};

}  // namespace ht
