// speed_error_frontier: the remote step's speed against its error, measured against the
// full-resolution ground truth on the seed's benchmark scenes. See --help and the
// README section "Speed against error".

#include <CLI/CLI.hpp>
#include <cstdio>
#include <filesystem>
#include <string>

#include "haptic_core/model_build/haptic_model_build.h"
#include "slave_sim/benchmark_scenes.h"
#include "slave_sim/frontier.h"
#include "transport/command_line.h"

#ifndef HT_PLOT_FRONTIER_SCRIPT
#define HT_PLOT_FRONTIER_SCRIPT ""
#endif

int main(int argc, char** argv) {
  CLI::App app{
      "Speed against error of the remote step: each named setting (grid N, texture size, coarse\n"
      "triangle count, threads, depth fields, CPU or GPU) and two baselines (coarse meshes\n"
      "without textures; full-resolution meshes through FCL) on in-contact poses of the seed's\n"
      "scenes, timed, and compared with the ground truth computed on the full-resolution meshes.\n"
      "Errors against two truths: the pipeline truth (the full-resolution meshes' own contact\n"
      "patches; OUT/patches.csv) and the texture stage's (the truth on each setting's windows).\n"
      "Writes OUT/frontier.csv, OUT/contacts.csv, OUT/patches.csv, OUT/meshes/*.glb,\n"
      "OUT/frontier.png and OUT/summary.md (last)."};
  ht::FrontierOptions options;
  std::vector<std::string> traces;
  options.cache_dir = ht::HapticModelCache::DefaultDir();
  bool no_gpu = false, quiet = false;
  app.add_option("--out", options.out_dir,
                 "output folder (created; required unless --list-settings)");
  bool list_settings = false;
  app.add_flag("--list-settings", list_settings,
               "print every setting's name (what --setting and deadband_lockstep's setting= take)\n"
               "and exit");
  app.add_flag("--quick", options.quick,
               "fig75 and fig76 only, 12 poses, 10 settings: a few minutes (what ctest runs)");
  std::string scene_list;
  for (const std::string& n : ht::BenchmarkSceneNames()) scene_list += " " + n;
  app.add_option("--scene", options.scenes, "scenes to run (repeatable):" + scene_list);
  app.add_option("--setting", options.settings,
                 "settings to run, by name (repeatable; default all), e.g. --setting default\n"
                 "--setting grid100");
  app.add_option("--poses", options.poses,
                 "in-contact poses per scene (default 200; 12 with --quick)")
      ->check(CLI::Range(1, 100000));
  app.add_option("--trace", traces,
                 "SCENE=FILE: take that scene's poses from a run's trace.csv (rows in contact),\n"
                 "e.g. fig75=out/fig75/trace.csv from deploy/run-loopback (repeatable)");
  app.add_option("--trace-from", options.trace_from_s,
                 "with --trace: the --poses consecutive rows in contact from this time (s) on\n"
                 "instead of rows spread over the run, and the model-switch measure along them\n"
                 "(frontier.csv switch_jump_*: the held model at each row's pose against that\n"
                 "row's own)")
      ->check(CLI::Range(0.0, 1e6));
  app.add_option("--switch-lag-rows", options.switch_lag_rows,
                 "with --trace-from: rows between the held model and the next (the model's age)")
      ->check(CLI::Range(1, 1000))
      ->capture_default_str();
  app.add_option("--cache-dir", options.cache_dir, "model cache folder")->capture_default_str();
  app.add_flag("--no-gpu", no_gpu, "leave out the GPU settings");
  app.add_flag("--on-product-models", options.on_product_models,
               "run every setting on the models slave_sim --scene builds (fig77: coarse x2,\n"
               "2048 texture) instead of the texture size and coarse scale it names");
  app.add_option("--threads", options.threads, "threads for the ground truth")
      ->check(CLI::Range(1, 256))
      ->capture_default_str();
  app.add_option("--gt-initial-samples", options.ground_truth.initial_samples,
                 "ground truth: M of the first grid")
      ->capture_default_str();
  app.add_option("--gt-max-samples", options.ground_truth.max_samples,
                 "ground truth: largest M tried")
      ->capture_default_str();
  app.add_option("--gt-tolerance-um", options.ground_truth.tolerance_m,
                 "ground truth: converged when doubling M changes delta by less than this (µm)")
      ->transform([](std::string v) { return std::to_string(std::stod(v) * 1e-6); });
  bool truth_no_merge = false;
  app.add_flag("--truth-no-merge", truth_no_merge,
               "pipeline truth without its merges: the single-linkage patches as they "
               "are (no merges of patches that measure one interpenetration twice) and each "
               "patch's depth along -grad V rather than the surface's 5 mm normal");
  double truth_share_fade_mm = ht::ContactPatchTruthOptions{}.share_fade_m * 1e3;
  app.add_option("--truth-share-fade-mm", truth_share_fade_mm,
                 "pipeline truth: neighbouring patches share one penalty, fading out over this "
                 "distance (mm) past the clustering distance (contact_patch_truth.h, step 4a); "
                 "0: separate patches always sum")
      ->check(CLI::Range(0.0, 1000.0))
      ->capture_default_str();
  double truth_tilt_lift_um = ht::ContactPatchTruthOptions{}.tilt_lift_m * 1e6;
  app.add_option("--truth-tilt-lift-um", truth_tilt_lift_um,
                 "pipeline truth: the tilt step of its rotation gradient as the lift (um) it "
                 "gives a point half the window from the centre (contact_patch_truth.h); 0: a "
                 "texel step's lift (0.1 mm, about 5 mrad), which rounds a resting face's torque "
                 "over +-5 mrad; 1: reads a resting face's arms, and one crest's lever where an "
                 "edge lies across many")
      ->check(CLI::Range(0.0, 1000.0))
      ->capture_default_str();
  bool no_model_prediction = false;
  app.add_flag("--no-model-prediction", no_model_prediction,
               "skip the model-prediction measure (a second pipeline truth at displaced, deeper "
               "poses, which takes about as long as the first); its columns are left empty");
  double prediction_mm = options.prediction_translation_m * 1e3;
  app.add_option("--prediction-translation-mm", prediction_mm,
                 "model-prediction measure: displace the tool by ± this along W's x and y (mm); "
                 "a round trip's travel (0.5–1 mm at 10–20 mm/s and 50 ms) asks more of a model "
                 "than the default")
      ->check(CLI::Range(1e-4, 10.0))
      ->capture_default_str();
  double prediction_mrad = options.prediction_rotation_rad * 1e3;
  app.add_option("--prediction-rotation-mrad", prediction_mrad,
                 "model-prediction measure: tilt the tool by ± this about W's x and y (mrad)")
      ->check(CLI::Range(1e-3, 100.0))
      ->capture_default_str();
  double prediction_yaw_mrad = 0.0;
  app.add_option("--prediction-yaw-mrad", prediction_yaw_mrad,
                 "model-prediction measure: also turn the tool by ± this about W's z (mrad; 0: "
                 "no turn)")
      ->check(CLI::Range(0.0, 1000.0))
      ->capture_default_str();
  app.add_flag("--quiet", quiet, "no progress lines");
  if (const auto rc = ht::ParseCommandLine(app, argc, argv, "speed_error_frontier")) return *rc;
  if (list_settings) {
    for (const ht::FrontierSetting& st : ht::FrontierSettings(false, !no_gpu)) {
      std::printf("%s\n", st.name.c_str());
    }
    return 0;
  }
  if (options.out_dir.empty()) {
    std::fprintf(stderr, "speed_error_frontier: --out is required (the folder for the results)\n");
    return 2;
  }
  std::string command = "speed_error_frontier";
  for (int i = 1; i < argc; ++i) command += std::string(" ") + argv[i];
  try {
    for (const std::string& t : traces) {
      const auto eq = t.find('=');
      if (eq == std::string::npos || eq == 0 || eq + 1 == t.size()) {
        throw std::invalid_argument("--trace " + t + ": expected SCENE=FILE");
      }
      options.traces[t.substr(0, eq)] = t.substr(eq + 1);
    }
    options.gpu = !no_gpu;
    options.truth_merge_patches = !truth_no_merge;
    options.truth_share_fade_m = truth_share_fade_mm * 1e-3;
    options.truth_tilt_lift_m = truth_tilt_lift_um * 1e-6;
    options.model_prediction = !no_model_prediction;
    options.prediction_translation_m = prediction_mm * 1e-3;
    options.prediction_rotation_rad = prediction_mrad * 1e-3;
    options.prediction_yaw_rad = prediction_yaw_mrad * 1e-3;
    options.progress = !quiet;
    options.command_line = command;
    // The plot script: in the source tree (a build), else beside an installed binary.
    options.plot_script = HT_PLOT_FRONTIER_SCRIPT;
    if (options.plot_script.empty() || !std::filesystem::exists(options.plot_script)) {
      std::error_code ec;
      const auto exe = std::filesystem::read_symlink("/proc/self/exe", ec);
      const auto installed = exe.parent_path() / "../share/haptic_teleop/plot-frontier";
      options.plot_script =
          !ec && std::filesystem::exists(installed) ? installed.lexically_normal().string() : "";
    }
    ht::RunSpeedErrorFrontier(options);
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "speed_error_frontier: error: %s\n", e.what());
    return 2;
  }
}
