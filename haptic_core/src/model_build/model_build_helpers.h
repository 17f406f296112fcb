// Small helpers shared by the model build (haptic_model_build.cc) and its cache file
// (haptic_model_cache.cc). Internal to src/model_build/.
#pragma once

#include <bit>
#include <chrono>
#include <glm/glm.hpp>
#include <limits>
#include <stdexcept>
#include <vector>

#include "haptic_core/model_build/haptic_model_build.h"
#include "haptic_core/model_build/surface_error.h"

namespace ht::model_build {

// A size TextureSizingParams may name: a power of two in [16, 8192].
inline bool IsSizingSize(int n) noexcept {
  return n >= 16 && n <= 8192 && std::has_single_bit(static_cast<unsigned>(n));
}

inline double Seconds(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

// Axis-aligned bounds of a point set (lo > hi in every axis when it is empty).
struct Bounds {
  glm::dvec3 lo{std::numeric_limits<double>::max()};
  glm::dvec3 hi{-std::numeric_limits<double>::max()};
};
inline Bounds BoundsOf(const std::vector<glm::dvec3>& points) {
  Bounds b;
  for (const glm::dvec3& p : points) {
    b.lo = glm::min(b.lo, p);
    b.hi = glm::max(b.hi, p);
  }
  return b;
}

// MeasureSurfaceError at its defaults, or samples = 0 when it cannot measure (the model is valid,
// so only a full-resolution mesh without area gets here).
inline SurfaceErrorReport MeasuredSurface(const HapticModel& model, const TriangleMesh& full_O) {
  try {
    return MeasureSurfaceError(model, full_O);
  } catch (const std::invalid_argument&) {
    return {};
  }
}

}  // namespace ht::model_build
