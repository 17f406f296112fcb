#pragma once
// The coarse proximity query between two convex-hull hierarchies (DESIGN.md §3, step 1 of the
// remote node's step): every pair of leaf hulls (convex surface patches) of a tool A and an object
// B that lie within a tolerance ε of each other, or penetrate, with signed distance, normal and
// witness points. Method: a best-first simultaneous traversal of both hierarchies (node pairs in
// order of a lower bound of their signed distance), bounding spheres and oriented boxes (the
// face axes of the separating-axis test of Gottschalk, Lin & Manocha, "OBBTree", SIGGRAPH 1996) as
// the cheap first tests, then GJK distance on the hulls (Gilbert, Johnson & Keerthi, IEEE J.
// Robotics & Automation 1988, with Ericson's closest-point-on-simplex routines, "Real-Time
// Collision Detection" §5.1, §9.5); for penetrating leaf pairs libccd's MPR (Snethen,
// "XenoCollide", Game Programming Gems 7) plus the hulls' own face normals as candidate separating
// directions. As in Otaduy & Lin (SIGGRAPH 2003, IEEE T-RO 22(4) 2006), whose contact query
// traverses the BVH of convex hulls in the same way.

#include <chrono>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "haptic_core/haptic_model.h"
#include "haptic_core/hull_pair_contact.h"
#include "haptic_core/spatial.h"

