#include "slave_sim/scene_build.h"

#include <Eigen/Dense>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <glm/glm.hpp>
#include <glm/gtc/quaternion.hpp>
#include <iterator>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>
#include <numbers>
#include <stdexcept>

#include "codecs/json_nesting.h"
#include "haptic_core/demo/procedural_models.h"
#include "haptic_core/remote_step.h"

namespace ht {
namespace {

double Seconds(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

NodeRole ParseRole(const std::string& where, const std::string& role) {
  if (role == "tool") return NodeRole::kTool;
  if (role == "touchable") return NodeRole::kTouchable;
  if (role == "display") return NodeRole::kDisplay;
  throw std::runtime_error(where + ": role '" + role + "' is not one of tool, touchable, display");
}

// Reads the keys of `j` (an object) into `spec`, over what it already holds.
void ReadSpec(const std::string& where, const nlohmann::ordered_json& j, NodeSpec& spec) {
  if (!j.is_object()) throw std::runtime_error(where + ": must be a JSON object");
  for (const auto& [key, value] : j.items()) {
    const std::string at = where + "." + key;
    if (key == "role") {
      if (!value.is_string()) throw std::runtime_error(at + ": must be a string");
      spec.role = ParseRole(at, value.get<std::string>());
    } else if (key == "stiffness_n_per_m") {
      if (!value.is_number()) throw std::runtime_error(at + ": must be a number");
      spec.stiffness_n_per_m = value.get<double>();
      if (!(spec.stiffness_n_per_m > 0.0) || !std::isfinite(spec.stiffness_n_per_m)) {
        throw std::runtime_error(at + ": must be a positive stiffness in N/m");
      }
    } else if (key == "coarse_triangles") {
      if (!value.is_number_integer() || value.get<std::int64_t>() < 4 ||
          value.get<std::int64_t>() > 1'000'000) {
        throw std::runtime_error(at + ": must be an integer in [4, 1000000]");
      }
      spec.coarse_triangles = value.get<int>();
    } else if (key == "texture_size") {
      if (value.is_string() && value.get<std::string>() == "auto") {
        spec.texture_size = 0;  // from the surface's detail (TextureSizingParams)
        continue;
      }
      if (!value.is_number_integer()) {
        throw std::runtime_error(at + ": must be an integer or \"auto\"");
      }
      const auto n = value.get<std::int64_t>();
      if (n < 16 || n > 8192 || (n & (n - 1)) != 0) {
        throw std::runtime_error(at + ": must be a power of two in [16, 8192], got " +
                                 std::to_string(n));
      }
      spec.texture_size = static_cast<int>(n);
    } else if (key == "texture_budget_um") {
      if (!value.is_number() || !(value.get<double>() > 0.0) ||
          !std::isfinite(value.get<double>())) {
        throw std::runtime_error(at + ": must be a number of micrometres > 0");
      }
      spec.texture_budget_m = value.get<double>() * 1e-6;
    } else {
      throw std::runtime_error(at +
                               ": unknown key (known: role, stiffness_n_per_m, "
                               "coarse_triangles, texture_size, texture_budget_um)");
    }
  }
}

// Polar decomposition of the linear part of X_WN: L = R·S with R a rotation; S (returned in
// `residual`) keeps scale, shear and any mirror.
glm::dquat RotationOf(const glm::dmat4& X_WN, glm::dmat3& residual,
                      double* conditioning = nullptr) {
  Eigen::Matrix3d m;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) m(r, c) = X_WN[c][r];
  }
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(m, Eigen::ComputeFullU | Eigen::ComputeFullV);
  if (conditioning != nullptr) {
    const Eigen::Vector3d sv = svd.singularValues();  // decreasing
    *conditioning = sv(0) > 0.0 ? sv(2) / sv(0) : 0.0;
  }
  Eigen::Matrix3d u = svd.matrixU();
  if ((u * svd.matrixV().transpose()).determinant() < 0.0) u.col(2) *= -1.0;
  const Eigen::Matrix3d rotation = u * svd.matrixV().transpose();
  const Eigen::Matrix3d s = rotation.transpose() * m;
  glm::dmat3 R{1.0};
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) {
      R[c][r] = rotation(r, c);
      residual[c][r] = s(r, c);
    }
  }
  return glm::normalize(glm::quat_cast(R));
}

