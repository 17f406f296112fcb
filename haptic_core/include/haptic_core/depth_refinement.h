#pragma once
// Stage 5b of the remote step: the directional penetration depth refined from the
// N×N grid's cell samples to the finest texture level.
//
// Why. The grid samples each cell centre at the mip level whose texel matches the cell
// (HeightField::LevelForFootprint), a 2×2 box filter per level: a peak is first averaged (a mean
// is never above the maximum) and then missed between two centres, so δ reads low by tens of
// micrometres on the seed models (measured: docs/measurements.md), which at the runs' shallow
// presses is most of the force.
//
// How (our construction [R]; the depth is Otaduy & Lin's max over the window of b − a [L]):
//  - Seeds: the deepest cells of the base sample and of the four in-plane translation samples
//    (every backend reports them; a cell next to a seed is skipped), each the cell whose filtered
//    value is the largest, so that a level-0 peak the filter averaged lies within about a cell.
//    They are not a conservative screen: a level-0 peak under a cell whose filtered value is not
//    among them is not searched (tests/texture_stage_parity_test.cc: on random contacts of the
//    six seed models the refined δ0 is never below the grid's and is closer to the truth).
//    DepthRefinementOptions::conservative_screen (off by default) adds one after the seeds.
//    With parallax, each seed's cell carried by either side's h·N⊥ there is one more seed where
//    that moves it by more than half a cell: the grid is the render's form, which shows a tilted
//    facet's peak that far beside where it lies (fig77's product models: 1.2 mm, three cells).
//  - The refined deepest point of every contact of the previous step (BeginStep), kept in the
//    tool's frame T, is one more seed of each contact on the same environment model whose window
//    it falls in (a pattern search from the point, no sub-grid): a narrow peak whose filtered cell
//    is not among the grid's seeds is missed on some steps and found on the next (δ dips for
//    single steps; measured: docs/measurements.md). A seed only adds a candidate: δ0 is never
//    below the seeds-only value, and the result depends on the pose alone once the last step's
//    points are forgotten (ForgetLastStep). When it gives the deepest point, the ten displaced
//    samples are searched from there too.
//  - Neighbouring peaks: pattern searches from half a cell and a cell from the deepest point
//    along ±u and ±v (steps of two texels), each a seed. Beside a trough's vertex the other
//    flank's maximum lies in the cell next to the deepest's, which is never a seed of its own, so
//    δ0 would read the wrong flank, with a lateral slope of the wrong sign
//    (tests/depth_refinement_test.cc; measured: docs/measurements.md).
//  - At each seed, b − a is evaluated at level 0 (PatchHeightAt: the same coarse surface, normal
//    factor and box rule as the render, the texture sampled bilinearly at its full resolution) on
//    a sub-grid of about four texels' spacing over the seed's 1.5-cell square, then a pattern
//    search (u and v, first improvement, step halved down to search_floor_texels) climbs to the
//    local maximum. The deepest of the seeds is δ0 and its point the contact point.
//  - The ten rendered displaced samples are refined the same way from their own deepest cells
//    (a pattern search from the cell's centre), so that δ0, the
//    gradient and δ0 share one estimator.
//  - Gradient: the grid's one-cell central differences of the refined samples (h_x = W/N,
//    h_θ = h_x/(W/2)), a secant of the refined maximum; ∂δ/∂x_n = −1. Where another maximum takes
//    over within a cell (a face between two ridges' flanks: a V) the secant is the arms' mean,
//    which a depth field evaluated at the tool's pose resolves.
// PipelineOptions::refine_depth turns stage 5b on (the default); off is the grid alone, the
// reference path.

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "haptic_core/contact_linearization.h"
#include "haptic_core/haptic_model.h"
#include "haptic_core/penetration_depth.h"
#include "haptic_core/penetration_depth_backend.h"
#include "haptic_core/spatial.h"

