// Stage 2's traversal of one node pair (2_hull_proximity.cc): the lists a traversal keeps, the
// node-pair order, and NodePairTraversal, the tests one Query call's set-up fixes. Internal to the
// remote step.
#pragma once

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <glm/geometric.hpp>
#include <span>
#include <vector>

#include "2_posed_hull.h"
#include "haptic_core/hull_proximity.h"

namespace ht::hull_traversal {

using hull_geometry::GjkDistance;
using hull_geometry::GjkResult;
using hull_geometry::GjkStatus;
using hull_geometry::IsFiniteContact;
using hull_geometry::kInf;
using hull_geometry::kTouch_m;
using hull_geometry::Overlap;
using hull_geometry::PenetrationContact;
using hull_geometry::PosedHull;
using CoherentPair = HullProximityQuery::CoherentPair;
using FrontPair = HullProximityQuery::FrontPair;
using QueueEntry = HullProximityQuery::QueueEntry;
using Worker = HullProximityQuery::Worker;

// Internal node pairs get a GJK test only when their hulls have at most this many vertices in all
// (docs/measurements.md).
inline constexpr int kInternalGjkMaxVertices = 64;
// A node pair's oriented boxes cull it only when they are this much (m) farther apart than its
// tolerance: far above the rounding of the box test (1e-16 of the models' size), so that a culled
// pair is certainly one the exact test would have dropped.
inline constexpr double kBoxSlack_m = 1e-9;
// Min-heap order on the key.
inline bool HeapAfter(const HullProximityQuery::QueueEntry& x,
                      const HullProximityQuery::QueueEntry& y) noexcept {
  return x.key_m > y.key_m;
}

// Order of node pairs (CoherentPair, FrontPair) by node_A, then node_B.
template <typename Pair>
inline bool PairLess(const Pair& x, const Pair& y) noexcept {
  return x.node_A != y.node_A ? x.node_A < y.node_A : x.node_B < y.node_B;
}

// The entry of (node_A, node_B) in `pairs` (sorted by PairLess), or null.
template <typename Pair>
inline const Pair* FindPair(const std::vector<Pair>& pairs, int node_A, int node_B) noexcept {
  const Pair probe{node_A, node_B, glm::dvec3(0.0)};
  auto it = std::lower_bound(pairs.begin(), pairs.end(), probe, PairLess<Pair>);
  return it != pairs.end() && it->node_A == node_A && it->node_B == node_B ? &*it : nullptr;
}

// Where a traversal keeps its queue, the pairs it finds, their coherent directions, its front and
// its counts: the query's own lists, or one worker's (SetThreads).
struct TraversalLists {
  std::vector<QueueEntry>& queue;
  std::vector<HullPairContact>& results;
  std::vector<CoherentPair>& current;
  std::vector<FrontPair>& current_far;
  std::vector<FrontPair>& front;
  ProximityQueryStats& st;
};

inline TraversalLists ListsOf(Worker& w) noexcept {
  return {w.queue, w.results, w.current, w.current_far, w.front, w.st};
}

// What one Query() call's set-up fixed (the models, B's pose in A's frame, their bounds,
// the options, the previous call's coherent pairs) and the tests of one node pair. Reads nothing
// else, and writes only the lists it is given (and front_overflow), so that workers may run it at
// once on their own lists.
//
// The traversal (bounding spheres, oriented boxes, centre-line overlaps, internal GJK: culling
// and keys only) works in A's frame: A's hulls need no transform there, and B's one matrix
// product per support call (R_AB, p_AB) instead of two quaternion rotations. Leaf pairs, whose
// contacts are the output, are tested in W (PosedHull::QuaternionPath).
class NodePairTraversal {
 public:
  struct Setup {
    const HapticModel& A;
    const RigidTransform& X_WA;
    const HullBounds& bounds_A;
    const HapticModel& B;
    const RigidTransform& X_WB;
    const HullBounds& bounds_B;
    const ProximityQueryOptions& options;
    // The previous call's pairs within and beyond their tolerance (sorted by PairLess), read
    // where `coherent`.
    const std::vector<CoherentPair>& previous;
    const std::vector<FrontPair>& previous_far;
    bool coherent;     // the previous call was on these two models, with coherence
    bool track_front;  // this call's stops make the next call's front
    bool unlimited;    // no time or work budget
    std::size_t max_pairs;
  };

