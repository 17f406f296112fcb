// The contact force between two objects at a given pose, through the installed haptic core
// (find_package(haptic_teleop); CMakeLists.txt says how to build it).
//
// The scene is the seed's block on the gear (MakeBlockOnGearScene: the ridged block is the tool T,
// the ridged gear, axis along world x, the fixed object). The block is lowered from its home pose
// until its mean bottom face lies DEPTH_MM below the gear's mean top line (the ridges, 0.4 mm high
// on both, then overlap by DEPTH_MM + 0.8 mm), slid SLIDE_MM along world x (along the ridges) and
// turned YAW_DEG about world z; one remote step of the haptic texture pipeline (CPU) gives its
// contact model there.
//
// Usage: contact_force [DEPTH_MM [SLIDE_MM [YAW_DEG]]]   (defaults 0.2 0 0)
// Prints the tool pose X_WT (position in mm, world frame W, +z up), each contact's depth δ (µm,
// > 0 = penetrating) and direction n (unit, from the gear to the block, in W), and the wrench on
// the block F_T_W (force in N and torque in N·m, at the block's centre of mass, expressed in W).
// Exits 0 when the block touches and is pushed up (Fz > 0), 1 when it does not, 2 on bad input.
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <glm/gtc/quaternion.hpp>
#include <numbers>

#include "haptic_core/demo/demo_scenes.h"
#include "haptic_core/haptic_scene.h"
#include "haptic_core/remote_step.h"

namespace {

// argv[i] as a finite number, `fallback` when absent; exits 2 naming a bad one.
double NumberArg(int argc, char** argv, int i, double fallback) {
  if (i >= argc) return fallback;
  char* end = nullptr;
  const double v = std::strtod(argv[i], &end);
  if (end == argv[i] || *end != '\0' || !std::isfinite(v)) {
    std::fprintf(stderr, "contact_force: '%s' is not a number\n", argv[i]);
    std::exit(2);
  }
  return v;
}

}  // namespace

int main(int argc, char** argv) {
  const double depth_mm = NumberArg(argc, argv, 1, 0.2);
  const double slide_mm = NumberArg(argc, argv, 2, 0.0);
  const double yaw_deg = NumberArg(argc, argv, 3, 0.0);

  const ht::HapticScene scene = ht::MakeBlockOnGearScene();
  ht::HapticTexturePipeline pipeline(scene, ht::PipelineOptions{});
  ht::RigidTransform X_WT = ht::BlockOnGearHomePose();
  X_WT.translation += glm::dvec3(slide_mm, 0.0, -0.5 - depth_mm) * 1e-3;  // home: 0.5 mm above
  X_WT.rotation =
      glm::angleAxis(yaw_deg * std::numbers::pi / 180.0, glm::dvec3(0, 0, 1)) * X_WT.rotation;

  ht::StepTimings timings;
  const ht::ContactModel model = pipeline.Step(X_WT, 1, timings);
  const glm::dvec3 p_mm = X_WT.translation * 1e3;
  std::printf("tool '%s' on '%s': p_WT = (%.3f, %.3f, %.3f) mm, yaw %.1f deg\n",
              scene.tool->name.c_str(), scene.touchables[0].model->name.c_str(), p_mm.x, p_mm.y,
              p_mm.z, yaw_deg);
  for (int i = 0; i < model.num_contacts; ++i) {
    const ht::ContactLinearization& c = model.contacts[static_cast<std::size_t>(i)];
    std::printf("  contact %d: depth %.1f um, n_W = (%.3f, %.3f, %.3f)\n", i, c.depth_m * 1e6,
                c.normal_W.x, c.normal_W.y, c.normal_W.z);
  }
  const ht::Wrench& F = model.F_T_W_at_q0;
  std::printf(
      "F_T_W: force (%.3f, %.3f, %.3f) N, torque (%.4f, %.4f, %.4f) N*m; %d contact(s), "
      "step %.0f us\n",
      F.force.x, F.force.y, F.force.z, F.torque.x, F.torque.y, F.torque.z, model.num_contacts,
      timings.total_us);
  return model.num_contacts > 0 && F.force.z > 0.0 ? 0 : 1;
}
