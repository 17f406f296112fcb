// The full remote step (haptic_core/remote_step.h) on the seed's benchmark scenes:
// per scene, the step's p50 time and its split (coarse stages, texture stage, per contact), leaf
// pairs and contacts, over in-contact poses of the scene's scripted motion. A program, not a
// Google Benchmark: each pose is stepped --repeats times and the percentiles are over all steps.
// Speed is reported here, never asserted; accuracy is the speed-vs-error frontier's job
// (slave_sim/frontier.h), and parity of fast paths with the reference is tested
// (tests/texture_stage_parity_test.cc).
//
// --ab OPTION steps a second pipeline, the same but for OPTION turned the other way, on the same
// poses, interleaved step by step (the order A, B or B, A alternating from step to step), and
// prints its row beside: a comparison that one shared machine's noise cannot tilt, since both
// arms see it alike.
//
// Usage: remote_step_benchmark [--scenes fig75,fig76,fig77,hammer_torus] [--poses N]
//                              [--repeats R] [--grid N] [--threads T] [--path fast|reference]
//                              [--no-refine-depth] [--ab OPTION]
//                              [--csv FILE] [--cache-dir D]

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cstdio>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include "haptic_core/height_field_batch.h"
#include "haptic_core/model_build/haptic_model_build.h"
#include "haptic_core/remote_step.h"
#include "haptic_core/statistics.h"
#include "slave_sim/benchmark_scenes.h"

