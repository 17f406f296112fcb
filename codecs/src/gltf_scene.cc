// Loading a glTF 2.0 scene (codecs/gltf_scene.h): LoadGltfScene's top-level flow (parse the
// container, check the required extensions, build the node tree, read the animations) and the
// scene's JSON summary. The concerns live in gltf_container.cc, gltf_draco.cc,
// gltf_accessors.cc, gltf_nodes.cc and gltf_animation.cc (shared pieces in gltf_internal.h).

#include "codecs/gltf_scene.h"

#include <cctype>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <glm/common.hpp>
#include <limits>
#include <map>
#include <new>
#include <nlohmann/json.hpp>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "gltf_internal.h"

namespace ht {
namespace {

using gltf_internal::LoadError;

// The signature of PNG and JPEG bytes; "" for anything else.
std::string SniffImageMime(const std::vector<unsigned char>& b) {
  if (b.size() >= 8 && b[0] == 0x89 && b[1] == 'P' && b[2] == 'N' && b[3] == 'G')
    return "image/png";
  if (b.size() >= 3 && b[0] == 0xFF && b[1] == 0xD8 && b[2] == 0xFF) return "image/jpeg";
  return "";
}

// The bytes of an image the file names by a relative URI (tinygltf is built without external
// images): read from the glTF file's folder. Absolute paths and ".." are refused (a scene file
// must not make the node stream other files to the operator); a missing file gives a note.
std::vector<unsigned char> ReadExternalImage(const std::string& gltf_path, const std::string& uri,
                                             std::vector<std::string>* notes) {
  const std::optional<std::filesystem::path> local = GltfLocalFile(gltf_path, uri);
  if (!local) {
    notes->push_back("image '" + uri + "' is outside the file's folder: not read");
    return {};
  }
  const std::filesystem::path& file = *local;
  std::error_code ec;
  const auto size = std::filesystem::file_size(file, ec);
  if (ec || size > static_cast<std::uintmax_t>(kGltfMaxFileBytes)) {
    notes->push_back("image '" + uri + "' cannot be read (" +
                     (ec ? ec.message() : std::string("too large")) + "): colour only");
    return {};
  }
  std::ifstream in(file, std::ios::binary);
  std::vector<unsigned char> bytes(static_cast<std::size_t>(size));
  if (!in.read(reinterpret_cast<char*>(bytes.data()), static_cast<std::streamsize>(size))) {
    notes->push_back("image '" + uri + "' cannot be read: colour only");
    return {};
  }
  return bytes;
}

// Base colours and base-colour images of every material (indices kept as the file's).
void ReadMaterials(const tinygltf::Model& model, GltfScene* scene) {
  for (const tinygltf::Image& src : model.images) {
    GltfImage image;
    image.name = src.name;
    std::vector<unsigned char> external;
    if (src.image.empty() && !src.uri.empty() && src.uri.rfind("data:", 0) != 0) {
      external = ReadExternalImage(scene->path, src.uri, &scene->notes);
    }
    const std::vector<unsigned char>& bytes = src.image.empty() ? external : src.image;
    image.mime_type = SniffImageMime(bytes);
    if (image.mime_type.empty()) image.mime_type = src.mimeType;
    image.bytes.assign(bytes.begin(), bytes.end());
    scene->images.push_back(std::move(image));
  }
  for (std::size_t i = 0; i < model.materials.size(); ++i) {
    const tinygltf::Material& src = model.materials[i];
    GltfMaterial m;
    m.name = src.name;
    const std::vector<double>& f = src.pbrMetallicRoughness.baseColorFactor;
    if (f.size() == 4 && std::isfinite(f[0]) && std::isfinite(f[1]) && std::isfinite(f[2]) &&
        std::isfinite(f[3])) {
      m.base_colour_rgba = glm::clamp(glm::dvec4(f[0], f[1], f[2], f[3]), 0.0, 1.0);
    } else {
      scene->notes.push_back("material " + std::to_string(i) +
                             ": baseColorFactor is not 4 finite numbers; white used");
    }
    const int texture = src.pbrMetallicRoughness.baseColorTexture.index;
    if (texture >= 0) {
      const int source = static_cast<std::size_t>(texture) < model.textures.size()
                             ? model.textures[static_cast<std::size_t>(texture)].source
                             : -1;
      if (source >= 0 && static_cast<std::size_t>(source) < scene->images.size() &&
          !scene->images[static_cast<std::size_t>(source)].bytes.empty()) {
        m.base_colour_image = source;
      } else {
        scene->notes.push_back("material " + std::to_string(i) +
                               ": base-colour texture without image bytes; colour only");
      }
    }
    scene->materials.push_back(std::move(m));
  }
}

// The first node (depth-first) that shows a perspective camera.
void FindCamera(const tinygltf::Model& model, GltfScene* scene) {
  for (std::size_t e = 0; e < scene->nodes.size(); ++e) {
    const int c = model.nodes[static_cast<std::size_t>(scene->nodes[e].node_index)].camera;
    if (c < 0 || static_cast<std::size_t>(c) >= model.cameras.size()) continue;
    const tinygltf::Camera& cam = model.cameras[static_cast<std::size_t>(c)];
    if (cam.type != "perspective") continue;
    const tinygltf::PerspectiveCamera& p = cam.perspective;
    if (!(p.yfov > 0.0 && p.yfov < 3.1) || !(p.znear > 0.0) || !std::isfinite(p.zfar) ||
        p.zfar < 0.0) {
      scene->notes.push_back("camera " + std::to_string(c) + ": bad perspective values, ignored");
      continue;
    }
    scene->camera = {static_cast<int>(e), p.yfov, p.znear, p.zfar};
    scene->notes.push_back("camera " + std::to_string(c) + " (perspective, on node " +
                           std::to_string(scene->nodes[e].node_index) + ") used for display; " +
                           std::to_string(model.cameras.size() - 1) + " other camera(s) not used");
    return;
  }
  if (!model.cameras.empty() && scene->camera.scene_node < 0) {
    scene->notes.push_back(std::to_string(model.cameras.size()) +
                           " camera(s) not used (none perspective and shown by a scene node)");
  }
}

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
  if (!model.skins.empty())
    scene.notes.push_back(std::to_string(model.skins.size()) + " skin(s) ignored (bind pose used)");
  ReadMaterials(model, &scene);

  const gltf_internal::NodeTree tree = gltf_internal::BuildNodeTree(model, draco, &scene);
  FindCamera(model, &scene);
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

std::optional<std::filesystem::path> GltfLocalFile(const std::string& gltf_path,
                                                   const std::string& uri) {
  std::string decoded;
  for (std::size_t i = 0; i < uri.size(); ++i) {
    if (uri[i] == '%' && i + 2 < uri.size() &&
        std::isxdigit(static_cast<unsigned char>(uri[i + 1])) &&
        std::isxdigit(static_cast<unsigned char>(uri[i + 2]))) {
      decoded.push_back(static_cast<char>(std::stoi(uri.substr(i + 1, 2), nullptr, 16)));
      i += 2;
    } else {
      decoded.push_back(uri[i]);
    }
  }
  const std::filesystem::path rel(decoded);
  if (decoded.empty() || rel.is_absolute() || decoded.find(':') != std::string::npos) {
    return std::nullopt;
  }
  for (const auto& part : rel) {
    if (part == "..") return std::nullopt;
  }
  return std::filesystem::path(gltf_path).parent_path() / rel;
}

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
