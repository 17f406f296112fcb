#pragma once
// The remote step: the remote node's pipeline from a tool pose to a contact model, as a list of
// named stages (see HapticTexturePipeline below, and src/remote_step/, a file per stage).

#include <cmath>
#include <cstdint>
#include <memory>
#include <span>
#include <string>

#include "haptic_core/contact_linearization.h"
#include "haptic_core/contact_model.h"
#include "haptic_core/contact_windows.h"
#include "haptic_core/depth_field.h"
#include "haptic_core/depth_refinement.h"
#include "haptic_core/haptic_scene.h"
#include "haptic_core/penetration_depth_backend.h"

namespace ht {

/// The default largest window side as a multiple of the window side W
/// (PipelineOptions::max_window_extent_m; slave_sim applies it to a --window given alone).
inline constexpr double kDefaultMaxWindowPerWindow = 3.0;

struct RemoteStepModel;  // src/remote_step/0_remote_step_data.h: what the step derives
struct RemoteStepData;   // and what it writes

/// Contact clustering's normal angle (degrees): leaf pairs (and clusters) whose normals differ by
/// less than this merge into one contact, and stage 5c links contacts within it. On curved and
/// thin coarse hulls (the file on the CAD part) the hull pairs of one contact region carry normals
/// 30–60° apart, so at 30° one region makes several windows, and a tool leaf and the object leaf
/// it overlaps could land in different windows and be rendered in none (measured:
/// docs/measurements.md). Faces 90° apart (an L corner) stay apart.
inline constexpr double kClusteringAngleDeg = 60.0;

/// Options of the per-step pipeline. The coarse stages always:
///  - drop separated leaf pairs farther apart than their two leaves' own outward texture reach
///    (HullBounds::reach_m): they cannot touch through the textures and would only add windows
///    without overlap (unless speculative, below);
///  - size each window to its cluster's extent (between window_extent_m and max_window_extent_m,
///    N scaled to keep the cell), and centre a window whose cluster is the single pair of two
///    whole convex models (the procedural scenes: a block resting on a gear) on the pair's contact
///    region (PairRegionBounds, contact_region.h), sized to it plus the texture margin, not at the
///    hulls' witness point, which on parallel faces is a corner (docs/hard-cases.md);
///  - render in each contact only its cluster's own coarse triangles (ContactCluster::
///    tool_triangles, object_triangles: each leaf goes to its deepest pair's cluster, and to each
///    further cluster whose window is disjoint from those holding it), so that two windows on one
///    contact region do not both count its penetration; a side without hierarchy, or a step whose
///    lists overflow the pipeline's storage, picks by window;
///  - drop and count (StepFaults::grazing_dropped) a contact whose δ0 exceeds what its coarse
///    geometry allows: the largest over the cluster's hull pairs of the pair's penetration + its
///    two leaves' own outward texture reach + a cell (the grazing guard). Along a direction nearly
///    parallel to the surfaces the patches are no height fields and δ measures the sideways
///    overlap, bounded only by the window's box (DESIGN.md §4, docs/hard-cases.md).
/// The texture stages always, with the CPU backend:
///  - stage 5a: a window whose overlap at the tool's pose falls into regions farther apart than
///    10 mm (TexturePenetrationSolver::OverlapRegions, on stage 5's base render) keeps its whole
///    window for its deepest region, and each other region gets a window of its own (the
///    region's box plus 1 mm a side at the parent's cell size and rotation step, linearized
///    afresh), pushing with k·w, w = smoothstep(d_r / min(400 µm, d_max)) ·
///    smoothstep(−t / 400 µm): d_r the region's deepest cell sample of b − a, d_max the window's,
///    t its bridge level (OverlapRegion::bridge_m, ≤ 0: where it joins a deeper region). A region
///    fades in as it first overlaps and out as it joins a deeper one, so the force does not step
///    when the count of regions flips (an edge resting on stripes along its length); a region
///    whose weight is below 10⁻³ gets no window, and a window whose regions would take the step
///    past max_contacts stays whole (measured: docs/measurements.md). The GPU backend takes one
///    window size per batch: there the step runs without it;
///  - stage 5c: contacts on one object whose normals agree within kClusteringAngleDeg and whose
///    textured overlaps at the tool's pose come within 10 mm of each other (fading out over 5 mm
///    more) are one region and share one penalty (ShareConnectedContacts, connected_contacts.h,
///    at ContactSharingOptions' defaults): each keeps its δ, J and field, and its stiffness
///    becomes k·s_i, so that a region pushes with about its deepest contact's k·δ, as the
///    pipeline truth's one patch does (contact_patch_truth.h). The coarse clustering leaves such
///    contacts apart where their merged window would exceed max_window_extent_m (the hammer's
///    face on the torus: two windows, each reading the whole δ). Only contacts with δ0 > 0 that
///    have such a neighbour within reach of their windows are rendered again, so a step with one
///    contact per object pays nothing (measured: docs/measurements.md);
///  - stages 5a and 5c read the base pose's overlap (b − a per cell) from stage 5's own render
///    where the backend keeps it (PenetrationDepthBackend::base_overlap: the CPU backend), and
///    render it again elsewhere.
struct PipelineOptions {
  int grid_resolution = 50;  ///< N of the penetration-depth grid (seed: 50).
  /// W of each contact window (m): the smallest side, with the grid's N. A cluster whose members
  /// spread further gets a window sized to them (up to max_window_extent_m) at the same cell W/N.
  double window_extent_m = 0.02;
  /// Largest window side (m), ≥ window_extent_m; windows whose normals agree and overlap merge
  /// while the merged window fits it (contact clustering's pass 2), so that one contact region
  /// (a hammer's face along a torus) gets one window instead of several overlapping ones of which
  /// only one holds the region's leaves. The default is kDefaultMaxWindowPerWindow × the default
  /// window_extent_m (6 cm; measured: docs/measurements.md). Equal to window_extent_m: every
  /// window W×W.
  double max_window_extent_m = 0.06;
  double proximity_margin_m = 0.5e-3;  ///< Extra coarse tolerance beyond both texture reaches (m).
  /// Time budget of the coarse query per tool–object pair (µs; 0 = none): most important node
  /// pairs first, the step reports when it stopped early.
  double collision_budget_us = 0.0;
  /// Contact clustering (DESIGN.md §3): leaf pairs whose points are closer than this (m) and whose
  /// normals differ by less than kClusteringAngleDeg merge into one contact.
  double clustering_distance_m = 5e-3;
  /// Most contacts per step (1..kMaxContacts): clustering merges the shallowest clusters beyond
  /// it into the nearest kept ones (ClusteringOptions::max_contacts). The seed reports up to 7 on
  /// its Fig. 77 scene.
  int max_contacts = kMaxContacts;
  /// Threads of the CPU texture stage (the contacts of a step spread over them, oneTBB), and of
  /// the coarse query's traversal (HullProximityQuery::SetThreads: the same pairs); ≥ 1.
  /// The remote node's default leaves one core to the operator on a loopback machine
  /// (DefaultTextureThreads()).
  int texture_threads = 1;
  /// Stage 5b: δ refined from the grid's cell samples to the finest texture level
  /// (DepthRefiner, depth_refinement.h), after either backend. On: δ to the finest level, and a
  /// lower force error (measured: docs/measurements.md). Off (`slave_sim --no-refine-depth`, the
  /// frontier's "grid_only"): the grid's cell samples, the reference for parity. With
  /// depth_fields the stage does not run: each contact's δ and gradient are its field's (5d).
  bool refine_depth = true;
  /// How stage 5b refines (steps, sub-samples, search floor).
  DepthRefinementOptions depth_refinement;
  /// Speculative contacts (a lead time, s; 0 = off): a separated leaf pair farther apart than
  /// its local texture reach is kept (not dropped as unreachable) when the tool's
  /// twist given to Step closes it within this time, i.e. when
  ///   signed distance ≤ reach + min(max_speculative_margin_m, lead · closing speed),
  /// closing speed = −(v + ω × (p_A − p_WT))·n at the pair's tool witness point p_A (m/s, W).
  /// The contact it starts has δ0 < 0 (separated) and pushes with nothing until the operator's
  /// tool closes the gap on its local model: the surface is in the model before the tool
  /// reaches it, however late the model. Without it a model made a few milliseconds before an
  /// impact has no contact, the tool goes into the surface with no force until the next model,
  /// and that model's spring gives back more energy than the press took (DESIGN.md §5; measured:
  /// docs/measurements.md). A tool at rest or sliding along a surface (no closing speed) gets the
  /// contacts it got before.
  double speculative_lead_s = 0.05;
  /// Most speculative margin (m) beyond the texture reach, whatever the speed.
  double max_speculative_margin_m = 2e-3;
  /// The speculative margin's floor (m; 0: none, ≥ 0): on an object the tool does not touch yet
  /// (no leaf pair within its texture reach), a separated leaf pair within its reach plus this is
  /// kept whatever the tool's twist, so that a model answering a tool pose a round trip old still
  /// holds the surfaces the hand can reach meanwhile: a hand that lifts and presses again, or
  /// turns towards a surface after the pose was taken, finds the surface in its local model
  /// instead of a round trip later, 1-2 mm inside it (measured: docs/measurements.md). Beside a
  /// touching pair it adds nothing (the pair would only join its cluster). The remote node sets it
  /// from the operator's round trip (SetSpeculativeFloor,
  /// RemoteNodeConfig::speculative_speed_m_per_s).
  double speculative_floor_m = 0.0;

