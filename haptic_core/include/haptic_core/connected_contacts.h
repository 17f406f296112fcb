#pragma once
// Stage 5c of the remote step (remote_step.h; issue 32, tenth stop): contacts whose overlaps form
// one connected region share one penalty. The coarse clustering (contact_clustering.h) cannot
// merge two clusters whose merged window would exceed its largest side, so a large flat contact
// (the hammer's face on the torus) becomes two windows, each over its own coarse triangles, each
// reading the same penetration depth: the sum of their forces is twice what one patch pushes. The
// pipeline truth (accuracy/contact_patch_truth.h) links the overlapping surface within the
// clustering distance into one patch with one δ; this stage does the same with the textured
// overlap the windows render, and shares the penalty k among the linked contacts.

#include <cstdint>
#include <span>

#include "haptic_core/contact_linearization.h"
#include "haptic_core/contact_model.h"
#include "haptic_core/haptic_model.h"
#include "haptic_core/penetration_depth.h"
#include "haptic_core/penetration_depth_backend.h"
#include "haptic_core/spatial.h"

namespace ht {

/// One contact's textured overlap at the tool's pose, as blocks of its window
/// (TexturePenetrationSolver::OverlapOccupancy): `occupancy[bj · blocks_per_side + bi]` is 1 where
/// a cell of block (bi along u, bj along v; block_cells cells a side) has b − a > 0.
struct OverlapFootprint {
  ContactWindow window;
  int block_cells = 1;
  int blocks_per_side = 0;
  std::span<const std::uint8_t> occupancy;
};

/// True when an occupied block of `a` and one of `b` have centres closer than `link_m` (m, in
/// W). The blocks stand for their cells, so the test is the cells' single linkage to within a
/// block's diagonal. False when either footprint is empty or malformed (blocks_per_side ≤ 0,
/// occupancy shorter than blocks_per_side²) or link_m is not positive. noexcept, allocation-free;
/// O(occupied_a · occupied_b) at worst, with an early exit and a bounding-box test first.
bool FootprintsWithin(const OverlapFootprint& a, const OverlapFootprint& b, double link_m) noexcept;

/// True when the centroid of `b`'s occupied blocks lies in `a`'s overlap window: the square about
/// the centre of a's occupied cells' box (on a's window plane) whose side is that box's larger side
/// plus `margin_m` (m) on each side, within half that side along a's normal. This is the pipeline
/// truth's rule for patches that measure one interpenetration twice
/// (ContactPatchTruthOptions::overlap_merge_angle_deg); not symmetric. False for an empty or
/// malformed footprint. noexcept, allocation-free.
bool FootprintCentroidInside(const OverlapFootprint& a, const OverlapFootprint& b,
                             double margin_m) noexcept;

/// The shares s_i (Σ s_i = 1) of one group of linked contacts' penalty, from their depths δ_i (m):
/// s_i = exp((δ_i − δ_max)/τ) / Σ_j exp((δ_j − δ_max)/τ) with τ = `temperature_m` (m, > 0). The
/// group then pushes with Σ s_i k δ_i J_i: the deepest contact's kδ J where one is deeper by
/// several τ (one patch, one δ, as the pipeline truth has it), the mean of equally deep ones, and
/// continuous in the depths between (no step when the deepest contact changes). Non-finite depths
/// get share 0; all non-finite or τ ≤ 0 (or NaN): equal shares over the finite ones (none: all 0).
/// `shares` must be as long as `depths_m`. noexcept, allocation-free.
void PenaltySharesByDepth(std::span<const double> depths_m, double temperature_m,
                          std::span<double> shares) noexcept;

/// How ShareConnectedContacts links contacts and shares their penalty.
struct ContactSharingOptions {
  /// Single linkage of the overlaps (m; FootprintsWithin): the clustering distance.
  double link_m = 5e-3;
  /// Normals within this angle (deg) may link (the clustering angle).
  double max_normal_angle_deg = 30.0;
  /// Also link when one overlap's centroid lies in the other's overlap window
  /// (FootprintCentroidInside, 1 mm margin).
  bool centroid_in_window = true;
  /// τ of PenaltySharesByDepth (m).
  double temperature_m = 5e-6;
};

/// Most blocks a side of one contact's footprint (its blocks grow past a quarter of the link on
/// windows wider than this many quarter links).
inline constexpr int kMaxSharingBlocks = 64;

/// Stage 5c: links the contacts [0, n) (n = min of the spans' sizes and kMaxContacts) with δ0 > 0
/// that lie on one object (same model and pose) with normals within the angle and whose overlaps
/// link (FootprintsWithin, or FootprintCentroidInside both ways), single linkage, and multiplies
/// each linked contact's stiffness_n_per_m by its share within its group
/// (PenaltySharesByDepth). Each footprint is `solver`'s OverlapOccupancy of the contact's window
/// at X_WT (frame T at the tool's centre of mass, m) with its triangle subsets, in blocks of about
/// link/4, rendered only for contacts that have a candidate partner within reach of their windows.
/// `scratch` holds kMaxSharingBlocks² bytes per contact. Returns how many contacts were shared
/// (0 when fewer than two are positive, link_m ≤ 0, or scratch is short: nothing changes).
/// noexcept; allocation-free within the solver's reserve.
int ShareConnectedContacts(const HapticModel& tool, const RigidTransform& X_WT,
                           std::span<const ContactQuery> queries,
                           std::span<ContactLinearization> results,
                           const ContactSharingOptions& options, TexturePenetrationSolver& solver,
                           std::span<std::uint8_t> scratch) noexcept;

}  // namespace ht
