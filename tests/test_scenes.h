#pragma once
// Small textured patches for tests: a tool box A whose bottom face (−z) carries h_A, and an
// environment box B turned upside down so that its textured face looks up (+z) with top at z = 0.

#include <functional>

#include "haptic_core/demo/procedural_models.h"

namespace ht::testing {

inline constexpr double kHalf = 0.02;        // box half size in x and y (m)
inline constexpr double kHalfHeight = 0.01;  // box half height (m)

/// Tool box A with bottom texture h_A(x_A, y_A) (A's own coordinates).
inline HapticModel ToolBox(const std::function<double(double, double)>& h, int texture = 512) {
  return MakeTexturedBox({kHalf, kHalf, kHalfHeight}, h, texture, 0.1, "test_tool");
}

/// Environment box B; its textured face is up when posed with EnvironmentPose().
/// h_B is given in world coordinates (x_W, y_W) of that face.
inline HapticModel EnvironmentBox(const std::function<double(double, double)>& h_world,
                                  int texture = 512) {
  // Turned by π about x: local (x, y) maps to world (x, −y).
  return MakeTexturedBox(
      {kHalf, kHalf, kHalfHeight}, [h_world](double x, double y) { return h_world(x, -y); },
      texture, 1.0, "test_environment");
}

/// Pose of B with its textured face up and at world z = 0 (mean surface).
inline RigidTransform EnvironmentPose() {
  RigidTransform X;
  X.translation = {0.0, 0.0, -kHalfHeight};
  X.rotation = glm::dquat(0.0, 1.0, 0.0, 0.0);  // π about x
  return X;
}

/// Pose of A with its mean bottom face at world height z_bottom, centred above (x, y).
inline RigidTransform ToolPose(double x, double y, double z_bottom) {
  RigidTransform X;
  X.translation = {x, y, z_bottom + kHalfHeight};
  return X;
}

}  // namespace ht::testing