  /// Stage 5d: each contact of the model also carries its depth field (depth_field.h), the two
  /// surfaces over its window grown by depth_field_margin_m on each side (rounded up to cells,
  /// and cut to what fits kMaxDepthFieldSide nodes a side), which the operator's loop evaluates
  /// at the tool's pose every tick. The contact's linearization stays, as the loop's fallback
  /// where it lacks the field. HapticTexturePipeline::last_depth_fields() holds them after the
  /// step.
  bool depth_fields = false;
  /// The travel margin (m, ≥ 0): how far the tool may move from q0 before a field no longer
  /// holds. The remote node sets it from the operator's round trip (SetDepthFieldMargin).
  double depth_field_margin_m = 2e-3;
  /// Nodes per window cell along each axis (1..4): the fields are rendered on the window's grid
  /// refined this many times (and the textures sampled at that finer cell's mip level), so that
  /// the operator's bicubic between nodes follows ridges a few cells wide. The margin is cut
  /// before the cell is made coarser: lowered, down to 1, only where the refined grid would
  /// exceed kMaxDepthFieldSide with a margin of 2 mm (or depth_field_margin_m, if less).
  int depth_field_subdivision = 2;
  /// The fields' smooth-maximum width ε (m, > 0; DepthField::smooth_max_m).
  double depth_field_smooth_max_m = kDepthFieldSmoothMaxM;
  /// The force law the fields are evaluated with (ForceLaw; a contact without a field, and every
  /// contact without depth_fields, keeps the seed's law on its linearization), and the pressure
  /// law's k_p (N/m³, ≥ 0): 0 gives each contact k / A_tool, A_tool the largest face of the tool's
  /// bounding box in its own frame (ToolContactArea), so that a flat face of the tool pressed
  /// into a flat plate feels the seed law's k.
  ForceLaw force_law = ForceLaw::kSeed;
  double pressure_stiffness_n_per_m3 = 0.0;

