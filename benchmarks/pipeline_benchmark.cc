// Speed of the stages on the block-on-gear scene: the remote node's step (coarse query + texture
// penetration depth with its 11 evaluations) and the operator loop's per-tick work.
#include <benchmark/benchmark.h>

#include "haptic_core/demo/demo_scenes.h"
#include "haptic_core/haptic_scene.h"
#include "haptic_core/remote_step.h"
#include "haptic_core/tool_simulation.h"

namespace {

void BM_RemoteStepBlockOnGear(benchmark::State& state) {
  const ht::HapticScene scene = ht::MakeBlockOnGearScene();
  ht::PipelineOptions options;
  options.grid_resolution = static_cast<int>(state.range(0));
  ht::HapticTexturePipeline pipeline(scene, options);
  ht::RigidTransform X = scene.X_WT_home;
  X.translation.z -= 0.5e-3;  // pressed onto the ridges: one contact
  ht::StepTimings t;
  double texture_us = 0, collision_us = 0;
  int i = 0;
  for (auto _ : state) {
    X.translation.y = 1e-5 * (i++ % 300);
    benchmark::DoNotOptimize(pipeline.Step(X, 1, t));
    texture_us += t.texture_us;
    collision_us += t.collision_us;
  }
  state.counters["collision_us"] = collision_us / static_cast<double>(state.iterations());
  state.counters["texture_us"] = texture_us / static_cast<double>(state.iterations());
}
BENCHMARK(BM_RemoteStepBlockOnGear)->Arg(25)->Arg(50)->Arg(100)->Unit(benchmark::kMicrosecond);

void BM_OperatorTick(benchmark::State& state) {
  const ht::ToolSimulator sim(ht::BlockOnGearToolInertia(), ht::VirtualCoupling{});
  ht::ContactModel model;
  model.num_contacts = static_cast<int>(state.range(0));
  for (int i = 0; i < model.num_contacts; ++i) {
    model.contacts[i].depth_m = 1e-4;
    model.contacts[i].gradient = {{0.1, -0.3, -1.0}, {0.002, 0.001, -0.004}};
    model.contacts[i].stiffness_n_per_m = 8000;
  }
  ht::ToolState s;
  ht::RigidTransform X_WH;
  X_WH.translation.z = -1e-3;
  for (auto _ : state) benchmark::DoNotOptimize(sim.Step(s, X_WH, {}, model, 1.0, 1e-3));
}
BENCHMARK(BM_OperatorTick)->Arg(1)->Arg(7)->Arg(14);

}  // namespace

BENCHMARK_MAIN();