  explicit NodePairTraversal(const Setup& s) noexcept
      : s_(s),
        eps_(s.options.tolerance_m),
        local_reach_(s.options.local_reach_margin_m >= 0.0),
        near_exit_(!s.options.exact_internal_distances && s.unlimited),
        coherent_next_(s.options.temporal_coherence),
        R_AW_(glm::transpose(glm::mat3_cast(s.X_WA.rotation))),
        R_AB_(R_AW_ * glm::mat3_cast(s.X_WB.rotation)),
        R_BA_(glm::transpose(R_AB_)),
        p_AB_(R_AW_ * (s.X_WB.translation - s.X_WA.translation)) {}

  // A lower bound (m) of the distance between the two nodes' bounding spheres.
  double SphereBound(int node_A, int node_B) const noexcept {
    const glm::dvec4& a = s_.bounds_A.spheres_O[Slot(node_A)];
    const glm::dvec4& b = s_.bounds_B.spheres_O[Slot(node_B)];
    return glm::length(glm::dvec3(a) - (R_AB_ * glm::dvec3(b) + p_AB_)) - a.w - b.w;
  }

  // A lower bound (m) of the distance between the two nodes' oriented boxes, and so of their
  // hulls' (the boxes hold them): the largest gap along the boxes' six face normals, the face
  // axes of the separating-axis test of Gottschalk, Lin & Manocha (1996), in A's frame, or the
  // first three's largest where it is above `stop` (m). Negative when the boxes overlap along all
  // six. The test's nine edge-pair axes are left out: they cost more than they cull
  // (docs/measurements.md).
  double BoxGap(int node_A, int node_B, double stop) const noexcept {
    const OrientedBox& a = s_.bounds_A.boxes_O[Slot(node_A)];
    const OrientedBox& b = s_.bounds_B.boxes_O[Slot(node_B)];
    const glm::dmat3 R = glm::transpose(a.axes_O) * (R_AB_ * b.axes_O);  // R[j][i] = a_i · b_j
    const glm::dvec3 t = (R_AB_ * b.center_O + p_AB_ - a.center_O) * a.axes_O;  // along a_i
    const glm::dvec3& ea = a.half_extents_m;
    const glm::dvec3& eb = b.half_extents_m;
    glm::dmat3 Q;  // |R|
    for (int j = 0; j < 3; ++j) Q[j] = glm::abs(R[j]);
    double gap = -kInf;
    for (int i = 0; i < 3; ++i) {  // A's face normals a_i
      const double rb = eb.x * Q[0][i] + eb.y * Q[1][i] + eb.z * Q[2][i];
      gap = std::max(gap, std::abs(t[i]) - ea[i] - rb);
    }
    if (gap > stop) return gap;
    for (int j = 0; j < 3; ++j) {  // B's face normals b_j
      const double ra = glm::dot(ea, Q[j]);
      gap = std::max(gap, std::abs(glm::dot(t, R[j])) - ra - eb[j]);
    }
    return gap;
  }

  // The tolerance (m) of a node pair: ε, or with local reach the pair's own (never larger).
  double PairTolerance(int node_A, int node_B) const noexcept {
    if (!local_reach_) return eps_;
    const double ra = s_.bounds_A.reach_m[Slot(node_A)];
    const double rb = s_.bounds_B.reach_m[Slot(node_B)];
    return std::min(eps_, ra + rb + s_.options.local_reach_margin_m);
  }

  // Node `node` of A (−1: its single hull), posed in A's frame.
  PosedHull PoseA(int node) const noexcept {
    return Pose(s_.A, s_.bounds_A, s_.X_WA, nullptr, nullptr, glm::dvec3(0.0), node);
  }
  // Node `node` of B (−1: its single hull), posed in A's frame.
  PosedHull PoseB(int node) const noexcept {
    return Pose(s_.B, s_.bounds_B, s_.X_WB, &R_AB_, &R_BA_, p_AB_, node);
  }