namespace ht {

/// The height along the window's n (m, from the window plane through its centre) of the textured
/// surface of `model` posed at X_WO at the window point (s, t) (m along u and v from the window
/// centre), over the coarse triangles `triangles` (indices into model.triangles): the largest over
/// the triangles facing +n for kEnvironment, the smallest over those facing −n for kTool
/// (kPatchFacingThreshold), each the coarse height + h(uv)·(N·n) with N the interpolated unit
/// normal, as RenderPatchHeights writes per cell. `level` ≥ 0 samples that mip level (clamped to
/// the chain); −1 samples the level RenderPatchHeights uses for the window's cell
/// (LevelForFootprint), so that at a cell centre this is the reference render's value (a test
/// compares them). Heights with |height| > window.depth_range_m() are outside the window's box
/// and ignored. Returns −∞ (kEnvironment) or +∞ (kTool) where no triangle covers the point.
/// With `parallax` (level 0 only; DepthRefinementOptions::parallax) each triangle's value is
/// instead that of its displaced surface p + h(p)·N(p) where it crosses the line through (s, t)
/// along n (ParallaxValue in the .cc): the render's h·(N·n) at the coarse point under (s, t)
/// reads a point h·|N − (N·n)n| to the side of it, which on a coarse facet tilted from n under a
/// texture of large height is another part of the surface.
/// Never allocates, never throws.
double PatchHeightAt(const HapticModel& model, const RigidTransform& X_WO,
                     std::span<const int> triangles, const ContactWindow& window, PatchSide side,
                     double s_m, double t_m, int level = 0, bool parallax = false) noexcept;

/// How the depth is refined.
struct DepthRefinementOptions {
  /// Most sub-samples per side of a seed's square (its spacing is about two texels, at least one
  /// sample). In [1, 16].
  int max_subsamples = 6;
  /// The pattern search stops when its step falls below this many texels. > 0.
  double search_floor_texels = 0.25;
  /// The conservative screen of the base sample (off by default: it raises δ0 little at several
  /// times the texture stage's time; measured: docs/measurements.md): after the seeds, a branch and
  /// bound over the window finds every place where b − a can exceed the best found by more than
  /// screen_tolerance_m. A square's bound is the largest environment height over it minus the
  /// smallest tool height: per coarse triangle its linear height at the square's corners plus
  /// the texture's level-0 range under it (HeightField::RangeOver) times the normal factor's
  /// range, within the window's box. Squares whose bound cannot beat the best are dropped, the
  /// others split in four down to about two texels, where the local search runs. Off: the seeds
  /// alone (a level-0 peak under a cell whose filtered value is not among the deepest is missed).
  bool conservative_screen = false;
  /// Parallax: each height read where the displaced surface p + h(p)·N(p) crosses the line along
  /// n through the point (PatchHeightAt's `parallax`), found by damped fixed-point steps
  /// q ← (s, t) − h(q)·N⊥(q) on each coarse triangle (at most parallax_iterations, until the
  /// step is under a hundredth of a level-0 texel; a triangle whose steps leave it or do not settle
  /// holds no value there), instead of the render's h·(N·n) at the coarse point under (s, t).
  /// Where N ∥ n (flat coarse faces under the window: fig75, fig76) nothing changes. The grid
  /// (stage 5, the backend's render) still seeds the search with the render's form. Not with
  /// conservative_screen (its bounds are the render's form; Validate throws). On by default
  /// (measured: docs/measurements.md); off: the render's form (what the grid renders, and what the
  /// conservative screen bounds), which takes fewer evaluations where facets are tilted from n.
  bool parallax = true;
  /// Most fixed-point steps of the parallax per triangle and point; in [1, 64].
  int parallax_iterations = 12;
  /// How far above the best a dropped square's bound may reach (m). ≥ 0.
  double screen_tolerance_m = 1e-6;
  /// The screen looks for b − a above the larger of the best found and this (m): 0 looks for
  /// overlap only (a contact whose models do not overlap keeps the seeds' local maximum, which
  /// only the operator's contact model reads, as an onset distance). Finite.
  double screen_floor_m = 0.0;
  /// Most leaf squares the screen searches per contact; past it the screen stops and counts a
  /// truncation (DepthRefinementCounters::screen_truncated). ≥ 1.
  int max_screen_leaves = 4096;

