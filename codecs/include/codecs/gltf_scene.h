#pragma once
// Loading the triangle geometry of a glTF 2.0 scene (https://registry.khronos.org/glTF/specs/2.0/)
// for display and haptic baking: every mesh of the scene once, in its node frame, plus one
// instance per node that shows it, and the node tree with its translation/rotation/scale
// animations so that moving parts can be replayed (PoseInstancesAt) without a physics engine.
// For display, each material's base colour (and its base-colour texture's bytes, undecoded) and
// the first perspective camera are kept; skins and morph targets (with their `weights` animations)
// are ignored (a note says so). The parser is tinygltf 2.7 (compiled into this library under the
// name proj_tinygltf, see docs/DEPENDENCIES.md trap 1); Draco primitives
// (KHR_draco_mesh_compression) are decoded with libdraco.

#include <cstdint>
#include <filesystem>
#include <glm/gtc/quaternion.hpp>
#include <glm/mat4x4.hpp>
#include <glm/vec2.hpp>
#include <glm/vec3.hpp>
#include <glm/vec4.hpp>
#include <nlohmann/json_fwd.hpp>
#include <optional>
#include <string>
#include <vector>

#include "haptic_core/mesh.h"

namespace ht {

/// Most triangles (summed over the meshes of a scene, each mesh counted once) that
/// LoadGltfScene() accepts; a larger scene is refused rather than allocated.
inline constexpr std::int64_t kGltfMaxTriangles = 50'000'000;
/// Most vertices (summed over the meshes, each counted once) that LoadGltfScene() accepts.
inline constexpr std::int64_t kGltfMaxVertices = 50'000'000;
/// Largest file (bytes) that LoadGltfScene() reads; external buffers are bounded by the same
/// figure each.
inline constexpr std::int64_t kGltfMaxFileBytes = std::int64_t{1} << 31;
/// Most animation output elements (summed over the kept channels of all animations, a cubic
/// spline key counting 3) that LoadGltfScene() accepts: an accessor shared by many samplers could
/// otherwise multiply the memory taken past the file's size.
inline constexpr std::int64_t kGltfMaxAnimationKeys = 10'000'000;

/// One glTF mesh (all its triangle primitives merged), stored once however many nodes show it.
struct GltfMesh {
  /// The mesh's `name` in the file ("" when absent).
  std::string name;
  /// Index of the mesh in the file's `meshes` array.
  int gltf_mesh_index = -1;
  /// Geometry in the frame N of any node that shows the mesh, in the file's units (glTF says
  /// metres). Vertices #V; triangles #F, with the file's winding (counter-clockwise seen from the
  /// front). Strips and fans are converted to triangle lists. Triangles that repeat a vertex
  /// index carry no surface and are dropped (see dropped_degenerate_triangles); vertices are not
  /// merged or removed.
  TriangleMesh mesh_N;
  /// Texture coordinates TEXCOORD_0 of mesh_N's vertices, #V entries (uv_N[i] belongs to
  /// mesh_N.vertices[i]), as the file has them: glTF's convention, (0, 0) the image's top-left
  /// corner, u to the right and v down, (1, 1) the bottom-right, values outside [0, 1] repeating
  /// per the sampler. Normalized UNSIGNED_BYTE/SHORT coordinates are divided by 255 / 65535;
  /// Draco ones come dequantized. Either complete or empty: empty when no merged primitive has
  /// TEXCOORD_0, or when one without it has a material with a base-colour texture (a note says
  /// so). A primitive without TEXCOORD_0 whose material has no base-colour texture (or that has
  /// no material) gets (0, 0) at its vertices, with a note: its triangles sample no texture, and
  /// the mesh's other primitives keep theirs (CesiumMilkTruck's body beside its untextured glass
  /// and trim). Only TEXCOORD_0 is read: a material whose base-colour texture names another set,
  /// or has KHR_texture_transform, gets a note.
  std::vector<glm::dvec2> uv_N;
  /// The glTF material index (= index into GltfScene::materials) of the primitive each triangle
  /// came from, #F entries in the order of mesh_N.triangles (triangle_material[f] belongs to
  /// mesh_N.triangles[f]); -1 where the primitive names no material (or one out of range, with a
  /// note). Primitives are merged in the file's order, so each material's triangles form runs.
  std::vector<int> triangle_material;
  /// Number of triangle primitives merged into mesh_N (POINTS/LINES primitives excluded).
  int primitive_count = 0;
  /// How many of those primitives were KHR_draco_mesh_compression primitives.
  int draco_primitive_count = 0;
  /// Triangles dropped because they repeat a vertex index.
  std::int64_t dropped_degenerate_triangles = 0;
  /// Index into GltfScene::materials of the first merged primitive that names a material (the
  /// display shows the whole mesh in it); -1 when none does.
  int material = -1;
};

/// A glTF material as the display needs it: the base colour of pbrMetallicRoughness.
struct GltfMaterial {
  /// The material's `name` ("" when absent).
  std::string name;
  /// baseColorFactor (linear RGBA, each in [0, 1]; (1, 1, 1, 1) when absent).
  glm::dvec4 base_colour_rgba{1.0};
  /// Index into GltfScene::images of the baseColorTexture's source image; -1 when it has none
  /// (or the texture or image index is out of range, with a note).
  int base_colour_image = -1;
};

/// A glTF image's bytes as the file has them (PNG or JPEG, not decoded), from a buffer view, a
/// data URI or an external file.
struct GltfImage {
  /// The image's `name` ("" when absent).
  std::string name;
  /// "image/png" or "image/jpeg" from the bytes' signature; the file's mimeType otherwise.
  std::string mime_type;
  std::vector<std::uint8_t> bytes;
};

/// The scene's first perspective camera (the first node in depth-first order that shows one).
struct GltfCamera {
  /// Index into GltfScene::nodes of the node that carries it (the camera looks along −Z of that
  /// node's frame, +Y up, glTF 2.0 §3.10).
  int scene_node = -1;
  /// Vertical field of view (rad, > 0), near plane (m, > 0) and far plane (m; 0 = infinite).
  double yfov_rad = 0.8;
  double znear_m = 0.01;
  double zfar_m = 0.0;
};

/// One node of the scene that shows a mesh.
struct GltfMeshInstance {
  /// The node's `name` in the file ("" when absent), and its index in the `nodes` array.
  std::string node_name;
  int node_index = -1;
  /// Index into GltfScene::meshes (not the file's mesh index: see GltfMesh::gltf_mesh_index).
  int mesh = -1;
  /// Pose of node frame N in the scene frame W (the glTF scene root: right-handed, +Y up,
  /// metres), composed from the root down of each node's `matrix` or T·R·S. It may hold scale
  /// (and, when a file gives one, shear); the bottom row is (0, 0, 0, 1). Column-major like glTF:
  /// p_W = X_WN * (p_N, 1).
  glm::dmat4 X_WN{1.0};
  /// Index into GltfScene::nodes of the entry (the path from a root) this instance is shown at.
  int scene_node = -1;
};

/// One entry of the scene's node tree: a node reached from the scene's roots, once per path
/// (a node that several parents share, which glTF 2.0 forbids but some files do, has one entry
/// per path; in a conforming file every reachable node has exactly one entry).
struct GltfNode {
  /// Index of the node in the file's `nodes` array.
  int node_index = -1;
  /// Index into GltfScene::nodes of the parent entry (always smaller than this entry's index:
  /// entries are in depth-first pre-order), -1 for a root of the scene.
  int parent = -1;
  /// The next entry of the same file node (another path to it), -1 for none.
  int next_same_node = -1;
  /// True when the node gives a `matrix` (then translation/rotation/scale keep their defaults and
  /// the node is never animated); false when it gives translation/rotation/scale (or nothing).
  bool has_matrix = false;
  /// Rest translation of N in its parent P (metres), rest rotation R_PN (unit quaternion; the
  /// file's (x, y, z, w) normalized; glm::dquat's constructor takes (w, x, y, z)) and rest scale
  /// (per N axis, unitless). Defaults when the file omits them: (0,0,0), identity, (1,1,1).
  glm::dvec3 translation{0.0};
  glm::dquat rotation{1.0, 0.0, 0.0, 0.0};
  glm::dvec3 scale{1.0};
  /// Rest pose of N in its parent P (the scene frame W for a root): the `matrix`, or T·R·S.
  /// Column-major like glTF: p_P = X_PN * (p_N, 1).
  glm::dmat4 X_PN{1.0};
  /// The node's `name` ("" when absent).
  std::string name;
  /// Index into GltfScene::meshes of the mesh the node shows; -1 for none.
  int mesh = -1;
};

/// How an animation sampler interpolates between keys (glTF 2.0 §3.11, Appendix C).
enum class GltfInterpolation { kLinear, kStep, kCubicSpline };

/// One animated property of one node: an animation channel with its sampler's keys.
struct GltfAnimationChannel {
  /// The target's index in the file's `nodes` array.
  int node = -1;
  /// The first entry of GltfScene::nodes for that node (further paths to it: follow
  /// GltfNode::next_same_node).
  int scene_node = -1;
  /// The animated property: translation (metres, in the parent frame), rotation (R_PN as a
  /// quaternion) or scale (unitless); it replaces the node's rest value while the other two keep
  /// theirs.
  enum class Path { kTranslation, kRotation, kScale } path = Path::kTranslation;
  GltfInterpolation interpolation = GltfInterpolation::kLinear;
  /// Key times #K (seconds from the animation's start), finite, >= 0 and non-decreasing; K >= 1.
  std::vector<double> times_s;
  /// Key values as read from the file (FLOAT, finite): #K, or #3K for kCubicSpline, which keeps
  /// (in-tangent, value, out-tangent) triplets per key. (x, y, z, unused 0) for translation and
  /// scale; the quaternion (x, y, z, w) for rotation (values of non-zero length, normalized
  /// when sampled; tangents are not unit).
  std::vector<glm::dvec4> values;
};

/// One glTF animation: the channels that move translation/rotation/scale of nodes in the scene.
struct GltfAnimation {
  /// The animation's `name` in the file ("" when absent).
  std::string name;
  /// Kept channels, ordered by target node then path (translation, rotation, scale); a node and
  /// path appear at most once. Channels of `weights`, of nodes not reached from the scene and of
  /// nodes that give a `matrix` are left out (a note says so).
  std::vector<GltfAnimationChannel> channels;
  /// Latest key time over the kept channels (seconds); 0 when none is kept.
  double duration_s = 0.0;
};

/// The triangle geometry of one glTF scene.
struct GltfScene {
  /// The path given to LoadGltfScene().
  std::string path;
  /// The meshes that at least one instance shows, each once, in order of first appearance.
  std::vector<GltfMesh> meshes;
  /// One entry per node (reached from the scene's roots) that has a mesh, in depth-first order.
  std::vector<GltfMeshInstance> instances;
  /// The node tree reached from the scene's roots, in depth-first pre-order (parents first), one
  /// entry per path: what PoseInstancesAt() recomposes.
  std::vector<GltfNode> nodes;
  /// The file's animations, in the file's order (index = the file's animation index).
  std::vector<GltfAnimation> animations;
  /// The file's materials (index = the file's material index) and images (index = the file's
  /// image index).
  std::vector<GltfMaterial> materials;
  std::vector<GltfImage> images;
  /// The first perspective camera, when the scene shows one (scene_node -1 otherwise).
  GltfCamera camera;
  /// What was ignored or assumed: which scene was taken, skipped primitives, ignored cameras,
  /// skins, materials, animation channels, tinygltf's warnings.
  std::vector<std::string> notes;
};

/// Loads the triangle geometry of a glTF 2.0 file: `.gltf` (external or base64-embedded
/// buffers, resolved against the file's folder) or `.glb` (told apart by the file's first bytes,
/// not its name).
///
/// Scene: the file's `scene`, else scene 0, else (no `scenes`) every root node (a node that is
/// nobody's child); the choice is written in `notes`. Node transforms (`matrix` or
/// `translation`/`rotation`/`scale`) are composed from the root down into X_WN; the node tree and
/// the animations' translation/rotation/scale channels are kept for PoseInstancesAt(). Primitives
/// of mode TRIANGLES, TRIANGLE_STRIP and TRIANGLE_FAN are read, indexed or not, and merged per
/// mesh; POINTS and LINES primitives, and primitives without POSITION, are skipped with a note.
/// KHR_draco_mesh_compression primitives are decoded from their Draco buffer view (POSITION, and
/// TEXCOORD_0 when the extension's `attributes` names it).
///
/// Throws std::runtime_error, whose message starts with `path` and says what is wrong, when: the
/// file cannot be read or is larger than kGltfMaxFileBytes; a .glb header or chunk is truncated
/// or inconsistent; tinygltf refuses the file (its error and warning text are quoted); the file
/// requires an extension that changes geometry and is not supported (EXT_meshopt_compression,
/// KHR_mesh_quantization, EXT_mesh_gpu_instancing); an index (scene, node, mesh, accessor, buffer
/// view, buffer) is out of range; an accessor reaches past its buffer view or buffer; POSITION is
/// not FLOAT VEC3 or indices are not UNSIGNED_BYTE/SHORT/INT SCALAR; a vertex index is out of
/// range; TEXCOORD_0 is not FLOAT VEC2 or normalized UNSIGNED_BYTE/SHORT VEC2, or a texture
/// coordinate is NaN or infinite; the attributes of a primitive differ in count; a TRIANGLES
/// primitive has a corner count that is not a multiple of 3; `primitives` is not an array; a
/// position or transform is NaN or infinite; the node graph has a cycle, or shared children
/// multiply the paths past 1,000,000 node visits; a sparse accessor is used (not supported yet); a
/// Draco stream does not decode; the scene exceeds kGltfMaxTriangles or kGltfMaxVertices.
/// Animation channels (the message names the animation and channel) are refused when: the
/// sampler or target node index is out of range; two channels of one animation target the same
/// node and path; the interpolation is not LINEAR, STEP or CUBICSPLINE; the input is not FLOAT
/// SCALAR, is empty, or holds a time that is not finite, negative, or smaller than the one before;
/// the output is not FLOAT (KHR_mesh_quantization's normalized integers are not supported), not
/// VEC3 (translation, scale) or VEC4 (rotation), or its count is not the input's (3 times it for
/// CUBICSPLINE); a value is NaN or infinite, or a rotation value has zero length; the kept keys
/// exceed kGltfMaxAnimationKeys. Channels of `weights` (morph targets), of nodes not reached from
/// the scene and of nodes that give a `matrix` are ignored with a note.
GltfScene LoadGltfScene(const std::string& path);

/// The file a glTF `uri` (a buffer's or an image's) names beside the glTF at `gltf_path`: the
/// URI percent-decoded and resolved against the glTF's folder. nullopt for a data URI, a URI
/// with a scheme or a drive (any ':'), an absolute path, an empty one, or one with a ".."
/// component (a scene file must not make the node read, or stream, files outside its folder).
/// Does not touch the file system; never throws except std::bad_alloc.
std::optional<std::filesystem::path> GltfLocalFile(const std::string& gltf_path,
                                                   const std::string& uri);

/// Pose X_WN of every instance of `scene` (same order and frames as scene.instances: N the node
/// frame, W the scene frame, metres, column-major) at time `time_s` (seconds from the start) of
/// scene.animations[animation]: each animated node's channels replace its rest
/// translation/rotation/scale, and the node tree is recomposed from the roots down.
///
/// Sampling (glTF 2.0 Appendix C): LINEAR interpolates translation and scale linearly and rotation
/// by slerp along the shorter arc; STEP holds the previous key; CUBICSPLINE evaluates the Hermite
/// spline of the keys' values and tangents (scaled by the key interval). Rotations are normalized
/// after sampling. Before the first key a channel holds its first value, after the last key its
/// last value; with `loop`, time is first wrapped into [0, duration_s) (when duration_s > 0).
///
/// Never throws for any time and never reads out of range: animation -1 (or out of range, or a
/// scene without animations) and a NaN time give the rest pose, equal to scene.instances[i].X_WN;
/// +/-infinity holds the last/first key (also with `loop`). An instance whose scene_node is out
/// of range keeps its rest X_WN. Allocates only the returned vector (of scene.nodes.size()
/// capacity, used as scratch: see the overload below to reuse one).
std::vector<glm::dmat4> PoseInstancesAt(const GltfScene& scene, int animation, double time_s,
                                        bool loop = true);

/// The same into `X_WN` (resized to #instances); allocates only when X_WN's capacity is below
/// max(scene.nodes.size(), scene.instances.size()), so a caller that keeps the vector allocates
/// once. Throws only std::bad_alloc, and only from that growth.
void PoseInstancesAt(const GltfScene& scene, int animation, double time_s, bool loop,
                     std::vector<glm::dmat4>* X_WN);

/// Scales the whole scene by `factor` about W's origin (a file authored in millimetres takes
/// 0.001): the roots' rest poses (their `matrix`, or translation and scale), the animations'
/// translation and scale keys of root nodes, and every instance's X_WN, so that the rest poses,
/// PoseInstancesAt() and AnimatedNodePosesAt() all give the scaled scene. Meshes stay in their
/// node frames (the roots' scale carries them). The camera's near and far planes scale too.
/// Throws std::invalid_argument unless factor is finite and > 0.
void ScaleGltfScene(GltfScene& scene, double factor);

/// The local pose of one node entry (in its parent frame P) as an animation sets it.
struct GltfNodePose {
  /// Index into GltfScene::nodes.
  int scene_node = -1;
  /// Translation (m), rotation R_PN (unit quaternion) and scale of N in P.
  glm::dvec3 translation{0.0};
  glm::dquat rotation{1.0, 0.0, 0.0, 0.0};
  glm::dvec3 scale{1.0};
};

/// The local poses, at time `time_s` of scene.animations[animation], of every node entry the
/// animation moves (each path to an animated node, in channel order), sampled as PoseInstancesAt()
/// samples them; nodes given by a `matrix` are not animated and not listed. `poses` is cleared
/// first; an animation out of range, or a NaN time, leaves it empty. Allocates only when `poses`
/// grows past its capacity (throws only std::bad_alloc then).
void AnimatedNodePosesAt(const GltfScene& scene, int animation, double time_s, bool loop,
                         std::vector<GltfNodePose>* poses);

/// A JSON report of `scene`:
/// {"path", "notes": [...], "meshes": [{"name", "gltf_mesh_index", "triangles", "vertices",
///  "primitives", "draco_primitives", "dropped_degenerate_triangles"}],
///  "instances": [{"node", "node_index", "mesh", "mesh_name", "triangles", "vertices",
///  "bbox_min_W": [x,y,z], "bbox_max_W": [x,y,z]}],
///  "totals": {"instances", "meshes", "triangles" (summed over instances), "mesh_triangles"
///  (each mesh once), "vertices" (each mesh once), "bbox_min_W", "bbox_max_W"}},
///  "animations": [{"name", "channels" (kept channels), "duration_s"}]}.
/// Bounding boxes are axis-aligned in W (metres) over all vertices of the instance; they are
/// omitted for an instance whose mesh has no vertex, and totals' box is omitted when no instance
/// has one.
nlohmann::json SceneSummaryJson(const GltfScene& scene);

}  // namespace ht