int main(int argc, char** argv) {
  CLI::App app{
      "The full remote step on the seed's benchmark scenes: p50 time, its split, pairs and "
      "contacts"};
  std::vector<std::string> scenes = {"fig75", "fig76", "fig77", "hammer_torus"};
  int poses = 40, repeats = 5, grid = 50, threads = 1;
  std::string csv_path, cache_dir = ht::HapticModelCache::DefaultDir();
  app.add_option("--scenes", scenes, "comma-separated scene names")
      ->delimiter(',')
      ->capture_default_str();
  app.add_option("--poses", poses, "in-contact poses per scene (scripted motion)")
      ->check(CLI::Range(1, 10000))
      ->capture_default_str();
  app.add_option("--repeats", repeats, "steps per pose")
      ->check(CLI::Range(1, 1000))
      ->capture_default_str();
  app.add_option("--grid", grid, "penetration-depth grid N")
      ->check(CLI::Range(2, 1024))
      ->capture_default_str();
  app.add_option("--threads", threads, "threads of the CPU texture stage")
      ->check(CLI::Range(1, 64))
      ->capture_default_str();
  std::string path = "fast";
  app.add_option("--path", path,
                 "texture stage: fast (the product's) or reference (the path it replaced; the\n"
                 "same results within float rounding)")
      ->check(CLI::IsMember({"fast", "reference"}))
      ->capture_default_str();
  int max_contacts = ht::kMaxContacts;
  app.add_option("--max-contacts", max_contacts, "most contacts per step")
      ->check(CLI::Range(1, ht::kMaxContacts))
      ->capture_default_str();
  bool no_refinement = false;
  app.add_flag("--no-refine-depth", no_refinement,
               "stage 5b off: the grid's cell samples alone (by default each contact's depth is "
               "refined to the texture's full resolution)");
  bool parallax = true;
  app.add_flag("--parallax,!--no-parallax", parallax,
               "stage 5b reads heights through the displaced surface (DepthRefinementOptions::"
               "parallax, on by default); --no-parallax: the render's form h*(N.n)");
  std::string ab;
  app.add_option("--ab", ab,
                 "also step a pipeline with this option of the remote step turned the other way, "
                 "interleaved step by step with the first on the same poses, and print its row "
                 "(B) beside: parallax (DepthRefinementOptions::parallax)")
      ->check(CLI::IsMember({"parallax"}));
  bool product_models = false;
  app.add_flag("--product-models", product_models,
               "step the models slave_sim --scene builds (ProductModelSettings: fig77 and the "
               "hammer at twice or four times the seed's coarse count with textures from their "
               "detail) instead of the seed's counts at 1024^2");
  app.add_option("--csv", csv_path, "write one row per scene here");
  app.add_option("--cache-dir", cache_dir, "model cache folder")->capture_default_str();
  CLI11_PARSE(app, argc, argv);

  const ht::HapticModelCache cache(cache_dir);
  std::ofstream csv;
  if (!csv_path.empty()) {
    csv.open(csv_path);
    if (!csv) {
      std::fprintf(stderr, "remote_step_benchmark: cannot write %s\n", csv_path.c_str());
      return 1;
    }
    csv << "scene,arm,poses,steps,step_p50_us,step_p90_us,coarse_p50_us,texture_p50_us,"
           "texture_per_contact_us,leaf_pairs_mean,contacts_mean,contacts_max\n";
  }
  std::printf("%-13s %5s %9s %9s %9s %9s %12s %8s %9s %4s\n", "scene", "poses", "step p50",
              "step p90", "coarse", "texture", "per contact", "pairs", "contacts", "max");
  for (const std::string& name : scenes) {
    ht::BenchmarkScene scene;
    std::vector<ht::RigidTransform> poses_WFt;
    try {
      std::fprintf(stderr, "remote_step_benchmark: %s: building (cache %s)...\n", name.c_str(),
                   cache_dir.c_str());
      scene = ht::MakeBenchmarkScene(
          name, product_models ? ht::ProductModelSettings(name) : ht::BenchmarkModelSettings{},
          cache);
      std::fprintf(stderr, "remote_step_benchmark: %s: finding %d in-contact poses...\n",
                   name.c_str(), poses);
      poses_WFt = ht::ScriptedContactPoses(scene, poses);
    } catch (const std::exception& e) {
      std::fprintf(stderr, "remote_step_benchmark: %s: %s\n", name.c_str(), e.what());
      return 1;
    }
    ht::PipelineOptions options;
    options.grid_resolution = grid;
    options.texture_threads = threads;
    options.max_contacts = max_contacts;
    options.refine_depth = !no_refinement;
    options.depth_refinement.parallax = parallax;
    // Arm A is the options as given; arm B (with --ab) the same with one option flipped.
    ht::PipelineOptions options_b = options;
    std::string label_b;
    // The flag --ab names, in a pipeline's options (null without --ab).
    const auto ab_flag = [&](ht::PipelineOptions& o) -> bool* {
      if (ab == "parallax") return &o.depth_refinement.parallax;
      return nullptr;
    };
    if (bool* flag = ab_flag(options_b)) {
      *flag = !*flag;
      label_b = (*flag ? "" : "no-") + ab;
    }
    struct Arm {
      std::string label;
      std::unique_ptr<ht::HapticTexturePipeline> pipeline;
      std::vector<double> step_us, coarse_us, texture_us, per_contact_us;
      double pairs_sum = 0.0, contacts_sum = 0.0;
      int contacts_max = 0;
      std::uint64_t seq = 1;
    };
    std::vector<Arm> arms;
    for (const ht::PipelineOptions* o : {&options, &options_b}) {
      if (o == &options_b && ab.empty()) break;
      Arm arm;
      arm.label = o == &options ? "A" : "B: " + label_b;
      arm.pipeline = std::make_unique<ht::HapticTexturePipeline>(
          scene.haptic, *o,
          std::make_unique<ht::CpuPenetrationDepthBackend>(
              std::max(128, grid),
              path == "fast" ? ht::TextureStagePath::kFast : ht::TextureStagePath::kReference,
              threads));
      arms.push_back(std::move(arm));
    }
    const ht::RigidTransform X_FtT = scene.X_TFt.Inverse();
    ht::StepTimings timings;
    for (Arm& arm : arms) {
      arm.pipeline->Step(poses_WFt.empty() ? scene.haptic.X_WT_home : poses_WFt[0] * X_FtT, 0,
                         timings);  // warm-up
    }
    const auto step = [&](Arm& arm, const ht::RigidTransform& X_WT, int r) {
      arm.pipeline->Step(X_WT, arm.seq++, timings);
      arm.step_us.push_back(timings.total_us);
      arm.coarse_us.push_back(timings.collision_us);
      arm.texture_us.push_back(timings.texture_us);
      const int queried = static_cast<int>(arm.pipeline->last_contact_queries().size());
      if (queried > 0) arm.per_contact_us.push_back(timings.texture_us / queried);
      if (r == 0) {
        arm.pairs_sum += timings.leaf_pairs;
        arm.contacts_sum += queried;
        arm.contacts_max = std::max(arm.contacts_max, queried);
      }
    };
    for (std::size_t k = 0; k < poses_WFt.size(); ++k) {
      const ht::RigidTransform X_WT = poses_WFt[k] * X_FtT;
      for (int r = 0; r < repeats; ++r) {
        if (arms.size() == 2 && (k + static_cast<std::size_t>(r)) % 2 == 1) {
          step(arms[1], X_WT, r);
          step(arms[0], X_WT, r);
        } else {
          for (Arm& arm : arms) step(arm, X_WT, r);
        }
      }
    }
    const double n = std::max<double>(1.0, static_cast<double>(poses_WFt.size()));
    for (const Arm& arm : arms) {
      const std::string row_name = arms.size() == 1 ? name : name + " " + arm.label;
      std::printf("%-13s %5zu %9.1f %9.1f %9.1f %9.1f %12.1f %8.1f %9.2f %4d\n", row_name.c_str(),
                  poses_WFt.size(), ht::Percentile(arm.step_us, 0.5),
                  ht::Percentile(arm.step_us, 0.9), ht::Percentile(arm.coarse_us, 0.5),
                  ht::Percentile(arm.texture_us, 0.5), ht::Percentile(arm.per_contact_us, 0.5),
                  arm.pairs_sum / n, arm.contacts_sum / n, arm.contacts_max);
      const ht::DepthRefinementCounters& refined = arm.pipeline->depth_refinement_counters();
      if (refined.contacts > 0) {
        std::fprintf(
            stderr,
            "remote_step_benchmark: %s: stage 5b refined %llu contacts, %.1f seeds and "
            "%.0f evaluations of b - a per contact, δ0 raised %.1f µm on average\n",
            row_name.c_str(), static_cast<unsigned long long>(refined.contacts),
            static_cast<double>(refined.seeds) / static_cast<double>(refined.contacts),
            static_cast<double>(refined.evaluations) / static_cast<double>(refined.contacts),
            static_cast<double>(refined.raised_um) / static_cast<double>(refined.contacts));
        std::fprintf(
            stderr,
            "remote_step_benchmark: %s: conservative screen: %.1f squares and %.1f leaves "
            "per contact, deeper than the seeds on %llu contacts (%.1f µm on average), "
            "%llu stopped at the leaf budget\n",
            row_name.c_str(),
            static_cast<double>(refined.screen_squares) / static_cast<double>(refined.contacts),
            static_cast<double>(refined.screen_leaves) / static_cast<double>(refined.contacts),
            static_cast<unsigned long long>(refined.screen_found),
            refined.screen_found > 0 ? static_cast<double>(refined.screen_raised_um) /
                                           static_cast<double>(refined.screen_found)
                                     : 0.0,
            static_cast<unsigned long long>(refined.screen_truncated));
      }
      if (csv) {
        csv << name << ',' << (arms.size() == 1 ? "A" : arm.label) << ',' << poses_WFt.size() << ','
            << arm.step_us.size() << ',' << ht::Percentile(arm.step_us, 0.5) << ','
            << ht::Percentile(arm.step_us, 0.9) << ',' << ht::Percentile(arm.coarse_us, 0.5) << ','
            << ht::Percentile(arm.texture_us, 0.5) << ',' << ht::Percentile(arm.per_contact_us, 0.5)
            << ',' << arm.pairs_sum / n << ',' << arm.contacts_sum / n << ',' << arm.contacts_max
            << '\n';
      }
    }
    std::fflush(stdout);
  }
  std::printf(
      "(times in us; contacts = windows linearized per step; CPU %s path, %d texture "
      "thread(s), texture samples %s)\n",
      path.c_str(), threads, ht::SampleKernelName());
  return 0;
}
