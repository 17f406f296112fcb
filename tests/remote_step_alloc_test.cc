// The remote step allocates nothing after warm-up (issue 16; STYLE.md: MuJoCo-style preallocated
// data): its own program, because it counts allocations with a replaced global operator new.
// Also: a cluster that cannot give a window is counted, not thrown.

#include <gtest/gtest.h>

#include <cctype>
#include <glm/gtc/quaternion.hpp>
#include <string>

#include "allocation_counter.h"  // the tick / step must make no allocation
#include "haptic_core/demo/demo_scenes.h"
#include "haptic_core/demo/procedural_models.h"
#include "haptic_core/haptic_scene.h"
#include "haptic_core/remote_step.h"

using ht::testing_support::Allocations;

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
// oneTBB tasks), with either rotation gradient.
struct AllocCase {
  int threads;
  RotationGradient rotation;
};
class RemoteStepAlloc : public ::testing::TestWithParam<AllocCase> {};

TEST_P(RemoteStepAlloc, AllocatesNothingAfterWarmUp) {
  const HapticScene scene = MakeBlockOnGearScene();
  PipelineOptions options;
  options.texture_threads = GetParam().threads;
  options.rotation_gradient = GetParam().rotation;
  HapticTexturePipeline pipeline(scene, options);
  StepTimings t;
  int in_contact = 0;
  for (int k = 0; k < 200; ++k) pipeline.Step(PoseAt(k), k, t);  // warm-up: the scratch grows
  const long before = Allocations();
  for (int k = 200; k < 1200; ++k) in_contact += pipeline.Step(PoseAt(k), k, t).num_contacts > 0;
  EXPECT_EQ(Allocations() - before, 0);
  EXPECT_GT(in_contact, 100);
  EXPECT_LT(in_contact, 1000);  // and out of contact too
}

INSTANTIATE_TEST_SUITE_P(ThreadsAndRotationGradients, RemoteStepAlloc,
                         ::testing::Values(AllocCase{1, RotationGradient::kRenderedSamples},
                                           AllocCase{2, RotationGradient::kRenderedSamples},
                                           AllocCase{1, RotationGradient::kContactLever},
                                           AllocCase{2, RotationGradient::kContactLever},
                                           AllocCase{1, RotationGradient::kWarpedBaseRender},
                                           AllocCase{2, RotationGradient::kWarpedBaseRender}),
                         [](const ::testing::TestParamInfo<AllocCase>& param_info) {
                           std::string name = ToString(param_info.param.rotation);
                           name[0] =
                               static_cast<char>(std::toupper(static_cast<unsigned char>(name[0])));
                           return std::to_string(param_info.param.threads) + "Threads" + name;
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
