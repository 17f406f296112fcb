#pragma once
// Per-contact linearization of the texture penetration depth (DESIGN.md §4–§5): δ0, its 6-DoF
// gradient J by central differences, and the penalty wrench Φ = −k δ ∇δ.

#include <array>
#include <cstdint>
#include <limits>
#include <span>
#include <string>
#include <vector>

#include "haptic_core/haptic_model.h"
#include "haptic_core/overlap_links.h"
#include "haptic_core/penetration_depth.h"
#include "haptic_core/spatial.h"

namespace ht {

/// Gradient ∇δ of a penetration depth with respect to the tool's pose q = (x, θ): x the position
/// of the tool's centre of mass and θ a rotation vector about it, both along world axes [L].
struct PenetrationGradient {
  glm::dvec3 d_translation_W{0.0};  ///< ∂δ/∂x (dimensionless, m/m).
  glm::dvec3 d_rotation_W{0.0};     ///< ∂δ/∂θ (m/rad).

  /// J·Δq for a pose change Δq (Δq.linear in m, Δq.angular in rad, world axes). Returns metres.
  double Dot(const Twist& dq) const noexcept {
    return glm::dot(d_translation_W, dq.linear) + glm::dot(d_rotation_W, dq.angular);
  }
};

/// The linearized contact that the remote node sends and the operator loop evaluates:
/// δ_i(q) ≈ depth_m + J·(q ⊖ q0) with stiffness k (DESIGN.md §5), the fallback of a contact whose
/// depth field (depth_field.h) the operator does not hold.
struct ContactLinearization {
  double depth_m = 0.0;            ///< δ0 at q0 (m), signed: negative = separated along n.
  PenetrationGradient gradient;    ///< J = ∇δ at q0.
  double stiffness_n_per_m = 0.0;  ///< Penalty stiffness k (N/m).
  glm::dvec3 point_W{0.0};         ///< Deepest cell's centre on the window plane (m), for display.
  glm::dvec3 normal_W{0.0, 0.0, 1.0};  ///< Contact direction n (unit, from environment to tool).
  /// The contact's depth field (depth_field.h; 0: none). Where the evaluator holds that field and
  /// the tool is within its travel margin, δ and ∇δ are the field's at the tool's pose
  /// (EvaluateContactModel); elsewhere depth_m + J·Δq is the fallback.
  std::uint32_t depth_field_id = 0;
  /// Added to the field's δ (m): the operator's depth offset (the energy-bounded switch), which
  /// it also subtracts from depth_m.
  double depth_field_shift_m = 0.0;
};

/// Where a contact's depth is a V in the tool's tilt about an in-plane axis a ∈ {u, v} of its
/// window (a flat face resting on ridges: tilted either way, the edge that rises bears), sets
/// ∂δ/∂θ along a to the bearing edge's lever slope. From `lin`'s kGradientSamples depth samples
/// (the rendered ones, GradientSamplePoses() order, with their cells): the ±h_θ samples' deepest
/// cells c± are compared by their lever slopes s(c) = (r_c × ∂δ/∂x)·a (r_c the cell's centre less
/// the tool's centre of mass p_WT, m, W). Where s(c+) > 0 > s(c−) (a V) and the base sample's
/// deepest cell c0 bears like one of the arms (s(c0) within 10 % of that arm's: a sharp V, tilted
/// by h_θ the face still bears on the same edge), ∂δ/∂θ·a becomes s(c0): the secant of the
/// samples across the vertex reads the mean of the two arms, a tenth of the bearing edge's lever
/// on the fig75 block (docs/hard-cases.md). Fig. 75's torque error at q0 against the pipeline
/// truth: 18.8 % with it, 26.5 % with the secant. δ0 and ∂δ/∂x are never changed; nothing
/// changes where the samples lack cells or δ0 is not finite. noexcept, allocation-free.
void UseBearingEdgeRotationSlope(const ContactWindow& window, std::span<const DepthSample> samples,
                                 const glm::dvec3& p_WT, ContactLinearization& lin) noexcept;

/// Penalty wrench on the tool at its centre of mass, expressed in W, for depth δ and gradient J:
/// Φ = −k·max(δ, 0)·J (force N, torque N·m) [L]. Zero when δ ≤ 0 or δ is not finite.
Wrench PenaltyWrench(double depth_m, const PenetrationGradient& gradient,
                     double stiffness_n_per_m) noexcept;

/// Counters of numerical faults met while linearizing (MuJoCo-style: counted, never thrown).
struct LinearizationFaults {
  std::int64_t missing_overlap = 0;  ///< A perturbed evaluation had no overlapping cell.
};

/// Number of depth evaluations per contact for the gradient: the base pose and ± steps along u, v
/// (translation) and about u, v, n (rotation) [L][R].
inline constexpr int kGradientSamples = 11;

/// Step sizes of the central differences for `window`: h_x = W/N (m), h_θ = (W/N)/(W/2) (rad),
/// one grid-cell footprint at the patch border [R]; W in h_θ is window.gradient_extent_m where
/// that is set (stage 5a's split windows: their parent's).
struct GradientSteps {
  double h_x;      ///< Translation step along u and v (m).
  double h_theta;  ///< Rotation step about u, v and n (rad), about the tool's centre of mass.
  static GradientSteps For(const ContactWindow& window) noexcept {
    const double h_x = window.cell_size_m();
    return {h_x, h_x / (0.5 * window.gradient_lever_extent_m())};
  }
};

/// The kGradientSamples tool poses at which δ is evaluated, in this order: X_WT, then ±h_x along
/// u, ±h_x along v, ±h_θ about u, ±h_θ about v, ±h_θ about n (plus first), each applied with
/// Displace (world axes, about the tool's centre of mass). Both backends use this table.
std::array<RigidTransform, kGradientSamples> GradientSamplePoses(
    const RigidTransform& X_WT, const ContactWindow& window) noexcept;
/// The same table with the steps `steps` (h_x in m along u and v, h_θ in rad about u, v and n)
/// instead of the window's (the pipeline truth's fine tilt steps, ground_truth_depth.h).
std::array<RigidTransform, kGradientSamples> GradientSamplePoses(
    const RigidTransform& X_WT, const ContactWindow& window, const GradientSteps& steps) noexcept;

/// Builds the linearization from the kGradientSamples depths taken at GradientSamplePoses():
/// central differences, or one-sided ones (counted in `faults`) where a perturbed pose has no
/// overlapping cell; ∂δ/∂x_n = −1 exactly. Returns depth_m = −∞ when the base sample has no
/// overlap. `samples` must hold kGradientSamples entries.
ContactLinearization AssembleLinearization(const ContactWindow& window,
                                           std::span<const DepthSample> samples,
                                           double stiffness_n_per_m,
                                           LinearizationFaults& faults) noexcept;
/// The same with the samples taken at explicit steps: h_x (m) along u and v, h_tilt (rad) about u
/// and v, h_yaw (rad) about n (the pipeline truth's with a fine tilt step, ground_truth_depth.h).
ContactLinearization AssembleLinearization(const ContactWindow& window,
                                           std::span<const DepthSample> samples, double h_x,
                                           double h_tilt, double h_yaw, double stiffness_n_per_m,
                                           LinearizationFaults& faults) noexcept;

/// How the CPU texture stage renders. Both give the same δ and gradient within float
/// rounding (tests/texture_stage_parity_test.cc checks it on random contacts of all six seed
/// models).
enum class TextureStagePath {
  /// The reference: RenderPatchHeights, 11 tool renders per contact.
  kReference,
  /// RenderPatchHeightsFast; the four in-plane translation samples read one tool render on the
  /// window grown by a cell (the translation step is one cell, so they are exact shifts): 7 tool
  /// renders per contact.
  kFast,
};

/// Evaluates δ and its gradient for one contact, reusing preallocated height buffers: one
/// environment render and the tool at the 11 poses of GradientSamplePoses (base and ±h along u, v
/// and about u, v, n; see TextureStagePath for how many renders that takes); the derivative along
/// n is −1 exactly [L]. Step sizes: h_x = W/N, h_θ = (W/N)/(W/2) [R].
/// One region of a window's overlap (TexturePenetrationSolver::OverlapRegions): the cells where
/// b − a > 0 at the base pose, linked when closer than a distance; its bounding box in cells
/// (i along u, j along v, inclusive), its cell count and its largest b − a (m).
///
/// With a bridge floor (OverlapRegions' bridge_floor_m > 0) each region also carries its bridge
/// level: the highest level t ≤ 0 at which the cells with b − a > t, linked the same way, join it
/// to a deeper region (m; the saddle of the overlap's merge tree, by the elder rule), or −∞ where
/// they do not above −bridge_floor_m (and for the deepest). It is continuous in the pose, and it
/// reaches 0 as two regions touch and become one, which the regions' count is not.
struct OverlapRegion {
  int i0 = 0, i1 = -1, j0 = 0, j1 = -1;
  int cells = 0;
  double depth_m = 0.0;
  int peak_cell = -1;  ///< The cell (j·N + i) of depth_m.
  double bridge_m = -std::numeric_limits<double>::infinity();
};

class TexturePenetrationSolver {
 public:
  /// Preallocates buffers for windows of up to `max_resolution`² cells and models of up to
  /// `max_triangles` triangles (larger ones still work but allocate on first use).
  explicit TexturePenetrationSolver(int max_resolution = 128, int max_triangles = 4096,
                                    TextureStagePath path = TextureStagePath::kFast);