// True when the node key ("name" or "#index") names this instance.
bool KeyMatches(const std::string& key, const GltfMeshInstance& inst) {
  if (!key.empty() && key[0] == '#') return key.substr(1) == std::to_string(inst.node_index);
  return key == inst.node_name;
}

}  // namespace

const char* NodeRoleName(NodeRole role) noexcept {
  switch (role) {
    case NodeRole::kTool:
      return "tool";
    case NodeRole::kTouchable:
      return "touchable";
    case NodeRole::kDisplay:
      return "display";
  }
  return "?";
}

SceneDescription SceneDescription::ForGltf(const std::string& gltf_path) {
  SceneDescription d;
  d.gltf_path = gltf_path;
  return d;
}

SceneDescription SceneDescription::LoadFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error(path + ": cannot open the scene description");
  constexpr std::uintmax_t kMaxDescriptionBytes = 16u
                                                  << 20;  // a description is a few hundred bytes
  std::error_code size_error;
  if (std::filesystem::file_size(path, size_error) > kMaxDescriptionBytes && !size_error) {
    throw std::runtime_error(path + ": a scene description larger than 16 MiB is refused");
  }
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  // The parser recurses per nesting level: a deep file must not reach it (stack overflow).
  if (const std::size_t depth = JsonNestingDepth(text); depth > kMaxJsonNesting) {
    throw std::runtime_error(path + ": the JSON nests " + std::to_string(depth) +
                             " levels deep (at most " + std::to_string(kMaxJsonNesting) +
                             " are accepted)");
  }
  nlohmann::ordered_json j;  // keeps the file's key order
  try {
    j = nlohmann::ordered_json::parse(text);
  } catch (const nlohmann::json::exception& e) {
    throw std::runtime_error(path + ": not valid JSON: " + e.what());
  }
  if (!j.is_object()) throw std::runtime_error(path + ": must be a JSON object");
  SceneDescription d;
  bool have_scene = false;
  for (const auto& [key, value] : j.items()) {
    if (key == "scene") {
      if (!value.is_string()) throw std::runtime_error(path + ": scene must be a path string");
      std::filesystem::path p = value.get<std::string>();
      if (p.is_relative()) p = std::filesystem::path(path).parent_path() / p;
      d.gltf_path = p.lexically_normal().string();
      have_scene = true;
    } else if (key == "defaults") {
      ReadSpec(path + ": defaults", value, d.defaults);
      if (d.defaults.role == NodeRole::kTool) {
        throw std::runtime_error(path + ": defaults.role cannot be tool (name one node)");
      }
    } else if (key == "nodes") {
      if (!value.is_object()) throw std::runtime_error(path + ": nodes must be an object");
    } else if (key == "tool") {
      if (!value.is_string()) throw std::runtime_error(path + ": tool must be a node name");
      d.tool_node = value.get<std::string>();
    } else if (key == "scale") {
      if (j.contains("units")) {
        throw std::runtime_error(path + ": give \"scale\" or \"units\", not both");
      }
      if (!value.is_number() || !(value.get<double>() > 0.0) ||
          !std::isfinite(value.get<double>())) {
        throw std::runtime_error(path +
                                 ": scale must be a number > 0 (metres per unit of the glTF "
                                 "file: 0.001 for a file in millimetres)");
      }
      d.scale = value.get<double>();
    } else if (key == "units") {
      static const std::map<std::string, double> kUnits = {
          {"m", 1.0}, {"cm", 0.01}, {"mm", 0.001}, {"in", 0.0254}, {"ft", 0.3048}};
      const auto it = value.is_string() ? kUnits.find(value.get<std::string>()) : kUnits.end();
      if (it == kUnits.end()) {
        throw std::runtime_error(path + ": units must be one of m, cm, mm, in, ft");
      }
      d.scale = it->second;
    } else {
      throw std::runtime_error(path + ": unknown key '" + key +
                               "' (known: scene, units, scale, defaults, nodes, tool)");
    }
  }
  if (!have_scene) throw std::runtime_error(path + ": no \"scene\" (the glTF file) given");
  if (j.contains("nodes")) {
    // Node settings start from the defaults, whatever the key order in the file.
    for (const auto& [key, value] : j["nodes"].items()) {
      NodeSpec spec = d.defaults;
      ReadSpec(path + ": nodes." + key, value, spec);
      if (spec.role == NodeRole::kTool) {
        if (!d.tool_node.empty() && d.tool_node != key) {
          throw std::runtime_error(path + ": two tools: '" + d.tool_node + "' and '" + key + "'");
        }
        d.tool_node = key;
      }
      d.nodes.emplace_back(key, spec);
    }
  }
  return d;
}

