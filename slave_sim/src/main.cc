// slave_sim: the remote simulation node. Listens for tool states over UDP and streams contact
// models computed with 6-DoF haptic texture rendering on the scene. The command line's options
// and subcommands are in node_command_line.{h,cc} and node_subcommands.cc.

#include <CLI/CLI.hpp>
#include <csignal>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <fstream>
#include <memory>
#include <nlohmann/json.hpp>

#include "haptic_core/demo/demo_scenes.h"
#include "haptic_core/haptic_scene.h"
#include "node_command_line.h"
#include "slave_sim/benchmark_scenes.h"
#include "slave_sim/remote_node.h"
#include "slave_sim/scene_build.h"
#include "slave_sim/watched_scene.h"
#include "transport/command_line.h"

namespace {
std::atomic<bool> g_stop{false};
extern "C" void OnSignal(int) { g_stop.store(true); }

/// The node's scene: a built-in one, or a scene file (watched unless --no-watch).
struct NodeScene {
  ht::HapticScene builtin;
  std::unique_ptr<ht::WatchedScene> file;
  const ht::HapticScene& haptic() const { return file ? file->haptic() : builtin; }
};

/// Builds the scene --scene names and sets the display stream (and, for a scene file, its poses,
/// animation and reload hooks) in cl.config. Throws std::invalid_argument for a name that is
/// neither a built-in scene nor a file, and what the scene build throws.
NodeScene LoadNodeScene(ht::NodeCommandLine& cl) {
  NodeScene out;
  ht::RemoteNodeConfig& config = cl.config;
  const std::string& scene = cl.scene;
  const bool quiet = cl.quiet;
  const std::string benchmark_name = ht::BenchmarkSceneOfBuiltin(scene);
  if (scene == "block-on-gear" || scene == "stiff-wall") {
    out.builtin = scene == "stiff-wall" ? ht::MakeStiffWallScene() : ht::MakeBlockOnGearScene();
    config.scene_objects = ht::BlockOnGearDisplayStream(out.builtin).objects;
    return out;
  }
  if (!benchmark_name.empty()) {
    if (!quiet)
      std::printf("[slave] building scene %s (model cache: %s)\n", scene.c_str(),
                  cl.scene_cache_dir.empty() ? "none" : cl.scene_cache_dir.c_str());
    const ht::BenchmarkScene bench =
        ht::MakeBenchmarkScene(benchmark_name, ht::ProductModelSettings(benchmark_name),
                               ht::HapticModelCache(cl.scene_cache_dir));
    out.builtin = bench.haptic;
    out.builtin.name = scene;
    // The full-resolution meshes in their own frames, with the scene graph, for display.
    config.scene_objects = ht::MakeDisplayStream(out.builtin, *bench.tool_mesh_Ft, bench.X_TFt,
                                                 {bench.object_mesh_Fe.get()})
                               .objects;
    const ht::RigidTransform& home = bench.haptic.X_WT_home;
    if (!quiet) {
      std::printf("[slave] scene %s: tool %s on %s; tool home position in W %.4f,%.4f,%.4f\n",
                  scene.c_str(), bench.tool_name.c_str(), bench.object_name.c_str(),
                  home.translation.x, home.translation.y, home.translation.z);
    }
    return out;
  }
  if (!std::filesystem::exists(scene)) {
    throw std::invalid_argument("--scene " + scene +
                                ": neither a built-in scene (block-on-gear, stiff-wall, "
                                "striped-blocks, file-on-cad-part, hammer-on-torus) nor an "
                                "existing file");
  }
  out.file = std::make_unique<ht::WatchedScene>(
      scene, cl.scene_tool, ht::HapticModelCache(cl.scene_cache_dir),
      [quiet](const std::string& node, int index, int count) {
        if (!quiet) std::printf("[slave] model %d/%d: node '%s'\n", index, count, node.c_str());
      });
  ht::WatchedScene* file_scene = out.file.get();
  // The scene as a scene for display: its graph, each mesh once in its own frame, the
  // base-colour images; the moving nodes' poses follow at the display rate.
  config.scene_objects = file_scene->stream().objects;
  if (config.scene_objects.size() > 65535) {
    throw std::invalid_argument("--scene " + scene + ": " +
                                std::to_string(config.scene_objects.size()) +
                                " display objects (meshes and images); at most 65535 stream");
  }
  config.display_poses = [file_scene](double t_s, std::vector<ht::wire::NodePose>* poses) {
    file_scene->DisplayPoses(t_s, poses);
  };
  config.animate = [file_scene](double t_s) { file_scene->Animate(t_s); };
  const bool watch = !cl.no_watch;
  if (watch) {
    // A change of the file on disk rebuilds the scene (through the cache) and switches to it.
    file_scene->StartWatching(0.5);
    config.take_reload =
        [file_scene](std::vector<ht::StreamObject>* objects) -> const ht::HapticScene* {
      if (!file_scene->TakeReload()) return nullptr;
      *objects = file_scene->stream().objects;
      return &file_scene->haptic();
    };
  }
  const ht::BuiltScene& built = file_scene->built();
  for (const std::string& w : built.warnings) {
    std::fprintf(stderr, "[slave] warning: %s\n", w.c_str());
  }
  const ht::RigidTransform& home = built.haptic.X_WT_home;
  if (!quiet) {
    std::printf(
        "[slave] scene file %s: %zu touchable(s), tool %s; tool home position in W %.4f,%.4f,"
        "%.4f (the operator's workspace centre: sent in the Welcome)%s\n",
        scene.c_str(), built.haptic.touchables.size(),
        built.builtin_probe ? "built-in probe" : cl.scene_tool.c_str(), home.translation.x,
        home.translation.y, home.translation.z, watch ? "; watching the file for changes" : "");
  }
  return out;
}

/// Runs the node on `scene` until a signal or the operator's goodbye; prints the last line and
/// writes remote_summary.json to --out. Throws what RunRemoteNode throws, and std::runtime_error
/// when the summary cannot be written.
void RunNode(const ht::NodeCommandLine& cl, const NodeScene& scene) {
  nlohmann::json summary = ht::RunRemoteNode(cl.config, scene.haptic(), g_stop);
  if (scene.file) summary["scene_file"] = scene.file->StatsJson();
  std::printf(
      "[slave] done: %llu steps, %.1f steps/s, step compute p50 %.0f us over all steps, %.0f us "
      "in contact\n",
      static_cast<unsigned long long>(summary["steps"].get<std::uint64_t>()),
      summary["rate_hz"].get<double>(), summary["step_p50_us"].get<double>(),
      summary["step_in_contact_p50_us"].get<double>());
  if (!cl.out_dir.empty()) {
    std::filesystem::create_directories(cl.out_dir);
    std::ofstream f(cl.out_dir + "/remote_summary.json");
    f << summary.dump(2) << "\n";
    if (!f) throw std::runtime_error("cannot write " + cl.out_dir + "/remote_summary.json");
  }
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "slave_sim: remote simulation node of the networked 6-DoF haptic texture rendering system.\n"
      "Per step it takes the latest tool pose received, runs the coarse contact query and the\n"
      "texture penetration depth with its gradient, and sends the linearized contact model back.\n"
      "Every datagram is authenticated with a pre-shared key (--key; make one with 'slave_sim\n"
      "keygen FILE' and copy it to the operator machine). Stops on SIGINT/SIGTERM or when the\n"
      "operator side says goodbye (unless --stay)."};
  ht::NodeCommandLine cl;
  ht::AddNodeOptions(app, cl);
  if (const auto rc = ht::ParseCommandLine(app, argc, argv, "slave_sim")) return *rc;
  if (*cl.seed_models) return ht::RunSeedModelsCommand(cl);
  if (*cl.inspect) return ht::RunInspectCommand(cl);

  std::signal(SIGINT, OnSignal);
  std::signal(SIGTERM, OnSignal);
  try {
    if (ht::RunKeygenIfAsked(cl.key, "slave_sim")) return 0;
    ht::FinishNodeConfig(app, cl);
    if (!cl.out_dir.empty()) std::filesystem::create_directories(cl.out_dir);
    const NodeScene scene = LoadNodeScene(cl);
    RunNode(cl, scene);
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "slave_sim: error: %s\n", e.what());
    return 2;
  }
}