  /// Throws std::invalid_argument naming a value out of range.
  void Validate() const;
  /// The largest grid N a window of these options can have: ceil(N · max_window_extent_m /
  /// window_extent_m), at most 1024 (size the penetration-depth backend with it).
  int max_window_resolution() const noexcept;
};

/// Texture threads that leave one core free: hardware threads − 1, at least 1, at most 16.
int DefaultTextureThreads() noexcept;

/// Per-step timings and counts (µs), for traces and summaries (seed Fig. 77 splits these).
struct StepTimings {
  double collision_us = 0.0;
  double texture_us = 0.0;
  double total_us = 0.0;
  /// Tool–object pairs queried by the hierarchy query (those the broad phase let through).
  int convex_pairs = 0;
  /// Tool–object pairs the broad phase (bounding spheres) ruled out.
  int broad_phase_culled = 0;
  /// Leaf hull pairs found within tolerance, and contacts after clustering (before the cap of
  /// PipelineOptions::max_contacts per step).
  int leaf_pairs = 0;
  int clusters = 0;
  /// True when a coarse query stopped at options.collision_budget_us.
  bool collision_budget_exhausted = false;
  /// Free space (m): when the broad phase ruled out every object, how far any tool point can
  /// move (HapticTexturePipeline::ToolMotionBound) before a step could find a pair: the smallest
  /// bounding-sphere gap less the coarse query's largest tolerance (reaches, proximity margin and
  /// the speculative margin at its cap, whatever the speed). 0 when any object passed the broad
  /// phase; +∞ without touchables. A step at a pose that moved less than this gives the same
  /// empty model (the remote node waits instead), while the objects stay still.
  double free_space_clearance_m = 0.0;
};

/// The remote step (DESIGN.md §1): the remote node's per-step pipeline from a tool pose to a
/// contact model. Its stages, in order, each in the file named after it:
///  1. broad phase (broad_phase.h): root bounding spheres rule out far tool–object pairs;
///  2. hull proximity (hull_proximity.h): the coarse query between the tool's and each object's
///     convex-hull hierarchies (a model without a hierarchy is one hull) gives leaf hull pairs;
///  3. contact clustering (contact_clustering.h): leaf pairs merge into at most kMaxContacts
///     clusters, each a point and a normal;
///  4. contact windows (contact_windows.h): one ContactQuery per cluster;
///  5. texture penetration depth and linearization (penetration_depth_backend.h, one batch for
///     all contacts; the GPU backend falls back to the CPU backend if it fails), then the grazing
///     guard (contact_windows.h: DropGrazingContacts);
///  6. assembly (contact_assembly.h): the contact model and its wrench at q0.
/// With depth fields (PipelineOptions::depth_fields), stage 5d also linearizes each contact that
/// has a field from it (δ0 and J the field's δ and ∇δ at q0, the tangent of what the operator
/// evaluates), and a step whose stage-4 contacts are the last full step's, each still held by the
/// kept field stage 5d would give it, skips stages 5–5d: its contacts are that step's (stage 5a's
/// split windows and 5c's shares included, held while the fields hold), linearized from their
/// fields at the new pose (StepFaults::steps_from_kept_fields).
/// Nothing in it throws after construction (faults are counted), and after warm-up it does not
/// allocate. Holds preallocated scratch; not thread-safe, and must be stepped on the thread that
/// created its penetration-depth backend (a GL context is current there).
class HapticTexturePipeline {
 public:
  /// Keeps a reference to `scene`, which must outlive the pipeline. `backend` computes the
  /// penetration depth (null: the CPU backend, fast path, texture_threads threads); the
  /// constructor hands it the scene (PenetrationDepthBackend::UseScene: the GPU backend uploads
  /// the scene's models then). Builds the step's constant model (the coarse bounds, box trees and
  /// whole hulls of the scene's models) and its data block. Throws std::invalid_argument for bad
  /// options, a scene without a tool or with an empty touchable, or a tool whose centre of mass
  /// is not T's origin; what UseScene throws (GpuError for a failed upload); std::bad_alloc. A
  /// constructor that throws destroys `backend`.
  HapticTexturePipeline(const HapticScene& scene, const PipelineOptions& options,
                        std::unique_ptr<PenetrationDepthBackend> backend = nullptr);
  ~HapticTexturePipeline();
  /// Takes `other`'s model, data and backends; `other` may then only be destroyed.
  HapticTexturePipeline(HapticTexturePipeline&& other) noexcept;
  HapticTexturePipeline(const HapticTexturePipeline&) = delete;
  HapticTexturePipeline& operator=(const HapticTexturePipeline&) = delete;

