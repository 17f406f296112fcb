// Seed Fig. 77 scenario (DESIGN.md §7): the file scraping the CAD part for 500 frames of a
// scripted motion. Per frame: the coarse query's leaf pairs, the contacts after clustering, and
// the time of each stage, written as CSV; a summary goes to stdout (seed: ~104 pairs clustered
// into up to 7 contacts, collision detection ~2 ms).
//
// Motion: the file lies flat (teeth down) above the part and slides 60 mm along x while it
// sways ±10 mm in y and yaws ±5°; at each frame its height is found by bisection so that its
// deepest coarse pair penetrates 0.3 mm (resting on the highest features). Models: the seed
// models at the seed's coarse counts with 1024² textures, through the on-disk cache.
//
// Usage: fig77_scrape [--frames N] [--csv FILE] [--cache-dir DIR] [--tolerance-mm E]

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <glm/gtc/quaternion.hpp>
#include <numbers>
#include <vector>

#include "haptic_core/contact_clustering.h"
#include "haptic_core/demo/seed_models.h"
#include "haptic_core/hull_proximity.h"
#include "haptic_core/model_build/haptic_model_build.h"

namespace {

std::shared_ptr<const ht::HapticModel> Build(ht::SeedModel model, const std::string& cache_dir) {
  ht::HapticModelBuildParams params;
  params.coarse_triangles = static_cast<int>(ht::SeedModelSpecOf(model).seed_coarse_triangles);
  params.texture.texture_size = 1024;
  std::fprintf(stderr, "fig77: building %s (cached in %s)...\n", ht::SeedModelName(model),
               cache_dir.c_str());
  const auto b =
      ht::BuildHapticModelCached(ht::SeedModelName(model), ht::MakeSeedModelFullResolution(model),
                                 params, ht::HapticModelCache(cache_dir));
  std::fprintf(stderr, "fig77: %s: %lld coarse triangles, %d hull nodes, %s\n",
               ht::SeedModelName(model), static_cast<long long>(b.report.coarse_triangles),
               b.report.hull_nodes, b.report.from_cache ? "from cache" : "built");
  return b.model;
}

double Percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[static_cast<std::size_t>(q * static_cast<double>(v.size() - 1))];
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "Seed Fig. 77: the file scraping the CAD part; per-frame coarse pairs, contacts "
      "after clustering and query time"};
  int frames = 500;
  std::string csv_path = "fig77_scrape.csv";
  std::string cache_dir = ht::HapticModelCache::DefaultDir();
  app.add_option("--frames", frames, "frames of the scripted motion")
      ->check(CLI::Range(1, 100000))
      ->capture_default_str();
  app.add_option("--csv", csv_path, "per-frame output")->capture_default_str();
  app.add_option("--cache-dir", cache_dir, "model cache folder")->capture_default_str();
  double tolerance_mm = 0.0;
  app.add_option("--tolerance-mm", tolerance_mm,
                 "coarse query tolerance in mm (default 0: the remote step's, both models'\n"
                 "outward reaches + 0.5 mm)")
      ->check(CLI::NonNegativeNumber);
  CLI11_PARSE(app, argc, argv);

  const auto file = Build(ht::SeedModel::kFile, cache_dir);
  const auto part = Build(ht::SeedModel::kCadPart, cache_dir);
  const ht::RigidTransform X_WB;  // the part at the origin
  const double reach = file->OutwardReach() + part->OutwardReach();
  ht::ProximityQueryOptions options;
  options.tolerance_m = reach + 0.5e-3;  // as the remote step: outward reaches + margin
  if (tolerance_mm > 0.0) options.tolerance_m = tolerance_mm * 1e-3;
  ht::ClusteringOptions clustering;
  clustering.texture_margin_m = reach;
  clustering.min_extent_m = clustering.max_extent_m = 0.02;  // the pipeline's window W
  std::printf("fig77: tolerance %.3f mm (outward reaches %.3f + %.3f mm + 0.5 mm margin)\n",
              options.tolerance_m * 1e3, file->OutwardReach() * 1e3, part->OutwardReach() * 1e3);

  ht::HullProximityQuery timed_query, probe_query;
  const ht::HullBounds file_bounds = ht::HullBounds::Of(*file);
  const ht::HullBounds part_bounds = ht::HullBounds::Of(*part);
  ht::ContactClusterer clusterer;
  std::ofstream csv(csv_path);
  csv << "frame,x_m,y_m,yaw_rad,z_m,pairs,contacts,min_signed_distance_m,query_us,"
         "clustering_us,node_pairs_tested,front_pairs\n";
  std::vector<double> query_us, cluster_us, pairs_v, contacts_v;
  for (int k = 0; k < frames; ++k) {
    const double s = frames > 1 ? static_cast<double>(k) / (frames - 1) : 0.0;
    const double x = -0.03 + 0.06 * s;
    const double y = 0.01 * std::sin(2 * std::numbers::pi * 2 * s);
    const double yaw = 5.0 * std::numbers::pi / 180.0 * std::sin(2 * std::numbers::pi * 3 * s);
    ht::RigidTransform X_WA;
    X_WA.rotation = glm::angleAxis(yaw, glm::dvec3(0, 0, 1));
    // Bisection on height: the deepest pair at −0.3 mm (not timed).
    double lo = -0.006, hi = 0.08;  // lo: the blade deep in the plate; hi: clear above
    ht::ProximityQueryOptions probe = options;
    probe.tolerance_m = 0.0;
    for (int it = 0; it < 40; ++it) {
      const double mid = 0.5 * (lo + hi);
      X_WA.translation = glm::dvec3(x, y, mid);
      const auto p = probe_query.Query(*file, file_bounds, X_WA, *part, part_bounds, X_WB, probe);
      const double deepest = p.empty() ? 1.0 : p.front().signed_distance_m;
      (deepest < -0.3e-3 ? lo : hi) = mid;
    }
    X_WA.translation = glm::dvec3(x, y, hi);
    ht::ProximityQueryStats stats;
    const auto t0 = std::chrono::steady_clock::now();
    const auto pairs =
        timed_query.Query(*file, file_bounds, X_WA, *part, part_bounds, X_WB, options, &stats);
    const auto t1 = std::chrono::steady_clock::now();
    const auto clusters =
        clusterer.Cluster(pairs, file->hull_hierarchy, part->hull_hierarchy, clustering);
    const auto t2 = std::chrono::steady_clock::now();
    const double q_us = std::chrono::duration<double, std::micro>(t1 - t0).count();
    const double c_us = std::chrono::duration<double, std::micro>(t2 - t1).count();
    const double min_sd = pairs.empty() ? 0.0 : pairs.front().signed_distance_m;
    csv << k << ',' << x << ',' << y << ',' << yaw << ',' << hi << ',' << pairs.size() << ','
        << clusters.size() << ',' << min_sd << ',' << q_us << ',' << c_us << ','
        << stats.node_pairs_tested << ',' << stats.front_pairs << '\n';
    query_us.push_back(q_us);
    cluster_us.push_back(c_us);
    pairs_v.push_back(static_cast<double>(pairs.size()));
    contacts_v.push_back(static_cast<double>(clusters.size()));
  }
  double mean_pairs = 0, mean_contacts = 0;
  for (std::size_t i = 0; i < pairs_v.size(); ++i) {
    mean_pairs += pairs_v[i] / pairs_v.size();
    mean_contacts += contacts_v[i] / contacts_v.size();
  }
  std::printf(
      "fig77: %d frames: pairs mean %.1f (max %.0f), contacts mean %.2f (max %.0f); query us p50 "
      "%.0f p95 %.0f max %.0f; clustering us p50 %.1f p95 %.1f; per-frame CSV in %s\n",
      frames, mean_pairs, *std::max_element(pairs_v.begin(), pairs_v.end()), mean_contacts,
      *std::max_element(contacts_v.begin(), contacts_v.end()), Percentile(query_us, 0.5),
      Percentile(query_us, 0.95), Percentile(query_us, 1.0), Percentile(cluster_us, 0.5),
      Percentile(cluster_us, 0.95), csv_path.c_str());
  return 0;
}
