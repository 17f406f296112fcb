#pragma once
// The pipeline truth: what the two FULL-RESOLUTION objects would exert at one pose,
// computed from their meshes alone, so that it owns its contacts instead of borrowing the
// method's windows (ground_truth_depth.h measures the texture stage on the method's windows).
//
// At one pose (DESIGN.md §4 for δ and Φ; the patch geometry is our reconstruction [R]):
//  1. Intersecting triangle pairs of the two meshes (FCL's BVH collision, every pair).
//  2. Contact patches: the pairs linked when their points (the midpoint of the two triangles'
//     centroids) are closer than the method's clustering distance and the environment triangles'
//     normals agree within its angle (single linkage: connected regions, the granularity of
//     contact_clustering.h).
//  3. Per patch, the surfaces inside the other solid: each crossing triangle's inside part
//     (sub-triangles refined along the intersection curve, tested with RayCastSurface::IsInside)
//     and the triangles wholly inside, reached by a flood fill over edge neighbours from the
//     crossing ones. Their area-weighted normals give the gradient of the intersection volume V
//     with respect to the tool's pose (Reynolds transport: moving the tool by dx changes V by
//     ∫_{∂A∩B} n_A·dx dA):
//       ∇_x V = ∫_{∂A∩B} n_A dA = −∫_{∂B∩A} n_B dA,
//       ∇_θ V = ∫_{∂A∩B} (r × n_A) dA = −∫_{∂B∩A} (r × n_B) dA (r from the tool's centre of mass),
//     the two sides being two routes to one number (their sum is the closed intersection
//     surface's ∮ n dA = 0). The patch's direction is the macroscopic normal at its centre (the
//     flatter surface's normals averaged over 5 mm: texture finer than that does not tilt it),
//     else n = −∇_x V / |∇_x V| (from the environment towards the tool, the per-cluster
//     penetration direction of Kim, Otaduy, Lin & Manocha 2003 taken over the real surfaces); its
//     centre is the inside surfaces' area centroid, and its window the square on the plane ⟂ n
//     that holds their projection plus a margin.
//  3a. Neighbouring patches split by the fine normals of one textured face, merged when the
//     macroscopic normals at their centres agree (options below).
//  3b. Patches whose windows measure one interpenetration twice (overlapping windows with
//     directions within 60°), and slivers at a larger patch's edge, merged (options below).
//  4. T1, the pipeline truth: δ and ∇δ on that window by ray casting (GroundTruthDepthSolver,
//     gradient steps at texel scale; tilt_lift_m below sharpens the tilts), Φ_gt = Σ_patches
//     s_p · (−k δ_p ∇δ_p).
//  4a. The shares s_p: patches merge in step 2 when their
//     intersection curves come within merge_distance_m, and a merged patch pushes its deepest
//     point's k δ where the two pushed k δ_1 + k δ_2 a moment before; along a trajectory that is
//     a step in force, the measure's own (fig76's trace: |ΔF| > 0.5 N on 166 of 399 consecutive
//     poses 48 µm apart). So neighbouring patches share their penalty, fading out as they part:
//     λ_pq = 1 at merge_distance_m, falling linearly to 0 at merge_distance_m + share_fade_m,
//     closed over paths, s_p = e_p / (e_p + Σ_q λ_pq e_q), e = exp((δ − δ_max)/τ)
//     (connected_contacts.h's StrongestPathLinks and LinkedPenaltyShares, the law the method's
//     stage 5c uses on its own windows). At the merge distance s ≈ 1 on the deeper patch, as the
//     merged patch has it; share_fade_m = 0 gives the truth before (every s = 1).
//  4b. The pressure law's truth (depth_field.h, ForceLaw::kPressure), when asked: the overlap
//     along each patch's n integrated over its window by a grid of rays, refined until the wrench
//     converges (GroundTruthDepthSolver::ConvergedPressure); the patches' wrenches add.
//  5. T2, the volume truth, independent of the force law: −∇_x V's direction and the lever arm
//     |∇_θ V| / |∇_x V| (what a volume penalty k_V·V would give as |τ|/|F|), so that distributed
//     and grazing contact are judged by direction and arm, not by stiffness.

#include <limits>
#include <memory>
#include <vector>

#include "haptic_core/accuracy/ground_truth_depth.h"
#include "haptic_core/haptic_model.h"
#include "haptic_core/spatial.h"

