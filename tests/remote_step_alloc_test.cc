// The remote step allocates nothing after warm-up (issues 16 and 34; STYLE.md: MuJoCo-style
// preallocated data), on the block on the gear (one hull a model) and on the seed's scenes whose
// models are hull hierarchies: its own program, because it counts allocations through every
// allocator the step can reach (allocation_counter.h: the C allocator, so operator new and Eigen,
// and oneTBB's scalable allocator). Also: a cluster that cannot give a window is counted, not
// thrown.

#include <gtest/gtest.h>

#include <cctype>
#include <cmath>
#include <cstdint>
#include <glm/gtc/quaternion.hpp>
#include <ostream>
#include <string>
#include <vector>

#include "allocation_counter.h"  // the tick / step must make no allocation
#include "haptic_core/demo/demo_scenes.h"
#include "haptic_core/demo/procedural_models.h"
#include "haptic_core/haptic_scene.h"
#include "haptic_core/remote_step.h"
#include "slave_sim/benchmark_scenes.h"

using ht::testing_support::Allocations;
using ht::testing_support::TbbAllocations;

namespace ht {
namespace {

// Poses sliding the block over the gear, in and out of contact, tilted.
RigidTransform PoseAt(int k) {
  RigidTransform X = BlockOnGearHomePose();
  X.translation.x += 0.006 * std::sin(0.05 * k);
  X.translation.y += 0.004 * std::sin(0.031 * k);
  X.translation.z += 1e-3 + 3e-3 * std::sin(0.07 * k);  // from 2 mm in to 4 mm clear
  X.rotation = glm::angleAxis(0.03 * std::sin(0.02 * k), glm::dvec3(0, 1, 0));
  return X;
}

// On one thread and on two (the contacts, the coarse query's subtrees and a contact's renders as
// oneTBB tasks).
class RemoteStepAlloc : public ::testing::TestWithParam<int> {};

TEST_P(RemoteStepAlloc, AllocatesNothingAfterWarmUp) {
  const HapticScene scene = MakeBlockOnGearScene();
  PipelineOptions options;
  options.texture_threads = GetParam();
  HapticTexturePipeline pipeline(scene, options);
  StepTimings t;
  int in_contact = 0;
  for (int k = 0; k < 200; ++k) pipeline.Step(PoseAt(k), k, t);  // warm-up: the scratch grows
  const long before = Allocations(), before_tbb = TbbAllocations();
  for (int k = 200; k < 1200; ++k) in_contact += pipeline.Step(PoseAt(k), k, t).num_contacts > 0;
  EXPECT_EQ(Allocations() - before, 0) << "of which oneTBB's: " << TbbAllocations() - before_tbb;
  EXPECT_GT(in_contact, 100);
  EXPECT_LT(in_contact, 1000);  // and out of contact too
}

// With depth fields, at a hand's pace (a tenth of the slide above a step): the steps that render
// fields and the steps that take their contacts from the kept fields allocate nothing either.
TEST(RemoteStepAllocFields, AllocatesNothingAfterWarmUpRenderingOrKeepingFields) {
  const HapticScene scene = MakeBlockOnGearScene();
  PipelineOptions options;
  options.depth_fields = true;
  HapticTexturePipeline pipeline(scene, options);
  const auto pose = [](int k) {
    RigidTransform X = BlockOnGearHomePose();
    const double s = 0.1 * k;
    X.translation.x += 0.006 * std::sin(0.05 * s);
    X.translation.y += 0.004 * std::sin(0.031 * s);
    X.translation.z += 1e-3 + 3e-3 * std::sin(0.07 * s);
    X.rotation = glm::angleAxis(0.03 * std::sin(0.02 * s), glm::dvec3(0, 1, 0));
    return X;
  };
  StepTimings t;
  for (int k = 0; k < 2000; ++k) pipeline.Step(pose(k), k, t);  // warm-up: a whole period
  const std::int64_t kept_before = pipeline.step_faults().steps_from_kept_fields;
  int in_contact = 0;
  const long before = Allocations(), before_tbb = TbbAllocations();
  for (int k = 2000; k < 4000; ++k) in_contact += pipeline.Step(pose(k), k, t).num_contacts > 0;
  EXPECT_EQ(Allocations() - before, 0) << "of which oneTBB's: " << TbbAllocations() - before_tbb;
  const std::int64_t kept = pipeline.step_faults().steps_from_kept_fields - kept_before;
  EXPECT_GT(kept, 100) << "steps from kept fields";
  EXPECT_LT(kept, in_contact) << "and steps that render";
}

INSTANTIATE_TEST_SUITE_P(Threads, RemoteStepAlloc, ::testing::Values(1, 2),
                         [](const ::testing::TestParamInfo<int>& param_info) {
                           return std::to_string(param_info.param) + "Threads";
                         });

// The seed's scenes whose models are hull hierarchies (the coarse query's traversal, several
// windows a step, stage 5a's split on the interlocked blocks), at the seed's coarse counts and
// 512² textures through the build's model cache (the models texture_stage_parity_test builds;
// about a minute each when the cache is cold). The poses are the frontier's in-contact ones
// (ScriptedContactPoses), each also 1.5 mm lifted with a 3 mm speculative floor (the pairs kept
// as speculative contacts) and 10 mm lifted with no floor (free space). Warm-up: one pass over
// every pose moved 20 µm along x; then a pass over the poses themselves must not allocate.
struct SeedSceneCase {
  const char* scene;
  int threads;
  // The test's name in ctest's listing (instead of the parameter's bytes).
  friend void PrintTo(const SeedSceneCase& c, std::ostream* os) {
    *os << c.scene << " on " << c.threads << " thread(s)";
  }
};
class RemoteStepAllocSeedScenes : public ::testing::TestWithParam<SeedSceneCase> {};

TEST_P(RemoteStepAllocSeedScenes, AllocatesNothingAfterWarmUp) {
  BenchmarkModelSettings settings;
  settings.texture_size = 512;
  const BenchmarkScene scene =
      MakeBenchmarkScene(GetParam().scene, settings, HapticModelCache(HT_TEST_MODEL_CACHE));
  const std::vector<RigidTransform> poses_WFt = ScriptedContactPoses(scene, 24);
  ASSERT_GE(poses_WFt.size(), 12u) << "too few in-contact poses found on " << GetParam().scene;
  const RigidTransform X_FtT = scene.X_TFt.Inverse();
  struct Pose {
    RigidTransform X_WT;
    double floor_m;
  };
  std::vector<Pose> course;
  for (const RigidTransform& X_WFt : poses_WFt) {
    const RigidTransform X_WT = X_WFt * X_FtT;
    RigidTransform lifted = X_WT, free = X_WT;
    lifted.translation.z += 1.5e-3;
    free.translation.z += 10e-3;
    course.push_back({X_WT, 0.0});
    course.push_back({lifted, 3e-3});
    course.push_back({free, 0.0});
  }
  PipelineOptions options;
  options.texture_threads = GetParam().threads;
  HapticTexturePipeline pipeline(scene.haptic, options);
  StepTimings t;
  std::uint64_t seq = 0;
  for (Pose p : course) {  // warm-up: the scratch grows
    p.X_WT.translation.x += 20e-6;
    pipeline.SetSpeculativeFloor(p.floor_m);
    pipeline.Step(p.X_WT, ++seq, t);
  }
  const long before = Allocations(), before_tbb = TbbAllocations();
  int in_contact = 0, speculative = 0, free_space = 0;
  for (const Pose& p : course) {
    pipeline.SetSpeculativeFloor(p.floor_m);
    const ContactModel model = pipeline.Step(p.X_WT, ++seq, t);
    if (p.floor_m > 0.0) {
      speculative += model.num_contacts > 0;
    } else if (model.num_contacts > 0) {
      ++in_contact;
    } else {
      ++free_space;
    }
  }
  EXPECT_EQ(Allocations() - before, 0) << "of which oneTBB's: " << TbbAllocations() - before_tbb;
  // The course does what it says: contacts, speculative contacts, free space.
  const int n = static_cast<int>(poses_WFt.size());
  EXPECT_GE(in_contact, n / 2);
  EXPECT_GE(speculative, n / 2);
  EXPECT_GE(free_space, n / 2);
}

INSTANTIATE_TEST_SUITE_P(HullHierarchies, RemoteStepAllocSeedScenes,
                         ::testing::Values(SeedSceneCase{"fig76", 1}, SeedSceneCase{"fig76", 2},
                                           SeedSceneCase{"fig77", 1}, SeedSceneCase{"fig77", 2},
                                           SeedSceneCase{"hammer_torus", 1},
                                           SeedSceneCase{"hammer_torus", 2}),
                         [](const ::testing::TestParamInfo<SeedSceneCase>& param_info) {
                           return std::string(param_info.param.scene) + "_" +
                                  std::to_string(param_info.param.threads) + "Threads";
                         });

TEST(RemoteStep, NonFinitePosesAndFaultsAreCountedNotThrown) {
  const HapticScene scene = MakeBlockOnGearScene();
  HapticTexturePipeline pipeline(scene, PipelineOptions{});
  StepTimings t;
  RigidTransform bad = BlockOnGearHomePose();
  bad.translation.y = std::nan("");
  EXPECT_NO_THROW(pipeline.Step(bad, 1, t));
  EXPECT_EQ(pipeline.Step(bad, 1, t).num_contacts, 0);
  EXPECT_EQ(pipeline.step_faults().bad_windows, 0);
  EXPECT_FALSE(ContactWindow::TryMake({0, 0, 0}, {0, 0, 0}, 0.02, 50).has_value());
  EXPECT_FALSE(ContactWindow::TryMake({0, 0, std::nan("")}, {0, 0, 1}, 0.02, 50).has_value());
  EXPECT_TRUE(ContactWindow::TryMake({0, 0, 0}, {0, 0, 2}, 0.02, 50).has_value());
}

}  // namespace
}  // namespace ht
