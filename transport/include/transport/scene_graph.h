#pragma once
// The scene as a scene: the scene-graph object (SceneObjectKind::kSceneGraph) that places the
// meshes (kDracoMesh objects, positions in their own frames) and names their materials and
// base-colour textures (kImage objects), which node is the tool and which are touchable; and the
// operator's side of NodePoses (newest wins per node). The byte layout is in protocol.h.
//
// Frames: W the remote world; N a node's frame; P its parent's frame (W for a root).

#include <cstddef>
#include <cstdint>
#include <glm/gtc/quaternion.hpp>
#include <glm/mat4x4.hpp>
#include <glm/vec3.hpp>
#include <glm/vec4.hpp>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "transport/messages.h"

namespace ht {

/// Bits of SceneGraphNode::flags.
enum SceneNodeFlags : std::uint8_t {
  kSceneNodeTool = 1,       ///< the node whose frame is the tool T (its mesh is the tool's)
  kSceneNodeTouchable = 2,  ///< its mesh takes part in contact
  kSceneNodeMoving = 4,     ///< its local pose is sent in NodePoses
};
/// Every SceneNodeFlags bit; other bits are refused.
inline constexpr std::uint8_t kSceneNodeAllFlags =
    kSceneNodeTool | kSceneNodeTouchable | kSceneNodeMoving;

/// One node of the scene graph: a frame N placed in its parent frame P, optionally carrying a mesh.
struct SceneGraphNode {
  std::string name;             ///< ≤ kMaxSceneGraphNameBytes bytes of UTF-8
  std::int32_t parent = -1;     ///< index into nodes, < this node's index; −1 = root (P is W)
  glm::dvec3 translation{0.0};  ///< p_PN, of N's origin in P (m)
  glm::dquat rotation{1.0, 0.0, 0.0, 0.0};  ///< R_PN; not zero, normalized where it is used
  glm::dvec3 scale{1.0};                    ///< along N's axes (1)
  /// Scene object id of its mesh (a kDracoMesh object, positions in N); 0 = none.
  std::uint32_t mesh_object = 0;
  std::int32_t material = -1;  ///< index into materials, −1 = default
  std::uint8_t flags = 0;      ///< SceneNodeFlags
};

/// A material: glTF's base colour (factor and texture), the rest is the operator's default.
struct SceneMaterial {
  std::string name;                              ///< ≤ kMaxSceneGraphNameBytes bytes of UTF-8
  glm::vec4 base_colour_rgba{1.0f};              ///< linear, glTF baseColorFactor
  std::uint32_t base_colour_texture_object = 0;  ///< kImage object id, 0 = none
  std::string texture_mime;                      ///< "image/png", "image/jpeg", or "" (no texture)
};

/// The scene file's camera: looks along −z of its node's frame, +y up (glTF's convention).
struct SceneGraphCamera {
  std::int32_t node = -1;  ///< index into nodes; −1 = the camera frame is W itself
  double yfov_rad = 0.8;   ///< vertical field of view, (0, π)
  double znear_m = 0.01;   ///< > 0
  double zfar_m = 0.0;     ///< 0 = infinite, else > znear_m
};

/// What a kSceneGraph object carries.
struct SceneGraphDescription {
  std::string scene_name;                  ///< ≤ kMaxSceneGraphNameBytes bytes of UTF-8
  std::vector<SceneGraphNode> nodes;       ///< parents first; ≤ kMaxSceneGraphNodes
  std::vector<SceneMaterial> materials;    ///< ≤ kMaxSceneMaterials
  std::optional<SceneGraphCamera> camera;  ///< the file's camera, when it has one
};

inline constexpr std::size_t kMaxSceneGraphNodes = 65535;
inline constexpr std::size_t kMaxSceneMaterials = 4096;
/// Longest name, scene name or MIME type (bytes).
inline constexpr std::size_t kMaxSceneGraphNameBytes = 255;

/// `name` as a scene graph can carry it: "" when it is not well-formed UTF-8, else its longest
/// prefix of at most kMaxSceneGraphNameBytes bytes that ends on a character boundary. For names
/// taken from files (glTF node, mesh and material names have no length limit). Never throws
/// except std::bad_alloc.
std::string SceneGraphName(std::string_view name);

/// The bytes of a kSceneGraph object (layout in protocol.h). Throws std::invalid_argument, with a
/// message naming the node, material or field, on: a parent not in [−1, index), a non-finite
/// value, a rotation of zero length (or whose squared norm is not a finite double ≥ 1e-24), a
/// name, scene name or MIME type longer than kMaxSceneGraphNameBytes or not UTF-8, unknown flag
/// bits, more than kMaxSceneGraphNodes nodes or kMaxSceneMaterials materials, a material index
/// outside [−1, #materials), a camera node outside [−1, #nodes), a camera yfov outside (0, π), a
/// znear ≤ 0, a zfar neither 0 nor > znear.
std::vector<std::uint8_t> EncodeSceneGraph(const SceneGraphDescription& graph);

/// Reads a kSceneGraph object. True and `*out` replaced when the bytes are a graph
/// EncodeSceneGraph would write (it gives these bytes back exactly); otherwise false, `*out`
/// untouched and `*error` (when not null) a message naming what is wrong: truncation, bad magic
/// or format version, counts beyond their limits or beyond the bytes present (checked before any
/// allocation), a value EncodeSceneGraph refuses (parent out of order, non-finite value, zero
/// rotation, bad material or camera index, ...), trailing bytes. Never reads out of range; throws
/// nothing but std::bad_alloc.
bool DecodeSceneGraph(std::span<const std::uint8_t> bytes, SceneGraphDescription* out,
                      std::string* error);

/// A node's local transform in its parent frame: X_PN = T(translation)·R(rotation)·S(scale).
struct SceneNodeTransform {
  glm::dvec3 translation{0.0};              ///< p_PN (m)
  glm::dquat rotation{1.0, 0.0, 0.0, 0.0};  ///< R_PN (normalized where it is used)
  glm::dvec3 scale{1.0};
};

/// The rest transform of every node (#nodes), as the graph gives them.
std::vector<SceneNodeTransform> RestTransforms(const SceneGraphDescription& graph);

/// X_WN of every node (#nodes, column-major 4×4, m), composed from the roots down:
/// X_WN = X_WP·T(translation)·R(rotation/‖rotation‖)·S(scale), X_WP = identity for a root.
/// Throws std::invalid_argument when a parent is not in [−1, index).
std::vector<glm::dmat4> ComposeWorldPoses(const SceneGraphDescription& graph);
/// The same with each node's local transform taken from `local` (#nodes, e.g.
/// SceneNodePoses::local()) instead of the graph's rest pose; an empty `local` means the rest
/// poses. Throws std::invalid_argument when a parent is not in [−1, index) or `local` has another
/// size.
std::vector<glm::dmat4> ComposeWorldPoses(const SceneGraphDescription& graph,
                                          std::span<const SceneNodeTransform> local);

/// Counters of SceneNodePoses.
struct SceneNodePosesStats {
  std::uint64_t entries_applied = 0;
  std::uint64_t entries_stale = 0;         ///< older scene_time_s than the node's current one
  std::uint64_t entries_bad_node = 0;      ///< node index ≥ #nodes
  std::uint64_t messages_other_graph = 0;  ///< graph_version not this graph's
};

/// Operator side of NodePoses: every node's current local transform, the graph's rest pose until
/// a NodePoses entry for it arrives, then per node the entry of the newest scene_time_s (an entry
/// as new as the current one replaces it; older ones are dropped). Apply() neither allocates nor
/// throws.
class SceneNodePoses {
 public:
  /// Starts at `graph`'s rest poses. `graph_version`: the version of the kSceneGraph object the
  /// graph came from (SceneReassembler::CompletedVersion), which NodePoses must name.
  SceneNodePoses(const SceneGraphDescription& graph, std::uint32_t graph_version);
  /// Applies a decoded NodePoses message. A message for another graph_version is ignored (the
  /// operator has not got that graph yet, or the remote node moved on). Returns the entries
  /// applied.
  std::size_t Apply(const wire::NodePosesMessage& message) noexcept;
  /// Current X_PN of every node (#nodes), for ComposeWorldPoses(graph, local()).
  std::span<const SceneNodeTransform> local() const noexcept { return local_; }
  /// scene_time_s of the entry a node holds; −∞ while it holds its rest pose (or out of range).
  double node_time_s(std::size_t node) const noexcept;
  /// The newest scene_time_s applied to any node; −∞ before any.
  double newest_time_s() const noexcept { return newest_time_s_; }
  std::uint32_t graph_version() const noexcept { return graph_version_; }
  const SceneNodePosesStats& stats() const noexcept { return stats_; }

 private:
  std::uint32_t graph_version_;
  std::vector<SceneNodeTransform> local_;
  std::vector<double> time_s_;
  double newest_time_s_;
  SceneNodePosesStats stats_;
};

}  // namespace ht
