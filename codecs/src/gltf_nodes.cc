// The glTF node tree: checks of the node graph, the roots of the scene, each node's rest
// transform, and the depth-first walk that turns nodes showing meshes into scene instances
// (each mesh read once, its triangle primitives merged, with their texture coordinates and the
// material of each triangle).

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtc/quaternion.hpp>
#include <map>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "codecs/gltf_scene.h"
#include "gltf_internal.h"

namespace ht::gltf_internal {
namespace {

constexpr std::int64_t kMaxNodeVisits = 1'000'000;

// The rest transform of file node `index` (checked), without its place in the tree.
GltfNode RestNode(const tinygltf::Node& node, int index) {
  const std::string what = "node " + std::to_string(index);
  auto check = [&](const std::vector<double>& v, std::size_t n, const char* field) {
    if (!v.empty() && v.size() != n) {
      throw LoadError(what + ": " + field + " has " + std::to_string(v.size()) +
                      " numbers, expected " + std::to_string(n));
    }
    for (double x : v) {
      if (!std::isfinite(x)) throw LoadError(what + ": " + field + " is not finite");
    }
  };
  check(node.matrix, 16, "matrix");
  check(node.translation, 3, "translation");
  check(node.rotation, 4, "rotation");
  check(node.scale, 3, "scale");
  GltfNode out;
  out.node_index = index;
  if (!node.matrix.empty()) {
    out.has_matrix = true;
    glm::dmat4& X = out.X_PN;
    for (int c = 0; c < 4; ++c) {
      for (int r = 0; r < 4; ++r) X[c][r] = node.matrix[static_cast<std::size_t>(4 * c + r)];
    }
    if (X[0][3] != 0.0 || X[1][3] != 0.0 || X[2][3] != 0.0 || X[3][3] != 1.0) {
      throw LoadError(what + ": matrix's bottom row is not (0, 0, 0, 1)");
    }
    return out;
  }
  if (!node.translation.empty())
    out.translation = glm::dvec3(node.translation[0], node.translation[1], node.translation[2]);
  if (!node.rotation.empty()) {
    // glTF quaternions are (x, y, z, w); glm::dquat's constructor takes (w, x, y, z).
    glm::dquat q(node.rotation[3], node.rotation[0], node.rotation[1], node.rotation[2]);
    const double norm = glm::length(q);
    if (!(norm > 1e-12)) throw LoadError(what + ": rotation quaternion has zero length");
    out.rotation = q / norm;
  }
  if (!node.scale.empty()) out.scale = glm::dvec3(node.scale[0], node.scale[1], node.scale[2]);
  out.X_PN = ComposeTrs(out.translation, out.rotation, out.scale);
  return out;
}

// Reads all triangle primitives of mesh `m` into one GltfMesh.
GltfMesh BuildMesh(const tinygltf::Model& model, int m,
                   const std::map<DracoKey, DracoPrimitive>& draco,
                   std::vector<std::string>* notes) {
  const tinygltf::Mesh& src = model.meshes[static_cast<std::size_t>(m)];
  GltfMesh out;
  out.name = src.name;
  out.gltf_mesh_index = m;
  // Texture coordinates are kept when every merged primitive that needs them has them: a
  // primitive without TEXCOORD_0 whose material has no base-colour texture gets (0, 0) (never
  // sampled); one whose material has such a texture drops the mesh's coordinates.
  bool any_uv = false;
  int first_missing_needed = -1;    // first primitive without coordinates that needs them
  std::vector<std::string> filled;  // primitives given (0, 0)
  std::set<int> materials_seen;
  for (std::size_t p = 0; p < src.primitives.size(); ++p) {
    const tinygltf::Primitive& prim = src.primitives[p];
    const std::string what =
        "mesh " + std::to_string(m) + " (\"" + src.name + "\") primitive " + std::to_string(p);
    if (prim.mode == TINYGLTF_MODE_POINTS || prim.mode == TINYGLTF_MODE_LINE ||
        prim.mode == TINYGLTF_MODE_LINE_LOOP || prim.mode == TINYGLTF_MODE_LINE_STRIP) {
      notes->push_back(what + ": mode " + std::to_string(prim.mode) +
                       " (points or lines) skipped: no surface");
      continue;
    }
    if (prim.mode != TINYGLTF_MODE_TRIANGLES && prim.mode != TINYGLTF_MODE_TRIANGLE_STRIP &&
        prim.mode != TINYGLTF_MODE_TRIANGLE_FAN) {
      throw LoadError(what + ": unknown mode " + std::to_string(prim.mode));
    }
    PrimitiveData data;
    int mode = prim.mode;
    auto d = draco.find({m, static_cast<int>(p)});
    if (d != draco.end()) {
      data = DecodeDracoPrimitive(model, d->second, what);
      mode = TINYGLTF_MODE_TRIANGLES;  // the decoded faces are a triangle list
      ++out.draco_primitive_count;
    } else {
      auto pos = prim.attributes.find("POSITION");
      if (pos == prim.attributes.end()) {
        notes->push_back(what + ": no POSITION attribute, skipped");
        continue;
      }
      ReadPositions(model, pos->second, what, &data.positions);
      for (const auto& [attribute, accessor] : prim.attributes) {
        if (accessor < 0 || static_cast<std::size_t>(accessor) >= model.accessors.size()) {
          throw LoadError(what + ": attribute " + attribute + " refers to accessor " +
                          std::to_string(accessor) + " out of range");
        }
        const std::size_t count = model.accessors[static_cast<std::size_t>(accessor)].count;
        if (count != data.positions.size()) {
          throw LoadError(what + ": attribute " + attribute + " has " + std::to_string(count) +
                          " elements, POSITION has " + std::to_string(data.positions.size()) +
                          " (vertex arrays of different lengths)");
        }
      }
      if (auto tex = prim.attributes.find("TEXCOORD_0"); tex != prim.attributes.end()) {
        ReadTexCoords(model, tex->second, what, &data.uv);
      }
      if (prim.indices >= 0) {
        ReadIndices(model, prim.indices, what, &data.corners);
      } else {
        data.corners.resize(data.positions.size());
        for (std::size_t i = 0; i < data.corners.size(); ++i)
          data.corners[i] = static_cast<std::uint32_t>(i);
      }
    }
    const std::size_t nv = data.positions.size();
    for (std::size_t i = 0; i < data.corners.size(); ++i) {
      if (data.corners[i] >= nv) {
        throw LoadError(what + ": index " + std::to_string(data.corners[i]) + " at position " +
                        std::to_string(i) + " out of range [0, " + std::to_string(nv) +
                        ") (index out of range)");
      }
    }
    const std::size_t base = out.mesh_N.vertices.size();
    if (static_cast<std::int64_t>(base + nv) > kGltfMaxVertices) {
      throw LoadError(what + ": more than " + std::to_string(kGltfMaxVertices) +
                      " vertices in the mesh");
    }
    out.mesh_N.vertices.insert(out.mesh_N.vertices.end(), data.positions.begin(),
                               data.positions.end());
    // The primitive's material, -1 for none or an index out of range.
    int material = -1;
    if (prim.material >= 0 && static_cast<std::size_t>(prim.material) < model.materials.size()) {
      material = prim.material;
    } else if (prim.material >= 0) {
      notes->push_back(what + ": material " + std::to_string(prim.material) +
                       " out of range; drawn without one");
    }
    if (data.uv.size() == nv) {
      any_uv = true;
      out.uv_N.resize(base, glm::dvec2(0.0));  // (0, 0) for earlier primitives without
      out.uv_N.insert(out.uv_N.end(), data.uv.begin(), data.uv.end());
    } else {
      const bool textured =
          material >= 0 && model.materials[static_cast<std::size_t>(material)]
                                   .pbrMetallicRoughness.baseColorTexture.index >= 0;
      if (textured && first_missing_needed < 0) first_missing_needed = static_cast<int>(p);
      if (!textured) filled.push_back(std::to_string(p));
    }
    if (material >= 0 && materials_seen.insert(material).second) {
      const tinygltf::TextureInfo& t =
          model.materials[static_cast<std::size_t>(material)].pbrMetallicRoughness.baseColorTexture;
      if (t.index >= 0 && t.texCoord != 0) {
        notes->push_back(what + ": material " + std::to_string(material) +
                         "'s base-colour texture uses TEXCOORD_" + std::to_string(t.texCoord) +
                         "; only TEXCOORD_0 is read");
      }
      if (t.index >= 0 && t.extensions.count("KHR_texture_transform") != 0) {
        notes->push_back(what + ": material " + std::to_string(material) +
                         "'s base-colour texture has KHR_texture_transform, ignored");
      }
    }
    auto add = [&](std::uint32_t a, std::uint32_t b, std::uint32_t c) {
      if (a == b || b == c || c == a) {
        ++out.dropped_degenerate_triangles;
        return;
      }
      out.mesh_N.triangles.emplace_back(static_cast<int>(base + a), static_cast<int>(base + b),
                                        static_cast<int>(base + c));
      out.triangle_material.push_back(material);
    };
    const std::vector<std::uint32_t>& k = data.corners;
    const std::size_t n = k.size();
    if (mode == TINYGLTF_MODE_TRIANGLES) {
      if (n % 3 != 0) {
        throw LoadError(what + ": TRIANGLES with " + std::to_string(n) +
                        " corners, not a multiple of 3 (incorrect vertex array length)");
      }
      for (std::size_t i = 0; i + 2 < n; i += 3) add(k[i], k[i + 1], k[i + 2]);
    } else if (mode == TINYGLTF_MODE_TRIANGLE_STRIP) {
      // glTF 2.0 §3.7.2.1: triangle i = (v_i, v_{i+1+i%2}, v_{i+2-i%2}).
      for (std::size_t i = 0; i + 2 < n; ++i) {
        if (i % 2 == 0) {
          add(k[i], k[i + 1], k[i + 2]);
        } else {
          add(k[i], k[i + 2], k[i + 1]);
        }
      }
    } else {
      // Fan: triangle i = (v_{i+1}, v_{i+2}, v_0).
      for (std::size_t i = 0; i + 2 < n; ++i) add(k[i + 1], k[i + 2], k[0]);
    }
    if (static_cast<std::int64_t>(out.mesh_N.triangles.size()) > kGltfMaxTriangles) {
      throw LoadError(what + ": more than " + std::to_string(kGltfMaxTriangles) +
                      " triangles in the mesh");
    }
    ++out.primitive_count;
    if (out.material < 0) out.material = material;
  }
  const std::string mesh_what = "mesh " + std::to_string(m) + " (\"" + src.name + "\")";
  if (!any_uv) {
    // Nothing was stored.
  } else if (first_missing_needed >= 0) {
    notes->push_back(mesh_what + " primitive " + std::to_string(first_missing_needed) +
                     " has no TEXCOORD_0 but its material has a base-colour texture: the mesh is "
                     "loaded without texture coordinates");
    std::vector<glm::dvec2>().swap(out.uv_N);  // frees them
  } else if (!filled.empty()) {
    out.uv_N.resize(out.mesh_N.vertices.size(), glm::dvec2(0.0));  // later primitives without
    std::string list;
    for (const std::string& f : filled) list += (list.empty() ? "" : ", ") + f;
    notes->push_back(mesh_what + " primitive(s) " + list +
                     " have no TEXCOORD_0 and no base-colour texture: their vertices get (0, 0)");
  }
  return out;
}

}  // namespace

// T·R·S as a matrix (glTF 2.0 §3.5.3), the same operations for rest and animated poses.
glm::dmat4 ComposeTrs(const glm::dvec3& t, const glm::dquat& r, const glm::dvec3& s) noexcept {
  glm::dmat4 X = glm::translate(glm::dmat4(1.0), t);
  X = X * glm::mat4_cast(r);
  return glm::scale(X, s);
}

NodeTree BuildNodeTree(const tinygltf::Model& model,
                       const std::map<DracoKey, DracoPrimitive>& draco, GltfScene* scene_out) {
  GltfScene& scene = *scene_out;
  // The node graph must be acyclic, with children in range. glTF 2.0 asks for disjoint trees,
  // but some files (Draco's CubeScaledInstances) instance a node under several parents: such a
  // node is shown once per path from the root, with a note.
  const std::size_t node_count = model.nodes.size();
  std::vector<int> parents(node_count, 0);
  for (std::size_t n = 0; n < node_count; ++n) {
    for (int c : model.nodes[n].children) {
      if (c < 0 || static_cast<std::size_t>(c) >= node_count) {
        throw LoadError("node " + std::to_string(n) + " has child " + std::to_string(c) +
                        " out of range [0, " + std::to_string(node_count) + ")");
      }
      ++parents[static_cast<std::size_t>(c)];
    }
  }
  {
    // Iterative three-colour depth-first search: reaching a node that is still open is a cycle.
    enum : char { kNew, kOpen, kDone };
    std::vector<char> colour(node_count, kNew);
    std::vector<std::pair<int, std::size_t>> stack;  // node, next child to look at
    for (std::size_t start = 0; start < node_count; ++start) {
      if (colour[start] != kNew) continue;
      stack.emplace_back(static_cast<int>(start), 0);
      colour[start] = kOpen;
      while (!stack.empty()) {
        auto& [n, next] = stack.back();
        const std::vector<int>& children = model.nodes[static_cast<std::size_t>(n)].children;
        if (next == children.size()) {
          colour[static_cast<std::size_t>(n)] = kDone;
          stack.pop_back();
          continue;
        }
        const int c = children[next++];
        if (colour[static_cast<std::size_t>(c)] == kOpen) {
          throw LoadError("node " + std::to_string(n) + " has child " + std::to_string(c) +
                          ", which is one of its ancestors (node cycle)");
        }
        if (colour[static_cast<std::size_t>(c)] == kNew) {
          colour[static_cast<std::size_t>(c)] = kOpen;
          stack.emplace_back(c, 0);
        }
      }
    }
  }
  const std::size_t shared = static_cast<std::size_t>(
      std::count_if(parents.begin(), parents.end(), [](int p) { return p > 1; }));
  if (shared > 0) {
    scene.notes.push_back(std::to_string(shared) +
                          " node(s) have several parents (glTF 2.0 asks for trees): shown once "
                          "per path from the root");
  }

  std::vector<int> roots;
  if (!model.scenes.empty()) {
    int s = model.defaultScene;
    if (s < 0) {
      s = 0;
      scene.notes.push_back("no default scene: scene 0 of " + std::to_string(model.scenes.size()) +
                            " used");
    } else if (static_cast<std::size_t>(s) >= model.scenes.size()) {
      throw LoadError("default scene " + std::to_string(s) + " out of range [0, " +
                      std::to_string(model.scenes.size()) + ")");
    } else {
      scene.notes.push_back("scene " + std::to_string(s) + " (default) used");
    }
    for (int n : model.scenes[static_cast<std::size_t>(s)].nodes) {
      if (n < 0 || static_cast<std::size_t>(n) >= node_count) {
        throw LoadError("scene " + std::to_string(s) + " lists node " + std::to_string(n) +
                        " out of range");
      }
      if (parents[static_cast<std::size_t>(n)] > 0) {
        scene.notes.push_back("scene " + std::to_string(s) + " lists node " + std::to_string(n) +
                              ", which is also a child of another node");
      }
      roots.push_back(n);
    }
    if (roots.empty())
      scene.notes.push_back("scene " + std::to_string(s) + " has no nodes: nothing to show");
  } else {
    for (std::size_t n = 0; n < node_count; ++n) {
      if (parents[n] == 0) roots.push_back(static_cast<int>(n));
    }
    scene.notes.push_back("no scene in the file: all " + std::to_string(roots.size()) +
                          " root nodes used");
  }

  // Depth-first from the roots. The graph is acyclic (checked above), so this ends; shared
  // children can still multiply the paths, hence the cap on visits.
  std::int64_t visits = 0;
  std::vector<int> mesh_slot(model.meshes.size(), -1);
  std::int64_t total_triangles = 0;
  std::int64_t total_vertices = 0;
  // Entries of scene.nodes per file node: the first, and the last (to chain next_same_node).
  std::vector<int> first_entry(node_count, -1);
  std::vector<int> last_entry(node_count, -1);
  struct Pending {
    int node;
    int parent_entry;
    glm::dmat4 X_WP;
  };
  std::vector<Pending> stack;
  for (auto it = roots.rbegin(); it != roots.rend(); ++it)
    stack.push_back({*it, -1, glm::dmat4(1.0)});
  while (!stack.empty()) {
    const Pending top = stack.back();
    const int n = top.node;
    stack.pop_back();
    if (++visits > kMaxNodeVisits) {
      throw LoadError("more than " + std::to_string(kMaxNodeVisits) +
                      " node visits (shared children multiply the paths)");
    }
    const tinygltf::Node& node = model.nodes[static_cast<std::size_t>(n)];
    GltfNode entry = RestNode(node, n);
    entry.parent = top.parent_entry;
    entry.name = node.name;
    const int e = static_cast<int>(scene.nodes.size());
    const std::size_t un = static_cast<std::size_t>(n);
    if (first_entry[un] < 0) {
      first_entry[un] = e;
    } else {
      scene.nodes[static_cast<std::size_t>(last_entry[un])].next_same_node = e;
    }
    last_entry[un] = e;
    const glm::dmat4 X_WN = top.X_WP * entry.X_PN;
    scene.nodes.push_back(entry);
    if (node.mesh >= 0) {
      if (static_cast<std::size_t>(node.mesh) >= model.meshes.size()) {
        throw LoadError("node " + std::to_string(n) + " refers to mesh " +
                        std::to_string(node.mesh) + " out of range [0, " +
                        std::to_string(model.meshes.size()) + ")");
      }
      int& slot = mesh_slot[static_cast<std::size_t>(node.mesh)];
      if (slot < 0) {
        GltfMesh mesh = BuildMesh(model, node.mesh, draco, &scene.notes);
        total_triangles += static_cast<std::int64_t>(mesh.mesh_N.triangles.size());
        total_vertices += static_cast<std::int64_t>(mesh.mesh_N.vertices.size());
        if (total_triangles > kGltfMaxTriangles || total_vertices > kGltfMaxVertices) {
          throw LoadError("scene exceeds the limit of " + std::to_string(kGltfMaxTriangles) +
                          " triangles / " + std::to_string(kGltfMaxVertices) + " vertices");
        }
        slot = static_cast<int>(scene.meshes.size());
        scene.meshes.push_back(std::move(mesh));
      }
      scene.nodes.back().mesh = slot;
      scene.instances.push_back({node.name, n, slot, X_WN, e});
    }
    for (auto c = node.children.rbegin(); c != node.children.rend(); ++c)
      stack.push_back({*c, e, X_WN});
  }
  const std::size_t unused =
      static_cast<std::size_t>(std::count(mesh_slot.begin(), mesh_slot.end(), -1));
  return {std::move(first_entry), unused};
}

}  // namespace ht::gltf_internal