  /// Builds the contact model at tool pose X_WT (q0), tagging it with `tool_state_seq`.
  /// A non-finite pose gives an empty model. Fills `timings`. `V_WT_W` is the tool's twist
  /// (linear velocity of T's origin, m/s, and angular velocity, rad/s, both along W), for the
  /// speculative contacts (PipelineOptions::speculative_lead_s); zero (a tool at rest) or
  /// non-finite gives none.
  /// Nothing throws, and after a warm-up over the scene's contact counts nothing allocates,
  /// through any allocator (remote_step_alloc_test, on the block on the gear and on the seed's
  /// hull hierarchies): the step writes its data block (RemoteStepData, preallocated at
  /// construction, with the stage objects in it), its backend and, when the backend fails, the
  /// fallback's count and reason (reserved) and the switch to the CPU backend built with the
  /// pipeline.
  ContactModel Step(const RigidTransform& X_WT, std::uint64_t tool_state_seq, StepTimings& timings,
                    const Twist& V_WT_W = {}) noexcept;

  /// The most any point of the tool's bounding sphere moves (m) between the tool poses X_WT_a and
  /// X_WT_b (W): |Δ centre| + 2·sin(θ/2)·r, θ the rotation between them. Compare it with
  /// StepTimings::free_space_clearance_m. Non-finite poses give +∞.
  double ToolMotionBound(const RigidTransform& X_WT_a, const RigidTransform& X_WT_b) const noexcept;

