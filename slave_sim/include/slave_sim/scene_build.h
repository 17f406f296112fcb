#pragma once
// Scenes from files: a glTF 2.0 scene plus an optional scene description say which
// nodes are the tool, which are touchable and which only shown; the touchable ones (and a tool
// node) are built into haptic models (DESIGN.md §2) through the on-disk cache.

#include <functional>
#include <memory>
#include <nlohmann/json_fwd.hpp>
#include <string>
#include <vector>

#include "codecs/gltf_scene.h"
#include "haptic_core/haptic_scene.h"
#include "haptic_core/model_build/haptic_model_build.h"

namespace ht {

/// What a node of the scene is for.
enum class NodeRole {
  kTool,       ///< The operator's tool T (at most one node).
  kTouchable,  ///< A touchable object O: coarse mesh, haptic texture and hull hierarchy built.
  kDisplay,    ///< Shown only: nothing is built for it.
};

/// "tool", "touchable", "display".
const char* NodeRoleName(NodeRole role) noexcept;

/// Build settings of one node.
struct NodeSpec {
  NodeRole role = NodeRole::kTouchable;
  /// Penalty stiffness of the object's surface (N/m).
  double stiffness_n_per_m = 8000.0;
  /// Coarse triangle target.
  int coarse_triangles = 500;
  /// Haptic texture atlas side (texels, power of two); 0 ("auto" in a description): chosen per
  /// object from its surface's detail (TextureSizingParams, haptic_model_build.h).
  int texture_size = 512;
  /// With texture_size 0: the surface error p99 (m) a size must reach
  /// (TextureSizingParams::surface_budget_m; "texture_budget_um" in a description).
  double texture_budget_m = 10e-6;
};

/// A scene file and what to build from it. Written as JSON:
/// ```json
/// {"scene": "Duck.glb",                      // glTF path, relative to this file's folder
///  "defaults": {"role": "touchable", "stiffness_n_per_m": 8000, "coarse_triangles": 500,
///               "texture_size": 512},           // or "auto" (with "texture_budget_um": 10)
///  "nodes": {"LOD3spShape": {"coarse_triangles": 800}, "camera1": {"role": "display"},
///            "#12": {"role": "display"}},     // by node name, or "#" + node index
///  "tool": "probe"}                          // node name or "#index"; absent: built-in probe
/// ```
/// Unknown keys are refused (a typo must not silently change a build).
struct SceneDescription {
  /// The glTF file (absolute or relative to the working folder).
  std::string gltf_path;
  /// Settings of nodes the description does not name.
  NodeSpec defaults;
  /// Per-node overrides, in file order: key is a node name or "#<node index>".
  std::vector<std::pair<std::string, NodeSpec>> nodes;
  /// The tool node (name or "#index"); "" means the built-in probe (a small ridged block).
  std::string tool_node;
  /// The glTF file's length unit in metres (ScaleGltfScene): glTF is in metres, but many CAD
  /// exports are in millimetres. From the description's "scale" (a number > 0) or "units"
  /// ("m", "cm", "mm", "in", "ft"), at most one of them; 1 by default.
  double scale = 1.0;

  /// Reads a description file. Throws std::runtime_error starting with `path` when the file
  /// cannot be read, is not JSON, has an unknown key, a role that is not tool/touchable/display,
  /// a non-positive stiffness, a coarse target below 4, a texture size that is neither "auto" nor a
  /// power of two in [16, 8192], a texture budget that is not a number > 0, a scale that is not a
  /// finite number > 0, units it does not know, or both scale and units.
  static SceneDescription LoadFile(const std::string& path);