  TextureStagePath path() const noexcept { return path_; }

  /// kFast only: run a contact's tool renders (the grown base render and the six rotations) as
  /// parallel tasks of the oneTBB arena the caller is in (CpuPenetrationDepthBackend
  /// turns it on when it has more than one thread, so that a step with fewer contacts than threads
  /// still uses them all). Each render has its own buffer, so the results are the same either way.
  /// Must only be turned on for calls made inside a task arena sized as the caller wants.
  /// Turning it on reserves the six rotation buffers (allocates; call it at set-up).
  void set_parallel_renders(bool on) {
    parallel_renders_ = on;
    const auto cells = static_cast<std::size_t>(max_resolution_) * max_resolution_;
    if (on) {
      for (std::vector<float>& b : rotation_heights_) b.reserve(cells);
    }
  }

  /// kFast: when the six rotation samples are rendered culled
  /// (RenderToolDepth: the same depths and cells, fewer cells drawn).
  enum class CullRotations {
    kWhenItPays,  ///< the first rotation culled, the other five too when it drew few cells
                  ///< (kCullPaysFraction); with parallel renders, none (the rotations start
                  ///< with the base); the default
    kAlways,      ///< every rotation (with parallel renders, without a first cell)
    kNever,       ///< whole renders, as before the cull
  };
  void set_cull_rotations(CullRotations c) noexcept { cull_rotations_ = c; }
  /// Contacts whose six rotation renders were all culled (serial renders) since construction.
  std::uint64_t culled_contacts() const noexcept { return culled_contacts_; }

