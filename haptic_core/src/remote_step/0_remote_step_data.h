#pragma once
// The remote step's two blocks, after MuJoCo's mjModel and mjData (docs/STYLE.md): what the step
// derives from its scene once and never changes (RemoteStepModel), and everything the step writes
// (RemoteStepData), both built by HapticTexturePipeline's constructor (remote_step.h). The stage
// functions (0_remote_step.cc, 5a_window_split.cc) read the first and write the second; nothing
// in either is resized after construction.

#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "haptic_core/connected_contacts.h"
#include "haptic_core/contact_clustering.h"
#include "haptic_core/contact_linearization.h"
#include "haptic_core/contact_region.h"
#include "haptic_core/contact_windows.h"
#include "haptic_core/depth_field.h"
#include "haptic_core/depth_refinement.h"
#include "haptic_core/haptic_scene.h"
#include "haptic_core/hull_proximity.h"
#include "haptic_core/penetration_depth.h"
#include "haptic_core/remote_step.h"

namespace ht {

/// What the remote step derives from its scene's models (index 0 the tool, in frame T; k + 1
/// touchable k, in its frame O), built once at construction and read-only afterwards. The scene
/// holds its models as shared_ptr<const HapticModel>, so none changes under it.
struct RemoteStepModel {
  /// Builds every field from `scene` (which has a tool and no empty touchable; checked by the
  /// pipeline first). Allocates; throws only std::bad_alloc.
  explicit RemoteStepModel(const HapticScene& scene);

  /// The coarse query's bounds (HullBounds::Of) of the tool and of every touchable. Their root
  /// spheres (spheres_O[0]) are the broad phase's, so that objects far from the tool cost one
  /// distance test per step.
  HullBounds tool_bounds;
  std::vector<HullBounds> object_bounds;
  /// The texture stage's box trees (TriangleBoxTree::ForModel; null where the scan costs less),
  /// carried by each contact's triangle subsets.
  std::unique_ptr<TriangleBoxTree> tool_tree;
  std::vector<std::unique_ptr<TriangleBoxTree>> object_trees;
  /// Per model: its hull when it has no hierarchy and its coarse mesh is convex within a
  /// micrometre (ConvexMeshHull; no planes otherwise).
  std::vector<ConvexHull> whole_hulls;
  /// Per model: the hull bounding the whole model, for the free-space bound
  /// (HullSeparationBound): its hierarchy's root, or its whole_hulls entry; null when neither
  /// exists.
  std::vector<const ConvexHull*> root_hulls;
  /// Per model with a whole hull: the indices of all its coarse triangles (empty otherwise).
  std::vector<std::vector<int>> whole_triangles;
};

/// Everything the remote step writes, preallocated at construction for the scene's contact
/// counts (kMaxContacts contacts, the clusterer's pair and triangle limits), so that the step
/// allocates nothing after warm-up. The stage objects keep the state they carry from one step to
/// the next (the coarse query's coherence, stage 5b's seeds) and their own scratch.
struct RemoteStepData {
  /// `kept_field_resolution`: the side (cells) of the largest overlap field stage 5a copies
  /// (HapticTexturePipeline::KeptFieldResolution). Allocates; throws what DepthRefiner's
  /// constructor throws for bad depth-refinement options (std::invalid_argument; the pipeline
  /// validates them first) and std::bad_alloc.
  RemoteStepData(const HapticScene& scene, const PipelineOptions& options,
                 int kept_field_resolution);

  // ---- The stage objects.
  /// Stage 2: one proximity query per touchable (each keeps its own last-frame pairs).
  std::vector<HullProximityQuery> queries;
  /// Stage 3.
  ContactClusterer clusterer;
  /// Stage 5b (PipelineOptions::refine_depth): its buffers, and its seeds from the last step.
  DepthRefiner refiner;
  /// Stages 5a and 5c: the solver that renders a window's overlap regions.
  std::unique_ptr<TexturePenetrationSolver> region_solver;

