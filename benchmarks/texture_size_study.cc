// The texture size against the surface error it leaves (issue 32, "model only what a scene
// needs"): each seed model at the seed's coarse count and at twice it, baked at every size from
// 256² to 4096², and MeasureSurfaceError's percentiles of the full-resolution surface's distance
// to the textured coarse model (whole surface, 4096 samples), beside what
// TextureSizingParams' rule chooses. The ridged block and gear are procedural (not baked): their
// texture is sampled at each size. A program, not a benchmark: CSV on stdout.
//
// Usage: texture_size_study [--models file,cad_part,...] [--coarse-scales 1,2] [--max-size N]

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <functional>
#include <string>
#include <vector>

#include "haptic_core/demo/procedural_models.h"
#include "haptic_core/demo/seed_models.h"
#include "haptic_core/model_build/haptic_model_build.h"
#include "haptic_core/model_build/mesh_decimation.h"
#include "haptic_core/model_build/surface_error.h"
#include "haptic_core/model_build/texture_bake.h"

int main(int argc, char** argv) {
  CLI::App app{
      "Surface error of each seed model's textured coarse model at texture sizes 256..4096 "
      "(CSV on stdout), and the size TextureSizingParams' rule chooses"};
  std::vector<std::string> models = {"block", "gear", "file", "cad_part", "hammer", "torus"};
  std::vector<double> scales = {1.0, 2.0};
  int max_size = 4096;
  app.add_option("--models", models, "models (block gear file cad_part hammer torus)")
      ->delimiter(',');
  app.add_option("--coarse-scales", scales, "coarse counts as multiples of the seed's")
      ->delimiter(',');
  app.add_option("--max-size", max_size, "largest size baked (a power of two)")
      ->check(CLI::IsMember({256, 512, 1024, 2048, 4096, 8192}));
  CLI11_PARSE(app, argc, argv);

  std::printf(
      "model,coarse_scale,coarse_triangles,size,p50_um,p95_um,p99_um,outside_p99_um,"
      "share_outside_25um,seconds\n");
  for (const std::string& name : models) {
    for (const double scale : scales) {
      const bool procedural = name == "block" || name == "gear";
      if (procedural && name == "block" && scale != 1.0) continue;  // a box at every scale
      ht::TriangleMesh full;
      std::function<ht::HapticModel(int)> make;
      ht::DecimationResult coarse;
      if (name == "block") {
        full = ht::MakeRidgedBlockFullResolution();
        make = [](int size) {
          ht::RidgedBlockParams p;
          p.texture_size = size;
          return ht::MakeRidgedBlock(p);
        };
      } else if (name == "gear") {
        full = ht::MakeRidgedGearFullResolution();
        make = [scale](int size) {
          ht::RidgedGearParams p;
          p.texture_size = size;
          p.coarse_segments = static_cast<int>(std::lround(400 * scale));
          return ht::MakeRidgedGear(p);
        };
      } else {
        const ht::SeedModel seed = ht::ParseSeedModelName(name);
        full = ht::MakeSeedModelFullResolution(seed);
        coarse = ht::DecimateQuadric(
            full,
            static_cast<int>(std::lround(
                scale * static_cast<double>(ht::SeedModelSpecOf(seed).seed_coarse_triangles))));
        make = [&](int size) {
          ht::HapticModel m;
          m.vertices_O = coarse.mesh.vertices;
          m.triangles = coarse.mesh.triangles;
          ht::TextureBakeParams p;
          p.texture_size = size;
          ht::ApplyBakedTexture(ht::BakeHapticTexture(coarse.mesh, full, p), m);
          return m;
        };
      }
      std::vector<ht::TextureSizeTrial> all;
      const std::size_t triangles =
          procedural ? make(256).triangles.size() : coarse.mesh.triangles.size();
      const int first = std::max(256, ht::SmallestAtlasSize(static_cast<int>(triangles), 2));
      for (int size = first; size <= max_size; size *= 2) {
        const auto t0 = std::chrono::steady_clock::now();
        const ht::HapticModel m = make(size);
        const ht::SurfaceErrorReport e = ht::MeasureSurfaceError(m, full);
        const double s =
            std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        std::printf("%s,%g,%zu,%d,%.3f,%.3f,%.3f,%.3f,%.4f,%.2f\n", name.c_str(), scale,
                    m.triangles.size(), size, e.p50_m * 1e6, e.p95_m * 1e6, e.p99_m * 1e6,
                    e.outside_p99_m * 1e6, e.share_outside, s);
        std::fflush(stdout);
        all.push_back({size, e.p99_m, e.outside_p99_m, s});
      }
      if (all.empty()) {
        std::fprintf(stderr, "%s x%g: no size up to %d fits its coarse triangles\n", name.c_str(),
                     scale, max_size);
        continue;
      }
      // The rule on the measured sizes (no second bake).
      ht::TextureSizingParams rule;
      rule.min_size = first;
      rule.max_size = max_size;
      const ht::TextureSizeChoice c = ht::ChooseTextureSize(rule, [&](int size) {
        ht::SurfaceErrorReport r;
        for (const auto& t : all) {
          if (t.size == size) {
            r.samples = 4096;
            r.p99_m = t.surface_p99_m;
            r.outside_p99_m = t.surface_outside_p99_m;
          }
        }
        return r;
      });
      std::fprintf(stderr, "%s x%g: rule chooses %s\n", name.c_str(), scale, c.reason.c_str());
    }
  }
  return 0;
}
