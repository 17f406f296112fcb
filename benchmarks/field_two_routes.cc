// Two routes to the wrench at a displaced pose: the contact model made at q0 with its depth
// fields, evaluated at q0 + Δq as the operator's loop evaluates it, against a fresh remote step
// at q0 + Δq (its own model and fields, evaluated at that pose). On the seed's scenes, at poses
// where the tool rests on the environment (lowered from its home pose, spread over a few
// millimetres), for slides of 0.5, 1.5 and 5 mm, tilts and twists of 1 and 10 mrad. Prints per
// displacement the relative RMS difference of force and torque over the poses (the fresh step's
// wrench the reference), and the largest force difference (N).
//
// Usage: field_two_routes [--scene NAME]... [--starts K] [--margin-mm M] [--subdivision S]

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "haptic_core/demo/demo_scenes.h"
#include "haptic_core/depth_field.h"
#include "haptic_core/penetration_depth_backend.h"
#include "haptic_core/remote_step.h"
#include "slave_sim/benchmark_scenes.h"

namespace {

struct Displacement {
  std::string name;
  ht::Twist dq;  // W: translation (m), rotation vector (rad)
};

/// The model and fields of one step at X_WT, from scratch (the step before forgotten), and the
/// model's wrench at `X_eval` through those fields.
ht::Wrench WrenchThroughFields(ht::HapticTexturePipeline& pipeline, const ht::RigidTransform& X_WT,
                               const ht::RigidTransform& X_eval, ht::DepthFieldCache& cache,
                               int* contacts = nullptr) {
  pipeline.ForgetLastStep();
  ht::StepTimings timings;
  const ht::ContactModel model = pipeline.Step(X_WT, 0, timings);
  cache.Clear();
  for (const ht::DepthField* f : pipeline.last_depth_fields()) {
    ht::DepthField copy = *f;
    cache.Take(copy, {});
  }
  if (contacts != nullptr) *contacts = model.num_contacts;
  return ht::EvaluateContactModel(model, X_eval, 1.0, std::numeric_limits<double>::infinity(),
                                  &cache)
      .F_T_W;
}

double Norm2(const glm::dvec3& v) { return glm::dot(v, v); }

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "Two routes to the wrench at a displaced pose: the model made at q0 with its depth fields,\n"
      "evaluated at q0 + dq, against a fresh remote step at q0 + dq. CPU penetration depth."};
  std::vector<std::string> scenes{"block-on-gear", "striped-blocks", "file-on-cad-part",
                                  "hammer-on-torus"};
  int starts = 9, subdivision = 2;
  double margin_mm = 7.5, spread_mm = 4.0, force_n = 1.0;
  std::string cache_dir = ht::HapticModelCache::DefaultDir();
  app.add_option("--scene", scenes,
                 "scenes (as slave_sim --scene): block-on-gear, striped-blocks, file-on-cad-part, "
                 "hammer-on-torus")
      ->capture_default_str();
  app.add_option("--starts", starts, "resting poses per scene (a square grid of lateral starts)")
      ->check(CLI::Range(1, 100))
      ->capture_default_str();
  app.add_option("--spread-mm", spread_mm, "the starts' grid side (mm)")->capture_default_str();
  app.add_option("--force-n", force_n,
                 "how hard the tool rests: lowered until its contact force through the depth "
                 "fields reaches this (N)")
      ->capture_default_str();
  app.add_option("--margin-mm", margin_mm,
                 "the fields' travel margin (mm; 7.5 = 50 mm/s over a 150 ms round trip)")
      ->capture_default_str();
  app.add_option("--subdivision", subdivision, "depth-field nodes per window cell (1..4)")
      ->check(CLI::Range(1, 4))
      ->capture_default_str();
  app.add_option("--cache-dir", cache_dir, "model cache folder (the benchmark scenes)")
      ->capture_default_str();
  CLI11_PARSE(app, argc, argv);
  using namespace ht;
  const std::vector<Displacement> displacements = {{"slide 0.5 mm x", {{0.5e-3, 0, 0}, {0, 0, 0}}},
                                                   {"slide 1.5 mm y", {{0, 1.5e-3, 0}, {}}},
                                                   {"slide 5 mm x", {{5e-3, 0, 0}, {}}},
                                                   {"slide 5 mm y", {{0, 5e-3, 0}, {}}},
                                                   {"tilt 1 mrad x", {{}, {1e-3, 0, 0}}},
                                                   {"tilt 10 mrad y", {{}, {0, 10e-3, 0}}},
                                                   {"twist 1 mrad z", {{}, {0, 0, 1e-3}}},
                                                   {"twist 10 mrad z", {{}, {0, 0, 10e-3}}}};
  for (const std::string& scene_name : scenes) {
    HapticScene scene;
    try {
      if (scene_name == "block-on-gear") {
        scene = MakeBlockOnGearScene();
      } else {
        const std::string name = BenchmarkSceneOfBuiltin(scene_name);
        scene = MakeBenchmarkScene(name, ProductModelSettings(name), HapticModelCache(cache_dir))
                    .haptic;
      }
    } catch (const std::exception& e) {
      std::fprintf(stderr, "field_two_routes: scene %s: %s\n", scene_name.c_str(), e.what());
      return 2;
    }
    PipelineOptions options;
    options.texture_threads = 1;
    options.depth_fields = true;
    options.depth_field_margin_m = margin_mm * 1e-3;
    options.depth_field_subdivision = subdivision;
    options.Validate();
    HapticTexturePipeline pipeline(
        scene, options,
        std::make_unique<CpuPenetrationDepthBackend>(options.max_window_resolution(),
                                                     TextureStagePath::kFast, 1));
    DepthFieldCache at_q0(kMaxContacts), fresh(kMaxContacts);
    // Resting poses: from a grid of lateral starts, lowered until the contact force through the
    // depth fields reaches force_n (0.1 mm steps to the first contact, then 1 µm).
    std::vector<RigidTransform> poses;
    const int side = std::max(1, static_cast<int>(std::lround(std::sqrt(starts))));
    for (int a = 0; a < side; ++a) {
      for (int b = 0; b < side; ++b) {
        RigidTransform X = scene.X_WT_home;
        if (side > 1) {
          X.translation.x += spread_mm * 1e-3 * (a / (side - 1.0) - 0.5);
          X.translation.y += spread_mm * 1e-3 * (b / (side - 1.0) - 0.5);
        }
        const auto force = [&](const RigidTransform& T) {
          return glm::length(WrenchThroughFields(pipeline, T, T, at_q0).force);
        };
        int k = 0;
        for (; k < 2000 && !(force(X) > 0.0); ++k) X.translation.z -= 0.1e-3;
        if (k == 2000) continue;
        X.translation.z += 0.1e-3;
        for (k = 0; k < 400 && force(X) < force_n; ++k) X.translation.z -= 1e-6;
        if (k < 400) poses.push_back(X);
      }
    }
    std::printf("%s: %zu resting poses, fields' margin %.1f mm, %d nodes a window cell\n",
                scene_name.c_str(), poses.size(), margin_mm, subdivision);
    std::printf("  %-16s %10s %10s %12s %10s %9s\n", "displacement", "force rms", "torque rms",
                "largest dF N", "|F| rms N", "contacts");
    for (const Displacement& d : displacements) {
      double fe = 0, fr = 0, te = 0, tr = 0, largest = 0;
      int contacts_q0 = 0, contacts_fresh = 0;
      for (const RigidTransform& X_WT0 : poses) {
        const RigidTransform X = Displace(X_WT0, d.dq);
        int c0 = 0, c1 = 0;
        const Wrench a = WrenchThroughFields(pipeline, X_WT0, X, at_q0, &c0);
        const Wrench b = WrenchThroughFields(pipeline, X, X, fresh, &c1);
        contacts_q0 += c0;
        contacts_fresh += c1;
        fe += Norm2(a.force - b.force);
        fr += Norm2(b.force);
        te += Norm2(a.torque - b.torque);
        tr += Norm2(b.torque);
        largest = std::max(largest, glm::length(a.force - b.force));
      }
      std::printf("  %-16s %9.2f%% %9.2f%% %12.3f %10.3f %4d/%-4d\n", d.name.c_str(),
                  fr > 0 ? 100 * std::sqrt(fe / fr) : 0.0, tr > 0 ? 100 * std::sqrt(te / tr) : 0.0,
                  largest,
                  std::sqrt(fr / static_cast<double>(std::max<std::size_t>(1, poses.size()))),
                  contacts_q0, contacts_fresh);
    }
  }
  return 0;
}