  /// Faults of the backend in use.
  const LinearizationFaults& faults() const noexcept { return backend_->faults(); }
  /// Faults of the step's own stages (counted, never thrown).
  struct StepFaults {
    /// Clusters whose window could not be set up (non-finite point, zero normal), and stage 5a
    /// regions whose window could not: skipped.
    std::int64_t bad_windows = 0;
    /// Contacts dropped by the grazing guard (PipelineOptions).
    std::int64_t grazing_dropped = 0;
    /// Separated leaf pairs beyond their local texture reach, left out of clustering
    /// (PipelineOptions).
    std::int64_t unreachable_pairs = 0;
    /// Separated leaf pairs beyond their local texture reach kept because the tool closes them
    /// within the lead time (PipelineOptions::speculative_lead_s); not a fault, a count.
    std::int64_t speculative_pairs = 0;
    /// Contact sides whose cluster's triangle list did not fit the pipeline's storage and were
    /// picked by window instead (PipelineOptions).
    std::int64_t triangle_lists_overflowed = 0;
    /// Windows centred on and sized from the contact region of two whole models
    /// (PipelineOptions); not a fault, a count.
    std::int64_t region_windows = 0;
    /// Contacts whose penalty stage 5c shared with a linked contact
    /// (stage 5c, PipelineOptions); not a fault, a count.
    std::int64_t shared_contacts = 0;
    /// Steps whose contacts were the last full step's, linearized from their kept depth fields
    /// at the step's pose, with stages 5–5d skipped (PipelineOptions::depth_fields); not a
    /// fault, a count.
    std::int64_t steps_from_kept_fields = 0;
  };
  const StepFaults& step_faults() const noexcept;
  /// The backend in use: the one given, or the CPU backend after that one failed.
  const PenetrationDepthBackend& backend() const noexcept { return *backend_; }
  /// Gives up the backend in use (for a pipeline built on a new scene, e.g. after the scene file
  /// changed: the GPU backend keeps its context and its uploaded textures). The pipeline must not
  /// be stepped afterwards.
  std::unique_ptr<PenetrationDepthBackend> ReleaseBackend() noexcept { return std::move(backend_); }
  /// Batches the given backend failed (the step is then recomputed on the CPU, which stays in
  /// use), and the reason of the first failure ("" when none).
  std::int64_t backend_failures() const noexcept { return backend_failures_; }
  const std::string& fallback_reason() const noexcept { return fallback_reason_; }