  /// Linearizes the contact of `tool` posed at X_WT (frame T at the tool's centre of mass) against
  /// `environment` posed at X_WO over `window`, with penalty stiffness k (N/m).
  /// Returns depth_m = −∞ and a zero gradient when the patches do not overlap on the window.
  /// When `samples_out` holds kGradientSamples entries, the raw depths are copied there.
  /// `environment_triangles` and
  /// `tool_triangles` restrict which coarse triangles of each side may be rendered (the contact's
  /// cluster's own; default: all, picked by the window alone).
  ///
  /// When `base_overlap_out` holds N² entries and both sides have surface on the window at the
  /// base pose (depth_m > −∞; negative where they are apart), the base pose's overlap field is
  /// written there: b − a per cell (m along the window normal, float,
  /// row-major j·N + i; −∞ where a side has no surface), the field OverlapRegions renders afresh,
  /// here from this call's own base render (under kFast the base on the window grown by a cell,
  /// whose inner N² cells are the window's; the tool's triangles picked with the gradient's
  /// margins, a superset of Depth's). Untouched otherwise.
  ContactLinearization Linearize(const HapticModel& tool, const RigidTransform& X_WT,
                                 const HapticModel& environment, const RigidTransform& X_WO,
                                 const ContactWindow& window, double stiffness_n_per_m,
                                 std::span<DepthSample> samples_out = {},
                                 TriangleSubset environment_triangles = TriangleSubset::All(),
                                 TriangleSubset tool_triangles = TriangleSubset::All(),
                                 std::span<float> base_overlap_out = {}) noexcept;

