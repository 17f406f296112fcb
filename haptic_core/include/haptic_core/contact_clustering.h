#pragma once
// Contact clustering (DESIGN.md §3): the leaf pairs that the coarse proximity query returns
// (HullPairContact) are grouped into a few contacts, each with one point, one direction and one
// texture window, after Kim, Otaduy, Lin & Manocha, "Six-degree-of-freedom haptic display using
// localized contact computations", HAPTICS 2002 / IEEE TVCG 2003 (contacts close in space and
// with similar normals are clustered, and one contact point and penetration direction are computed
// per cluster); seed: on average 104 pairs clustered into up to 7 contacts (file vs CAD part).
//
// Called every remote step: ContactClusterer preallocates everything at construction and
// Cluster() never allocates nor throws afterwards.

#include <glm/vec3.hpp>
#include <limits>
#include <span>
#include <utility>
#include <vector>

#include "haptic_core/contact_model.h"
#include "haptic_core/hull_hierarchy.h"
#include "haptic_core/hull_pair_contact.h"

namespace ht {

/// Parameters of ContactClusterer::Cluster(). Lengths in m, angles in degrees.
struct ClusteringOptions {
  /// Pass 1: a pair joins a cluster whose running weighted centroid is closer than this to the
  /// pair's contact point (m).
  double merge_distance_m = 5e-3;
  /// Pairs and clusters merge only when their normals differ by at most this angle (deg); the
  /// same angle is used in all three passes. Valid in [0, 90): below 90° a weighted normal sum can
  /// never cancel, so n and −n never average to zero.
  double max_normal_angle_deg = 30.0;
  /// Added on each side of the members' spread to make the window's side (m); set it to at least
  /// OutwardReach() of both models so that the texture around the outermost pairs is inside.
  double texture_margin_m = 1e-3;
  /// Bounds of the window side extent_m (m), 0 < min_extent_m ≤ max_extent_m. min_extent_m is the
  /// side a single pair gets when 2·texture_margin_m is smaller: set it to the size of a leaf patch
  /// (the clusterer sees contact points, not the patches' geometry).
  double min_extent_m = 2e-3;
  double max_extent_m = 0.05;
  /// Weight floor f (m) of ContactPairWeight(): the weight of a touching pair; > 0.
  double weight_floor_m = 1e-4;
  /// Most clusters returned (≥ 1). Surplus clusters, shallowest first, are merged into the
  /// nearest kept cluster when their normals agree and the merged window fits max_extent_m, and
  /// are dropped otherwise (both counted in ClusteringStats).
  int max_contacts = kMaxContacts;
  /// Pass 4: a leaf met by the pairs of several kept clusters goes to the cluster of its deepest
  /// pair (false, the default), and also (true) to each further cluster, deepest pair first,
  /// whose window is disjoint from the windows of every cluster holding the leaf already (the box
  /// test of pass 2). One large leaf (a hammer's flat face on a torus) then serves each contact
  /// region it touches, and no part of it is rendered in two windows, which do not overlap.
  bool share_leaves_between_disjoint_windows = false;
  /// Pass 4, after the object's leaves are placed: each tool leaf of a kept pair also goes to the
  /// cluster holding that pair's object leaf (its deepest pair's cluster), so that every kept pair
  /// has both its leaves in one window. Without it a pair whose tool leaf went to one cluster and
  /// object leaf to another is rendered in no window: the full-resolution surfaces interpenetrate
  /// there and no contact feels it (the hammer's seven poses without force on the frontier's spread
  /// poses). Each object leaf stays in its clusters as before, so a pair is counted only in
  /// a window that holds its object leaf.
  bool tool_leaves_follow_object_leaves = false;

