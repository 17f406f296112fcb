#include "haptic_core/demo/demo_scenes.h"

#include <glm/gtc/quaternion.hpp>
#include <memory>
#include <numbers>

#include "haptic_core/demo/procedural_models.h"

namespace ht {

HapticScene MakeBlockOnGearScene() {
  HapticScene scene;
  scene.name = "block_on_gear";
  const RidgedBlockParams block_params;
  const RidgedGearParams gear_params;
  scene.tool = std::make_shared<const HapticModel>(MakeRidgedBlock(block_params));
  TouchableObject gear;
  gear.model = std::make_shared<const HapticModel>(MakeRidgedGear(gear_params));
  gear.X_WO = RigidTransform::Identity();
  gear.stiffness_n_per_m = 8000.0;
  scene.touchables.push_back(gear);
  scene.X_WT_home = BlockOnGearHomePose();
  return scene;
}

HapticScene MakeStiffWallScene() {
  HapticScene scene;
  scene.name = "stiff_wall";
  scene.tool = std::make_shared<const HapticModel>(MakeRidgedBlock(RidgedBlockParams{}));
  const glm::dvec3 half{0.06, 0.06, 0.01};
  TouchableObject wall;
  // MakeTexturedBox puts its (here flat) texture on the bottom face; turned over, that face is
  // the top, at z = the gear's radius.
  wall.model = std::make_shared<const HapticModel>(MakeTexturedBox(
      half, [](double, double) { return 0.0; }, 16, 2.0, "stiff_wall"));
  wall.X_WO.translation = {0.0, 0.0, RidgedGearParams{}.radius_m - half.z};
  wall.X_WO.rotation = glm::angleAxis(std::numbers::pi, glm::dvec3(1.0, 0.0, 0.0));
  wall.stiffness_n_per_m = 40000.0;
  scene.touchables.push_back(wall);
  scene.X_WT_home = BlockOnGearHomePose();
  return scene;
}

RigidTransform BlockOnGearHomePose() {
  RigidTransform X_WT;
  X_WT.translation = {0.0, 0.0,
                      RidgedGearParams{}.radius_m + RidgedBlockParams{}.half_extents_m.z + 0.5e-3};
  return X_WT;
}

ToolInertia BlockOnGearToolInertia() {
  const RidgedBlockParams p;
  const glm::dvec3 s = 2.0 * p.half_extents_m;
  const double m = p.mass_kg;
  return {m,
          {m / 12 * (s.y * s.y + s.z * s.z), m / 12 * (s.x * s.x + s.z * s.z),
           m / 12 * (s.x * s.x + s.y * s.y)}};
}

}  // namespace ht