  /// δ only (m), at one tool pose; same conventions as Linearize (the triangle subsets too).
  DepthSample Depth(const HapticModel& tool, const RigidTransform& X_WT,
                    const HapticModel& environment, const RigidTransform& X_WO,
                    const ContactWindow& window,
                    TriangleSubset environment_triangles = TriangleSubset::All(),
                    TriangleSubset tool_triangles = TriangleSubset::All()) noexcept;

  /// The overlap of `tool` at X_WT and `environment` at X_WO on `window` (rendered afresh, the
  /// triangle subsets as Linearize takes them) split into regions: the cells where b − a > 0,
  /// two of them in one region when their centres are closer than `link_m` (m; single linkage,
  /// the granularity of contact clustering, contact_clustering.h). Writes the first out.size()
  /// regions in cell order, sorted deepest first, and returns how many there are (0: no
  /// overlap; at most 64 are counted). With `bridge_floor_m` > 0 and two regions or more, each
  /// region's bridge level too (OverlapRegion::bridge_m; a second union-find over the cells with
  /// b − a > −bridge_floor_m in decreasing order). Reserved at
  /// construction for windows up to the solver's max_resolution; never allocates there.
  int OverlapRegions(const HapticModel& tool, const RigidTransform& X_WT,
                     const HapticModel& environment, const RigidTransform& X_WO,
                     const ContactWindow& window, double link_m, std::span<OverlapRegion> out,
                     TriangleSubset environment_triangles = TriangleSubset::All(),
                     TriangleSubset tool_triangles = TriangleSubset::All(),
                     double bridge_floor_m = 0.0) noexcept;

  /// OverlapRegions on a given overlap field instead of a fresh render: `overlap` holds the
  /// window's N² values of b − a at the base pose (m, row-major j·N + i; ≤ 0 or −∞ where the
  /// patches do not overlap), as Linearize's `base_overlap_out` keeps them. The rendering overload
  /// is this one on its own render, so one field gives the same regions, order, depths and bridge
  /// levels either way. Returns 0 when `overlap` holds fewer than N² values, the window exceeds
  /// the solver's max_resolution, or link_m is negative or NaN. Never allocates within the
  /// reserve.
  int OverlapRegions(std::span<const float> overlap, const ContactWindow& window, double link_m,
                     std::span<OverlapRegion> out, double bridge_floor_m = 0.0) noexcept;

  /// The overlap of `tool` at X_WT and `environment` at X_WO on `window` (rendered afresh, the
  /// triangle subsets as Linearize takes them) as an occupancy of blocks of `block_cells` ×
  /// `block_cells` cells: `occupancy[bj · nb + bi]` = 1 where a cell of block (bi along u, bj along
  /// v) has b − a > 0, else 0, with nb = ceil(N / block_cells). Returns the number of occupied
  /// blocks (0: no overlap), or −1, writing nothing, when block_cells < 1, the window exceeds the
  /// solver's max_resolution, or `occupancy` holds fewer than nb² entries. Never allocates within
  /// the reserve (stage 5c of the remote step, remote_step.h).
  int OverlapOccupancy(const HapticModel& tool, const RigidTransform& X_WT,
                       const HapticModel& environment, const RigidTransform& X_WO,
                       const ContactWindow& window, int block_cells,
                       std::span<std::uint8_t> occupancy,
                       TriangleSubset environment_triangles = TriangleSubset::All(),
                       TriangleSubset tool_triangles = TriangleSubset::All()) noexcept;

