#pragma once
// Stage 5c of the remote step (remote_step.h): contacts whose overlaps form one connected region
// share one penalty. The coarse clustering (contact_clustering.h) cannot merge two clusters whose
// merged window would exceed its largest side, so a large flat contact (the hammer's face on the
// torus) becomes two windows, each over its own coarse triangles, each reading the same penetration
// depth: the sum of their forces is twice what one patch pushes. The pipeline truth
// (accuracy/contact_patch_truth.h) links the overlapping surface within the clustering distance
// into one patch with one δ; this stage links the textured overlaps the windows render and shares
// the penalty k among linked contacts, continuously in their depths and in the gap between their
// overlaps.

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
  ContactWindow window;     ///< The window rendered (centre and axes in W, m).
  int block_cells = 1;      ///< Cells a block side (≥ 1); a block is block_cells · W/N m a side.
  int blocks_per_side = 0;  ///< ceil(N / block_cells).
  std::span<const std::uint8_t> occupancy;  ///< blocks_per_side² entries, 0 or 1.
};

/// The smallest distance (m, in W) between the centres of an occupied block of `a` and one of
/// `b`: the gap between the two overlaps to within a block's diagonal. Stops at the first pair
/// closer than `enough_m` (m) and returns that pair's distance. +∞ when either footprint is empty
/// or malformed (blocks_per_side ≤ 0, occupancy shorter than blocks_per_side²). noexcept,
/// allocation-free; O(occupied_a · occupied_b) at worst.
double FootprintGap(const OverlapFootprint& a, const OverlapFootprint& b,
                    double enough_m = 0.0) noexcept;

/// The link λ ∈ [0, 1] of two overlaps `gap_m` apart (m): 1 up to `link_m`, falling linearly to
/// 0 at link_m + fade_m (fade_m > 0; 0 gives a step at link_m), 0 for a NaN gap.
double OverlapLink(double gap_m, double link_m, double fade_m) noexcept;

/// The shares s_i ∈ (0, 1] of linked contacts' penalties: with e_i = exp((δ_i − δ_max)/τ),
///   s_i = e_i / (e_i + Σ_{j≠i} λ_ij e_j),
/// λ_ij = λ_ji ∈ [0, 1] the links (`links[i · n + j]`, n = depths_m.size(), the diagonal unread),
/// τ = `temperature_m` (m, > 0). Unlinked contacts keep their whole penalty (s = 1); a group whose
/// members are all linked to each other (λ = 1) pushes Σ s_i k δ_i J_i with Σ s_i = 1, which is
/// the deepest contact's k δ J where one is deeper by several τ (one patch, one δ, as the pipeline
/// truth has it) and the mean of equally deep ones; s is continuous in the depths and the links
/// (no step when the deepest contact changes or a link fades in). A chain (i linked to j, j to k,
/// not i to k) sums to more than 1. Non-finite depths get s = 0 and take no part; τ ≤ 0 or NaN: τ
/// = 1 µm. `shares` must be as long as depths_m and `links` hold n² entries (else nothing is
/// written). noexcept, allocation-free.
void LinkedPenaltyShares(std::span<const double> depths_m, std::span<const double> links,
                         double temperature_m, std::span<double> shares) noexcept;

/// The strongest-path closure of n×n links (`links[i · n + j]`, symmetric, in place): each entry
/// becomes the largest, over all paths from i to j, of the smallest link along the path
/// (max–min, Floyd–Warshall). With links of 0 and 1 this is single linkage's connected components
/// (a chain's ends are linked); it is continuous in the links. Nothing happens when links holds
/// fewer than n² entries. O(n³), noexcept, allocation-free.
void StrongestPathLinks(std::span<double> links, int n) noexcept;

/// How ShareConnectedContacts links contacts and shares their penalty.
struct ContactSharingOptions {
  /// Overlaps closer than this (m; FootprintGap) are one region: λ = 1.
  double link_m = 10e-3;
  /// λ falls to 0 over this much more gap (m).
  double fade_m = 5e-3;
  /// Normals within this angle (deg) may link (the clustering angle).
  double max_normal_angle_deg = 30.0;
  /// τ of LinkedPenaltyShares (m).
  double temperature_m = 5e-6;
};

/// Most blocks a side of one contact's footprint (blocks grow past a quarter of the link on
/// windows wider than this many quarter links).
inline constexpr int kMaxSharingBlocks = 64;

/// Stage 5c: among the contacts [0, n) (n = min of the spans' sizes and kMaxContacts), those with
/// δ0 > 0 on one object (same model and pose) with normals within the angle get links
/// λ = OverlapLink(FootprintGap) of their overlaps, closed over paths (StrongestPathLinks: a
/// region spread over a chain of windows is one), and each contact's stiffness_n_per_m is
/// multiplied by its share (LinkedPenaltyShares). Each footprint is `solver`'s OverlapOccupancy
/// of the contact's window at X_WT (frame T at the tool's centre of mass, m) with its triangle
/// subsets, in blocks of about a quarter of the link, rendered only for contacts that have a
/// candidate partner within reach of their windows. `scratch` holds kMaxSharingBlocks² bytes per
/// contact. Returns how many contacts' stiffness changed (0 when fewer than two are positive,
/// link_m ≤ 0, or scratch is short: nothing changes). `family`, where it is as long as
/// `queries`, names each contact's family (≥ 0; −1: none): contacts of one family never link
/// (stage 5a's split regions and the parent window they lie in, which its bridge fade weighs
/// instead). `base_overlaps`, where it is as long
/// as `queries`, gives each contact's overlap field at the base pose (stage 5's own render,
/// PenetrationDepthBackend::base_overlap; empty: none): a contact with one is not rendered again
/// (the same footprint from the same field). noexcept; allocation-free within the solver's
/// reserve.
int ShareConnectedContacts(const HapticModel& tool, const RigidTransform& X_WT,
                           std::span<const ContactQuery> queries,
                           std::span<ContactLinearization> results,
                           const ContactSharingOptions& options, TexturePenetrationSolver& solver,
                           std::span<std::uint8_t> scratch, std::span<const int> family = {},
                           std::span<const std::span<const float>> base_overlaps = {}) noexcept;

}  // namespace ht