  // The first node pair of a traversal from the roots: queued unless its spheres and boxes cull
  // it (it then joins the front).
  void StartFromRoots(TraversalLists& t) noexcept {
    const int root_A = s_.A.hull_hierarchy.nodes.empty() ? -1 : 0;
    const int root_B = s_.B.hull_hierarchy.nodes.empty() ? -1 : 0;
    const double lb = SphereBound(root_A, root_B);
    const double eps_root = PairTolerance(root_A, root_B);
    const double gap = lb > eps_root ? kInf : BoxGap(root_A, root_B, eps_root + kBoxSlack_m);
    if (gap > eps_root + kBoxSlack_m) {
      ++t.st.node_pairs_culled;
      StopAt(t, root_A, root_B, glm::dvec3(0.0));
    } else {
      Push(t, lb, root_A, root_B, glm::dvec3(0.0), gap);
    }
  }

  // One queued node pair: a leaf pair is tested and emitted, an internal pair split into its
  // children (queued unless culled).
  void Process(TraversalLists& t, const QueueEntry& e) noexcept {
    const PosedHull hA = PoseA(e.node_A);
    const PosedHull hB = PoseB(e.node_B);
    const bool leaf_A = IsLeaf(s_.A, e.node_A);
    const bool leaf_B = IsLeaf(s_.B, e.node_B);
    ++t.st.node_pairs_tested;
    if (leaf_A && leaf_B) {
      TestLeafPair(t, e, hA, hB);
    } else {
      SplitInternalPair(t, e, hA, hB, leaf_A, leaf_B);
    }
  }

  // A pair of the previous call's front, tested again by the cheap tests, cheapest first: the
  // bounding spheres, the oriented boxes, for a pair that internal GJK culled the overlap along
  // its separating direction then (f.axis_A, nonzero), and the centre-line bound. These are
  // SplitInternalPair's child tests, which stay written out there: a call to this function from
  // its child loop made the query without coherence 8 % slower (docs/measurements.md). A pair
  // none of them culls is queued (key: the bound; GJK's first guess: f.axis_A); one that is
  // culled joins the front again. The hulls are posed only once spheres and boxes pass.
  void RetestFrontPair(TraversalLists& t, const FrontPair& f) noexcept {
    const double lb = SphereBound(f.node_A, f.node_B);
    const double eps_pair = PairTolerance(f.node_A, f.node_B);
    if (lb > eps_pair) {
      ++t.st.node_pairs_culled;
      StopAt(t, f.node_A, f.node_B, glm::dvec3(0.0));
      return;
    }
    const double gap = BoxGap(f.node_A, f.node_B, eps_pair + kBoxSlack_m);
    if (gap > eps_pair + kBoxSlack_m) {
      ++t.st.node_pairs_culled;
      StopAt(t, f.node_A, f.node_B, glm::dvec3(0.0));
      return;
    }
    const PosedHull cA = PoseA(f.node_A);
    const PosedHull cB = PoseB(f.node_B);
    if (glm::dot(f.axis_A, f.axis_A) > 0.0 &&
        -Overlap(cA, cB, f.axis_A) > eps_pair * glm::length(f.axis_A)) {
      ++t.st.node_pairs_culled;
      StopAt(t, f.node_A, f.node_B, f.axis_A);
      return;
    }
    const double bound = CentreLineBound(cA, cB, lb);
    if (bound > eps_pair) {
      ++t.st.node_pairs_culled;
      StopAt(t, f.node_A, f.node_B, glm::dvec3(0.0));
      return;
    }
    Push(t, bound, f.node_A, f.node_B, f.axis_A, gap);
  }