namespace ht {

/// Options of HullProximityQuery::Query().
struct ProximityQueryOptions {
  /// ε (m, ≥ 0): leaf pairs whose hulls are closer than this, touch or penetrate are reported.
  /// A caller rendering textures passes at least A.OutwardReach() + B.OutwardReach().
  double tolerance_m = 0.0;
  /// Time budget (µs): 0 = unlimited. Otherwise the traversal stops refining once this much wall
  /// time is spent (checked before each node pair, so it overruns by at most one node-pair test)
  /// and sets ProximityQueryStats::budget_exhausted. Node pairs are refined best first (smallest
  /// lower bound of their signed distance first), so the pairs found by then are the deepest ones
  /// up to the looseness of that bound.
  double time_budget_us = 0.0;
  /// Work budget (node-pair tests, leaf pairs included): 0 = unlimited. The same stop as
  /// time_budget_us, but deterministic (for tests and reproducible runs).
  int max_node_pair_tests = 0;
  /// Capacity (pairs). Clamped to the capacity given to the constructor. When more pairs are
  /// within ε, the shallowest ones are dropped and counted in ProximityQueryStats::pairs_dropped.
  int max_pairs = 4096;
  /// Temporal coherence: a leaf pair that was reported by the previous call (on the same two
  /// bounds, HullBounds::id) starts GJK from its previous separating direction, and its previous
  /// normal is one more candidate direction when it penetrates. A leaf pair that the previous call
  /// tested and found farther apart than its tolerance is first tested along the direction GJK
  /// separated it by then: where the hulls' support intervals along that axis are still more than
  /// the tolerance apart (a lower bound of their distance) the pair is dropped without GJK
  /// (ProximityQueryStats::coherent_culls). Never changes which pairs are reported (a
  /// penetrating pair's depth estimate can only get closer to the true depth). Measured:
  /// docs/measurements.md.
  ///
  /// Front tracking (Ehmann & Lin, "Accurate and fast proximity queries between polyhedra using
  /// convex surface decomposition", Eurographics 2001): without a budget, the traversal starts
  /// from the previous call's front, the node pairs where it stopped (pairs culled, leaf pairs
  /// tested), instead of from the two roots. Each front pair is tested again as it was (spheres,
  /// boxes, centre-line overlap, and for a pair internal GJK had culled, its separating
  /// direction then); a pair no test culls any more is descended as before. The front is a cut
  /// of the traversal tree, so every leaf pair is still decided by the exact tests: the same
  /// pairs are reported. Fronts are not pulled up: when one has grown past twice the size of the
  /// last front made from the roots (plus 64), the next call starts from the roots again, as it
  /// does after a call with a budget or on other bounds (HullBounds::id).
  /// Measured: docs/measurements.md.
  bool temporal_coherence = true;
  /// Local reach (an approximation, placed on the speed-vs-error frontier): when ≥ 0,
  /// a node pair's tolerance is min(tolerance_m, reach_A(node) + reach_B(node) +
  /// local_reach_margin_m), with a node's reach the largest positive texture height over its
  /// triangles (level 0, the triangle's texel box grown by a texel; capped at the model's
  /// OutwardReach()). Far leaves whose own textures are flat then stop counting. Negative: off
  /// (tolerance_m everywhere).
  double local_reach_margin_m = -1.0;
  /// Internal node pairs' GJK runs to the exact hull distance. Otherwise, when no budget is set,
  /// it stops once the two hulls are known to be within the pair's tolerance (then the pair
  /// descends whatever the distance; measured: docs/measurements.md). Either way the same leaf
  /// pairs are reported with the same contacts in the same order; only the traversal's
  /// keys differ. With a budget the exact distances are kept: there the best-first order decides
  /// which pairs are found. For tests and before/after measurements.
  bool exact_internal_distances = false;
};

/// What one Query() did.
struct ProximityQueryStats {
  /// Node pairs tested (after passing the bounding-sphere, oriented-box and centre-line tests),
  /// leaf pairs included.
  int node_pairs_tested = 0;
  /// Leaf pairs tested with GJK.
  int leaf_pairs_tested = 0;
  /// Node pairs rejected before testing: by their bounding spheres, their oriented boxes or the
  /// overlap of their hulls along the centre line (or, for a pair of the previous call's front
  /// that internal GJK culled then, along GJK's separating direction).
  int node_pairs_culled = 0;
  /// Pairs returned.
  int pairs_found = 0;
  /// Pairs within ε that did not fit in max_pairs (the shallowest ones).
  int pairs_dropped = 0;
  /// True when time_budget_us or max_node_pair_tests stopped the traversal early: the pairs
  /// returned are then a valid subset of the full answer.
  bool budget_exhausted = false;
  /// Leaf pairs found again from the previous call (temporal coherence was used for them).
  int coherent_hits = 0;
  /// Leaf pairs dropped without GJK because the previous call's separating direction still
  /// separates them by more than their tolerance (temporal coherence; counted in
  /// leaf_pairs_tested too).
  int coherent_culls = 0;
  /// Node pairs of the previous call's front that the traversal started from (temporal
  /// coherence, see ProximityQueryOptions::temporal_coherence); 0 when it started from the
  /// roots.
  int front_pairs = 0;
  /// Calls refused because a pose or the tolerance was not finite (0 or 1 per call).
  int invalid_input = 0;
  /// Leaf pairs whose result came out non-finite and was dropped (never expected; counted).
  int numerical_faults = 0;
  /// Wall time of the call (µs).
  double query_us = 0.0;
};

/// A box holding a hull: centre (m) and unit axes (columns) in the model's frame O, and the
/// half-extents (m) along them; the axes are the principal axes of the hull's vertices
/// (Gottschalk, Lin & Manocha 1996, "OBBTree"), the extents their vertices' range, padded for
/// rounding.
struct OrientedBox {
  glm::dvec3 center_O{0.0};
  glm::dmat3 axes_O{1.0};
  glm::dvec3 half_extents_m{0.0};
};

/// The coarse query's bounds of one model, one entry per node of its hull hierarchy (one for a
/// model without hierarchy, whose single hull is hull_vertices_O; node −1 reads it): derived data,
/// built once with the model's set-up (HullBounds::Of; the remote step builds its scene's in its
/// constructor) and read by every HullProximityQuery::Query on the model. Frame O, metres.
struct HullBounds {
  /// Per node: bounding sphere centre (xyz, the hull's centre_O, or for a single hull its
  /// vertices' centroid) and radius (w, the largest vertex distance from it).
  std::vector<glm::dvec4> spheres_O;
  /// Per node: an oriented box holding the node's hull (a box too big to cull anything for a
  /// hull without vertices).
  std::vector<OrientedBox> boxes_O;
  /// Per node: the outward texture reach (m): the largest positive level-0 texture height over
  /// the node's triangles, each triangle's texel box grown by a texel (bilinear samples reach that
  /// far), capped at the model's OutwardReach() (a triangle whose box touches a wrapped border
  /// counts the cap); ProximityQueryOptions::local_reach_margin_m reads it.
  std::vector<double> reach_m;
  /// A number no other HullBounds::Of call gives (copies keep it): a query's temporal coherence
  /// holds only between calls on the same two bounds' ids.
  std::uint64_t id = 0;