  /// Throws std::invalid_argument naming a value out of range.
  void Validate() const;
};

/// What a DepthRefiner did since construction (for reports).
struct DepthRefinementCounters {
  std::uint64_t contacts = 0;     ///< Contacts refined.
  std::uint64_t seeds = 0;        ///< Base seeds searched.
  std::uint64_t evaluations = 0;  ///< Point evaluations of b − a (each two PatchHeightAt-like).
  std::uint64_t raised_um = 0;    ///< Σ (refined δ0 − sampled δ0), µm (rounded per contact).
  /// The conservative screen: squares bounded, leaves searched, contacts where it found a
  /// deeper point than the seeds (and Σ of how much deeper, µm), contacts it stopped at
  /// max_screen_leaves.
  std::uint64_t screen_squares = 0;
  std::uint64_t screen_leaves = 0;
  std::uint64_t screen_found = 0;
  std::uint64_t screen_raised_um = 0;
  std::uint64_t screen_truncated = 0;
  /// The seeds carried by parallax: points searched, and contacts where one gave the deepest point
  /// (and Σ of how much deeper, µm).
  std::uint64_t parallax_offset_seeds = 0;
  std::uint64_t parallax_offset_found = 0;
  std::uint64_t parallax_offset_raised_um = 0;
  /// The last step's seeds: searched, and contacts where
  /// one gave a deeper point than the grid's seeds (and Σ of how much deeper, µm).
  std::uint64_t last_step_seeds = 0;
  std::uint64_t last_step_found = 0;
  std::uint64_t last_step_raised_um = 0;
  /// The neighbouring peaks: searches, and contacts where a neighbouring
  /// peak was deeper than the seeds' best (and Σ of how much deeper, µm).
  std::uint64_t neighbour_peak_seeds = 0;
  std::uint64_t neighbour_peak_found = 0;
  std::uint64_t neighbour_peak_raised_um = 0;
};

/// Refines the linearizations of a texture stage's batch to the finest texture level (see the
/// header comment). One per thread; preallocates at construction and never allocates in Refine
/// (unless a window holds more coarse triangles, or more cells a side, than reserved).
class DepthRefiner {
 public:
  /// Reserves for windows of up to `max_triangles` coarse triangles per side. Throws
  /// std::invalid_argument for bad options.
  explicit DepthRefiner(const DepthRefinementOptions& options = {},
                        std::size_t max_triangles = 8192);

  /// Refines one contact that a backend linearized: `query` as the backend got it (the
  /// environment, its pose, the window, the triangle subsets), the tool posed at X_WT (frame T at
  /// its centre of mass), `samples` its kGradientSamples rendered samples (GradientSamplePoses
  /// order; their depths are replaced by the refined ones, cells kept except the base's, which
  /// becomes the cell holding the refined point), and `lin` the backend's linearization: its δ0,
  /// point and gradient are replaced (stiffness and normal kept). Returns false, changing
  /// nothing, when the base sample has no overlap or the refinement finds none. noexcept.
  bool Refine(const HapticModel& tool, const RigidTransform& X_WT, const ContactQuery& query,
              std::span<DepthSample> samples, ContactLinearization& lin) noexcept;

  const DepthRefinementCounters& counters() const noexcept { return counters_; }
  const DepthRefinementOptions& options() const noexcept { return options_; }
  /// The last step's seeds: the deepest points of the contacts refined
  /// since the last call become the seeds of the contacts refined from now on (at most
  /// kMaxLastStepSeeds, the first ones kept), and the buffer for this step's starts empty. Call
  /// once per step before its contacts. noexcept, allocation-free.
  void BeginStep() noexcept;
  /// Forgets the last step's points and this step's so far: the next contacts have their grid's
  /// seeds alone, as a first step (e.g. before a pose that does not follow the last one).
  void ForgetLastStep() noexcept { num_last_ = num_next_ = 0; }
  /// Most points kept from one step.
  static constexpr int kMaxLastStepSeeds = 16;

  /// One coarse triangle projected on a window at one pose (internal; public for the .cc's
  /// helpers): corners along u, v and n (m), the normal factors N_c·n, texture coordinates, the
  /// corner normals' cosines, and its bounding box on the window plane.
  struct Projected {
    double x[3], y[3], d[3], nn[3];
    // The corner normals' components along u and v (parallax only) and the bound of the
    // displaced surface's lateral reach (m) that widened the box.
    double nu[3], nv[3];
    double reach;
    // The projection's altitude over each corner (m), for the reach test.
    double altitude[3];
    bool parallax;
    double inv_area;
    float tu[3], tv[3];
    double cos01, cos02, cos12;
    double x0, x1, y0, y1;
    double texel_m;
    int face;
    bool textured;
  };

