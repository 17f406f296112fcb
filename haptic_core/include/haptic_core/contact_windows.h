#pragma once
// Stage 4 of the remote step (remote_step.h): one contact window per cluster. Each cluster of the
// coarse query (contact_clustering.h) becomes a ContactQuery: the object, its pose, the window
// (centre on the cluster's point, z axis along its normal; penetration_depth.h) and the
// stiffness. A cluster whose window cannot be set up is a fault of the coarse stage, counted and
// skipped: nothing in the remote step throws.

#include <cstdint>
#include <glm/vec3.hpp>
#include <span>

#include "haptic_core/haptic_scene.h"
#include "haptic_core/penetration_depth_backend.h"

namespace ht {

/// A contact found by the coarse stages: the touchable object, and the cluster's point and
/// normal in W (the normal points from the object towards the tool).
struct ContactCandidate {
  const TouchableObject* object = nullptr;
  glm::dvec3 point_W{0.0};
  glm::dvec3 normal_W{0.0, 0.0, 1.0};
};

/// Writes one query per candidate into `out`, in order, with windows of extent W (m) and an N×N
/// grid (ContactWindow::TryMake). Candidates with a non-finite point, a zero or non-finite normal
/// or a null object are skipped and counted in `bad_windows`. Stops when `out` is full. Returns
/// the number of queries written. noexcept, allocation-free.
int MakeContactQueries(std::span<const ContactCandidate> candidates, double window_extent_m,
                       int grid_resolution, std::span<ContactQuery> out,
                       std::int64_t& bad_windows) noexcept;

}  // namespace ht