  /// The contacts of the last Step() before the texture stage dropped any: one query per cluster
  /// (object, its pose X_WO, window, stiffness), in the order they were linearized; after a step
  /// from kept fields, the last full step's (their triangle subsets All()). Valid until the next
  /// Step(). For accuracy studies (the speed-vs-error frontier recomputes each window's
  /// ground truth); the step itself does not need them.
  std::span<const ContactQuery> last_contact_queries() const noexcept;
  /// The linearization of each of last_contact_queries() (depth_m = −∞ where the patches did not
  /// overlap on the window, so that the step left that contact out of its model).
  std::span<const ContactLinearization> last_linearizations() const noexcept;
  /// The kGradientSamples depth samples of each of last_contact_queries() (query-major,
  /// GradientSamplePoses() order), as stage 5b left them (refined where PipelineOptions::
  /// refine_depth is on and depth_fields off); a step from kept fields takes none (the last full
  /// step's stay). Valid until the next Step().
  std::span<const DepthSample> last_depth_samples() const noexcept;
  /// What stage 5b did since construction.
  const DepthRefinementCounters& depth_refinement_counters() const noexcept;
  /// PipelineOptions::speculative_floor_m (m) from the next Step() on; a negative or non-finite
  /// value is taken as 0. The remote node sets it from the operator's round trip. noexcept.
  void SetSpeculativeFloor(double floor_m) noexcept {
    options_.speculative_floor_m = std::isfinite(floor_m) && floor_m > 0.0 ? floor_m : 0.0;
  }
  /// PipelineOptions::depth_field_margin_m (m) from the next Step() on; a negative or
  /// non-finite value is taken as 0. noexcept.
  void SetDepthFieldMargin(double margin_m) noexcept {
    options_.depth_field_margin_m = std::isfinite(margin_m) && margin_m > 0.0 ? margin_m : 0.0;
  }
  /// PipelineOptions::depth_fields from the next Step() on (the remote node turns it on for a
  /// session whose operator takes depth fields). Turning it on reserves the fields' buffers
  /// (allocates) where the options at construction did not.
  void SetDepthFields(bool on);
  /// Whether the next Step() renders depth fields (PipelineOptions::depth_fields).
  bool depth_fields() const noexcept { return options_.depth_fields; }
  /// The depth fields of the last Step()'s model (PipelineOptions::depth_fields), the field of
  /// each contact that refers to one (ContactLinearization::depth_field_id): rendered at this
  /// step, or kept from an earlier one (the same id and bits) while it still holds the contact.
  /// A sender sends only the ids its receiver lacks. Valid until the next Step().
  std::span<const DepthField* const> last_depth_fields() const noexcept;
  /// Every depth field the pipeline keeps (rendered at this or an earlier step and not yet
  /// replaced; entries not prepared hold none), for evaluating a model sent earlier whose fields
  /// the receiver holds (ContactModelDeadband::Decide). Valid until the next Step().
  std::span<const DepthField* const> kept_depth_fields() const noexcept;
  /// The floor the next Step() uses (m).
  double speculative_floor_m() const noexcept { return options_.speculative_floor_m; }
  /// Stage 5b's seeds from the last step (depth_refinement.h) forgotten:
  /// the next step's contacts start from their grid alone, as after construction (for a pose that
  /// does not follow the last one, e.g. the frontier's spread poses). noexcept.
  void ForgetLastStep() noexcept;

