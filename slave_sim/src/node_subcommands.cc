// slave_sim's subcommands (node_command_line.h): 'seed-models' and 'inspect'.

#include <sys/resource.h>

#include <algorithm>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "codecs/glb_writer.h"
#include "haptic_core/demo/seed_models.h"
#include "node_command_line.h"
#include "slave_sim/scene_build.h"

namespace ht {

int RunSeedModelsCommand(const NodeCommandLine& cl) {
  try {
    for (const std::string& n : cl.seed_names) ParseSeedModelName(n);  // a typo is an error
    std::filesystem::create_directories(cl.seed_out);
    for (const SeedModelSpec& spec : SeedModelSpecs()) {
      if (!cl.seed_names.empty() &&
          std::find(cl.seed_names.begin(), cl.seed_names.end(), spec.name) == cl.seed_names.end()) {
        continue;
      }
      TriangleMesh mesh = MakeSeedModelFullResolution(spec.model);
      const std::string glb = cl.seed_out + "/" + spec.name + ".glb";
      const std::size_t triangles = mesh.triangles.size();
      WriteGlb(glb, {{spec.name, std::move(mesh), glm::dmat4(1.0), ""}});
      nlohmann::json desc = {{"scene", std::string(spec.name) + ".glb"},
                             {"defaults",
                              {{"role", "touchable"},
                               {"coarse_triangles", spec.seed_coarse_triangles},
                               {"texture_size", 1024}}}};
      const std::string json_path = cl.seed_out + "/" + spec.name + ".json";
      std::ofstream json_file(json_path);
      json_file << desc.dump(2) << "\n";
      if (!json_file.flush()) throw std::runtime_error("cannot write " + json_path);
      if (!cl.quiet) {
        std::printf("seed-models: %s: %zu triangles (seed %lld) -> %s\n", spec.name, triangles,
                    static_cast<long long>(spec.seed_full_triangles), glb.c_str());
      }
    }
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "slave_sim seed-models: error: %s\n", e.what());
    return 2;
  }
}

int RunInspectCommand(const NodeCommandLine& cl) {
  try {
    const SceneDescription description = LoadSceneInput(cl.inspect_path, cl.inspect_tool);
    const HapticModelCache cache(cl.no_cache ? std::string() : cl.cache_dir);
    const BuiltScene built =
        BuildScene(description, cache, [&](const std::string& node, int index, int count) {
          if (!cl.quiet) {
            std::fprintf(stderr, "[inspect] model %d/%d: node '%s'\n", index, count, node.c_str());
          }
        });
    for (const std::string& w : built.warnings) {
      std::fprintf(stderr, "[inspect] warning: %s\n", w.c_str());
    }
    nlohmann::json out = InspectJson(built);
    struct rusage usage {};
    getrusage(RUSAGE_SELF, &usage);
    out["peak_rss_mb"] = static_cast<double>(usage.ru_maxrss) / 1024.0;  // ru_maxrss is KiB
    out["cache_dir"] = cache.dir();
    std::printf("%s\n", out.dump(2).c_str());
    return 0;
  } catch (const std::exception& e) {
    std::string line = e.what();
    for (char& c : line) {
      if (c == '\n' || c == '\r') c = ' ';
    }
    std::fprintf(stderr, "slave_sim inspect: error: %s\n", line.c_str());
    return 2;
  }
}

}  // namespace ht