  /// Builds the bounds of `model` (allocates; throws std::bad_alloc only).
  static HullBounds Of(const HapticModel& model);
  /// True when these bounds have one entry per node of `model` (one for a model without
  /// hierarchy): the check Query makes before reading them, which keeps its indices in range; it
  /// cannot tell another model of the same node count, or this one edited in place (the caller
  /// keeps bounds with their model).
  bool Fits(const HapticModel& model) const noexcept;
  /// Node `node`'s sphere, box and reach (node < 0: entry 0). Throw std::out_of_range for a node
  /// the bounds do not have.
  glm::dvec4 Sphere(int node) const { return spheres_O.at(Index(node)); }
  const OrientedBox& Box(int node) const { return boxes_O.at(Index(node)); }
  double Reach(int node) const { return reach_m.at(Index(node)); }

 private:
  static std::size_t Index(int node) noexcept {
    return node < 0 ? 0 : static_cast<std::size_t>(node);
  }
};

/// The proximity query between the convex-hull hierarchies of two posed HapticModels, with all
/// working memory preallocated: given the models' HullBounds, after the first calls on a pair of
/// models (warm-up: the traversal queue grows to its working size) a call allocates nothing. Not
/// thread-safe: one object per thread.
class HullProximityQuery {
 public:
  /// Preallocates room for `max_pairs` (≥ 1) results and a traversal queue. Throws
  /// std::invalid_argument when max_pairs < 1.
  explicit HullProximityQuery(int max_pairs = 4096);

  /// All leaf pairs of A (posed at X_WA) and B (posed at X_WB) whose hulls are within
  /// options.tolerance_m of each other or penetrate, as HullPairContact (frame W, metres, normal
  /// from B towards A), sorted by increasing signed distance (deepest first).
  ///
  /// A model whose hull_hierarchy is empty stands in with the convex hull of its hull_vertices_O
  /// as a single leaf (node index −1); a model with neither hierarchy nor hull vertices gives no
  /// pairs. Non-finite or non-unit poses (IsFiniteRigidTransform), a negative or non-finite
  /// tolerance, give no pairs and count ProximityQueryStats::invalid_input; the call never
  /// throws.
  ///
  /// Accuracy: separated pairs: the GJK distance between the two hulls and its closest points,
  /// to 1e-12 m plus 1e-10 relative (normal = the unit vector between the closest points).
  /// Touching or penetrating pairs (GJK distance below 1e-12 m): the normal n is, among libccd
  /// MPR's direction, both hulls' face normals, (coherence) the previous normal and, where MPR
  /// finds no overlap (the hulls touch), GJK's direction with A moved apart by 1e-7 of the pair's
  /// size, the one with the smallest overlap of the hulls' support intervals along it, and
  /// signed_distance_m is −that overlap: exact for vertex-face and face-face contact (a face
  /// normal realizes the penetration depth) and for touching pairs whose closest features the
  /// hair's move separates (edges touching crosswise: within 1e-11 m, tested), otherwise never
  /// shallower than the true penetration depth (any direction's overlap bounds the depth from
  /// above). Witness points lie on the line through a
  /// point of the overlap region (MPR's) along n, at the two hulls' supporting planes, so
  /// point_A_W − point_B_W = signed_distance_m · normal_W to rounding.
  ///
  /// `bounds_A` and `bounds_B` are the models' HullBounds; bounds that do not fit their model
  /// (HullBounds::Fits) give no pairs and count ProximityQueryStats::invalid_input. Temporal
  /// coherence carries over between calls on the same two bounds (their ids) only.
  ///
  /// The returned span points into this object and is valid until the next call.
  std::span<const HullPairContact> Query(const HapticModel& A, const HullBounds& bounds_A,
                                         const RigidTransform& X_WA, const HapticModel& B,
                                         const HullBounds& bounds_B, const RigidTransform& X_WB,
                                         const ProximityQueryOptions& options,
                                         ProximityQueryStats* stats = nullptr) noexcept;
  /// The same with both models' bounds built for this call (allocates; no temporal coherence
  /// between calls): for one-off queries and tests. An allocation failure gives no pairs and
  /// counts ProximityQueryStats::numerical_faults.
  std::span<const HullPairContact> Query(const HapticModel& A, const RigidTransform& X_WA,
                                         const HapticModel& B, const RigidTransform& X_WB,
                                         const ProximityQueryOptions& options,
                                         ProximityQueryStats* stats = nullptr) noexcept;