 private:
  /// Stages 1–3 for every touchable: appends to the data's candidates (up to kMaxContacts) and
  /// fills the coarse counts and flags of `timings`.
  void FindContactCandidates(const RigidTransform& X_WT, const Twist& V_WT_W,
                             StepTimings& timings) noexcept;
  /// Stages 5–5d on the data's last_queries[0, last_num_queries) (stage 4's) at tool pose X_WT (W,
  /// T at the tool's centre of mass): linearization, 5a's split, 5b's refinement (without depth
  /// fields), the bearing edge's slope, the grazing guard, 5c's shares and 5d's depth fields
  /// (recording the step for TakeStepFromKeptFields); leaves last_queries, last_results and
  /// last_num_queries for stage 6.
  void RunTextureStages(const RigidTransform& X_WT) noexcept;
  /// Stage 5: linearizes the data's last_queries[0, n) into last_results with the backend in use
  /// (the GPU backend takes one window size per batch: windows sized from their clusters go to it
  /// in one batch per size); when that backend fails, switches to the CPU backend for good and
  /// recomputes the batch.
  void LinearizeContacts(const RigidTransform& X_WT, int n) noexcept;
  /// Stage 5a (PipelineOptions): adds, for each linearized window of last_queries[0, n) whose
  /// overlap is in separated regions, one window per region other than its deepest (at the end
  /// of the batch), and linearizes those; returns the new count. CPU backend only.
  int SplitSeparatedOverlap(const RigidTransform& X_WT, int n) noexcept;
  /// Moves `point_W` to the centre of the contact region of the tool and touchable `k`, both
  /// whole convex models, on the window axes of `normal_W`, and sets `extent_m` to the region's
  /// larger side plus 2·texture_margin_m; leaves both unchanged when a model has no hull or the
  /// region is empty.
  void RegionWindow(const RigidTransform& X_WT, std::size_t k, const glm::dvec3& normal_W,
                    double texture_margin_m, glm::dvec3& point_W, double& extent_m) noexcept;
  /// Stage 5c: shares the penalty of contacts [0, n) whose overlaps are one region
  /// (PipelineOptions). Allocation-free.
  void ShareConnectedContacts(const RigidTransform& X_WT, int n) noexcept;
  /// The CPU backend of these options (fast path, texture_threads threads).
  std::unique_ptr<PenetrationDepthBackend> MakeCpuBackend() const;
  /// Whether stages 5a and 5c read stage 5's render: the backend keeps it (the CPU's).
  bool ReusesBaseRender() const noexcept;
  /// The largest window whose field is kept: max_window_resolution() (150 at the defaults), at
  /// most kMaxKeptFieldResolution (3.7 MB of fields in the backend and as much in the data;
  /// larger windows, from grids or windows far past the defaults, are rendered again).
  int KeptFieldResolution() const noexcept;
  static constexpr int kMaxKeptFieldResolution = 256;

  const HapticScene& scene_;
  PipelineOptions options_;
  /// What the step derives from the scene, built at construction, constant afterwards
  /// (src/remote_step/0_remote_step_data.h).
  std::unique_ptr<const RemoteStepModel> model_;
  /// Everything the step writes, preallocated at construction (0_remote_step_data.h).
  std::unique_ptr<RemoteStepData> data_;
  std::unique_ptr<PenetrationDepthBackend> backend_;
  /// The CPU backend a backend other than the CPU's falls back on, built with the pipeline (null
  /// when the backend in use is the CPU's).
  std::unique_ptr<PenetrationDepthBackend> cpu_fallback_;
  std::int64_t backend_failures_ = 0;
  /// Reserved at construction (kMaxFallbackReason characters; a longer reason is cut), so that
  /// the failing step writes it without allocating.
  std::string fallback_reason_;
  static constexpr std::size_t kMaxFallbackReason = 512;
};

}  // namespace ht
