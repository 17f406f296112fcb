// A model uploaded for the GPU penetration depth: its corners' vertex array (gpu_shaders.h's
// layout) and its height-field texture with the mip levels. Internal to src/gpu/.
#pragma once

#include <GLES3/gl31.h>

#include <memory>

#include "haptic_core/gpu_penetration_depth.h"

namespace ht {

struct GpuPenetrationDepthBackend::GpuModel {
  GLuint vao = 0, vbo = 0, texture = 0;
  GLsizei corners = 0;
  int num_levels = 1;
  int wrap_u = 0, wrap_v = 0;
  /// The model uploaded, held while its upload is kept (UseScene), so that no other model takes
  /// its address; null for a model a batch met first.
  std::shared_ptr<const HapticModel> held;
};

}  // namespace ht
