// Load a glTF scene and print the haptic models the remote node builds from it: for each mesh
// node its role, the triangles of its full-resolution and coarse meshes, its convex-hull
// hierarchy, its haptic texture (height field) and how well the texture holds the detail.
//
// Usage: gltf_scene_models [SCENE]
//   SCENE: a .gltf or .glb file (every mesh node touchable, the built-in probe as the tool) or a
//   scene description .json (roles, stiffness, coarse and texture sizes per node; see
//   slave_sim/include/slave_sim/scene_build.h), e.g. ../shared/data/gltf/Duck/Duck.glb where the
//   team's data is. Without SCENE it writes a small one first: the seed's ridged block (the tool)
//   over the ridged gear, as block_on_gear.glb and block_on_gear.json in a temporary folder.
// Models are built through the model cache ($HT_CACHE_DIR, else ~/.cache/haptic_teleop).
//
// Printed: per node, triangles (full → coarse), hull nodes and leaves, texture side (texels),
// outward reach (µm: how far the textured surface lies outside the coarse one), the bake's
// largest and RMS error (µm), the surface error p99 (µm), mass (kg) and the position of its frame
// O in the scene frame W (glTF's: +Y up, metres). The tool's frame T is at its centre of mass.
//
// Built in the tree (it links slave_sim_lib, which is not installed): HT_BUILD_EXAMPLES, on by
// default, makes build/examples/gltf_scene_models/gltf_scene_models; ctest runs it
// (example_gltf_scene_models).
#include <cstdio>
#include <exception>
#include <filesystem>
#include <fstream>
#include <glm/gtc/matrix_transform.hpp>
#include <string>

#include "codecs/glb_writer.h"
#include "haptic_core/demo/procedural_models.h"
#include "slave_sim/scene_build.h"

namespace {

// Writes the block over the gear as a glTF file and a scene description naming the block as
// the tool; returns the description's path.
std::string WriteDemoScene(const std::filesystem::path& dir) {
  std::filesystem::create_directories(dir);
  ht::RidgedBlockParams block;
  block.full_resolution_grid = 60;  // a small file: 7,200 bottom triangles
  ht::RidgedGearParams gear;
  gear.full_resolution_segments = 800;
  // glTF's up is +Y: the block's ridged bottom face (−z of its frame) turned to face −Y, 2 mm
  // above the gear's ridge tops; the gear's axis along x.
  glm::dmat4 X_WBlock = glm::translate(glm::dmat4(1.0), glm::dvec3(0.0, 0.0372, 0.0));
  X_WBlock = glm::rotate(X_WBlock, glm::radians(-90.0), glm::dvec3(1.0, 0.0, 0.0));
  ht::WriteGlb((dir / "block_on_gear.glb").string(),
               {{"gear", ht::MakeRidgedGearFullResolution(gear), glm::dmat4(1.0), ""},
                {"block", ht::MakeRidgedBlockFullResolution(block), X_WBlock, ""}});
  const std::string json = (dir / "block_on_gear.json").string();
  std::ofstream(json) << R"({"scene": "block_on_gear.glb", "tool": "block",
  "defaults": {"coarse_triangles": 800, "texture_size": 256, "stiffness_n_per_m": 8000},
  "nodes": {"block": {"coarse_triangles": 16}}})"
                      << "\n";
  return json;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    const std::string input =
        argc > 1 ? argv[1]
                 : WriteDemoScene(std::filesystem::temp_directory_path() / "ht_gltf_scene_models");
    const ht::SceneDescription description = ht::LoadSceneInput(input);
    const ht::HapticModelCache cache(ht::HapticModelCache::DefaultDir());
    const ht::BuiltScene scene = ht::BuildScene(description, cache);

    std::printf("%s: %zu mesh node(s), %zu touchable; built in %.2f s (glTF read in %.2f s)\n",
                input.c_str(), scene.objects.size(), scene.haptic.touchables.size(), scene.total_s,
                scene.load_s);
    const std::string tool = scene.builtin_probe ? "the built-in probe " + scene.haptic.tool->name
                                                 : "node '" + description.tool_node + "'";
    std::printf("tool: %s\n", tool.c_str());
    std::printf("%-16s %-9s %9s %7s %11s %7s %8s %15s %8s %8s  %s\n", "node", "role", "full tri",
                "coarse", "hulls/leaf", "texels", "reach um", "bake max/rms um", "surf p99",
                "mass kg", "p_WO (m)");
    for (const ht::SceneNode& o : scene.objects) {
      std::printf("%-16.16s %-9s %9lld", o.label.c_str(), ht::NodeRoleName(o.spec.role),
                  static_cast<long long>(o.full_triangles));
      if (o.model) {
        const ht::HapticModelBuildReport& r = o.report;
        std::printf(" %7lld %5d/%-5d %7d %8.1f %7.1f/%-7.1f %8.1f %8.3g",
                    static_cast<long long>(r.coarse_triangles), r.hull_nodes, r.hull_leaves,
                    r.texture_size, r.outward_reach_m * 1e6, r.bake.max_bake_error_m * 1e6,
                    r.bake.rms_bake_error_m * 1e6, r.surface.p99_m * 1e6, o.model->mass_kg);
      } else {
        std::printf(" %7s %11s %7s %8s %15s %8s %8s", "-", "-", "-", "-", "-", "-", "-");
      }
      std::printf("  (%.4f, %.4f, %.4f)%s\n", o.X_WO.translation.x, o.X_WO.translation.y,
                  o.X_WO.translation.z, o.report.from_cache ? "  [cache]" : "");
    }
    const glm::dvec3& p = scene.haptic.X_WT_home.translation;
    std::printf("tool home X_WT: p = (%.4f, %.4f, %.4f) m in W\n", p.x, p.y, p.z);
    for (const std::string& w : scene.warnings) std::printf("warning: %s\n", w.c_str());
    return scene.haptic.touchables.empty() ? 1 : 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "gltf_scene_models: error: %s\n", e.what());
    return 2;
  }
}
