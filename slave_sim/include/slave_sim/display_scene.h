#pragma once
// The scene as the remote node streams it for the operator's display (protocol v5): one Draco
// mesh per distinct mesh in its own frame, the scene graph (nodes with parent, local pose, mesh,
// material and the tool/touchable/moving flags), the materials' base-colour images as the file has
// them, and afterwards the local poses of the moving nodes at a display rate.

#include <cstdint>
#include <string>
#include <vector>

#include "codecs/gltf_scene.h"
#include "haptic_core/haptic_model.h"
#include "haptic_core/haptic_scene.h"
#include "transport/messages.h"
#include "transport/scene_graph.h"

namespace ht {

struct BuiltScene;

/// One object of the scene stream (transport/scene_stream.h): its id, what its bytes are, and the
/// bytes.
struct StreamObject {
  std::uint32_t id = 0;
  wire::SceneObjectKind kind = wire::SceneObjectKind::kDracoMesh;
  std::vector<std::uint8_t> bytes;
};

/// Object id of the scene graph in every stream MakeDisplayStream() makes; meshes and images
/// follow it (2, 3, ...).
inline constexpr std::uint32_t kSceneGraphObjectId = 1;

/// What the remote node streams for display.
struct DisplayStream {
  /// The scene graph first (kSceneGraphObjectId), then one kDracoMesh per distinct mesh and
  /// material (positions in the mesh's node frame N, metres; with TEXCOORD_0 as a Draco TEX_COORD
  /// attribute when the mesh has it), then one kImage per base-colour image a material uses.
  std::vector<StreamObject> objects;
  /// The decoded form of objects[0].
  SceneGraphDescription graph;
  /// For a scene from a glTF file: for each entry of GltfScene::nodes, its node index in `graph`
  /// (-1 for none). Empty for the built-in scenes.
  std::vector<int> graph_node_of_entry;
  /// Nodes of `graph` whose local pose the stream updates (kSceneNodeMoving, not the tool).
  std::vector<std::uint16_t> moving_nodes;
  /// For a scene from a glTF file: per node of `graph`, the node whose glTF mesh it shows a
  /// further material part of (a child at the identity), −1 for the nodes of the file. A mesh
  /// whose primitives have several materials is sent as one Draco object per material (the
  /// first on the node itself), so that each part can be drawn in its material and texture.
  std::vector<int> part_of;
};

/// The stream of a built-in scene: the tool's full-resolution mesh in its frame Ft (placed at
/// X_TFt in the tool frame T; the tool node is a root flagged kSceneNodeTool whose pose is given
/// in T, which the operator places at its simulated tool pose), and each touchable object's
/// full-resolution mesh in its model frame O (nullptr: its coarse model mesh), placed at its X_WO.
/// Names and base colours are fixed per role. Throws std::invalid_argument when `object_meshes`
/// is not one per touchable, and what EncodeMeshDraco / EncodeSceneGraph throw.
DisplayStream MakeDisplayStream(const HapticScene& scene, const TriangleMesh& tool_mesh_Ft,
                                const RigidTransform& X_TFt,
                                const std::vector<const TriangleMesh*>& object_meshes);

/// The stream of a scene built from a glTF file: every node of the file's node tree, its meshes
/// (each once, in N), the materials (base colour, base-colour image), the file's camera, the
/// tool node (or the built-in probe) as a root in the tool frame T, the touchable nodes flagged,
/// and the nodes that animation 0 moves flagged kSceneNodeMoving. Meshes without triangles are not
/// sent (their nodes stay, without a mesh). Throws what EncodeMeshDraco / EncodeSceneGraph throw.
DisplayStream MakeDisplayStream(const BuiltScene& scene);

/// The local poses of the stream's moving nodes at `time_s` of the scene's animation 0 (looping,
/// the clock the haptic scene is animated with): appended to `poses` (cleared first), one per
/// moving node. `scratch` is reused so that, once grown, a call allocates nothing. No-op for a
/// scene without animations.
void DisplayNodePosesAt(const BuiltScene& scene, const DisplayStream& stream, double time_s,
                        std::vector<GltfNodePose>* scratch, std::vector<wire::NodePose>* poses);

}  // namespace ht
