#pragma once
// Private to codecs/src/gltf_*.cc (not installed): what the files of glTF loading share. The
// loader is split by concern: gltf_container.cc (the file, GLB chunks or JSON text, tinygltf),
// gltf_draco.cc (KHR_draco_mesh_compression primitives), gltf_accessors.cc (checked typed reads
// of accessors), gltf_nodes.cc (node tree, transforms, meshes -> instances), gltf_animation.cc
// (animation channels and their sampling) and gltf_scene.cc (LoadGltfScene's top-level flow).

// tiny_gltf.h's configuration, the same in every unit that includes it (the TinyGLTF class's
// default members depend on it). gltf_container.cc alone defines TINYGLTF_IMPLEMENTATION, then
// includes this header first.
#define TINYGLTF_NO_STB_IMAGE
#define TINYGLTF_NO_STB_IMAGE_WRITE
#define TINYGLTF_NO_EXTERNAL_IMAGE
#include <tiny_gltf.h>
// tiny_gltf.h is included first so that its implementation sees only its own configuration.

#include <cstddef>
#include <cstdint>
#include <glm/gtc/quaternion.hpp>
#include <glm/mat4x4.hpp>
#include <glm/vec2.hpp>
#include <glm/vec3.hpp>
#include <map>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "codecs/gltf_scene.h"

namespace ht::gltf_internal {

// Thrown inside the gltf_*.cc files; LoadGltfScene() prefixes the path.
struct LoadError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// What was taken out of one Draco primitive's JSON.
struct DracoPrimitive {
  int buffer_view = -1;
  std::map<std::string, int> attributes;  // glTF attribute name -> Draco unique id
  int original_indices = -1;
};
using DracoKey = std::pair<int, int>;  // mesh index, primitive index

// Vertex positions, texture coordinates and the corner list (before strip/fan conversion) of one
// primitive.
struct PrimitiveData {
  std::vector<glm::dvec3> positions;
  std::vector<glm::dvec2> uv;          // TEXCOORD_0, one per position; empty when absent
  std::vector<std::uint32_t> corners;  // indices, or 0..#V-1 for a non-indexed primitive
};

// A checked view of an accessor's elements.
struct AccessorView {
  const unsigned char* data = nullptr;  // null when the accessor has no buffer view (all zeros)
  std::size_t stride = 0;
  std::size_t count = 0;
};

// ---- gltf_container.cc

// Reads the file at `path` (at most kGltfMaxFileBytes), a GLB container or a JSON glTF, takes
// the Draco objects (into `*draco`) and the skins out of its JSON, and runs tinygltf on the
// result with images ignored. Appends what was ignored to `*notes`. Throws LoadError on an
// unreadable or malformed file, naming what is wrong.
tinygltf::Model ParseWithTinyGltf(const std::string& path,
                                  std::map<DracoKey, DracoPrimitive>* draco,
                                  std::vector<std::string>* notes);

// ---- gltf_draco.cc

// Removes KHR_draco_mesh_compression (and the primitive's `indices`) from every primitive of
// `doc` and returns what was removed. Leaves anything it does not understand for tinygltf.
// Throws LoadError on a malformed KHR_draco_mesh_compression object.
std::map<DracoKey, DracoPrimitive> ExtractDraco(nlohmann::json& doc);

// Decodes the Draco stream of one primitive: its POSITION attribute (3 components read as
// float, finite), its TEXCOORD_0 attribute when `d.attributes` names one (2 components read as
// float, normalized integers divided by their maximum, finite), one of each per Draco point, and
// its faces as a triangle list. `what` names the primitive in error messages. Throws LoadError
// on an index or range out of bounds, a stream that does not decode, an attribute id the stream
// lacks, a wrong component count, a non-finite value, or a mesh over the limits.
PrimitiveData DecodeDracoPrimitive(const tinygltf::Model& model, const DracoPrimitive& d,
                                   const std::string& what);

// ---- gltf_accessors.cc

// A checked view of accessor `index` whose elements take `element_size` bytes: the view, the
// buffer and every element lie in range. Throws LoadError naming `what` otherwise, or for a
// sparse accessor.
AccessorView ViewAccessor(const tinygltf::Model& model, int index, std::size_t element_size,
                          const std::string& what);

// The glTF name of a component type code ("FLOAT", ...), or "unknown".
const char* ComponentName(int type);

// Reads a FLOAT VEC3 POSITION accessor (finite values, at most kGltfMaxVertices) into `*out`.
void ReadPositions(const tinygltf::Model& model, int accessor_index, const std::string& what,
                   std::vector<glm::dvec3>* out);

// Reads an UNSIGNED_BYTE/SHORT/INT SCALAR indices accessor into `*out`.
void ReadIndices(const tinygltf::Model& model, int accessor_index, const std::string& what,
                 std::vector<std::uint32_t>* out);

// Reads a TEXCOORD accessor into `*out` as the file has it ((0, 0) the image's top-left, u
// right, v down): FLOAT VEC2, or normalized UNSIGNED_BYTE / UNSIGNED_SHORT VEC2 (divided by 255
// or 65535), glTF 2.0 §3.7.2.1. Throws LoadError naming `what` for any other type, an integer
// accessor that is not normalized, a non-finite value, or more than kGltfMaxVertices elements.
void ReadTexCoords(const tinygltf::Model& model, int accessor_index, const std::string& what,
                   std::vector<glm::dvec2>* out);

// Reads `count`-checked FLOAT elements of `components` numbers (1, 3 or 4) from an accessor into
// dvec4s (unused components 0), refusing NaN and infinities.
void ReadFloatElements(const tinygltf::Model& model, int accessor_index, int components,
                       const std::string& what, std::vector<glm::dvec4>* out);

// ---- gltf_nodes.cc

// T·R·S as a matrix (glTF 2.0 §3.5.3), the same operations for rest and animated poses.
glm::dmat4 ComposeTrs(const glm::dvec3& t, const glm::dquat& r, const glm::dvec3& s) noexcept;

// What BuildNodeTree() leaves for the steps after it.
struct NodeTree {
  // Maps a file node to its first entry in GltfScene::nodes (-1 when the scene does not reach
  // it).
  std::vector<int> first_entry;
  // Meshes of the file that no reached node shows (not loaded).
  std::size_t unused_meshes = 0;
};

// Checks the node graph (children in range, no cycle), picks the roots (the default scene's
// nodes; scene 0's when none is default; every parentless node when the file has no scene) and
// walks the tree depth-first from them, filling scene->nodes, scene->meshes and
// scene->instances and appending to scene->notes. Throws LoadError on a bad node, mesh or
// primitive, or when the scene exceeds the limits.
NodeTree BuildNodeTree(const tinygltf::Model& model,
                       const std::map<DracoKey, DracoPrimitive>& draco, GltfScene* scene);

// ---- gltf_animation.cc

// Reads and checks the translation/rotation/scale channels of every animation. `first_entry`
// maps a file node to its first entry in `nodes` (-1 when the scene does not reach it).
std::vector<GltfAnimation> ReadAnimations(const tinygltf::Model& model,
                                          const std::vector<int>& first_entry,
                                          const std::vector<GltfNode>& nodes,
                                          std::vector<std::string>* notes);

}  // namespace ht::gltf_internal