  // ---- Stages 1–3 (FindContactCandidates).
  /// The leaf pairs within their local texture reach, as many as the clusterer takes, and the
  /// grazing guard's bound of each (from the pair's two leaves' own reach).
  std::vector<HullPairContact> reachable_pairs;
  std::vector<double> pair_bounds;
  /// The candidates' triangle lists (each texture once), copied from the
  /// clusterer, whose lists last only until its next call (one per touchable).
  std::vector<int> candidate_triangles;
  /// Per touchable: its bounding-sphere gap (m) when the coarse query found no pair for it, NaN
  /// otherwise (the free space is taken from these after the query loop).
  std::vector<double> free_space_gaps;
  std::array<ContactCandidate, kMaxContacts> candidates{};
  int num_candidates = 0;
  /// Candidates of objects kept by the speculative floor alone (touched nowhere): they take only
  /// the slots the touching objects leave, after those.
  std::array<ContactCandidate, kMaxContacts> floor_candidates{};

  // ---- Stages 4–6: the batch (HapticTexturePipeline::last_contact_queries() and the rest).
  std::array<ContactQuery, kMaxContacts> last_queries{};
  std::array<ContactLinearization, kMaxContacts> last_results{};
  /// The depth samples of last_queries (kGradientSamples each, query-major), for stage 5b.
  std::array<DepthSample, kMaxContacts * kGradientSamples> last_samples{};
  int last_num_queries = 0;
  /// Stage 5: one window size's queries, results, samples and their indices in last_queries (the
  /// GPU backend's batches).
  std::array<ContactQuery, kMaxContacts> size_queries{};
  std::array<ContactLinearization, kMaxContacts> size_results{};
  std::array<DepthSample, kMaxContacts * kGradientSamples> size_samples{};
  std::array<int, kMaxContacts> size_index{};
  /// Each contact's overlap field at the base pose from stage 5's render
  /// (PenetrationDepthBackend::base_overlap; empty: none), in last_queries' order, for stages 5a
  /// and 5c; and where the kept contacts' fields are copied before stage 5a's own batch
  /// overwrites the backend's (kMaxContacts fields of kept_field_resolution² floats).
  std::array<std::span<const float>, kMaxContacts> base_fields{};
  std::vector<float> base_field_store;

  // ---- Stage 5a.
  /// A window's overlap regions, and the windows replacing a split one.
  std::array<OverlapRegion, 8> regions{};
  std::array<ContactQuery, kMaxContacts> split_queries{};
  /// Each split window's weight (birth ramp and bridge fade), in split_queries' order,
  /// applied to its stiffness after stage 5b.
  std::array<double, kMaxContacts> split_weights{};
  /// The first split window in last_queries and how many follow (0: none this step).
  int split_first = 0;
  int split_count = 0;
  /// Each split window's parent (its index in last_queries), and
  /// each contact's family for stage 5c (−1: none; a parent and its split windows share one, and
  /// never share a penalty).
  std::array<int, kMaxContacts> split_parent{};
  std::array<int, kMaxContacts> split_family{};

  // ---- Stage 5c.
  /// The block occupancy of each contact (kMaxSharingBlocks² a contact).
  std::vector<std::uint8_t> sharing_occupancy;

  // ---- Stage 5d (depth_fields).
  /// Its renderer; the fields it keeps (rendered at earlier steps, reused while they hold the
  /// tool), the step each was last referred to at, and the step count; the fields of the last
  /// model (the first num_fields, one per contact that has one); and the last id given.
  DepthFieldRenderer field_renderer;
  static constexpr int kFieldPoolSize = 2 * kMaxContacts;
  std::array<DepthField, kFieldPoolSize> field_pool{};
  std::array<std::uint64_t, kFieldPoolSize> field_used_at{};
  /// The pool's fields (HapticTexturePipeline::kept_depth_fields()).
  std::array<const DepthField*, kFieldPoolSize> field_pool_fields{};
  std::uint64_t field_step = 0;
  std::array<const DepthField*, kMaxContacts> fields{};
  int num_fields = 0;
  std::uint32_t last_field_id = 0;
  /// The tool whose ToolContactArea (m²) the pressure law's fields take.
  const HapticModel* pressure_area_tool = nullptr;
  double tool_contact_area_m2 = 0.0;
  /// The lattices the fields are sampled on, each fixed in its environment's frame (axes and
  /// normal in O; the nodes at the environment's origin plus whole cells along u and v), reused
  /// by every contact on that environment whose window normal is within 0.1 rad, the least
  /// recently used replaced.
  struct FieldLattice {
    const HapticModel* environment = nullptr;
    glm::dvec3 axis_u_O{1.0, 0.0, 0.0}, axis_v_O{0.0, 1.0, 0.0}, normal_O{0.0, 0.0, 1.0};
    double cell_m = 0.0;
    std::uint64_t last_used = 0;
    std::uint32_t id = 0;
  };
  std::array<FieldLattice, 2 * kMaxContacts> field_lattices{};
  std::uint64_t field_lattice_clock = 0;
  std::uint32_t last_lattice_id = 0;
  /// Each contact's slot in field_pool at the last step (−1: no field), in last_queries' order.
  std::array<int, kMaxContacts> contact_field_slot{};