  /// True when every field is finite and in its documented range. Never throws.
  bool IsValid() const noexcept;
  /// Throws std::invalid_argument naming the first field out of range (start-up check).
  void Validate() const;
};

/// Weight w(d) (m) of a pair with signed distance d (m), d < 0 penetrating, and floor f (m):
/// w = f − d for d ≤ 0 (deeper pairs weigh more, linearly in the depth), w = f·exp(−d/f) for
/// d > 0 (separated pairs within the query tolerance weigh less the farther apart they are). C¹ in
/// d, so the cluster point and normal do not jump when a pair crosses d = 0; always > 0 for finite
/// d (the exponent is clamped at −50). NaN for NaN d.
double ContactPairWeight(double signed_distance_m, double weight_floor_m) noexcept;

/// One clustered contact: what the texture stage needs for one window
/// (ContactWindow::Make(point_W, normal_W, extent_m, N)) and the coarse triangles to render in it.
struct ContactCluster {
  /// Weighted centroid Σ w_i p_i / Σ w_i of the members' contact points p_i (the midpoint of
  /// point_A_W and point_B_W), m, in W.
  glm::dvec3 point_W{0.0};
  /// Unit direction normalize(Σ w_i n_i), from the object B towards the tool A, in W.
  glm::dvec3 normal_W{0.0, 0.0, 1.0};
  /// Window side (m): 2·(members' half spread) + 2·texture_margin_m, clamped to
  /// [min_extent_m, max_extent_m]. The half spread is the largest |Δ·u|, |Δ·v| over both witness
  /// points of every member, Δ from point_W, with u, v the axes ContactWindow::Make() picks for
  /// normal_W, so the window made from this cluster covers every member (unless clamped).
  double extent_m = 0.0;
  /// Smallest member signed distance (m): the deepest pair (< 0 penetrating).
  double min_signed_distance_m = 0.0;
  /// The largest of the members' depth bounds given to Cluster() (m), +∞ when none was given: the
  /// most δ this cluster's coarse geometry allows (the remote step's grazing guard).
  double depth_bound_m = std::numeric_limits<double>::infinity();
  /// Σ w_i of the members (m).
  double total_weight_m = 0.0;
  /// Number of member pairs (≥ 1).
  int num_pairs = 0;
  /// Coarse triangles of the tool A and the object B to render in this window: indices into that
  /// model's coarse triangles, the union of the triangle lists of the leaves assigned to this
  /// cluster. A leaf goes to the cluster holding its deepest pair, so every leaf, and since leaves
  /// partition the coarse mesh every triangle, is in at most one cluster. Views into the
  /// clusterer's storage, valid until its next Cluster() call.
  std::span<const int> tool_triangles;
  std::span<const int> object_triangles;
  /// True when a member had node −1 on that side (a model without hierarchy, its single hull
  /// standing in): that side has no triangle list and the caller selects from the whole model
  /// (SelectPatchTriangles()); disjointness then rests on the windows (see ContactClusterer).
  bool tool_whole_model = false;
  bool object_whole_model = false;
};

/// What the last Cluster() call dropped or changed; all counts reset at each call.
struct ClusteringStats {
  /// Pairs given.
  int input_pairs = 0;
  /// Pairs skipped for a non-finite field or a normal of length ≤ 1e-12.
  int skipped_nonfinite = 0;
  /// Valid pairs beyond the clusterer's max_pairs: the shallowest were left out.
  int skipped_over_capacity = 0;
  /// Clusters after pass 1 (distance and normal) and after pass 2 (overlapping windows).
  int clusters_pass1 = 0;
  int clusters_pass2 = 0;
  /// Surplus clusters (beyond max_contacts) merged into the nearest kept one, or dropped.
  int merged_for_capacity = 0;
  int dropped_for_capacity = 0;
  /// Member node indices that were neither −1 nor a leaf of their hierarchy: no triangles taken.
  int invalid_nodes = 0;
  /// Triangle indices that did not fit the clusterer's max_triangles storage.
  int truncated_triangles = 0;
  /// True when the options were invalid: no clusters were returned.
  bool rejected_options = false;
};

/// Greedy agglomerative clustering of hull-pair contacts into at most max_contacts contacts, after
/// Kim, Otaduy, Lin & Manocha (2002/2003). Method, in passes:
///   0. Valid pairs are sorted deepest first (signed distance, then input index).
///   1. Each pair joins the nearest cluster whose running weighted centroid is within
///      merge_distance_m of its contact point and whose running normal is within
///      max_normal_angle_deg of its normal; otherwise it seeds a new cluster. Pairs with n and −n
///      at one spot therefore stay apart.
///   2. Clusters whose windows overlap (the boxes W×W×2W of ContactWindow, tested in the frame of
///      their mean normal) and whose normals agree merge, repeatedly, as long as the merged window
///      fits max_extent_m: overlapping windows with similar normals would render the same texture
///      twice and add its force twice.
///   3. Beyond max_contacts, the shallowest clusters (largest min_signed_distance_m), deepest of
///      them first, merge into the nearest (centroid distance) of the max_contacts deepest
///      clusters among those whose normal agrees and whose merged window fits max_extent_m; with
///      none such they are dropped. Kept clusters' depths are unchanged by these merges.
///   4. Triangles: each leaf met in a kept pair goes to the cluster holding its deepest pair
///      (and, with share_leaves_between_disjoint_windows, to each further cluster whose window
///      is disjoint from those of the clusters holding it; with
///      tool_leaves_follow_object_leaves, each tool leaf also to the cluster holding each of its
///      pairs' object leaves).
/// Windows that overlap with different normals (a corner, two faces) stay separate. The same
/// texture is still not counted twice because each coarse triangle is listed in one cluster only,
/// or in several whose windows do not overlap (a tool leaf that follows its pairs' object leaves
/// may be listed in overlapping windows, but each object leaf is not, so a pair of leaves is
/// still rendered together in one window only).
/// The texture stage's facing test (face normal·n > kPatchFacingThreshold) alone would not ensure
/// it: a triangle faces two windows whose normals are α apart whenever cos(α/2) > 0.05, i.e. for
/// all α < 174.3°; it only separates nearly opposite windows. A leaf's triangles that do not face
/// their cluster's normal contribute nothing (they are not given to another cluster).
///
/// Output clusters are ordered deepest first. Cost O(P log P + P·C + C²) for P pairs and C
/// clusters after pass 1, plus O(C + members) per merge.
class ContactClusterer {
 public:
  /// Preallocates storage for `max_pairs` valid pairs (≥ 1) and `max_triangles` (≥ 0) triangle
  /// indices over both sides. Throws std::invalid_argument naming a bad value.
  explicit ContactClusterer(int max_pairs = 4096, int max_triangles = 65536);

