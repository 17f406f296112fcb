// Loading a glTF 2.0 scene (codecs/gltf_scene.h): LoadGltfScene's top-level flow (parse the
// container, check the required extensions, build the node tree, read the animations) and the
// scene's JSON summary. The concerns live in gltf_container.cc, gltf_draco.cc,
// gltf_accessors.cc, gltf_nodes.cc and gltf_animation.cc (shared pieces in gltf_internal.h).

#include "codecs/gltf_scene.h"

#include <cstdint>
#include <glm/common.hpp>
#include <limits>
#include <map>
#include <new>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <string>
#include <vector>

#include "gltf_internal.h"

namespace ht {
namespace {

using gltf_internal::LoadError;

GltfScene BuildScene(const std::string& path) {
  GltfScene scene;
  scene.path = path;
  std::map<gltf_internal::DracoKey, gltf_internal::DracoPrimitive> draco;
  const tinygltf::Model model = gltf_internal::ParseWithTinyGltf(path, &draco, &scene.notes);

  for (const std::string& ext : model.extensionsRequired) {
    if (ext == "KHR_draco_mesh_compression") continue;
    if (ext == "EXT_meshopt_compression" || ext == "KHR_meshopt_compression" ||
        ext == "KHR_mesh_quantization" || ext == "EXT_mesh_gpu_instancing") {
      throw LoadError("requires extension " + ext +
                      ", which changes geometry and is not supported");
    }
    scene.notes.push_back("required extension " + ext + " ignored (does not change geometry)");
  }
  if (!model.cameras.empty())
    scene.notes.push_back(std::to_string(model.cameras.size()) + " camera(s) ignored");
  if (!model.skins.empty())
    scene.notes.push_back(std::to_string(model.skins.size()) + " skin(s) ignored (bind pose used)");
  if (!model.materials.empty())
    scene.notes.push_back(std::to_string(model.materials.size()) + " material(s) ignored");

  const gltf_internal::NodeTree tree = gltf_internal::BuildNodeTree(model, draco, &scene);
  scene.animations =
      gltf_internal::ReadAnimations(model, tree.first_entry, scene.nodes, &scene.notes);
  if (tree.unused_meshes > 0) {
    scene.notes.push_back(std::to_string(tree.unused_meshes) +
                          " mesh(es) not shown by the scene, not loaded");
  }
  return scene;
}

nlohmann::json Vec3Json(const glm::dvec3& v) { return nlohmann::json::array({v.x, v.y, v.z}); }

}  // namespace

GltfScene LoadGltfScene(const std::string& path) {
  try {
    return BuildScene(path);
  } catch (const LoadError& e) {
    throw std::runtime_error(path + ": " + e.what());
  } catch (const std::bad_alloc&) {
    throw std::runtime_error(path + ": out of memory while loading");
  } catch (const std::exception& e) {
    throw std::runtime_error(path + ": " + e.what());
  }
}

nlohmann::json SceneSummaryJson(const GltfScene& scene) {
  nlohmann::json j;
  j["path"] = scene.path;
  j["notes"] = scene.notes;
  j["meshes"] = nlohmann::json::array();
  std::int64_t mesh_triangles = 0;
  std::int64_t vertices = 0;
  for (const GltfMesh& m : scene.meshes) {
    j["meshes"].push_back({{"name", m.name},
                           {"gltf_mesh_index", m.gltf_mesh_index},
                           {"triangles", m.mesh_N.triangles.size()},
                           {"vertices", m.mesh_N.vertices.size()},
                           {"primitives", m.primitive_count},
                           {"draco_primitives", m.draco_primitive_count},
                           {"dropped_degenerate_triangles", m.dropped_degenerate_triangles}});
    mesh_triangles += static_cast<std::int64_t>(m.mesh_N.triangles.size());
    vertices += static_cast<std::int64_t>(m.mesh_N.vertices.size());
  }
  j["instances"] = nlohmann::json::array();
  std::int64_t triangles = 0;
  constexpr double kInf = std::numeric_limits<double>::infinity();
  glm::dvec3 lo_all(kInf);
  glm::dvec3 hi_all(-kInf);
  for (const GltfMeshInstance& inst : scene.instances) {
    nlohmann::json e = {
        {"node", inst.node_name}, {"node_index", inst.node_index}, {"mesh", inst.mesh}};
    if (inst.mesh >= 0 && static_cast<std::size_t>(inst.mesh) < scene.meshes.size()) {
      const GltfMesh& m = scene.meshes[static_cast<std::size_t>(inst.mesh)];
      e["mesh_name"] = m.name;
      e["triangles"] = m.mesh_N.triangles.size();
      e["vertices"] = m.mesh_N.vertices.size();
      triangles += static_cast<std::int64_t>(m.mesh_N.triangles.size());
      if (!m.mesh_N.vertices.empty()) {
        glm::dvec3 lo(kInf);
        glm::dvec3 hi(-kInf);
        for (const glm::dvec3& p_N : m.mesh_N.vertices) {
          const glm::dvec3 p_W = glm::dvec3(inst.X_WN * glm::dvec4(p_N, 1.0));
          lo = glm::min(lo, p_W);
          hi = glm::max(hi, p_W);
        }
        e["bbox_min_W"] = Vec3Json(lo);
        e["bbox_max_W"] = Vec3Json(hi);
        lo_all = glm::min(lo_all, lo);
        hi_all = glm::max(hi_all, hi);
      }
    }
    j["instances"].push_back(std::move(e));
  }
  nlohmann::json totals = {{"instances", scene.instances.size()},
                           {"meshes", scene.meshes.size()},
                           {"triangles", triangles},
                           {"mesh_triangles", mesh_triangles},
                           {"vertices", vertices}};
  if (lo_all.x <= hi_all.x) {
    totals["bbox_min_W"] = Vec3Json(lo_all);
    totals["bbox_max_W"] = Vec3Json(hi_all);
  }
  j["totals"] = std::move(totals);
  j["animations"] = nlohmann::json::array();
  for (const GltfAnimation& a : scene.animations) {
    j["animations"].push_back(
        {{"name", a.name}, {"channels", a.channels.size()}, {"duration_s", a.duration_s}});
  }
  return j;
}

}  // namespace ht
