// Speed of the coarse proximity query (haptic_core/hull_proximity.h) on the seed scenes (DESIGN.md
// §7): the file on the CAD part and the hammer on the torus, coarse models at the seed's coarse
// triangle counts (632/720, 518/532), against FCL on the same coarse triangles (OBBRSS BVHs):
// fcl::collide with all contacts, and fcl::distance. Poses: the tool sinks into the environment
// by 0.3 mm (found by bisection on our query's deepest pair), then slides 1 µm per frame over a
// 64-frame cycle (so temporal coherence has something to reuse, and nothing is free).
//
// Models are built once (decimation 15–35 s per model) and cached on disk through
// BuildHapticModelCached (HapticModelCache::DefaultDir(), texture_size 256: 64 does not fit 700
// charts).
#include <benchmark/benchmark.h>
#include <fcl/fcl.h>

#include <cmath>
#include <iostream>
#include <map>
#include <memory>
#include <numbers>
#include <string>
#include <vector>

#include "haptic_core/accuracy/fcl_mesh.h"
#include "haptic_core/demo/seed_models.h"
#include "haptic_core/hull_proximity.h"
#include "haptic_core/model_build/haptic_model_build.h"

namespace {

struct Scene {
  std::shared_ptr<const ht::HapticModel> tool;  // A
  std::shared_ptr<const ht::HapticModel> env;   // B
  std::shared_ptr<fcl::BVHModel<fcl::OBBRSSd>> fcl_tool, fcl_env;
  ht::RigidTransform X_WA;  // touching pose
  double tolerance_m = 0.0;
};

std::shared_ptr<const ht::HapticModel> Build(ht::SeedModel model) {
  ht::HapticModelBuildParams params;
  params.coarse_triangles = static_cast<int>(ht::SeedModelSpecOf(model).seed_coarse_triangles);
  params.texture.texture_size = 256;
  const ht::HapticModelCache cache(ht::HapticModelCache::DefaultDir());
  const auto build = ht::BuildHapticModelCached(
      ht::SeedModelName(model), ht::MakeSeedModelFullResolution(model), params, cache);
  std::cerr << ht::SeedModelName(model) << ": " << build.model->triangles.size()
            << " coarse triangles, " << build.report.hull_leaves << " leaves, "
            << build.report.hull_nodes << " nodes" << (build.report.from_cache ? " (cached)" : "")
            << "\n";
  return build.model;
}

// Lowers the tool along −z from `start` (clear of B) in 1 mm steps until its deepest pair
// penetrates by more than `depth_m`, then bisects the last step to that depth.
ht::RigidTransform Sink(const ht::HapticModel& A, ht::RigidTransform start,
                        const ht::HapticModel& B, double depth_m) {
  ht::HullProximityQuery q;
  const ht::HullBounds bounds_A = ht::HullBounds::Of(A), bounds_B = ht::HullBounds::Of(B);
  ht::ProximityQueryOptions opt;
  auto deepest = [&](double z) {
    start.translation.z = z;
    const auto pairs = q.Query(A, bounds_A, start, B, bounds_B, ht::RigidTransform{}, opt);
    return pairs.empty() ? 1.0 : pairs[0].signed_distance_m;
  };
  double hi = start.translation.z;
  while (deepest(hi - 1e-3) > -depth_m) hi -= 1e-3;
  double lo = hi - 1e-3;
  for (int i = 0; i < 50; ++i) {
    const double mid = 0.5 * (lo + hi);
    (deepest(mid) > -depth_m ? hi : lo) = mid;
  }
  start.translation.z = hi;
  return start;
}

Scene& GetScene(int which) {
  static std::map<int, Scene> scenes;
  auto it = scenes.find(which);
  if (it != scenes.end()) return it->second;
  Scene s;
  if (which == 0) {
    // File lying flat across the CAD part's low plate, near the bosses.
    s.tool = Build(ht::SeedModel::kFile);
    s.env = Build(ht::SeedModel::kCadPart);
    s.X_WA.translation = {-0.01, 0.0, 0.1};
    s.X_WA.rotation = glm::angleAxis(0.3, glm::dvec3(0, 0, 1));
  } else {
    // Hammer head lying across the torus tube.
    s.tool = Build(ht::SeedModel::kHammer);
    s.env = Build(ht::SeedModel::kTorus);
    s.X_WA.translation = {-0.084, 0.0, 0.3};  // head (at O's z ≈ +0.134) over the tube
    s.X_WA.rotation = glm::angleAxis(std::numbers::pi / 2, glm::dvec3(0, 1, 0));
  }
  // ε = 1 mm, about twice the seed models' texture amplitudes (0.1–0.5 mm). The remote step's
  // own tolerance, the sum of both models' OutwardReach() (5.4 mm for the CAD part alone), is
  // measured with the step itself by fig77_scrape and the speed-vs-error frontier.
  s.tolerance_m = 1e-3;
  s.X_WA = Sink(*s.tool, s.X_WA, *s.env, 3e-4);
  s.fcl_tool = ht::MakeFclMesh({s.tool->vertices_O, s.tool->triangles}, "coarse tool");
  s.fcl_env = ht::MakeFclMesh({s.env->vertices_O, s.env->triangles}, "coarse environment");
  return scenes.emplace(which, std::move(s)).first->second;
}

ht::RigidTransform Frame(const Scene& s, int i) {
  ht::RigidTransform X = s.X_WA;
  X.translation.x += 1e-6 * (i % 64);
  return X;
}

void BM_HullProximity(benchmark::State& state) {
  const Scene& s = GetScene(static_cast<int>(state.range(0)));
  ht::HullProximityQuery q;
  const ht::HullBounds tool_bounds = ht::HullBounds::Of(*s.tool);
  const ht::HullBounds env_bounds = ht::HullBounds::Of(*s.env);
  ht::ProximityQueryOptions opt;
  opt.tolerance_m = s.tolerance_m;
  opt.temporal_coherence = state.range(1) != 0;
  ht::ProximityQueryStats st;
  double pairs = 0, tests = 0, leaf_tests = 0, culls = 0, min_sd = 0;
  int i = 0;
  for (auto _ : state) {
    const auto r = q.Query(*s.tool, tool_bounds, Frame(s, i++), *s.env, env_bounds,
                           ht::RigidTransform{}, opt, &st);
    benchmark::DoNotOptimize(r.data());
    pairs += st.pairs_found;
    tests += st.node_pairs_tested;
    leaf_tests += st.leaf_pairs_tested;
    culls += st.coherent_culls;
    if (!r.empty()) min_sd = r[0].signed_distance_m;
  }
  const double n = static_cast<double>(state.iterations());
  state.counters["pairs"] = pairs / n;
  state.counters["node_pairs"] = tests / n;
  state.counters["leaf_pairs"] = leaf_tests / n;
  state.counters["coherent_culls"] = culls / n;
  state.counters["min_sd_mm"] = 1e3 * min_sd;
  state.counters["eps_mm"] = 1e3 * s.tolerance_m;
  state.SetLabel(state.range(0) == 0 ? "file/CAD part" : "hammer/torus");
}
BENCHMARK(BM_HullProximity)
    ->ArgsProduct({{0, 1}, {0, 1}})
    ->ArgNames({"scene", "coherence"})
    ->Unit(benchmark::kMicrosecond);

void BM_FclCollideAllContacts(benchmark::State& state) {
  const Scene& s = GetScene(static_cast<int>(state.range(0)));
  fcl::CollisionObjectd env(s.fcl_env, fcl::Transform3d::Identity());
  fcl::CollisionRequestd req(1000000, true);
  double contacts = 0;
  int i = 0;
  for (auto _ : state) {
    fcl::CollisionObjectd tool(s.fcl_tool, ht::ToFcl(Frame(s, i++)));
    fcl::CollisionResultd res;
    fcl::collide(&tool, &env, req, res);
    contacts += static_cast<double>(res.numContacts());
  }
  state.counters["contacts"] = contacts / static_cast<double>(state.iterations());
  state.SetLabel(state.range(0) == 0 ? "file/CAD part" : "hammer/torus");
}
BENCHMARK(BM_FclCollideAllContacts)
    ->Arg(0)
    ->Arg(1)
    ->ArgName("scene")
    ->Unit(benchmark::kMicrosecond);

void BM_FclDistance(benchmark::State& state) {
  const Scene& s = GetScene(static_cast<int>(state.range(0)));
  fcl::CollisionObjectd env(s.fcl_env, fcl::Transform3d::Identity());
  fcl::DistanceRequestd req;
  double d = 0;
  int i = 0;
  for (auto _ : state) {
    fcl::CollisionObjectd tool(s.fcl_tool, ht::ToFcl(Frame(s, i++)));
    fcl::DistanceResultd res;
    fcl::distance(&tool, &env, req, res);
    d = res.min_distance;
  }
  state.counters["distance_mm"] = 1e3 * d;
  state.SetLabel(state.range(0) == 0 ? "file/CAD part" : "hammer/torus");
}
BENCHMARK(BM_FclDistance)->Arg(0)->Arg(1)->ArgName("scene")->Unit(benchmark::kMicrosecond);

}  // namespace

BENCHMARK_MAIN();