SceneDescription LoadSceneInput(const std::string& path, const std::string& tool_node) {
  const std::string ext = std::filesystem::path(path).extension().string();
  SceneDescription d =
      ext == ".json" ? SceneDescription::LoadFile(path) : SceneDescription::ForGltf(path);
  if (!tool_node.empty()) d.tool_node = tool_node;
  return d;
}

glm::dquat SceneUpRotation() noexcept {
  return glm::angleAxis(-0.5 * std::numbers::pi, glm::dvec3(1.0, 0.0, 0.0));
}

BuiltScene BuildScene(const SceneDescription& description, const HapticModelCache& cache,
                      const SceneBuildProgress& progress) {
  const auto start = std::chrono::steady_clock::now();
  BuiltScene scene;
  scene.description = description;
  scene.gltf = LoadGltfScene(description.gltf_path);
  ScaleGltfScene(scene.gltf, description.scale);
  scene.load_s = Seconds(start);
  const std::string& file = description.gltf_path;

  // Every description key must name a node of the scene.
  const auto names_a_node = [&](const std::string& key) {
    for (const auto& inst : scene.gltf.instances) {
      if (KeyMatches(key, inst)) return true;
    }
    return false;
  };
  for (const auto& [key, spec] : description.nodes) {
    if (!names_a_node(key)) {
      throw std::runtime_error(file + ": the scene description names node '" + key +
                               "', which is not a mesh node of the scene");
    }
  }
  if (!description.tool_node.empty() && !names_a_node(description.tool_node)) {
    throw std::runtime_error(file + ": the tool node '" + description.tool_node +
                             "' is not a mesh node of the scene");
  }

  for (const GltfMeshInstance& inst : scene.gltf.instances) {
    SceneNode obj;
    obj.node_name = inst.node_name;
    obj.node_index = inst.node_index;
    obj.mesh = inst.mesh;
    const std::string& mesh_name = scene.gltf.meshes[static_cast<std::size_t>(inst.mesh)].name;
    obj.label = !inst.node_name.empty() ? inst.node_name
                : !mesh_name.empty()    ? mesh_name
                                        : "#" + std::to_string(inst.node_index);
    obj.spec = description.defaults;
    for (const auto& [key, spec] : description.nodes) {
      if (KeyMatches(key, inst)) obj.spec = spec;
    }
    if (!description.tool_node.empty() && KeyMatches(description.tool_node, inst)) {
      obj.spec.role = NodeRole::kTool;
    } else if (obj.spec.role == NodeRole::kTool) {
      obj.spec.role = NodeRole::kTouchable;  // tool named elsewhere (override)
    }
    obj.full_triangles =
        static_cast<std::int64_t>(scene.gltf.meshes[inst.mesh].mesh_N.triangles.size());
    scene.objects.push_back(std::move(obj));
  }
  int tools = 0;
  for (const SceneNode& obj : scene.objects) tools += obj.spec.role == NodeRole::kTool;
  if (tools > 1) {
    throw std::runtime_error(file + ": the tool '" + description.tool_node + "' names " +
                             std::to_string(tools) + " nodes; name one node (\"#index\")");
  }

  int to_build = 0;
  for (const SceneNode& obj : scene.objects) to_build += obj.spec.role != NodeRole::kDisplay;
  int built = 0;
  std::map<std::string, std::size_t> first_with_key;  // instances share a build
  glm::dvec3 lo{std::numeric_limits<double>::max()}, hi{-std::numeric_limits<double>::max()};
  for (std::size_t i = 0; i < scene.objects.size(); ++i) {
    SceneNode& obj = scene.objects[i];
    const GltfMeshInstance& inst = scene.gltf.instances[i];
    glm::dmat3 residual{1.0};
    double conditioning = 0.0;
    obj.X_WO.rotation = RotationOf(inst.X_WN, residual, &conditioning);
    obj.X_WO.translation = glm::dvec3(inst.X_WN[3]);
    obj.rest_residual = residual;
    if (obj.spec.role == NodeRole::kDisplay) continue;
    if (progress) progress(obj.label, ++built, to_build);
    const std::string& label = obj.label;
    if (scene.gltf.meshes[inst.mesh].mesh_N.triangles.empty()) {
      scene.notes.push_back("node '" + label + "' has no triangles: shown only (display)");
      obj.spec.role = NodeRole::kDisplay;
      continue;
    }
    if (!(conditioning > 1e-9)) {
      scene.notes.push_back("node '" + label +
                            "' has a zero (singular) scale: shown only (display)");
      obj.spec.role = NodeRole::kDisplay;
      continue;
    }

    // The model's frame O is the node frame without its scale: vertices carry the residual.
    TriangleMesh mesh_O = scene.gltf.meshes[inst.mesh].mesh_N;
    for (glm::dvec3& p : mesh_O.vertices) p = residual * p;
    if (glm::determinant(residual) < 0.0) {
      for (glm::ivec3& t : mesh_O.triangles) std::swap(t.y, t.z);  // a mirror flips winding
    }
    HapticModelBuildParams params;
    params.coarse_triangles = obj.spec.coarse_triangles;
    if (obj.spec.texture_size == 0) {
      params.texture_sizing.from_detail = true;
      params.texture_sizing.surface_budget_m = obj.spec.texture_budget_m;
    } else {
      params.texture.texture_size = obj.spec.texture_size;
    }
    const std::string name =
        obj.node_name.empty() ? "node#" + std::to_string(obj.node_index) : obj.node_name;
    const std::string key = HapticModelCacheKey(mesh_O, params);
    if (auto it = first_with_key.find(key); it != first_with_key.end()) {
      obj.model = scene.objects[it->second].model;
      obj.report = scene.objects[it->second].report;
      obj.report.name = name;
      obj.report.from_cache = true;
      obj.report.cache_note =
          "shares the model of node '" + scene.objects[it->second].node_name + "'";
      obj.report.decimate_s = obj.report.bake_s = obj.report.hulls_s = 0.0;
      obj.report.cache_load_s = obj.report.total_s = 0.0;
    } else {
      try {
        HapticModelBuild b = BuildHapticModelCached(name, mesh_O, params, cache);
        obj.model = std::move(b.model);
        obj.report = std::move(b.report);
      } catch (const std::exception& e) {
        if (std::string(e.what()).find("forms a manifold surface") != std::string::npos) {
          // Every triangle degenerate once equal positions are welded: nothing to touch.
          scene.notes.push_back("node '" + label + "' has no surface (" + e.what() +
                                "): shown only (display)");
          obj.spec.role = NodeRole::kDisplay;
          continue;
        }
        throw std::runtime_error(file + ": node '" + name + "': " + e.what());
      }
      first_with_key.emplace(key, i);
    }
    if (obj.spec.role == NodeRole::kTool) {
      // The tool frame T sits at the tool's centre of mass (HapticTexturePipeline requires it),
      // and at the node's rest pose its +z is the scene's up (glTF's +Y): the Welcome's home pose
      // is the operator's workspace frame M, so the device's up is the scene's up whatever the
      // node's own rotation (issue 33). The tool keeps the orientation the node gives it.
      const glm::dvec3 com = obj.model->center_of_mass_O;
      const glm::dquat R_TO = glm::inverse(SceneUpRotation()) * obj.X_WO.rotation;
      auto turned = std::make_shared<HapticModel>(*obj.model);
      ShiftModelFrame(*turned, com);
      RotateModelFrame(*turned, R_TO);
      obj.model = std::move(turned);
      obj.X_WO.translation += obj.X_WO.rotation * com;
      obj.X_WO.rotation = SceneUpRotation();
      scene.haptic.tool = obj.model;
      scene.builtin_probe = false;
    } else {
      scene.haptic.touchables.push_back({obj.model, obj.X_WO, obj.spec.stiffness_n_per_m});
      scene.touchable_objects.push_back(static_cast<int>(i));
      const double reach = obj.model->OutwardReach();  // the textured surface's, beyond coarse
      for (const glm::dvec3& p : obj.model->vertices_O) {
        const glm::dvec3 p_W = obj.X_WO * p;
        lo = glm::min(lo, p_W - glm::dvec3(reach));
        hi = glm::max(hi, p_W + glm::dvec3(reach));
      }
    }
  }

  // A scene larger than a desk is most often a file in other units than glTF's metres (CAD
  // exports in millimetres): say so, and how to scale it.
  if (!scene.haptic.touchables.empty()) {
    const glm::dvec3 span = hi - lo;
    const double largest = std::max({span.x, span.y, span.z});
    if (largest > kLargestDeskSceneM) {
      char what[256];
      std::snprintf(what, sizeof what,
                    "the touchable objects span %.3g m, larger than a desk (%.0f m): if the file "
                    "is in millimetres, give it in a scene description with \"units\": \"mm\" "
                    "(or \"scale\"); scale in use %.6g",
                    largest, kLargestDeskSceneM, description.scale);
      scene.notes.push_back(what);
      scene.warnings.push_back(what);
    }
  }
  std::vector<const HapticModel*> warned;  // instances share a model: one warning per model
  for (const SceneNode& obj : scene.objects) {
    if (!obj.model || obj.spec.role == NodeRole::kDisplay) continue;
    if (std::find(warned.begin(), warned.end(), obj.model.get()) != warned.end()) continue;
    glm::dvec3 a{std::numeric_limits<double>::max()}, b{-std::numeric_limits<double>::max()};
    for (const glm::dvec3& p : obj.model->vertices_O) {
      a = glm::min(a, p);
      b = glm::max(b, p);
    }
    const double size = glm::length(b - a);
    const double err = obj.report.bake.max_bake_error_m;
    const SurfaceErrorReport& surf = obj.report.surface;
    const bool bake_misses = size > 0.0 && err > kLargeBakeErrorFraction * size;
    const bool surface_outside = surf.share_outside > kLargeSurfaceOutsideShare;
    if (bake_misses || surface_outside) {
      char what[560];
      std::snprintf(what, sizeof what,
                    "node '%s': the texture bake's largest error is %.3g m (%.0f %% of the "
                    "object's size, %.3g m) and %.1f %% of its full-resolution surface lies more "
                    "than %.0f um outside the model (p99 distance %.3g m): its coarse mesh misses "
                    "the surface there, and contacts there are felt late or not at all (more "
                    "\"coarse_triangles\" or %s in a scene description)",
                    obj.label.c_str(), err, size > 0.0 ? 100.0 * err / size : 0.0, size,
                    100.0 * surf.share_outside, SurfaceErrorParams{}.outside_threshold_m * 1e6,
                    surf.p99_m,
                    obj.spec.texture_size == 0 ? "a smaller \"texture_budget_um\""
                                               : "a larger \"texture_size\" (or \"auto\")");
      scene.notes.push_back(what);
      scene.warnings.push_back(what);
      warned.push_back(obj.model.get());
    }
  }

  scene.haptic.name = std::filesystem::path(file).stem().string();
  RigidTransform home;
  // T's +z is the scene's up at home (a tool node's frame was turned so above): the probe's
  // textured face (−z in T) faces the scene's down direction (−Y in W).
  home.rotation = SceneUpRotation();
  if (!scene.haptic.tool) {
    scene.haptic.tool = std::make_shared<const HapticModel>(MakeRidgedBlock());
  }
  if (scene.haptic.touchables.empty()) {
    home.translation = glm::dvec3(0.0);
  } else {
    double below = 0.0;  // tool's extent below its frame along −Y of W
    for (const glm::dvec3& p : scene.haptic.tool->vertices_O) {
      below = std::max(below, -(home.rotation * p).y);
    }
    home.translation = glm::dvec3(0.5 * (lo.x + hi.x), hi.y + 0.01 + below, 0.5 * (lo.z + hi.z));
  }
  scene.haptic.X_WT_home = home;
  scene.total_s = Seconds(start);
  return scene;
}

