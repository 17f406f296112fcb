// The scene as the remote node streams it for display (slave_sim/display_scene.h).
#include "slave_sim/display_scene.h"

#include <algorithm>
#include <glm/gtc/matrix_access.hpp>
#include <stdexcept>

#include "codecs/draco_mesh_codec.h"
#include "slave_sim/scene_build.h"

namespace ht {
namespace {

// Base colours per role, linear RGBA like glTF's baseColorFactor (the display writes sRGB
// images): a steel-blue tool and a bronze object.
constexpr glm::vec4 kToolColour{0.17f, 0.26f, 0.45f, 1.0f};
constexpr glm::vec4 kObjectColour{0.48f, 0.21f, 0.055f, 1.0f};

TriangleMesh CoarseMesh(const HapticModel& model) {
  TriangleMesh m;
  m.vertices = model.vertices_O;
  m.triangles = model.triangles;
  return m;
}

SceneGraphNode NodeAt(const std::string& name, const RigidTransform& X, std::uint32_t mesh,
                      int material, std::uint8_t flags) {
  SceneGraphNode n;
  n.name = name;
  n.translation = X.translation;
  n.rotation = X.rotation;
  n.mesh_object = mesh;
  n.material = material;
  n.flags = flags;
  return n;
}

// One material's triangles of a glTF mesh, with only the vertices they use (and their UVs).
struct MeshPart {
  int material = -1;
  TriangleMesh mesh;
  std::vector<glm::dvec2> uv;
  std::uint32_t object = 0;
};

std::vector<MeshPart> SplitByMaterial(const GltfMesh& m) {
  const std::size_t nf = m.mesh_N.triangles.size();
  const bool per_triangle = m.triangle_material.size() == nf;
  const bool with_uv = m.uv_N.size() == m.mesh_N.vertices.size();
  std::vector<MeshPart> parts;
  std::vector<int> remap(m.mesh_N.vertices.size(), -1);
  for (std::size_t f = 0; f < nf;) {
    const int material = per_triangle ? m.triangle_material[f] : m.material;
    MeshPart part;
    part.material = material;
    std::fill(remap.begin(), remap.end(), -1);
    for (; f < nf && (per_triangle ? m.triangle_material[f] : m.material) == material; ++f) {
      glm::ivec3 t = m.mesh_N.triangles[f];
      for (int c = 0; c < 3; ++c) {
        int& r = remap[static_cast<std::size_t>(t[c])];
        if (r < 0) {
          r = static_cast<int>(part.mesh.vertices.size());
          part.mesh.vertices.push_back(m.mesh_N.vertices[static_cast<std::size_t>(t[c])]);
          if (with_uv) part.uv.push_back(m.uv_N[static_cast<std::size_t>(t[c])]);
        }
        t[c] = r;
      }
      part.mesh.triangles.push_back(t);
    }
    parts.push_back(std::move(part));
  }
  return parts;
}

// Translation, rotation and per-axis scale of an affine X (its columns' lengths; a mirror goes
// into the scale of z). Shear is not carried.
void SetFromMatrix(const glm::dmat4& X, SceneGraphNode* out) {
  const glm::dmat3 M(X);
  out->scale = glm::dvec3(glm::length(M[0]), glm::length(M[1]), glm::length(M[2]));
  glm::dmat3 R = M;
  for (int c = 0; c < 3; ++c) R[c] = out->scale[c] > 0.0 ? M[c] / out->scale[c] : R[c];
  if (glm::determinant(R) < 0.0) {
    R[2] = -R[2];
    out->scale.z = -out->scale.z;
  }
  out->rotation = glm::normalize(glm::quat_cast(R));
  out->translation = glm::dvec3(X[3]);
}

void EncodeGraph(DisplayStream* s) {
  s->objects.insert(s->objects.begin(),
                    StreamObject{kSceneGraphObjectId, wire::SceneObjectKind::kSceneGraph,
                                 EncodeSceneGraph(s->graph)});
}

}  // namespace

DisplayStream MakeDisplayStream(const HapticScene& scene, const TriangleMesh& tool_mesh_Ft,
                                const RigidTransform& X_TFt,
                                const std::vector<const TriangleMesh*>& object_meshes) {
  if (object_meshes.size() != scene.touchables.size()) {
    throw std::invalid_argument("MakeDisplayStream: " + std::to_string(object_meshes.size()) +
                                " object meshes for " + std::to_string(scene.touchables.size()) +
                                " touchable objects");
  }
  DisplayStream s;
  s.graph.scene_name = scene.name;
  s.graph.materials.push_back({"tool", kToolColour, 0, ""});
  s.graph.materials.push_back({"object", kObjectColour, 0, ""});
  std::uint32_t id = kSceneGraphObjectId + 1;
  s.objects.push_back({id, wire::SceneObjectKind::kDracoMesh, EncodeMeshDraco(tool_mesh_Ft)});
  s.graph.nodes.push_back(NodeAt(scene.tool ? scene.tool->name : "tool", X_TFt, id, 0,
                                 kSceneNodeTool | kSceneNodeMoving));
  for (std::size_t k = 0; k < scene.touchables.size(); ++k) {
    const TouchableObject& o = scene.touchables[k];
    ++id;
    const TriangleMesh mesh = object_meshes[k] != nullptr ? *object_meshes[k]
                              : o.model                   ? CoarseMesh(*o.model)
                                                          : TriangleMesh{};
    if (mesh.triangles.empty()) continue;
    s.objects.push_back({id, wire::SceneObjectKind::kDracoMesh, EncodeMeshDraco(mesh)});
    s.graph.nodes.push_back(NodeAt(o.model ? o.model->name : "object " + std::to_string(k), o.X_WO,
                                   id, 1, kSceneNodeTouchable));
  }
  EncodeGraph(&s);
  return s;
}

DisplayStream MakeDisplayStream(const BuiltScene& scene) {
  DisplayStream s;
  const GltfScene& g = scene.gltf;
  s.graph.scene_name = SceneGraphName(scene.haptic.name);
  std::uint32_t id = kSceneGraphObjectId + 1;
  // Meshes, each once, in N: one Draco object per (mesh, material) part, with its texture
  // coordinates when the mesh has them.
  std::vector<std::vector<MeshPart>> parts(g.meshes.size());
  for (std::size_t m = 0; m < g.meshes.size(); ++m) {
    for (MeshPart& part : SplitByMaterial(g.meshes[m])) {
      if (part.mesh.triangles.empty()) continue;
      part.object = id;
      s.objects.push_back({id++, wire::SceneObjectKind::kDracoMesh,
                           part.uv.empty() ? EncodeMeshDraco(part.mesh)
                                           : EncodeMeshDracoWithUv(part.mesh, part.uv)});
      parts[m].push_back(std::move(part));
    }
  }
  // Materials and the images they use.
  std::vector<std::uint32_t> image_object(g.images.size(), 0);
  for (const GltfMaterial& m : g.materials) {
    SceneMaterial out;
    out.name = SceneGraphName(m.name);
    out.base_colour_rgba = glm::vec4(m.base_colour_rgba);
    if (m.base_colour_image >= 0) {
      const auto i = static_cast<std::size_t>(m.base_colour_image);
      if (image_object[i] == 0) {
        image_object[i] = id;
        s.objects.push_back({id++, wire::SceneObjectKind::kImage, g.images[i].bytes});
      }
      out.base_colour_texture_object = image_object[i];
      out.texture_mime = SceneGraphName(g.images[i].mime_type);
    }
    s.graph.materials.push_back(std::move(out));
  }
  // Roles of the mesh nodes (instances), by node entry.
  std::vector<NodeRole> role(g.nodes.size(), NodeRole::kDisplay);
  std::vector<int> object_of_entry(g.nodes.size(), -1);
  for (std::size_t i = 0; i < scene.objects.size() && i < g.instances.size(); ++i) {
    const int e = g.instances[i].scene_node;
    if (e < 0 || static_cast<std::size_t>(e) >= g.nodes.size()) continue;
    role[static_cast<std::size_t>(e)] = scene.objects[i].spec.role;
    object_of_entry[static_cast<std::size_t>(e)] = static_cast<int>(i);
  }
  std::vector<bool> moving(g.nodes.size(), false);
  if (!g.animations.empty()) {
    for (const GltfAnimationChannel& c : g.animations[0].channels) {
      for (int v = c.scene_node; v >= 0 && static_cast<std::size_t>(v) < g.nodes.size();) {
        moving[static_cast<std::size_t>(v)] = true;
        const int next = g.nodes[static_cast<std::size_t>(v)].next_same_node;
        if (next <= v) break;
        v = next;
      }
    }
  }
  // The node tree, entry for entry (parents first). The tool node becomes a root in T.
  s.graph_node_of_entry.assign(g.nodes.size(), -1);
  int tool_entry = -1;
  for (std::size_t e = 0; e < g.nodes.size(); ++e) {
    const GltfNode& n = g.nodes[e];
    SceneGraphNode out;
    out.name = SceneGraphName(n.name);
    out.parent = n.parent >= 0 ? s.graph_node_of_entry[static_cast<std::size_t>(n.parent)] : -1;
    if (n.has_matrix) {
      SetFromMatrix(n.X_PN, &out);
    } else {
      out.translation = n.translation;
      out.rotation = n.rotation;
      out.scale = n.scale;
    }
    if (n.mesh >= 0 && !parts[static_cast<std::size_t>(n.mesh)].empty()) {
      const MeshPart& first = parts[static_cast<std::size_t>(n.mesh)].front();
      out.mesh_object = first.object;
      out.material = first.material;
    }
    if (role[e] == NodeRole::kTouchable) out.flags |= kSceneNodeTouchable;
    if (moving[e]) out.flags |= kSceneNodeMoving;
    if (role[e] == NodeRole::kTool && object_of_entry[e] >= 0) {
      // Pose of N in the tool frame T: X_TN = X_WT⁻¹·X_WN (rest poses; T is the node's rigid
      // part moved to the model's centre of mass).
      const SceneNode& obj = scene.objects[static_cast<std::size_t>(object_of_entry[e])];
      SetFromMatrix(glm::inverse(obj.X_WO.Matrix()) *
                        g.instances[static_cast<std::size_t>(object_of_entry[e])].X_WN,
                    &out);
      out.parent = -1;
      out.flags = kSceneNodeTool | kSceneNodeMoving;
      tool_entry = static_cast<int>(e);
    }
    s.graph_node_of_entry[e] = static_cast<int>(s.graph.nodes.size());
    s.graph.nodes.push_back(std::move(out));
  }
  // A mesh's further material parts: child nodes of each node that shows it, at the identity.
  // Appended after every entry, so that parents still come first.
  s.part_of.assign(s.graph.nodes.size(), -1);
  for (std::size_t e = 0; e < g.nodes.size(); ++e) {
    const int mesh = g.nodes[e].mesh;
    if (mesh < 0) continue;
    const std::vector<MeshPart>& p = parts[static_cast<std::size_t>(mesh)];
    const int node = s.graph_node_of_entry[e];
    for (std::size_t k = 1; k < p.size(); ++k) {
      SceneGraphNode child;
      child.name = s.graph.nodes[static_cast<std::size_t>(node)].name;
      child.parent = node;
      child.mesh_object = p[k].object;
      child.material = p[k].material;
      child.flags = s.graph.nodes[static_cast<std::size_t>(node)].flags &
                    static_cast<std::uint8_t>(kSceneNodeTouchable);
      s.graph.nodes.push_back(std::move(child));
      s.part_of.push_back(node);
    }
  }
  if (tool_entry < 0 && scene.haptic.tool) {
    // The built-in probe: its coarse mesh, in T.
    const std::uint32_t probe = id++;
    s.objects.push_back({probe, wire::SceneObjectKind::kDracoMesh,
                         EncodeMeshDraco(CoarseMesh(*scene.haptic.tool))});
    s.graph.materials.push_back({"probe", kToolColour, 0, ""});
    s.graph.nodes.push_back(NodeAt("probe", RigidTransform::Identity(), probe,
                                   static_cast<int>(s.graph.materials.size()) - 1,
                                   kSceneNodeTool | kSceneNodeMoving));
    s.part_of.push_back(-1);
  }
  for (std::size_t v = 0; v < s.graph.nodes.size(); ++v) {
    const SceneGraphNode& n = s.graph.nodes[v];
    if ((n.flags & kSceneNodeMoving) != 0 && (n.flags & kSceneNodeTool) == 0) {
      s.moving_nodes.push_back(static_cast<std::uint16_t>(v));
    }
  }
  if (g.camera.scene_node >= 0) {
    SceneGraphCamera c;
    c.node = s.graph_node_of_entry[static_cast<std::size_t>(g.camera.scene_node)];
    c.yfov_rad = g.camera.yfov_rad;
    c.znear_m = g.camera.znear_m;
    c.zfar_m = g.camera.zfar_m;
    s.graph.camera = c;
  }
  EncodeGraph(&s);
  return s;
}

void DisplayNodePosesAt(const BuiltScene& scene, const DisplayStream& stream, double time_s,
                        std::vector<GltfNodePose>* scratch, std::vector<wire::NodePose>* poses) {
  poses->clear();
  if (scene.gltf.animations.empty()) return;
  AnimatedNodePosesAt(scene.gltf, 0, time_s, /*loop=*/true, scratch);
  for (const GltfNodePose& p : *scratch) {
    if (p.scene_node < 0 ||
        static_cast<std::size_t>(p.scene_node) >= stream.graph_node_of_entry.size()) {
      continue;
    }
    const int node = stream.graph_node_of_entry[static_cast<std::size_t>(p.scene_node)];
    if (node < 0 || (stream.graph.nodes[static_cast<std::size_t>(node)].flags & kSceneNodeTool)) {
      continue;
    }
    wire::NodePose out;
    out.node = static_cast<std::uint16_t>(node);
    out.translation = glm::vec3(p.translation);
    out.rotation = glm::quat(p.rotation);
    out.scale = glm::vec3(p.scale);
    poses->push_back(out);
  }
}

}  // namespace ht