 private:
  struct Seed {
    double depth_m, s, t;
  };
  // A square on the window plane (m along u and v) that a search stays in.
  struct Box {
    double s0, s1, t0, t1;
  };
  // The finer level-0 texel (m) of env_local_ and `tool_tris` (a quarter cell where neither is
  // textured: a smooth coarse surface is linear inside its triangles).
  double TexelOfGathered(std::span<const Projected> tool_tris) const noexcept;
  // The triangles of `list` facing the side's way, projected on the window at pose X.
  void ProjectAll(const HapticModel& model, const RigidTransform& X, PatchSide side,
                  std::span<const int> list, std::vector<Projected>& out) noexcept;
  // The environment's projected triangles over a box (env_local_, from env_all_), and the tool's
  // (tool_local_, from `from`).
  void GatherEnvironment(double s0, double s1, double t0, double t1) noexcept;
  void GatherTool(std::span<const Projected> from, double s0, double s1, double t0,
                  double t1) noexcept;
  // b − a at (s, t) at level 0, the tool's heights read at (s − shift_s, t − shift_t); −∞ where
  // either side is missing.
  double Difference(std::span<const Projected> tool, double s, double t, double shift_s,
                    double shift_t) noexcept;
  // The best of a sub-grid of `subsamples`² points over the square of half side `half_side`
  // around (s, t) (the point alone for 1; where that reads nothing, the first of its four
  // neighbours that does, from max(floor_m, step/64) doubling up to `step`), then a pattern search
  // from it with `step` halved down to `floor_m`, staying in `box`.
  Seed Search(std::span<const Projected> tool, const Box& box, double s, double t, double half_side,
              int subsamples, double step, double floor_m, double shift_s, double shift_t) noexcept;

  // The conservative screen (DepthRefinementOptions::conservative_screen): the bound of one
  // side's triangles `list` (indices into `all`) over a square (the environment's largest height,
  // −∞ without one; the tool's smallest, +∞ without one), the squares' branch and bound from
  // `depth` with the triangles of the square in env_screen_[depth] / tool_screen_[depth].
  double SideBound(std::span<const Projected> all, std::span<const int> list,
                   const HeightField& texture, bool environment, const Box& square) const noexcept;
  double ScreenThreshold(double best_m) const noexcept;
  void ScreenSquare(const Box& square, int depth, Seed& best, int& leaves) noexcept;
  void Screen(Seed& best) noexcept;

  DepthRefinementOptions options_;
  DepthRefinementCounters counters_;
  // Per depth of the screen's quadtree: the triangles (indices into env_all_ / tool_all_)
  // overlapping the square at that depth.
  static constexpr int kMaxScreenDepth = 24;
  std::array<std::vector<int>, kMaxScreenDepth + 1> env_screen_, tool_screen_;
  std::uint64_t squares_ = 0;
  bool truncated_ = false;
  std::vector<int> env_list_, tool_list_;
  std::vector<double> vertex_scratch_;
  // The window's triangles projected once per contact (the tool at the base pose, and at one
  // rendered rotation at a time), and those near the point being searched.
  std::vector<Projected> env_all_, tool_all_, tool_pose_all_;
  std::vector<Projected> env_local_, tool_local_;
  // Set per contact.
  const HapticModel* env_ = nullptr;
  const HapticModel* tool_ = nullptr;
  RigidTransform X_WO_;
  ContactWindow window_;
  std::uint64_t evaluations_ = 0;
  // The last step's seeds: its deepest points (p_T in the tool's
  // frame, with their environment model) and this step's so far.
  struct LastStepPoint {
    const HapticModel* environment;
    glm::dvec3 p_T;
  };
  std::array<LastStepPoint, kMaxLastStepSeeds> last_{}, next_{};
  int num_last_ = 0, num_next_ = 0;
  // This contact's neighbouring peaks.
  static constexpr int kMaxNeighbourPeaks = 8;
  std::array<Seed, kMaxNeighbourPeaks> neighbour_peaks_{};
  int num_neighbour_peaks_ = 0;
};

}  // namespace ht