void AnimateScene(BuiltScene& scene, int animation, double time_s,
                  std::vector<glm::dmat4>* scratch) {
  PoseInstancesAt(scene.gltf, animation, time_s, /*loop=*/true, scratch);
  for (std::size_t k = 0; k < scene.haptic.touchables.size(); ++k) {
    const auto i = static_cast<std::size_t>(scene.touchable_objects[k]);
    if (i >= scratch->size()) continue;
    // The model carries the rest scale S_rest (M = R·S): the rotation now is the polar rotation of
    // M(t)·S_rest⁻¹, which stays unique when S_rest mirrors with equal scales.
    const glm::dmat4& M = (*scratch)[i];
    const glm::dmat3 L = glm::dmat3(M) * glm::inverse(scene.objects[i].rest_residual);
    glm::dmat3 residual{1.0};
    RigidTransform X_WO;
    X_WO.rotation = RotationOf(glm::dmat4(L), residual);
    X_WO.translation = glm::dvec3(M[3]);
    scene.objects[i].X_WO = X_WO;
    scene.haptic.touchables[k].X_WO = X_WO;
  }
}

nlohmann::json InspectJson(const BuiltScene& scene) {
  using nlohmann::json;
  json out;
  out["file"] = scene.description.gltf_path;
  out["scale"] = scene.description.scale;
  out["warnings"] = scene.warnings;
  out["load_s"] = scene.load_s;
  out["total_s"] = scene.total_s;
  out["tool"] = scene.builtin_probe ? json("built-in probe: " + scene.haptic.tool->name)
                                    : json(scene.description.tool_node);
  json objects = json::array();
  for (const SceneNode& obj : scene.objects) {
    json o;
    o["name"] = obj.label;  // the node's name, else its mesh's, else "#index"
    o["node_name"] = obj.node_name;
    o["node_index"] = obj.node_index;
    o["role"] = NodeRoleName(obj.spec.role);
    o["full_triangles"] = obj.full_triangles;
    if (obj.model) {
      const HapticModelBuildReport& r = obj.report;
      o["coarse_triangles"] = r.coarse_triangles;
      o["coarse_closed"] = r.coarse_boundary_edges == 0;
      o["hull_count"] = r.hull_nodes;
      o["hull_leaves"] = r.hull_leaves;
      o["texture_size"] = r.texture_size;
      if (!r.texture_trials.empty()) {
        // "texture_size": "auto" (issue 32): each size baked and its surface error, and why.
        json trials = json::array();
        for (const TextureSizeTrial& t : r.texture_trials) {
          trials.push_back({{"size", t.size},
                            {"surface_p99_m", t.surface_p99_m},
                            {"surface_outside_p99_m", t.surface_outside_p99_m},
                            {"seconds", t.seconds}});
        }
        o["texture_size_chosen"] = {{"trials", std::move(trials)},
                                    {"reason", r.texture_size_reason}};
      }
      o["bake_max_error_m"] = r.bake.max_bake_error_m;
      o["bake_rms_error_m"] = r.bake.rms_bake_error_m;
      o["bake_max_abs_height_m"] = r.bake.max_abs_height_m;
      o["outward_reach_m"] = r.outward_reach_m;
      // The other direction (issue 32): full-resolution points against the textured coarse
      // model (MeasureSurfaceError), which the bake's validation cannot see.
      o["surface_error"] = {{"samples", r.surface.samples},
                            {"p50_m", r.surface.p50_m},
                            {"p95_m", r.surface.p95_m},
                            {"p99_m", r.surface.p99_m},
                            {"max_m", r.surface.max_m},
                            {"outside_p99_m", r.surface.outside_p99_m},
                            {"share_outside_25um", r.surface.share_outside}};
      o["bake_misses"] = r.bake.misses;
      o["bake_texels"] = r.bake.texels_baked;
      o["bake_clamped"] = r.bake.clamped;
      // What the texture's size buys (issue 32): the heights a texture of half, a quarter and
      // an eighth the side would lose (largest and RMS: the largest is dominated by the atlas'
      // chart seams, which coarser levels blur), and the smallest size whose RMS loss is within
      // the bake's own RMS error (or 1 µm): it models the surface as well as this one does.
      const HeightField& tex = obj.model->texture;
      if (!tex.empty()) {
        json coarser = json::array();
        const double budget = std::max(r.bake.rms_bake_error_m, 1e-6);
        int needed = tex.level(0).width;
        bool still = true;
        for (int level = 1; level <= 3 && level < tex.num_levels(); ++level) {
          const HeightField::LevelLoss loss = tex.LossAtLevel(level);
          coarser.push_back({{"size", tex.level(level).width},
                             {"max_loss_m", loss.max_m},
                             {"rms_loss_m", loss.rms_m}});
          if (still && loss.rms_m <= budget) {
            needed = tex.level(level).width;
          } else {
            still = false;
          }
        }
        char reason[256];
        if (needed == tex.level(0).width) {
          std::snprintf(reason, sizeof reason,
                        "a %d texture loses more than %.3g um RMS (the bake's own RMS error, or "
                        "1 um): the surface has detail at %d",
                        tex.level(0).width / 2, budget * 1e6, tex.level(0).width);
        } else {
          std::snprintf(reason, sizeof reason,
                        "%d reproduces the heights within %.3g um RMS (the bake's own RMS error, "
                        "or 1 um): a %d texture holds no detail that %d does not",
                        needed, budget * 1e6, tex.level(0).width, needed);
        }
        o["texture_detail"] = {
            {"coarser", std::move(coarser)}, {"size_needed", needed}, {"reason", reason}};
      }
      o["stiffness_n_per_m"] = obj.spec.stiffness_n_per_m;
      o["from_cache"] = r.from_cache;
      if (!r.cache_note.empty()) o["cache_note"] = r.cache_note;
      o["seconds"] = {{"decimate", r.decimate_s},
                      {"bake", r.bake_s},
                      {"hulls", r.hulls_s},
                      {"cache_load", r.cache_load_s},
                      {"total", r.total_s}};
    }
    objects.push_back(std::move(o));
  }
  out["objects"] = std::move(objects);
  json animations = json::array();
  for (const GltfAnimation& a : scene.gltf.animations) {
    animations.push_back(
        {{"name", a.name}, {"channels", a.channels.size()}, {"duration_s", a.duration_s}});
  }
  out["animations"] = std::move(animations);
  json notes = scene.gltf.notes;
  for (const std::string& n : scene.notes) notes.push_back(n);
  out["notes"] = std::move(notes);
  return out;
}

}  // namespace ht