  /// Clusters `pairs` (leaf pairs between the tool A with hierarchy `tool_hulls` and one object B
  /// with `object_hulls`; node_A indexes tool_hulls.nodes, node_B object_hulls.nodes). Returns the
  /// clusters, at most options.max_contacts, deepest first; a view into the clusterer's storage,
  /// valid until the next call. Empty for no valid pairs or invalid options. Never throws, never
  /// allocates; skipped pairs and other faults are counted in stats().
  /// `pair_depth_bound_m`, when it holds one entry per pair, gives each pair's depth bound (m);
  /// each cluster reports the largest of its members' (ContactCluster::depth_bound_m).
  std::span<const ContactCluster> Cluster(std::span<const HullPairContact> pairs,
                                          const ConvexHullHierarchy& tool_hulls,
                                          const ConvexHullHierarchy& object_hulls,
                                          const ClusteringOptions& options,
                                          std::span<const double> pair_depth_bound_m = {}) noexcept;

  /// Counts of the last call.
  const ClusteringStats& stats() const noexcept { return stats_; }
  int skipped_nonfinite() const noexcept { return stats_.skipped_nonfinite; }
  int merged_for_capacity() const noexcept { return stats_.merged_for_capacity; }
  int dropped_for_capacity() const noexcept { return stats_.dropped_for_capacity; }

  int max_pairs() const noexcept { return max_pairs_; }
  int max_triangles() const noexcept { return max_triangles_; }

 private:
  // One valid input pair.
  struct PairRecord {
    int input_index;
    double signed_distance_m;
    double weight_m;
    glm::dvec3 point_W;  // midpoint of the witnesses
    glm::dvec3 point_A_W, point_B_W;
    glm::dvec3 normal_W;  // unit
    int node_A, node_B;
    int cluster;  // −1: dropped
    int next;     // next member of the same cluster, −1 at the end
  };
  // A cluster under construction.
  struct WorkCluster {
    glm::dvec3 sum_wp_W;
    glm::dvec3 sum_wn_W;
    double sum_w;
    double min_signed_distance_m;
    double depth_bound_m;
    int num_pairs;
    int head, tail;  // member list through PairRecord::next
    bool alive;
    glm::dvec3 point_W, normal_W;  // derived from the sums
    double extent_m;               // derived (clamped window side)
  };
  // One (leaf, pair) incidence for the triangle assignment.
  struct LeafEntry {
    int leaf;
    double signed_distance_m;
    int input_index;
    int cluster;   // final output index
    bool follows;  // tool_leaves_follow_object_leaves: kept whatever the windows
  };

  void Refresh(WorkCluster& c, const ClusteringOptions& options) const noexcept;
  double MergedRawExtent(const WorkCluster& a, const WorkCluster& b,
                         const ClusteringOptions& options) const noexcept;
  // Pass 2's test: windows overlap, normals agree, merged window fits max_extent_m.
  bool MayMerge(const WorkCluster& a, const WorkCluster& b, double cos_max,
                const ClusteringOptions& options) const noexcept;
  void Absorb(int into, int from) noexcept;
  int AssignTriangles(const ConvexHullHierarchy& hulls, bool tool_side, int num_records,
                      int num_out, int write_at, bool share_disjoint,
                      bool follow_object_leaves = false, bool placement_only = false) noexcept;
  // The cluster holding object leaf `leaf` first (its deepest kept pair's), from
  // object_leaf_cluster_; −1 when none.
  int ObjectLeafCluster(int leaf) const noexcept;
  // Whether output clusters a and b have windows that overlap (pass 2's box test on their
  // points, normals and extents).
  bool WindowsOverlap(int a, int b) const noexcept;

  int max_pairs_;
  int max_triangles_;
  std::vector<PairRecord> records_;
  std::vector<int> order_;
  std::vector<WorkCluster> work_;
  std::vector<int> kept_;
  std::vector<int> work_to_out_;
  std::vector<LeafEntry> leaf_entries_;
  // (object leaf, its first cluster), sorted by leaf: the object side's placement, for
  // tool_leaves_follow_object_leaves.
  std::vector<std::pair<int, int>> object_leaf_cluster_;
  int num_object_leaves_ = 0;
  std::vector<int> triangles_;
  std::vector<ContactCluster> out_;
  ClusteringStats stats_;
};

}  // namespace ht