  /// The description of a plain glTF file: every mesh node touchable with `defaults`, built-in
  /// probe as the tool.
  static SceneDescription ForGltf(const std::string& gltf_path);
};

/// A `.json` path is read as a SceneDescription, anything else as a plain glTF file; a non-empty
/// `tool_node` overrides the description's tool. Throws as LoadFile().
SceneDescription LoadSceneInput(const std::string& path, const std::string& tool_node = "");

/// One node of a built scene.
struct SceneNode {
  std::string node_name;
  int node_index = -1;
  /// What messages call the node: its name, else its mesh's name, else "#<node index>".
  std::string label;
  /// Index into GltfScene::meshes.
  int mesh = -1;
  NodeSpec spec;
  /// Rigid part of the node's pose, X_WO (the glTF scene frame W: +Y up, metres). The node's
  /// scale and shear are applied to the vertices of its model instead. For the tool, O is moved
  /// to the model's centre of mass (the tool frame T).
  RigidTransform X_WO;
  /// The scale and shear of the node's rest pose, baked into the model's vertices
  /// (X_WN = [R_WO·rest_residual | p_WO]).
  glm::dmat3 rest_residual{1.0};
  /// Triangles of the node's mesh.
  std::int64_t full_triangles = 0;
  /// The haptic model (tool and touchable roles; null for display nodes) and how it was built.
  std::shared_ptr<const HapticModel> model;
  HapticModelBuildReport report;
};

/// A scene ready for the remote node.
struct BuiltScene {
  SceneDescription description;
  GltfScene gltf;
  /// Every mesh node of the glTF scene, in the loader's order.
  std::vector<SceneNode> objects;
  /// The haptic scene: tool (a node, or the built-in probe) and the touchable objects with their
  /// stiffness; X_WT_home puts the tool 1 cm above the top (+Y) of the touchables' bounds (their
  /// coarse meshes widened by the texture's outward reach), its rotation SceneUpRotation(): the
  /// operator's workspace frame M, whose +z is the scene's up. A tool node's model frame T is
  /// turned so that the node keeps its own orientation at that pose (RotateModelFrame).
  HapticScene haptic;
  /// For each entry of haptic.touchables, the index of its object in `objects`.
  std::vector<int> touchable_objects;
  /// True when the tool is the built-in probe.
  bool builtin_probe = true;
  /// What the build decided on its own: nodes shown only because they have no triangles or a
  /// zero (singular) scale; and the warnings below.
  std::vector<std::string> notes;
  /// What a user should look at (also in notes): touchables spanning more than
  /// kLargestDeskSceneM (most often a file in millimetres), or a node whose bake's largest error
  /// is above kLargeBakeErrorFraction of its size. slave_sim prints them at start.
  std::vector<std::string> warnings;
  /// Time to load the glTF file (s) and for the whole build (s).
  double load_s = 0.0;
  double total_s = 0.0;
};

/// The rotation R_WM from the operator's workspace axes (M: +z up, +y away from the user, +x to
/// the right) to a glTF scene's (W: +Y up, −Z away from a viewer on the default camera, +X to the
/// right): a quarter turn about x. Every built scene's home pose has it.
glm::dquat SceneUpRotation() noexcept;

/// A scene whose touchable objects span more than this (m) gets a warning (BuiltScene::warnings).
inline constexpr double kLargestDeskSceneM = 2.0;
/// A node whose bake's largest error exceeds this fraction of its size (its coarse mesh's
/// bounding-box diagonal) gets a warning.
inline constexpr double kLargeBakeErrorFraction = 0.05;
/// A model whose full-resolution surface lies more than 25 µm outside it (MeasureSurfaceError,
/// HapticModelBuildReport::surface) on a larger share of its area than this is warned about too.
inline constexpr double kLargeSurfaceOutsideShare = 0.05;

/// Progress callback: called before each model is built or loaded from the cache, with the
/// object's label (SceneNode::label), its position among the models to build (from 1) and their
/// count.
using SceneBuildProgress = std::function<void(const std::string& node, int index, int count)>;

/// Loads `description.gltf_path` and builds the haptic model of every tool and touchable node
/// through `cache` (one build per distinct mesh, scale and settings; instances share it).
/// Display nodes get none. Throws std::runtime_error starting with the glTF path when it cannot be
/// loaded, a description key names no node, two nodes are the tool, or a build fails.
BuiltScene BuildScene(const SceneDescription& description, const HapticModelCache& cache,
                      const SceneBuildProgress& progress = {});

/// Plays the glTF node animations (DESIGN.md: moving parts without a physics engine): moves every
/// touchable object to its pose at `time_s` (s) of animation `animation` (an index into
/// gltf.animations; looping), writing objects[i].X_WO and haptic.touchables[k].X_WO. Only the
/// rigid part of an animated node transform moves the model (its scale stays the one it was
/// built with). An out-of-range `animation` or a non-finite time gives the rest poses. `scratch`
/// is reused between calls so that, once grown, a call allocates nothing. Never throws except
/// std::bad_alloc when `scratch` grows.
void AnimateScene(BuiltScene& scene, int animation, double time_s,
                  std::vector<glm::dmat4>* scratch);

/// The JSON object `slave_sim inspect` prints: {"file", "load_s", "total_s", "tool",
/// "objects": [{"name", "node_index", "role", "full_triangles", "coarse_triangles",
/// "hull_count", "hull_leaves", "texture_size", "bake_max_error_m", "bake_rms_error_m",
/// "bake_misses", "bake_clamped", "from_cache", "seconds": {"decimate", "bake", "hulls",
/// "cache_load", "total"}}], "notes": [...]} (display nodes carry only name, role and
/// full_triangles).
nlohmann::json InspectJson(const BuiltScene& scene);

}  // namespace ht
