#pragma once
// Demo scenes built from the procedural models (demo/procedural_models.h): the seed's Fig. 72-b
// block on gear and a stiff wall under the same block. Demo content, in the haptic_demo_models
// library; nothing of the method itself depends on it.

#include "haptic_core/haptic_scene.h"
#include "haptic_core/tool_simulation.h"

namespace ht {

/// The seed's Fig. 72-b scene: the ridged block (tool) resting on the fixed ridged gear, the gear
/// axis along world x through the origin, so that both sets of ridges run along x. The home pose
/// puts the block's mean bottom face 0.5 mm above the gear's mean top line.
HapticScene MakeBlockOnGearScene();

/// A stiff, smooth wall under the same ridged block (a hard case for stability: k = 40,000 N/m,
/// five times the gear's): a 12 × 12 × 2 cm box whose top face lies where the gear's top is, so
/// the home pose and the experiments are those of MakeBlockOnGearScene().
HapticScene MakeStiffWallScene();

/// Home pose X_WT of the tool in MakeBlockOnGearScene(), without building the scene.
RigidTransform BlockOnGearHomePose();

/// Mass properties of the ridged block of MakeBlockOnGearScene() (the default tool).
ToolInertia BlockOnGearToolInertia();

}  // namespace ht
