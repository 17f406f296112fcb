// The remote step allocates nothing after warm-up (issue 16; STYLE.md: MuJoCo-style preallocated
// data): its own program, because it counts allocations with a replaced global operator new.
// Also: a cluster that cannot give a window is counted, not thrown.

#include <gtest/gtest.h>

#include <atomic>
#include <cstdlib>
#include <glm/gtc/quaternion.hpp>
#include <new>

#include "haptic_core/haptic_scene.h"
#include "haptic_core/procedural_models.h"

static std::atomic<long> g_allocations{0};
void* operator new(std::size_t n) {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  if (void* p = std::malloc(n == 0 ? 1 : n)) return p;
  throw std::bad_alloc();
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }

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

TEST(RemoteStep, AllocatesNothingAfterWarmUp) {
  const HapticScene scene = MakeBlockOnGearScene();
  HapticTexturePipeline pipeline(scene, PipelineOptions{});
  StepTimings t;
  int in_contact = 0;
  for (int k = 0; k < 200; ++k) pipeline.Step(PoseAt(k), k, t);  // warm-up: the scratch grows
  const long before = g_allocations.load();
  for (int k = 200; k < 1200; ++k) in_contact += pipeline.Step(PoseAt(k), k, t).num_contacts > 0;
  EXPECT_EQ(g_allocations.load() - before, 0);
  EXPECT_GT(in_contact, 100);
  EXPECT_LT(in_contact, 1000);  // and out of contact too
}

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
