#pragma once
// A scene as the remote node sees it: the tool's haptic model and the touchable objects with their
// poses and stiffness. The remote step that turns a tool pose into a contact model over such a
// scene is in remote_step.h; the demo scenes (block on gear, stiff wall) in demo/demo_scenes.h.

#include <memory>
#include <string>
#include <vector>

#include "haptic_core/haptic_model.h"
#include "haptic_core/spatial.h"

namespace ht {

/// One touchable object O of the scene: its haptic model, pose X_WO and penalty stiffness.
struct TouchableObject {
  std::shared_ptr<const HapticModel> model;
  RigidTransform X_WO;
  double stiffness_n_per_m = 8000.0;
};

/// The haptic part of a scene: the tool (frame T at its centre of mass) and the touchables.
struct HapticScene {
  std::string name;
  std::shared_ptr<const HapticModel> tool;
  std::vector<TouchableObject> touchables;
  /// Where the tool starts (and where the operator's workspace is centred), X_WT.
  RigidTransform X_WT_home;
};

}  // namespace ht
