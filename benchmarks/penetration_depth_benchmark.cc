// The texture penetration-depth stage alone (DESIGN.md §4), CPU reference vs GPU (headless EGL),
// for 1, 7 and 32 contacts at 25², 50² and 100² grids: one batch = every contact's 11 depth
// evaluations (base and ± gradient steps) and the linearization. Counter us_per_contact is the
// batch time divided by the contacts; the profiled GPU variant splits the batch into stages
// (upload, draw, reduce, readback) with glFinish between them.
//
// Run: build/benchmarks/penetration_depth_benchmark   (MESA_SHADER_CACHE_DISABLE=true to keep
// Mesa from writing a shader cache; HT_DEPTH_BITS=32 for the float depth buffer)
#include <benchmark/benchmark.h>

#include <cstdlib>
#include <memory>
#include <random>
#include <vector>

#include "haptic_core/demo/demo_scenes.h"
#include "haptic_core/demo/procedural_models.h"
#include "haptic_core/gpu_penetration_depth.h"
#include "haptic_core/haptic_scene.h"

namespace {

struct Models {
  ht::HapticModel block = ht::MakeRidgedBlock(ht::RidgedBlockParams{});
  ht::HapticModel gear = ht::MakeRidgedGear(ht::RidgedGearParams{});
  // Their box trees, built with the models as the remote step builds its scene's.
  std::unique_ptr<ht::TriangleBoxTree> block_tree = ht::TriangleBoxTree::ForModel(block);
  std::unique_ptr<ht::TriangleBoxTree> gear_tree = ht::TriangleBoxTree::ForModel(gear);
};

const Models& SharedModels() {
  static const Models m;
  return m;
}

// `count` contact windows over the block-on-gear contact (block pressed 0.6 mm), fixed seed.
std::vector<ht::ContactQuery> MakeQueries(int count, int grid) {
  const Models& m = SharedModels();
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  const double r = ht::RidgedGearParams{}.radius_m;
  std::vector<ht::ContactQuery> q;
  for (int i = 0; i < count; ++i) {
    const glm::dvec3 n = glm::normalize(glm::dvec3(0.1 * U(rng), 0.1 * U(rng), 1.0));
    q.push_back({&m.gear, ht::RigidTransform::Identity(),
                 ht::ContactWindow::Make({0.012 * U(rng), 0.004 * U(rng), r}, n, 0.02, grid),
                 8000.0});
    q.back().environment_triangles.tree = m.gear_tree.get();
    q.back().tool_triangles.tree = m.block_tree.get();
  }
  return q;
}

ht::RigidTransform PressedPose() {
  ht::RigidTransform X = ht::BlockOnGearHomePose();
  X.translation.z -= 0.6e-3;
  return X;
}

void Run(benchmark::State& state, ht::PenetrationDepthBackend& backend) {
  const int contacts = static_cast<int>(state.range(0)), grid = static_cast<int>(state.range(1));
  const auto queries = MakeQueries(contacts, grid);
  std::vector<ht::ContactLinearization> out(queries.size());
  const ht::RigidTransform X = PressedPose();
  if (!backend.LinearizeBatch(SharedModels().block, X, queries, out)) {  // warm-up, uploads
    state.SkipWithError(backend.last_error().c_str());
    return;
  }
  for (auto _ : state) {
    if (!backend.LinearizeBatch(SharedModels().block, X, queries, out)) {
      state.SkipWithError(backend.last_error().c_str());
      break;
    }
    benchmark::DoNotOptimize(out.data());
  }
  // Wall time: the GPU (or llvmpipe's threads) works outside this thread's CPU time.
  state.counters["us_per_contact"] =
      benchmark::Counter(static_cast<double>(state.iterations()) * contacts,
                         benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}

void BM_PenetrationDepthCpu(benchmark::State& state) {
  ht::CpuPenetrationDepthBackend cpu(128);
  Run(state, cpu);
}

ht::GpuPenetrationDepthBackend* Gpu(bool profile) {
  static std::unique_ptr<ht::GpuPenetrationDepthBackend> plain, profiled;
  auto& slot = profile ? profiled : plain;
  if (!slot) {
    ht::GpuPenetrationDepthOptions o;
    o.max_contacts = 32;
    if (const char* bits = std::getenv("HT_DEPTH_BITS")) o.depth_bits = std::atoi(bits);
    o.max_resolution = 100;
    o.profile_stages = profile;
    try {
      slot = ht::GpuPenetrationDepthBackend::Create(o);
    } catch (const std::exception& e) {
      std::fprintf(stderr, "no GPU backend: %s\n", e.what());
      return nullptr;
    }
  }
  return slot.get();
}

void BM_PenetrationDepthGpu(benchmark::State& state) {
  auto* gpu = Gpu(false);
  if (gpu == nullptr) {
    state.SkipWithError("GPU backend did not start");
    return;
  }
  state.SetLabel(gpu->info().renderer);
  Run(state, *gpu);
}

void BM_PenetrationDepthGpuStages(benchmark::State& state) {
  auto* gpu = Gpu(true);
  if (gpu == nullptr) {
    state.SkipWithError("GPU backend did not start");
    return;
  }
  double upload = 0, draw = 0, reduce = 0, readback = 0;
  const int contacts = static_cast<int>(state.range(0)), grid = static_cast<int>(state.range(1));
  const auto queries = MakeQueries(contacts, grid);
  std::vector<ht::ContactLinearization> out(queries.size());
  const ht::RigidTransform X = PressedPose();
  gpu->LinearizeBatch(SharedModels().block, X, queries, out);
  for (auto _ : state) {
    gpu->LinearizeBatch(SharedModels().block, X, queries, out);
    const ht::GpuStageTimes& t = gpu->stage_times();
    upload += t.upload_us;
    draw += t.draw_us;
    reduce += t.reduce_us;
    readback += t.readback_us;
  }
  const double n = static_cast<double>(state.iterations());
  state.counters["upload_us"] = upload / n;
  state.counters["draw_us"] = draw / n;
  state.counters["reduce_us"] = reduce / n;
  state.counters["readback_us"] = readback / n;
}

void Sizes(benchmark::internal::Benchmark* b) {
  for (int grid : {25, 50, 100}) {
    for (int contacts : {1, 7, 32}) b->Args({contacts, grid});
  }
  b->ArgNames({"contacts", "grid"})->Unit(benchmark::kMicrosecond)->UseRealTime();
}

BENCHMARK(BM_PenetrationDepthCpu)->Apply(Sizes);
BENCHMARK(BM_PenetrationDepthGpu)->Apply(Sizes);
BENCHMARK(BM_PenetrationDepthGpuStages)->Apply(Sizes);

}  // namespace

BENCHMARK_MAIN();