  /// Lets Query() run its traversal on `threads` threads (a oneTBB task arena of that many, the
  /// calling thread among them) when no budget is set and both models have hierarchies: once a
  /// few node pairs are queued, they are dealt out to the threads, each descending its own. The
  /// pairs, contacts, their order and the statistics (but query_us) are those of one thread
  /// (tested). 1 (the default) runs on the calling thread alone. Preallocates each thread's
  /// queue and results; throws std::invalid_argument outside [1, 256].
  void SetThreads(int threads);
  /// Threads the traversal may use (SetThreads; 1 by default).
  int threads() const noexcept { return workers_.empty() ? 1 : static_cast<int>(workers_.size()); }

  /// Forgets the previous call's pairs, separating directions and front (allocation-free): the
  /// next call starts from the roots.
  void ClearCoherence() noexcept;

  // The implementation's private types are declared here so that the object can hold them by
  // value (no pimpl allocation); they are not part of the API.
  struct QueueEntry {
    double key_m;  ///< Lower bound of the signed distance of every leaf pair below (m).
    int node_A;
    int node_B;
    /// The parent pair's last GJK direction p_A − p_B in A's frame (0: none), GJK's first guess
    /// for this pair when it is internal.
    glm::dvec3 guess_A{0.0};
    /// The largest gap (m) between the pair's oriented boxes along their face normals: a lower
    /// bound of its hulls' distance, negative where the boxes overlap along all six (and
    /// internal GJK is then skipped without a budget).
    double box_gap_m = 0.0;
  };
  struct CoherentPair {
    int node_A;
    int node_B;
    /// Previous closest-point direction v = p_A − p_B, or normal, in W.
    glm::dvec3 direction_W;
  };
  /// A node pair where a traversal stopped (culled, or a leaf pair tested), with the direction
  /// that showed it farther apart than its tolerance where GJK gave one: an entry of a front, or
  /// of the leaf pairs found beyond their tolerance (previous_far_).
  struct FrontPair {
    int node_A;
    int node_B;
    /// GJK's last direction p_A − p_B (any length) in the frame of Query's A, for a pair GJK
    /// showed beyond its tolerance; else 0.
    glm::dvec3 axis_A;
  };
  /// One thread's share of a traversal (SetThreads).
  struct Worker {
    std::vector<FrontPair> front;
    std::vector<QueueEntry> queue;
    std::vector<HullPairContact> results;
    std::vector<CoherentPair> current;
    std::vector<FrontPair> current_far;
    ProximityQueryStats st;
  };

 private:
  int capacity_;
  std::vector<HullPairContact> results_;
  std::vector<QueueEntry> queue_;
  std::vector<CoherentPair> previous_;
  std::vector<CoherentPair> current_;
  // Leaf pairs the previous call tested and found farther than their tolerance, with the
  // direction that showed it (temporal coherence), and this call's.
  std::vector<FrontPair> previous_far_;
  std::vector<FrontPair> current_far_;
  // The previous call's front and this call's (front tracking); front_valid_ when the previous
  // call's is complete; front_base_ the size of the last front made from the roots.
  std::vector<FrontPair> front_;
  std::vector<FrontPair> next_front_;
  bool front_valid_ = false;
  std::size_t front_base_ = 0;
  // The bounds' ids of the previous call (0: none), for temporal coherence.
  std::uint64_t previous_A_ = 0;
  std::uint64_t previous_B_ = 0;
  struct Arena;  // the oneTBB task arena, kept out of this header
  std::shared_ptr<Arena> arena_;
  std::vector<Worker> workers_;
};

}  // namespace ht