namespace ht {

/// How the pipeline truth groups and measures its patches.
struct ContactPatchTruthOptions {
  /// Patches: pair points closer than this (m) with environment normals within the angle (deg)
  /// are one region (the method's clustering: PipelineOptions::clustering_distance_m/_angle_deg).
  double merge_distance_m = 5e-3;
  double max_normal_angle_deg = 30.0;
  /// The macroscopic normal at a patch: each surface's normals averaged, area-weighted, over the
  /// ball of this radius (m) about the patch's centre; the flatter surface's (the longer mean:
  /// 1 on a plane, about 0.7 on a right-angled edge) gives it, the tool's turned to point from the
  /// environment to the tool; so a block's edge pressed on a face takes the face's normal.
  /// Step 3a: two neighbouring patches (pairs within merge_distance_m) split only by their
  /// triangles' own normals are one patch when their macroscopic normals agree within
  /// max_normal_angle_deg. Surface detail finer than this is texture on one face (the method's
  /// haptic texture), not separate contacts: on fig76 the ridge flanks facing +y and −y made two
  /// abutting 35 mm patches on one face, each pushing as much as the method's one contact. Two
  /// faces at 90° (an L corner) stay apart unless both patches' centres lie within this radius
  /// of the corner. 0 turns this step off.
  double macro_normal_radius_m = 5e-3;
  /// δ and ∇δ are taken along the macroscopic normal at the patch (above), not
  /// along −∇_x V, where that normal is defined and within 90° of −∇_x V. On textured faces a
  /// patch of ridge flanks has −∇_x V along the flanks (45° on fig76), and the depth along that
  /// direction runs into the neighbouring ridges: 0.9 mm where the overlap along the face's normal
  /// was 11 µm (fig76, 72 N against the method's 0.09 N). The method's own direction is its coarse
  /// surface's normal; detail finer than the radius is its texture. −∇_x V stays the volume
  /// truth's direction (T2) either way. False: −∇_x V.
  bool depth_along_macro_normal = true;
  /// Patches that measure one interpenetration twice become one (step 3b above), then their
  /// geometry is computed afresh: q joins p (the one with the larger |∇_x V|)
  ///  - when q's centre lies in p's window (inside its square and within half its side along
  ///    p's n) and their directions are within overlap_merge_angle_deg: on two textured faces
  ///    whose ridges interlock, the single-linkage regions split by the ridge flanks' normals
  ///    (facing ±y, 55° apart) had overlapping 35 mm windows, and the truth summed the same
  ///    penetration two or three times (fig76: 9.8 N against one 1.6 N contact); 0 turns this
  ///    rule off;
  ///  - when |∇_x V_q| ≤ minor_patch_fraction · |∇_x V_p| and q's centre lies in p's window
  ///    grown by merge_distance_m: a sliver at p's edge (a block's side face grazing the other
  ///    block) too small to turn p's direction, whose own direction is ill-defined (fig76: a
  ///    1e-10 m² sliver along the side normal gave 15 N through a δ gradient across the edge);
  ///    0 turns this rule off.
  /// A patch 90° from another (a tool in an L corner: floor and wall) stays its own patch.
  double overlap_merge_angle_deg = 60.0;
  double minor_patch_fraction = 0.05;
  /// Window: the inside surfaces' projected half extent plus this on each side (m), the side
  /// clamped to [min_extent_m, max_extent_m].
  double window_margin_m = 1e-3;
  double min_extent_m = 2e-3;
  double max_extent_m = 0.12;
  /// Translation step of ∇δ's central differences (m): texel scale (the seed's 1024² textures
  /// over objects of about 10 cm: 0.1 mm). The yaw step (about n) is this over half the window:
  /// it moves the window's edge along the surface by one step.
  double gradient_step_m = 1e-4;
  /// Tilt step (about u and v) of ∇δ's central differences as the lift along n it gives a point
  /// half the window from its centre (m): h_tilt = tilt_lift_m / (W/2). 0 (the default): the
  /// yaw's step h_x/(W/2), which lifts the window's edge by a whole h_x. A tilt moves points along
  /// n, so δ(θ) has a kink wherever the bearing point changes (a face resting on two supports: a
  /// V whose arms are their levers), and a secant over ±h reads |θ|/h of an arm within h of the
  /// kink. A small lift (1 µm) reads the arms, and also each crest's own lever where an edge lies
  /// across many crests (speed_error_frontier --truth-tilt-lift-um 0 and 1 compare the two).
  double tilt_lift_m = 0.0;
  /// Crossing triangles' inside part: split in four until no edge exceeds inside_cell_m (m), then
  /// only where a sub-triangle's corners and centroid disagree, down to boundary_cell_m (m).
  double inside_cell_m = 2e-3;
  double boundary_cell_m = 5e-5;
  /// Step 4a: neighbouring patches' shared penalty fades out over this distance (m) past
  /// merge_distance_m, measured between their intersection curves (the pairs' points) where their
  /// directions agree within max_normal_angle_deg; 0 turns the sharing off (separate patches
  /// always sum).
  double share_fade_m = 5e-3;
  /// τ of the shares' soft maximum (m, > 0): patches deeper by several τ take the whole penalty.
  double share_temperature_m = 5e-6;
  /// Most intersecting pairs gathered per pose (FCL's num_max_contacts).
  int max_pairs = 1 << 20;
  /// Step 4b, the pressure law's truth (depth_field.h, ForceLaw::kPressure): on each patch's
  /// window, GroundTruthDepthSolver::ConvergedPressure to this relative tolerance (0: not
  /// computed), M doubled from depth.initial_samples up to pressure_max_samples.
  double pressure_tolerance = 0.0;
  int pressure_max_samples = 1024;
  /// δ's ray casting on each window.
  GroundTruthOptions depth;