  // Keeps contact c in t.results; when they are full (max_pairs), the deeper of c and the
  // shallowest kept one, counting the drop.
  void Emit(TraversalLists& t, const HullPairContact& c) const noexcept {
    if (t.results.size() < s_.max_pairs) {
      t.results.push_back(c);
      return;
    }
    ++t.st.pairs_dropped;
    if (t.results.empty()) return;
    auto worst = std::max_element(t.results.begin(), t.results.end(),
                                  [](const HullPairContact& x, const HullPairContact& y) {
                                    return x.signed_distance_m < y.signed_distance_m;
                                  });
    if (c.signed_distance_m < worst->signed_distance_m) *worst = c;
  }

  // Set when a front did not fit its room: the next call then starts from the roots.
  std::atomic<bool> front_overflow{false};

 private:
  static std::size_t Slot(int node) noexcept {
    return node < 0 ? 0 : static_cast<std::size_t>(node);
  }
  static bool IsLeaf(const HapticModel& m, int node) noexcept {
    return node < 0 || m.hull_hierarchy.nodes[static_cast<std::size_t>(node)].is_leaf();
  }

  // Node `node` of m (frame O, bounds e, world pose X_WO) posed in the query frame by
  // (R_QO, p_QO); R_QO null: O is the query frame.
  static PosedHull Pose(const HapticModel& m, const HullBounds& e, const RigidTransform& X_WO,
                        const glm::dmat3* R_QO, const glm::dmat3* R_OQ, const glm::dvec3& p_QO,
                        int node) noexcept {
    PosedHull h;
    const glm::dvec4& sph = e.spheres_O[Slot(node)];
    if (node < 0) {
      h.vertices_O = m.hull_vertices_O.data();
      h.vertex_count = m.hull_vertices_O.size();
    } else {
      const ConvexHull& hull = m.hull_hierarchy.nodes[static_cast<std::size_t>(node)].hull;
      h.vertices_O = hull.vertices_O.data();
      h.vertex_count = hull.vertices_O.size();
      h.planes_O = hull.planes_O.data();
      h.plane_count = hull.planes_O.size();
    }
    h.map = R_QO == nullptr ? PosedHull::Map::kIdentity : PosedHull::Map::kMatrix;
    h.R_WO = R_QO;
    h.R_OW = R_OQ;
    h.p_WO = p_QO;
    h.center_W = R_QO == nullptr ? glm::dvec3(sph) : *R_QO * glm::dvec3(sph) + p_QO;
    h.X_WO = &X_WO;
    h.center_O = glm::dvec3(sph);
    h.radius_m = sph.w;
    return h;
  }

  // A node pair's lower bound from the overlap of its hulls' support intervals along the centre
  // line (−overlap ≤ every descendant pair's signed distance), or lb where that is larger.
  static double CentreLineBound(const PosedHull& cA, const PosedHull& cB, double lb) noexcept {
    const glm::dvec3 d = cA.center_W - cB.center_W;
    const double d_len = glm::length(d);
    return d_len > 0.0 ? std::max(lb, -Overlap(cA, cB, d / d_len)) : lb;
  }

  // A node pair where the traversal stops joins this call's front (when it fits; a front that
  // does not fit is not used by the next call).
  void StopAt(TraversalLists& t, int node_A, int node_B, const glm::dvec3& axis_A) noexcept {
    if (!s_.track_front) return;
    if (t.front.size() < t.front.capacity()) {
      t.front.push_back({node_A, node_B, axis_A});
    } else {
      front_overflow.store(true, std::memory_order_relaxed);
    }
  }

  static void Push(TraversalLists& t, double key, int node_A, int node_B, const glm::dvec3& guess_A,
                   double box_gap_m) noexcept {
    t.queue.push_back({key, node_A, node_B, guess_A, box_gap_m});  // grows only during warm-up
    std::push_heap(t.queue.begin(), t.queue.end(), HeapAfter);
  }

  // A leaf pair farther than its tolerance, remembered with the direction (A's frame) that
  // showed it, for the next call.
  static void RememberFar(TraversalLists& t, const QueueEntry& e, const glm::dvec3& v_A) noexcept {
    if (t.current_far.size() < t.current_far.capacity()) {
      t.current_far.push_back({e.node_A, e.node_B, v_A});
    }
  }

