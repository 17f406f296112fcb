// Uses the installed haptic core (find_package(haptic_teleop)): the seed's ridged block pressed
// 0.2 mm into the ridged gear, one remote step of the haptic texture pipeline on the CPU, and the
// contact wrench it gives. Exits 0 when the block is pushed out (Fz > 0), 1 otherwise.
#include <cstdio>

#include "haptic_core/demo/demo_scenes.h"
#include "haptic_core/haptic_scene.h"
#include "haptic_core/remote_step.h"

int main() {
  const ht::HapticScene scene = ht::MakeBlockOnGearScene();
  ht::HapticTexturePipeline pipeline(scene, ht::PipelineOptions{});
  ht::RigidTransform X_WT = ht::BlockOnGearHomePose();
  X_WT.translation.z -= 0.5e-3 + 0.2e-3;  // from 0.5 mm above to 0.2 mm in
  ht::StepTimings timings;
  const ht::ContactModel model = pipeline.Step(X_WT, 1, timings);
  const ht::Wrench& F = model.F_T_W_at_q0;
  std::printf("haptic_core_consumer: %d contact(s), F = (%.3f, %.3f, %.3f) N in %.0f us\n",
              model.num_contacts, F.force.x, F.force.y, F.force.z, timings.total_us);
  return model.num_contacts > 0 && F.force.z > 0.0 ? 0 : 1;
}
