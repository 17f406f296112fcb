#pragma once
// Stage 4 of the remote step (remote_step.h): one contact window per cluster. Each cluster of the
// coarse query (contact_clustering.h) becomes a ContactQuery: the object, its pose, the window
// (centre on the cluster's point, z axis along its normal; penetration_depth.h) and the
// stiffness. A cluster whose window cannot be set up is a fault of the coarse stage, counted and
// skipped: nothing in the remote step throws.

#include <cstdint>
#include <glm/vec3.hpp>
#include <limits>
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
  /// The cluster's window side (m; ContactCluster::extent_m): the members' spread plus the
  /// texture margin. 0: the minimum side.
  double extent_m = 0.0;
  /// The largest δ the coarse geometry allows (m; ContactQuery::depth_bound_m), +∞ for none.
  double depth_bound_m = std::numeric_limits<double>::infinity();
  /// The coarse triangles of the object and of the tool the contact may render
  /// (ContactQuery::environment_triangles, tool_triangles): its cluster's own leaves, or All().
  TriangleSubset object_triangles = TriangleSubset::All();
  TriangleSubset tool_triangles = TriangleSubset::All();
};

/// The grid N of a window of side `side_m` (m) that keeps the cell `window_extent_m` /
/// `grid_resolution` of the smallest window: ceil(grid_resolution · side_m / window_extent_m),
/// at most 1024. Expects positive, finite sides.
int WindowResolution(double side_m, double window_extent_m, int grid_resolution) noexcept;

/// Writes one query per candidate into `out`, in order (ContactWindow::TryMake), with the
/// candidate's triangle subsets: the window's side
/// is the candidate's extent_m clamped to [window_extent_m, max_window_extent_m] (m), and its grid
/// N = ceil(grid_resolution · side / window_extent_m), so that every window keeps the cell
/// window_extent_m / grid_resolution (issue 31: a window sized from its contact region, at the
/// texture's cell). Candidates with a non-finite point, a zero or non-finite normal
/// or a null object are skipped and counted in `bad_windows`. Stops when `out` is full. Returns
/// the number of queries written. noexcept, allocation-free.
int MakeContactQueries(std::span<const ContactCandidate> candidates, double window_extent_m,
                       double max_window_extent_m, int grid_resolution, std::span<ContactQuery> out,
                       std::int64_t& bad_windows) noexcept;

/// The grazing guard (issue 31): a contact whose δ0 exceeds its query's depth_bound_m (what its
/// coarse geometry allows) gets depth_m = −∞, so that the contact model leaves it out. Returns how
/// many were dropped. noexcept, allocation-free; `queries` and `results` are parallel.
int DropGrazingContacts(std::span<const ContactQuery> queries,
                        std::span<ContactLinearization> results) noexcept;

}  // namespace ht