  // A leaf pair: culled by the previous call's separating direction where that still separates
  // it; else GJK in W, and for a touching or penetrating pair PenetrationContact. A contact
  // within the pair's tolerance is emitted and remembered for the next call.
  void TestLeafPair(TraversalLists& t, const QueueEntry& e, const PosedHull& hA,
                    const PosedHull& hB) noexcept {
    const double eps_e = PairTolerance(e.node_A, e.node_B);
    ++t.st.leaf_pairs_tested;
    StopAt(t, e.node_A, e.node_B, glm::dvec3(0.0));
    const CoherentPair* prev = nullptr;
    const FrontPair* prev_far = nullptr;
    if (s_.coherent) {
      prev = FindPair(s_.previous, e.node_A, e.node_B);
      if (prev == nullptr) prev_far = FindPair(s_.previous_far, e.node_A, e.node_B);
    }
    if (prev_far != nullptr) {
      // The previous call's separating direction v: the hulls' support intervals along it are at
      // least −Overlap/|v| apart, a lower bound of their distance. Still beyond the tolerance:
      // dropped, as GJK would have (it reports only pairs within it).
      const glm::dvec3& v_A = prev_far->axis_A;
      if (-Overlap(hA, hB, v_A) > eps_e * glm::length(v_A)) {
        ++t.st.coherent_culls;
        RememberFar(t, e, v_A);
        return;
      }
    }
    // Leaf pairs in W with the quaternion arithmetic (QuaternionPath): their contacts are the
    // remote step's output, and downstream a window moved by a last bit can flip a cell that lies
    // exactly on a triangle's edge (the striped blocks of fig76 are axis-aligned). First guess:
    // this pair's direction in the previous query, else the centre line.
    const PosedHull wA = hA.QuaternionPath(), wB = hB.QuaternionPath();
    const GjkResult g =
        GjkDistance(wA, wB, prev != nullptr ? prev->direction_W : glm::dvec3(0.0), eps_e);
    if (g.status == GjkStatus::kFar) {
      if (coherent_next_) RememberFar(t, e, R_AW_ * g.v);
      return;
    }
    HullPairContact c;
    if (g.status == GjkStatus::kSeparated) {
      if (g.distance_m > eps_e) {
        if (coherent_next_) RememberFar(t, e, R_AW_ * g.v);
        return;
      }
      c.signed_distance_m = g.distance_m;
      c.normal_W = g.v / g.distance_m;
      c.point_A_W = g.p_A;
      c.point_B_W = g.p_B;
    } else {
      c = PenetrationContact(wA, wB, prev != nullptr ? &prev->direction_W : nullptr);
      // Touching within GJK's tolerance counts as within ε even when the support intervals leave
      // a gap of a few 1e-13 m.
      if (c.signed_distance_m > eps_e + kTouch_m) return;
    }
    c.node_A = e.node_A;
    c.node_B = e.node_B;
    if (!IsFiniteContact(c)) {
      ++t.st.numerical_faults;
      return;
    }
    if (prev != nullptr) ++t.st.coherent_hits;
    Emit(t, c);
    if (t.current.size() < t.current.capacity()) {
      t.current.push_back({c.node_A, c.node_B, c.normal_W});
    }
  }