  /// Throws std::invalid_argument naming a value out of range.
  void Validate() const;
};

/// One contact patch of the full-resolution meshes at one pose.
struct TruthPatch {
  /// Its window: centre (area centroid of the inside surfaces), n the macroscopic normal there
  /// (else −∇_x V / |∇_x V|; unit, from the environment towards the tool; see
  /// ContactPatchTruthOptions::depth_along_macro_normal), extent from the inside surfaces'
  /// projection; in W, m.
  ContactWindow window;
  /// Intersecting triangle pairs in it.
  int pairs = 0;
  /// Area (m²) of the tool's surface inside the environment and of the environment's surface
  /// inside the tool.
  double tool_inside_area_m2 = 0.0, environment_inside_area_m2 = 0.0;
  /// ∇V over the tool's pose from the tool's inside surface and from the environment's (m² and
  /// m³/rad; rotation about the tool's centre of mass, world axes). The truth uses their mean.
  glm::dvec3 dV_dx_tool_W{0.0}, dV_dtheta_tool_W{0.0};
  glm::dvec3 dV_dx_environment_W{0.0}, dV_dtheta_environment_W{0.0};
  /// The translation step of ∇δ_gt's central differences (m): options' gradient_step_m rounded so
  /// that a whole number of steps spans the window; the yaw step is this over half the window.
  double gradient_step_m = 0.0;
  /// The tilt step about u and v (rad): options' tilt_lift_m over half the window, or the yaw's
  /// step when that is 0.
  double tilt_step_rad = 0.0;
  /// T1 on the window: δ_gt, ∇δ_gt (steps at texel scale), Φ_gt on the tool at its centre of mass
  /// (the patch's own, before its share).
  GroundTruthContact contact;
  /// The pressure law's sums on its window (step 4b; zero when not computed).
  GroundTruthPressure pressure;
  /// Its share s ∈ [0, 1] of that penalty (step 4a; 1 when no other patch is within
  /// merge_distance_m + share_fade_m): PoseTruth::F_T_W sums s · contact.F_T_W.
  double share = 1.0;
  /// The gap (m) from its intersection curve to the nearest other patch's with a direction within
  /// max_normal_angle_deg; +∞ when there is none within merge_distance_m + share_fade_m.
  double gap_to_neighbour_m = std::numeric_limits<double>::infinity();
};

/// The truth at one pose.
struct PoseTruth {
  /// Intersecting triangle pairs found (0: the meshes do not intersect, and the truth is zero).
  int pairs = 0;
  /// True when FCL's pair list hit options.max_pairs.
  bool pairs_truncated = false;
  /// Patches folded into another by step 3b (overlapping windows, slivers).
  int patches_merged = 0;
  /// Patches whose share (step 4a) is below 1.
  int patches_shared = 0;
  std::vector<TruthPatch> patches;
  /// T1: Σ over patches of s · Φ_gt (N, N·m), on the tool at its centre of mass, in W.
  Wrench F_T_W;
  /// T2: Σ over patches of the mean of both routes' ∇V (m², m³/rad), in W.
  glm::dvec3 dV_dx_W{0.0}, dV_dtheta_W{0.0};
  /// The pressure law's truth (step 4b): Σ over patches of their wrench per unit k_p (m³, m⁴; the
  /// law sums every overlapping cell, so patches add without shares) and of their volume (m³).
  Wrench pressure_per_kp;
  double pressure_volume_m3 = 0.0;
  /// Rays cast (inside tests and δ).
  long long rays = 0;
};

/// Computes PoseTruth between one tool mesh and one environment mesh. Holds FCL's hierarchies,
/// each mesh's edge neighbours and a depth solver: one object per thread (FCL's objects are not
/// shared across threads); the ray-casting surfaces may be shared.
class ContactPatchTruth {
 public:
  /// `tool_Ft`, `environment_Fe`: the full-resolution meshes in their file frames (#V, #F,
  /// counter-clockwise seen from outside, closed), copied; `tool_rays`, `environment_rays`: the
  /// same meshes as ray-casting surfaces, which must outlive this object. Throws
  /// std::invalid_argument for bad options, an empty mesh or an index out of range.
  ContactPatchTruth(const TriangleMesh& tool_Ft, const TriangleMesh& environment_Fe,
                    const RayCastSurface& tool_rays, const RayCastSurface& environment_rays,
                    const ContactPatchTruthOptions& options = {});
  ~ContactPatchTruth();
  ContactPatchTruth(const ContactPatchTruth&) = delete;
  ContactPatchTruth& operator=(const ContactPatchTruth&) = delete;

  /// The truth with the tool's centre of mass frame T at X_WT, the tool mesh's frame at X_TFt in
  /// T, the environment mesh at X_WFe, penalty stiffness k (N/m). Non-finite poses give an empty
  /// truth (pairs 0).
  PoseTruth At(const RigidTransform& X_WT, const RigidTransform& X_TFt, const RigidTransform& X_WFe,
               double stiffness_n_per_m);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace ht
