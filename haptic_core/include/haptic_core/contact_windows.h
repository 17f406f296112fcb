#pragma once
// Stage 4 of the remote step (remote_step.h): one contact window per cluster. Each cluster of the
// coarse query (contact_clustering.h) becomes a ContactQuery: the object, its pose, the window
// (ContactWindow: centre on the cluster's point, z axis along its normal) and the
// stiffness. A cluster whose window cannot be set up is a fault of the coarse stage, counted and
// skipped: nothing in the remote step throws.

#include <cstdint>
#include <glm/vec3.hpp>
#include <limits>
#include <optional>
#include <span>

#include "haptic_core/haptic_model.h"
#include "haptic_core/haptic_scene.h"
#include "haptic_core/spatial.h"

namespace ht {

struct ContactLinearization;  // contact_linearization.h: stage 5's result
class TriangleBoxTree;        // penetration_depth.h: a model's triangles in a box tree

/// The orthographic sampling window of one contact: a W×W square on the plane through `center_W`
/// perpendicular to `normal_W`, sampled at N×N cell centres. Cell (i, j) (i along u, j along v)
/// is stored at index j*N + i and centred at center_W + ((i+0.5)/N − 0.5)·W·u + ((j+0.5)/N −
/// 0.5)·W·v.
struct ContactWindow {
  glm::dvec3 center_W{0.0};            ///< Window centre in world (m).
  glm::dvec3 normal_W{0.0, 0.0, 1.0};  ///< n: unit, from environment B towards tool A.
  glm::dvec3 axis_u_W{1.0, 0.0, 0.0};  ///< Unit, ⟂ n.
  glm::dvec3 axis_v_W{0.0, 1.0, 0.0};  ///< Unit, u × v = n.
  double extent_m = 0.02;              ///< W: side length (m).
  int resolution = 50;                 ///< N: cells per side (seed: 50).
  /// The extent (m) whose half is the rotation steps' lever (GradientSteps::For: h_θ = h_x /
  /// (this / 2)); 0: extent_m. Stage 5a's split windows keep their parent's, so that a region's
  /// rotation secant does not grow as its box shrinks (a 10 mm box at the seed's 0.8 mm cells
  /// would step 0.16 rad) nor move when its box changes by a cell.
  double gradient_extent_m = 0.0;

  /// The extent (m) whose half is the rotation steps' lever: gradient_extent_m where set (> 0),
  /// else extent_m.
  double gradient_lever_extent_m() const noexcept {
    return gradient_extent_m > 0.0 ? gradient_extent_m : extent_m;
  }

  /// Builds a window with u the projection of world x on the plane ⟂ n (world y when n is within
  /// 25° of x), v = n × u. Throws std::invalid_argument for a non-finite or zero normal, a
  /// non-positive extent, or a resolution outside [2, 1024].
  static ContactWindow Make(const glm::dvec3& center_W, const glm::dvec3& normal_W, double extent_m,
                            int resolution);
  /// The same rule without throwing (for the remote step, which counts faults instead): nullopt
  /// where Make() would throw.
  static std::optional<ContactWindow> TryMake(const glm::dvec3& center_W,
                                              const glm::dvec3& normal_W, double extent_m,
                                              int resolution) noexcept;

  /// Cell side W/N (m).
  double cell_size_m() const noexcept { return extent_m / resolution; }
  /// Half-depth R of the window's box along n (m): surface samples whose height along n lies
  /// outside [−R, R] are ignored by both backends, so δ saturates at 2R. R = W.
  double depth_range_m() const noexcept { return extent_m; }
  /// World position (m) of cell `index`'s centre on the window plane.
  glm::dvec3 CellCenter(int index) const noexcept;
};

/// Which of a model's coarse triangles a contact may render (each texture once): all of them
/// (`all`, the default: SelectPatchTriangles picks by the window alone), or only `indices` (into
/// HapticModel::triangles; the leaves contact clustering gave the contact's cluster, so that no
/// triangle is rendered in two windows of one step). A view: the indices must outlive the call that
/// reads them.
struct TriangleSubset {
  std::span<const int> indices;
  bool all = true;
  /// The model's box tree (TriangleBoxTree, built with the scene: the remote step builds its
  /// models' in its constructor), which narrows the scan of All(); null: the whole scan (the same
  /// triangles, slower). Must outlive the batch.
  const TriangleBoxTree* tree = nullptr;

  /// Every triangle of the model.
  static TriangleSubset All() noexcept { return {}; }
  /// Only `indices` (none when empty).
  static TriangleSubset Of(std::span<const int> indices) noexcept {
    return {indices, false, nullptr};
  }
};

/// One contact of a batch: the environment object O at X_WO, the window found by the coarse
/// query, and O's penalty stiffness k (N/m).
struct ContactQuery {
  const HapticModel* environment = nullptr;  ///< Must outlive the call; not null.
  RigidTransform X_WO;
  ContactWindow window;
  double stiffness_n_per_m = 0.0;
  /// The largest δ the coarse geometry allows this contact (m): the cluster's coarse penetration
  /// plus the texture reach plus a cell (the grazing guard, PipelineOptions); +∞ for none.
  /// The backends ignore it; the remote step drops a contact whose δ0 exceeds it.
  double depth_bound_m = std::numeric_limits<double>::infinity();
  /// The coarse triangles of the environment and of the tool this contact may render (the
  /// contact's cluster's own leaves, so that no triangle is rendered in two windows
  /// of one step); All(): picked by the window alone. Views: the lists must outlive the batch.
  TriangleSubset environment_triangles = TriangleSubset::All();
  TriangleSubset tool_triangles = TriangleSubset::All();
};

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
/// window_extent_m / grid_resolution (a window sized from its contact region, at the texture's
/// cell). Candidates with a non-finite point, a zero or non-finite normal
/// or a null object are skipped and counted in `bad_windows`. Stops when `out` is full. Returns
/// the number of queries written. noexcept, allocation-free.
int MakeContactQueries(std::span<const ContactCandidate> candidates, double window_extent_m,
                       double max_window_extent_m, int grid_resolution, std::span<ContactQuery> out,
                       std::int64_t& bad_windows) noexcept;

/// The grazing guard: a contact whose δ0 exceeds its query's depth_bound_m (what its
/// coarse geometry allows) gets depth_m = −∞, so that the contact model leaves it out. Returns how
/// many were dropped. noexcept, allocation-free; `queries` and `results` are parallel.
int DropGrazingContacts(std::span<const ContactQuery> queries,
                        std::span<ContactLinearization> results) noexcept;

}  // namespace ht