  // An internal pair: GJK, stopping as soon as the hulls are known to be farther than ε; skipped
  // for big hulls, whose support functions cost more than descending (the children's sphere, box
  // and centre-line tests then do the culling). Then its children, each queued unless its
  // spheres, boxes or centre-line overlap cull it (a culled pair joins the front).
  void SplitInternalPair(TraversalLists& t, const QueueEntry& e, const PosedHull& hA,
                         const PosedHull& hB, bool leaf_A, bool leaf_B) noexcept {
    const double eps_e = PairTolerance(e.node_A, e.node_B);
    GjkResult g;
    g.status = GjkStatus::kTouching;
    // Without a budget GJK is here only to cull: it stops as soon as the hulls are certainly
    // within ε (kNear), since then the pair descends whatever their exact distance; and it is
    // skipped where the pair's boxes overlap along all their face normals, where it hardly ever
    // culls (docs/measurements.md). With a budget the exact distance keeps the best-first order
    // sharp.
    const bool small =
        hA.vertex_count + hB.vertex_count <= static_cast<std::size_t>(kInternalGjkMaxVertices);
    if (small && !(near_exit_ && e.box_gap_m < 0.0)) {
      g = GjkDistance(hA, hB, e.guess_A, eps_e, near_exit_ ? eps_e : -1.0);
    }
    if (g.status == GjkStatus::kFar ||
        (g.status == GjkStatus::kSeparated && g.distance_m > eps_e)) {
      StopAt(t, e.node_A, e.node_B, g.v);
      return;
    }
    double key = e.key_m;
    if (g.status == GjkStatus::kSeparated || g.status == GjkStatus::kNear) {
      key = std::max(key, g.distance_m);
    } else if (!near_exit_) {
      // Overlapping: any direction's overlap bounds the penetration depth of every descendant
      // pair from above (descendant hulls lie inside these), so −overlap is a lower bound. (Keys
      // order the queue, which only a budget makes matter.)
      glm::dvec3 n = hA.center_W - hB.center_W;
      const double len = glm::length(n);
      if (len > 0.0) key = std::max(key, -Overlap(hA, hB, n / len));
    }
    // Without a budget, descend into both nodes where both are internal: each pair tested then
    // rules on four pairs below it, which cuts the internal pairs tested (docs/measurements.md).
    // With a budget, into the larger node (by bounding radius) only, which keeps the best-first
    // order's keys sharp. Leaves are never split.
    const bool split_A = !leaf_A && (leaf_B || s_.unlimited || hA.radius_m >= hB.radius_m);
    const bool split_B = !leaf_B && (leaf_A || s_.unlimited || !split_A);
    const auto children = [](const HapticModel& m, int node, bool split, const int& self) {
      return split ? std::span<const int>(
                         m.hull_hierarchy.nodes[static_cast<std::size_t>(node)].children)
                   : std::span<const int>(&self, 1);
    };
    const std::span<const int> next_A = children(s_.A, e.node_A, split_A, e.node_A);
    const std::span<const int> next_B = children(s_.B, e.node_B, split_B, e.node_B);
    const int count_A = static_cast<int>(s_.A.hull_hierarchy.nodes.size());
    const int count_B = static_cast<int>(s_.B.hull_hierarchy.nodes.size());
    for (const int node_A : next_A) {
      if (split_A && (node_A < 0 || node_A >= count_A)) continue;
      const PosedHull cA = !split_A ? hA : PoseA(node_A);
      for (const int node_B : next_B) {
        if (split_B && (node_B < 0 || node_B >= count_B)) continue;
        // Cheapest first: the bounding spheres, the oriented boxes, then the support intervals'
        // overlap along the centre line.
        const double lb = SphereBound(node_A, node_B);
        const double eps_child = PairTolerance(node_A, node_B);
        if (lb > eps_child) {
          ++t.st.node_pairs_culled;
          StopAt(t, node_A, node_B, glm::dvec3(0.0));
          continue;
        }
        const double gap = BoxGap(node_A, node_B, eps_child + kBoxSlack_m);
        if (gap > eps_child + kBoxSlack_m) {
          ++t.st.node_pairs_culled;
          StopAt(t, node_A, node_B, glm::dvec3(0.0));
          continue;
        }
        const PosedHull cB = !split_B ? hB : PoseB(node_B);
        const double bound = CentreLineBound(cA, cB, lb);
        if (bound > eps_child) {
          ++t.st.node_pairs_culled;
          StopAt(t, node_A, node_B, glm::dvec3(0.0));
          continue;
        }
        Push(t, std::max(key, bound), node_A, node_B, g.v, gap);
      }
    }
  }

  const Setup s_;
  const double eps_;
  const bool local_reach_;
  const bool near_exit_;  // internal GJK stops once the pair is known to be within ε
  const bool coherent_next_;
  const glm::dmat3 R_AW_, R_AB_, R_BA_;
  const glm::dvec3 p_AB_;
};

}  // namespace ht::hull_traversal