  /// OverlapOccupancy on a given overlap field instead of a fresh render (`overlap`: the window's
  /// N² values of b − a at the base pose, m, row-major j·N + i, as Linearize's
  /// `base_overlap_out` keeps them; the rendering overload is this one on its own render).
  /// Returns −1, writing nothing, as that one does, and also when `overlap` holds fewer than N²
  /// values.
  int OverlapOccupancy(std::span<const float> overlap, const ContactWindow& window, int block_cells,
                       std::span<std::uint8_t> occupancy) const noexcept;

  const LinearizationFaults& faults() const noexcept { return faults_; }

 private:
  void RenderEnvironment(const HapticModel& environment, const RigidTransform& X_WO,
                         const ContactWindow& window,
                         TriangleSubset subset = TriangleSubset::All()) noexcept;
  DepthSample EvaluateTool(const HapticModel& tool, const RigidTransform& X_WT,
                           const ContactWindow& window) noexcept;
  /// kFast: the tool at X_WT on the window grown by one cell (tool_ext_heights_) and samples
  /// 0..4 (the base, ±h_x along u and v) read from it; `samples` holds ≥ 5 entries.
  void RenderGrownBase(const HapticModel& tool, const RigidTransform& X_WT,
                       const ContactWindow& window, std::span<DepthSample> samples) noexcept;
  /// kWhenItPays: the remaining five rotations are rendered whole when the first culled one drew
  /// more than this fraction of the window's cells. A culled render costs more per cell drawn
  /// (two passes, the bound's test, flushes that raise the lower bound), so where most cells stay
  /// it is the slower one.
  static constexpr double kCullPaysFraction = 0.3;
  /// Culled rotations use the environment's max pyramid when the tool brings more triangles than
  /// this.
  static constexpr std::size_t kPyramidTriangles = 32;

  TextureStagePath path_;
  CullRotations cull_rotations_ = CullRotations::kWhenItPays;
  std::uint64_t culled_contacts_ = 0;
  /// SelectPatchTriangles' per-vertex coordinates (reserved for max_triangles vertices).
  std::vector<double> vertex_scratch_;
  /// The triangles the first culled rotation drew around the deepest cell (up to 64), which the
  /// other five draw first.
  std::vector<int> first_triangles_;
  /// The environment render's max pyramid, for the culled rotation renders.
  EnvironmentMaxPyramid env_max_;
  /// Its row blocks, for the culled rotation renders' rows.
  EnvironmentRowMax env_row_max_;
  /// The tool triangles' levels and texture bounds, shared by a contact's culled rotation renders.
  TriangleBoundCache tool_bounds_;
  std::vector<float> env_heights_;
  std::vector<float> tool_heights_;
  /// The base pose on the window grown by a cell (kFast, and the base-render rotation gradients).
  std::vector<float> tool_ext_heights_;
  int max_resolution_ = 0;
  bool parallel_renders_ = false;
  /// kFast with parallel renders: one buffer per rotated pose (samples 5..10).
  std::array<std::vector<float>, 6> rotation_heights_;
  std::vector<int> env_triangles_;
  std::vector<int> tool_triangles_;
  /// OverlapRegions' single linkage (overlap_links.h): its cells' b − a, each cell's region
  /// (its first cell; −1 where no overlap), and the bridge level per peak cell.
  OverlapCellLinks links_;
  std::vector<float> overlap_depth_;
  std::vector<int> region_parent_;
  std::vector<float> bridge_level_;
  LinearizationFaults faults_;
};

}  // namespace ht
