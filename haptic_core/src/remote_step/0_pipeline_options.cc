// The remote step's options (remote_step.h): their checks, the largest window grid they ask
// for, and the texture stage's default thread count.
#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>
#include <thread>

#include "haptic_core/remote_step.h"

namespace ht {

void PipelineOptions::Validate() const {
  depth_refinement.Validate();
  if (grid_resolution < 2 || grid_resolution > 1024) {
    throw std::invalid_argument("grid resolution must be in [2, 1024], got " +
                                std::to_string(grid_resolution));
  }
  if (!(window_extent_m > 0.0) || !std::isfinite(window_extent_m)) {
    throw std::invalid_argument("window extent must be positive, got " +
                                std::to_string(window_extent_m));
  }
  if (!(proximity_margin_m >= 0.0) || !std::isfinite(proximity_margin_m)) {
    throw std::invalid_argument("proximity margin must be >= 0, got " +
                                std::to_string(proximity_margin_m));
  }
  if (!(max_window_extent_m >= window_extent_m) || !std::isfinite(max_window_extent_m)) {
    throw std::invalid_argument("max window extent must be >= the window extent (" +
                                std::to_string(window_extent_m) + "), got " +
                                std::to_string(max_window_extent_m));
  }
  if (!(speculative_lead_s >= 0.0 && speculative_lead_s <= 10.0)) {
    throw std::invalid_argument("speculative lead must be in [0, 10] s, got " +
                                std::to_string(speculative_lead_s));
  }
  if (!(speculative_floor_m >= 0.0) || !std::isfinite(speculative_floor_m)) {
    throw std::invalid_argument("speculative floor must be >= 0, got " +
                                std::to_string(speculative_floor_m));
  }
  if (!(depth_field_margin_m >= 0.0) || !std::isfinite(depth_field_margin_m)) {
    throw std::invalid_argument("depth_field_margin_m must be >= 0 and finite, got " +
                                std::to_string(depth_field_margin_m));
  }
  if (depth_field_subdivision < 1 || depth_field_subdivision > 4) {
    throw std::invalid_argument("depth_field_subdivision must be in [1, 4], got " +
                                std::to_string(depth_field_subdivision));
  }
  if (force_law != ForceLaw::kSeed && force_law != ForceLaw::kPressure) {
    throw std::invalid_argument("force_law must be seed or pressure");
  }
  if (!(pressure_stiffness_n_per_m3 >= 0.0) || !std::isfinite(pressure_stiffness_n_per_m3)) {
    throw std::invalid_argument("pressure_stiffness_n_per_m3 must be >= 0 and finite, got " +
                                std::to_string(pressure_stiffness_n_per_m3));
  }
  if (!(depth_field_smooth_max_m > 0.0) || !std::isfinite(depth_field_smooth_max_m)) {
    throw std::invalid_argument("depth_field_smooth_max_m must be > 0 and finite, got " +
                                std::to_string(depth_field_smooth_max_m));
  }
  if (!(max_speculative_margin_m >= 0.0) || !std::isfinite(max_speculative_margin_m)) {
    throw std::invalid_argument("max speculative margin must be >= 0, got " +
                                std::to_string(max_speculative_margin_m));
  }
  if (max_contacts < 1 || max_contacts > kMaxContacts) {
    throw std::invalid_argument("max contacts must be in [1, " + std::to_string(kMaxContacts) +
                                "], got " + std::to_string(max_contacts));
  }
  if (texture_threads < 1 || texture_threads > 256) {
    throw std::invalid_argument("texture threads must be in [1, 256], got " +
                                std::to_string(texture_threads));
  }
}

int PipelineOptions::max_window_resolution() const noexcept {
  if (!(window_extent_m > 0.0) || !(max_window_extent_m >= window_extent_m)) return grid_resolution;
  return WindowResolution(max_window_extent_m, window_extent_m, grid_resolution);
}

int DefaultTextureThreads() noexcept {
  const unsigned hw = std::thread::hardware_concurrency();
  return std::clamp(static_cast<int>(hw) - 1, 1, 16);
}

}  // namespace ht