  // ---- The step from kept fields (TakeStepFromKeptFields).
  /// The last step that ran stages 5–5d: its stage-4 queries (before stage 5a) and their count,
  /// its contacts (queries with their triangle subsets cleared, and linearizations, after stage
  /// 5d) and their count, and whether a later step may take its contacts (every contact has a
  /// field).
  std::array<ContactQuery, kMaxContacts> full_stage4_queries{};
  int full_stage4_count = 0;
  std::array<ContactQuery, kMaxContacts> full_queries{};
  std::array<ContactLinearization, kMaxContacts> full_results{};
  int full_count = 0;
  bool full_valid = false;
  /// The fast step's evaluations before they are taken.
  std::array<DepthFieldEvaluation, kMaxContacts> field_evaluations{};

  /// What the stages counted (HapticTexturePipeline::step_faults()).
  HapticTexturePipeline::StepFaults step_faults;
};

/// Stage 5d (PipelineOptions::depth_fields): gives each of the data's last_queries[0,
/// last_num_queries) whose linearization is finite a depth field and sets the linearization's
/// depth_field_id: a kept field on the query's lattice that no other contact of this step took,
/// whose grid holds the window grown by half the travel margin and whose tool pose the tool has
/// moved at most half the travel margin from (DepthFieldEvaluation::within_margin's measure),
/// else a new render into the least recently used slot (ids counting on from d.last_field_id).
/// A contact whose field cannot be made keeps id 0 (its linearization alone). d.fields lists the
/// step's fields. Returns d.num_fields. Never allocates within the data's reserve.
int RenderContactDepthFields(const HapticModel& tool, const RigidTransform& X_WT,
                             const PipelineOptions& options, RemoteStepData& d) noexcept;

/// Sets each of the data's last_results[0, last_num_queries) that has a field (contact_field_slot
/// ≥ 0) to that field's evaluation at X_WT: δ0 and J are the field's δ and ∇δ there, so that the
/// contact's linearization is the tangent of the depth the operator's loop evaluates. A contact
/// whose evaluation has no finite δ keeps its stage-5 linearization.
void LinearizeFromDepthFields(const RigidTransform& X_WT, RemoteStepData& d) noexcept;

/// Records the step that just ran stages 5–5d (its stage-4 queries were copied to
/// d.full_stage4_queries before stage 5) for TakeStepFromKeptFields.
void RecordFullStep(RemoteStepData& d) noexcept;

/// The step from kept fields: when this step's stage-4 queries (d.last_queries[0,
/// last_num_queries)) are the last full step's, one for one (same environment at the same pose,
/// each window held by the field its contact had: on its lattice, within its grid grown by half
/// the travel margin), and the tool has moved at most half the travel margin of every field from
/// where it was rendered, the contacts are the last full step's with each δ0 and J the field's at
/// X_WT (stages 5–5c skipped, no render); returns true, with d.last_queries, last_results,
/// last_num_queries, fields and num_fields set. Returns false, changing nothing but the data's
/// evaluations scratch, otherwise. noexcept, allocation-free.
bool TakeStepFromKeptFields(const RigidTransform& X_WT, const PipelineOptions& options,
                            RemoteStepData& d) noexcept;

}  // namespace ht
