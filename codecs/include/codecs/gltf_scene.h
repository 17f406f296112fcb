#pragma once
// Loading the triangle geometry of a glTF 2.0 scene (https://registry.khronos.org/glTF/specs/2.0/)
// for display and haptic baking: every mesh of the scene once, in its node frame, plus one
// instance per node that shows it. Materials, textures, cameras, skins, morph targets and
// animations are ignored (a note says so). The parser is tinygltf 2.7 (compiled into this
// library under the name proj_tinygltf, see ../shared/design/DEPENDENCIES.md trap 1); Draco
// primitives (KHR_draco_mesh_compression) are decoded with libdraco.

#include <cstdint>
#include <glm/mat4x4.hpp>
#include <nlohmann/json_fwd.hpp>
#include <string>
#include <vector>

#include "haptic_core/haptic_model.h"

namespace ht {

/// Most triangles (summed over the meshes of a scene, each mesh counted once) that
/// LoadGltfScene() accepts; a larger scene is refused rather than allocated.
inline constexpr std::int64_t kGltfMaxTriangles = 50'000'000;
/// Most vertices (summed over the meshes, each counted once) that LoadGltfScene() accepts.
inline constexpr std::int64_t kGltfMaxVertices = 50'000'000;
/// Largest file (bytes) that LoadGltfScene() reads; external buffers are bounded by the same
/// figure each.
inline constexpr std::int64_t kGltfMaxFileBytes = std::int64_t{1} << 31;

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
  /// Number of triangle primitives merged into mesh_N (POINTS/LINES primitives excluded).
  int primitive_count = 0;
  /// How many of those primitives were KHR_draco_mesh_compression primitives.
  int draco_primitive_count = 0;
  /// Triangles dropped because they repeat a vertex index.
  std::int64_t dropped_degenerate_triangles = 0;
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
};

/// The triangle geometry of one glTF scene.
struct GltfScene {
  /// The path given to LoadGltfScene().
  std::string path;
  /// The meshes that at least one instance shows, each once, in order of first appearance.
  std::vector<GltfMesh> meshes;
  /// One entry per node (reached from the scene's roots) that has a mesh, in depth-first order.
  std::vector<GltfMeshInstance> instances;
  /// What was ignored or assumed: which scene was taken, skipped primitives, ignored cameras,
  /// skins, materials, tinygltf's warnings.
  std::vector<std::string> notes;
};

/// Loads the triangle geometry of a glTF 2.0 file: `.gltf` (external or base64-embedded
/// buffers, resolved against the file's folder) or `.glb` (told apart by the file's first bytes,
/// not its name).
///
/// Scene: the file's `scene`, else scene 0, else (no `scenes`) every root node (a node that is
/// nobody's child); the choice is written in `notes`. Node transforms (`matrix` or
/// `translation`/`rotation`/`scale`) are composed from the root down into X_WN. Primitives of
/// mode TRIANGLES, TRIANGLE_STRIP and TRIANGLE_FAN are read, indexed or not, and merged per mesh;
/// POINTS and LINES primitives, and primitives without POSITION, are skipped with a note.
/// KHR_draco_mesh_compression primitives are decoded from their Draco buffer view.
///
/// Throws std::runtime_error, whose message starts with `path` and says what is wrong, when: the
/// file cannot be read or is larger than kGltfMaxFileBytes; a .glb header or chunk is truncated
/// or inconsistent; tinygltf refuses the file (its error and warning text are quoted); the file
/// requires an extension that changes geometry and is not supported (EXT_meshopt_compression,
/// KHR_mesh_quantization, EXT_mesh_gpu_instancing); an index (scene, node, mesh, accessor, buffer
/// view, buffer) is out of range; an accessor reaches past its buffer view or buffer; POSITION is
/// not FLOAT VEC3 or indices are not UNSIGNED_BYTE/SHORT/INT SCALAR; a vertex index is out of
/// range; the attributes of a primitive differ in count; a TRIANGLES primitive has a
/// corner count that is not a multiple of 3; `primitives` is not an array; a position
/// or transform is NaN or infinite; the node graph has a cycle, or shared children
/// multiply the paths past 1,000,000 node visits; a sparse accessor is used (not supported yet); a
/// Draco stream does not decode; the scene exceeds kGltfMaxTriangles or kGltfMaxVertices.
GltfScene LoadGltfScene(const std::string& path);

/// A JSON report of `scene`:
/// {"path", "notes": [...], "meshes": [{"name", "gltf_mesh_index", "triangles", "vertices",
///  "primitives", "draco_primitives", "dropped_degenerate_triangles"}],
///  "instances": [{"node", "node_index", "mesh", "mesh_name", "triangles", "vertices",
///  "bbox_min_W": [x,y,z], "bbox_max_W": [x,y,z]}],
///  "totals": {"instances", "meshes", "triangles" (summed over instances), "mesh_triangles"
///  (each mesh once), "vertices" (each mesh once), "bbox_min_W", "bbox_max_W"}}.
/// Bounding boxes are axis-aligned in W (metres) over all vertices of the instance; they are
/// omitted for an instance whose mesh has no vertex, and totals' box is omitted when no instance
/// has one.
nlohmann::json SceneSummaryJson(const GltfScene& scene);

}  // namespace ht
