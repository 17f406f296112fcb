#include "haptic_core/contact_clustering.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdlib>
#include <glm/geometric.hpp>
#include <limits>
#include <new>
#include <numbers>
#include <random>
#include <set>
#include <vector>

#include "haptic_core/penetration_depth.h"
#include "haptic_core/remote_step.h"

// Counts every global allocation of this test binary, to check that Cluster() makes none after
// warm-up. Kept out of line so that GCC does not pair an inlined malloc with a free
// (-Wmismatched-new-delete).
namespace {
std::atomic<long> g_allocations{0};
}  // namespace

[[gnu::noinline]] void* operator new(std::size_t size) {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  if (void* p = std::malloc(size == 0 ? 1 : size)) return p;
  throw std::bad_alloc();
}
[[gnu::noinline]] void operator delete(void* p) noexcept { std::free(p); }
[[gnu::noinline]] void operator delete(void* p, std::size_t) noexcept { std::free(p); }

namespace ht {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

// A pair whose contact point (the witnesses' midpoint) is p_W, with witnesses d/2 apart along n
// on either side (point_A − point_B = d·n).
HullPairContact MakePair(const glm::dvec3& p_W, const glm::dvec3& n_W, double d, int node_A,
                         int node_B) {
  HullPairContact pair;
  pair.node_A = node_A;
  pair.node_B = node_B;
  pair.signed_distance_m = d;
  pair.normal_W = n_W;
  pair.point_A_W = p_W + 0.5 * d * n_W;
  pair.point_B_W = p_W - 0.5 * d * n_W;
  return pair;
}

// A "hierarchy" of `num_leaves` leaves, leaf i holding triangles [i·k, i·k + k). The clusterer
// only reads the leaves' triangle lists.
ConvexHullHierarchy MakeLeaves(int num_leaves, int k = 3) {
  ConvexHullHierarchy h;
  h.nodes.resize(num_leaves);
  for (int i = 0; i < num_leaves; ++i)
    for (int t = 0; t < k; ++t) h.nodes[i].triangles.push_back(i * k + t);
  return h;
}

// The weight, written from the documentation (second route to the clusterer's number).
double ReferenceWeight(double d, double f) { return d <= 0.0 ? f - d : f * std::exp(-d / f); }

glm::dvec3 RandomUnitNear(const glm::dvec3& n, double max_angle_rad, std::mt19937& rng) {
  std::uniform_real_distribution<double> uni(-1.0, 1.0);
  glm::dvec3 t;
  do {
    t = {uni(rng), uni(rng), uni(rng)};
    t -= glm::dot(t, n) * n;
  } while (glm::length(t) < 1e-3);
  const double angle = 0.5 * (uni(rng) + 1.0) * max_angle_rad;
  return std::cos(angle) * n + std::sin(angle) * glm::normalize(t);
}

// Every triangle index appears in at most one cluster per side; every span lies in one storage.
void ExpectNoTriangleTwice(std::span<const ContactCluster> clusters) {
  std::set<int> tool, object;
  for (const ContactCluster& c : clusters) {
    for (const int t : c.tool_triangles) EXPECT_TRUE(tool.insert(t).second) << "tool tri " << t;
    for (const int t : c.object_triangles)
      EXPECT_TRUE(object.insert(t).second) << "object tri " << t;
  }
}

// Finite, unit normals, extents in range, members' witnesses inside the window made from the
// cluster by ContactWindow::Make (unless the extent was clamped at its maximum).
void ExpectWellFormed(std::span<const ContactCluster> clusters, const ClusteringOptions& options) {
  for (const ContactCluster& c : clusters) {
    EXPECT_TRUE(std::isfinite(c.point_W.x) && std::isfinite(c.point_W.y) &&
                std::isfinite(c.point_W.z));
    EXPECT_NEAR(glm::length(c.normal_W), 1.0, 1e-12);
    EXPECT_GE(c.extent_m, options.min_extent_m);
    EXPECT_LE(c.extent_m, options.max_extent_m);
    EXPECT_GE(c.num_pairs, 1);
    EXPECT_GT(c.total_weight_m, 0.0);
    EXPECT_NO_THROW(ContactWindow::Make(c.point_W, c.normal_W, c.extent_m, 50));
  }
  ExpectNoTriangleTwice(clusters);
}

// Σ w p / Σ w and normalize(Σ w n) over `members`, computed here.
struct Reference {
  glm::dvec3 point{0.0}, normal{0.0};
  double min_d = kInf;
  double half_spread = 0.0;  // in the axes ContactWindow::Make picks for `normal`
};
Reference ComputeReference(const std::vector<HullPairContact>& members, double floor_m) {
  Reference ref;
  double sw = 0.0;
  glm::dvec3 swp(0.0), swn(0.0);
  for (const HullPairContact& p : members) {
    const double w = ReferenceWeight(p.signed_distance_m, floor_m);
    sw += w;
    swp += w * 0.5 * (p.point_A_W + p.point_B_W);
    swn += w * p.normal_W;
    ref.min_d = std::min(ref.min_d, p.signed_distance_m);
  }
  ref.point = swp / sw;
  ref.normal = glm::normalize(swn);
  const ContactWindow window = ContactWindow::Make(ref.point, ref.normal, 1.0, 2);
  for (const HullPairContact& p : members) {
    for (const glm::dvec3& q : {p.point_A_W, p.point_B_W}) {
      ref.half_spread =
          std::max({ref.half_spread, std::abs(glm::dot(q - ref.point, window.axis_u_W)),
                    std::abs(glm::dot(q - ref.point, window.axis_v_W))});
    }
  }
  return ref;
}

// The cluster nearest to p.
const ContactCluster& Nearest(std::span<const ContactCluster> clusters, const glm::dvec3& p) {
  const ContactCluster* best = &clusters[0];
  for (const ContactCluster& c : clusters)
    if (glm::length(c.point_W - p) < glm::length(best->point_W - p)) best = &c;
  return *best;
}

TEST(ContactClustering, SeedCase104PairsOnSevenSeparatedSpotsGiveSevenWeightedClusters) {
  std::mt19937 rng(104);
  std::uniform_real_distribution<double> uni(-1.0, 1.0);
  const ClusteringOptions options;
  std::vector<glm::dvec3> centers, normals;
  std::vector<std::vector<HullPairContact>> spots(7);
  std::vector<HullPairContact> pairs;
  for (int s = 0; s < 7; ++s) {
    centers.push_back({0.05 * s, 0.03 * (s % 2), 0.01 * s});
    normals.push_back(RandomUnitNear(glm::dvec3(0, 0, 1), 1.2, rng));
  }
  for (int i = 0; i < 104; ++i) {
    const int s = i % 7;
    glm::dvec3 offset;
    do {
      offset = {uni(rng), uni(rng), uni(rng)};
    } while (glm::length(offset) > 1.0);
    const glm::dvec3 p = centers[s] + 1.5e-3 * offset;
    const glm::dvec3 n = RandomUnitNear(normals[s], 5.0 * std::numbers::pi / 180.0, rng);
    const double d = -1e-3 + 1.2e-3 * 0.5 * (uni(rng) + 1.0);  // [−1, 0.2] mm
    pairs.push_back(MakePair(p, n, d, i, 200 + i));
    spots[s].push_back(pairs.back());
  }
  ContactClusterer clusterer;
  const auto clusters = clusterer.Cluster(pairs, MakeLeaves(104), MakeLeaves(304), options);
  ASSERT_EQ(clusters.size(), 7u);
  EXPECT_EQ(clusterer.skipped_nonfinite(), 0);
  EXPECT_EQ(clusterer.merged_for_capacity(), 0);
  ExpectWellFormed(clusters, options);
  int total_tool_triangles = 0;
  for (int s = 0; s < 7; ++s) {
    const Reference ref = ComputeReference(spots[s], options.weight_floor_m);
    const ContactCluster& c = Nearest(clusters, centers[s]);
    EXPECT_EQ(c.num_pairs, static_cast<int>(spots[s].size()));
    EXPECT_NEAR(glm::length(c.point_W - ref.point), 0.0, 1e-12);
    EXPECT_NEAR(glm::length(c.normal_W - ref.normal), 0.0, 1e-12);
    EXPECT_EQ(c.min_signed_distance_m, ref.min_d);
    EXPECT_NEAR(c.extent_m,
                std::clamp(2.0 * (ref.half_spread + options.texture_margin_m), options.min_extent_m,
                           options.max_extent_m),
                1e-12);
    // Each pair's leaves give 3 triangles per side.
    EXPECT_EQ(c.tool_triangles.size(), 3 * spots[s].size());
    EXPECT_EQ(c.object_triangles.size(), 3 * spots[s].size());
    total_tool_triangles += static_cast<int>(c.tool_triangles.size());
  }
  EXPECT_EQ(total_tool_triangles, 3 * 104);
  // Deepest first.
  for (std::size_t i = 1; i < clusters.size(); ++i)
    EXPECT_LE(clusters[i - 1].min_signed_distance_m, clusters[i].min_signed_distance_m);
}

TEST(ContactClustering, CornerSpotsWithinMergeDistanceButNormals90DegApartStaySeparate) {
  const ClusteringOptions options;
  std::vector<HullPairContact> pairs;
  for (int i = 0; i < 5; ++i) {
    pairs.push_back(MakePair({0.0, 0.3e-3 * i, 0.0}, {0, 0, 1}, -2e-4, i, 10 + i));
    pairs.push_back(MakePair({2e-3, 0.3e-3 * i, 1e-3}, {1, 0, 0}, -1e-4, 5 + i, 15 + i));
  }
  ContactClusterer clusterer;
  const auto clusters = clusterer.Cluster(pairs, MakeLeaves(10), MakeLeaves(20), options);
  ASSERT_EQ(clusters.size(), 2u);
  ExpectWellFormed(clusters, options);
  EXPECT_NEAR(glm::length(clusters[0].normal_W - glm::dvec3(0, 0, 1)), 0.0, 1e-12);
  EXPECT_NEAR(glm::length(clusters[1].normal_W - glm::dvec3(1, 0, 0)), 0.0, 1e-12);
  // Their windows overlap (2 mm apart, ≥ 2 mm wide each): still two contacts.
  EXPECT_EQ(clusterer.stats().clusters_pass2, 2);
}

// The pipeline clusters at 60° (kClusteringAngleDeg). One contact
// region whose hull pairs carry normals 45° apart (a curved or
// thin coarse hull) was two contacts at 30°, and object leaf 0, whose deepest pair is on the
// tilted side, went there while tool leaf 1, which overlaps it, stayed with the other: pair
// (1, 0) was rendered in no window. At the pipeline's angle it is one contact holding every
// leaf; faces 90° apart (an L corner) stay two.
TEST(ContactClustering, OneRegionsPairs45DegApartAreOneContactAtThePipelinesAngle) {
  const double c = std::cos(std::numbers::pi / 4.0);
  const std::vector<HullPairContact> pairs = {
      MakePair({0, 0, 0}, {0, 0, 1}, -3e-4, 0, 1),
      MakePair({0, 1e-3, 0}, {0, 0, 1}, -1e-4, 1, 0),
      MakePair({1e-3, 0, 0}, {0, c, c}, -2e-4, 2, 0),
  };
  // Whether some cluster lists both leaves of a pair (tool leaf a, object leaf b; 3 triangles
  // each).
  const auto rendered = [](std::span<const ContactCluster> clusters, int a, int b) {
    return std::any_of(clusters.begin(), clusters.end(), [&](const ContactCluster& k) {
      const bool has_a = std::find(k.tool_triangles.begin(), k.tool_triangles.end(), 3 * a) !=
                         k.tool_triangles.end();
      const bool has_b = std::find(k.object_triangles.begin(), k.object_triangles.end(), 3 * b) !=
                         k.object_triangles.end();
      return has_a && has_b;
    });
  };
  ClusteringOptions before;
  before.max_normal_angle_deg = 30.0;
  ContactClusterer clusterer;
  auto clusters = clusterer.Cluster(pairs, MakeLeaves(3), MakeLeaves(2), before);
  ASSERT_EQ(clusters.size(), 2u);
  EXPECT_FALSE(rendered(clusters, 1, 0)) << "at 30° the pair (1, 0) lies in no window";
  ClusteringOptions now;
  now.max_normal_angle_deg = kClusteringAngleDeg;
  EXPECT_EQ(now.max_normal_angle_deg, 60.0);
  clusters = clusterer.Cluster(pairs, MakeLeaves(3), MakeLeaves(2), now);
  ASSERT_EQ(clusters.size(), 1u);
  ExpectWellFormed(clusters, now);
  for (const HullPairContact& p : pairs) EXPECT_TRUE(rendered(clusters, p.node_A, p.node_B));
  // The corner of the test above, at the pipeline's angle: still two contacts.
  std::vector<HullPairContact> corner;
  for (int i = 0; i < 5; ++i) {
    corner.push_back(MakePair({0.0, 0.3e-3 * i, 0.0}, {0, 0, 1}, -2e-4, i, 10 + i));
    corner.push_back(MakePair({2e-3, 0.3e-3 * i, 1e-3}, {1, 0, 0}, -1e-4, 5 + i, 15 + i));
  }
  EXPECT_EQ(clusterer.Cluster(corner, MakeLeaves(10), MakeLeaves(20), now).size(), 2u);
}

// Issue 31's grazing guard: each cluster reports the largest of its members' depth bounds, and
// +∞ when the caller gives none (or a list of the wrong length).
TEST(ContactClustering, EachClusterCarriesItsMembersLargestDepthBound) {
  const ClusteringOptions options;
  std::vector<HullPairContact> pairs;
  std::vector<double> bounds;
  for (int i = 0; i < 5; ++i) {
    pairs.push_back(MakePair({0.0, 0.3e-3 * i, 0.0}, {0, 0, 1}, -2e-4, i, 10 + i));
    bounds.push_back(1e-3 * (i + 1));  // 1..5 mm on the first spot
    pairs.push_back(MakePair({2e-3, 0.3e-3 * i, 1e-3}, {1, 0, 0}, -1e-4, 5 + i, 15 + i));
    bounds.push_back(0.5e-3);  // the second spot's
  }
  ContactClusterer clusterer;
  auto clusters = clusterer.Cluster(pairs, MakeLeaves(10), MakeLeaves(20), options, bounds);
  ASSERT_EQ(clusters.size(), 2u);
  EXPECT_EQ(clusters[0].depth_bound_m, 5e-3);
  EXPECT_EQ(clusters[1].depth_bound_m, 0.5e-3);
  clusters = clusterer.Cluster(pairs, MakeLeaves(10), MakeLeaves(20), options);
  ASSERT_EQ(clusters.size(), 2u);
  EXPECT_TRUE(std::isinf(clusters[0].depth_bound_m));
  bounds.pop_back();
  clusters = clusterer.Cluster(pairs, MakeLeaves(10), MakeLeaves(20), options, bounds);
  EXPECT_TRUE(std::isinf(clusters[1].depth_bound_m));
}

TEST(ContactClustering, LeafSharedByTwoClustersGoesToTheClusterOfItsDeepestPair) {
  const ClusteringOptions options;
  // Object leaf 0 touches both faces of a corner; its deepest pair is on the +x face.
  std::vector<HullPairContact> pairs = {
      MakePair({0, 0, 0}, {0, 0, 1}, -3e-4, 0, 1),
      MakePair({0, 1e-3, 0}, {0, 0, 1}, -1e-4, 1, 0),
      MakePair({2e-3, 0, 1e-3}, {1, 0, 0}, -2e-4, 2, 0),
      MakePair({2e-3, 1e-3, 1e-3}, {1, 0, 0}, -1e-4, 3, 2),
  };
  ContactClusterer clusterer;
  const auto clusters = clusterer.Cluster(pairs, MakeLeaves(4), MakeLeaves(3), options);
  ASSERT_EQ(clusters.size(), 2u);
  ExpectWellFormed(clusters, options);
  // clusters[0]: +z (deepest, −0.3 mm), object leaves {1}; clusters[1]: +x, object leaves {0, 2}.
  EXPECT_EQ(
      std::vector<int>(clusters[0].object_triangles.begin(), clusters[0].object_triangles.end()),
      (std::vector<int>{3, 4, 5}));
  EXPECT_EQ(
      std::vector<int>(clusters[1].object_triangles.begin(), clusters[1].object_triangles.end()),
      (std::vector<int>{0, 1, 2, 6, 7, 8}));
  EXPECT_EQ(clusters[0].tool_triangles.size(), 6u);
  EXPECT_EQ(clusters[1].tool_triangles.size(), 6u);
}

// Issue 32's twenty-ninth stop: with tool_leaves_follow_object_leaves every kept pair has its
// two leaves in one cluster. The corner above: tool leaf 1 meets object leaf 0 only on the +z
// face, but object leaf 0 went to the +x cluster (its deepest pair), so pair (1, 0) is rendered in
// no window unless tool leaf 1 follows it there. On random pairs: every pair held by some
// cluster, the object's lists unchanged, and each object triangle still in one cluster.
TEST(ContactClustering, ToolLeavesFollowTheirPairsObjectLeaves) {
  const std::vector<HullPairContact> corner = {
      MakePair({0, 0, 0}, {0, 0, 1}, -3e-4, 0, 1),
      MakePair({0, 1e-3, 0}, {0, 0, 1}, -1e-4, 1, 0),
      MakePair({2e-3, 0, 1e-3}, {1, 0, 0}, -2e-4, 2, 0),
      MakePair({2e-3, 1e-3, 1e-3}, {1, 0, 0}, -1e-4, 3, 2),
  };
  const auto list = [](std::span<const int> v) { return std::set<int>(v.begin(), v.end()); };
  // Whether some cluster renders both leaves of `pair` (leaf i holds triangles 3i..3i+2).
  const auto held = [&](std::span<const ContactCluster> clusters, const HullPairContact& pair) {
    return std::any_of(clusters.begin(), clusters.end(), [&](const ContactCluster& c) {
      return list(c.tool_triangles).count(3 * pair.node_A) > 0 &&
             list(c.object_triangles).count(3 * pair.node_B) > 0;
    });
  };
  ClusteringOptions options;
  ContactClusterer before_clusterer, after_clusterer;
  auto before = before_clusterer.Cluster(corner, MakeLeaves(4), MakeLeaves(3), options);
  options.tool_leaves_follow_object_leaves = true;
  auto after = after_clusterer.Cluster(corner, MakeLeaves(4), MakeLeaves(3), options);
  ASSERT_EQ(before.size(), 2u);
  ASSERT_EQ(after.size(), 2u);
  EXPECT_FALSE(held(before, corner[1]));
  for (const HullPairContact& p : corner) EXPECT_TRUE(held(after, p)) << p.node_A << p.node_B;
  // Tool leaf 1 is now in both windows: the +z one (its own pair's) and the +x one.
  EXPECT_EQ(list(after[0].tool_triangles), (std::set<int>{0, 1, 2, 3, 4, 5}));
  EXPECT_EQ(list(after[1].tool_triangles), (std::set<int>{3, 4, 5, 6, 7, 8, 9, 10, 11}));
  for (std::size_t c = 0; c < 2; ++c) {
    EXPECT_EQ(list(before[c].object_triangles), list(after[c].object_triangles));
  }

  std::mt19937 rng(29);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  std::uniform_int_distribution<int> leaf(0, 11);
  int checked = 0;
  for (int trial = 0; trial < 50; ++trial) {
    std::vector<HullPairContact> pairs;
    for (int i = 0; i < 40; ++i) {
      const glm::dvec3 n =
          trial % 2 == 0 ? glm::dvec3(0, 0, 1) : RandomUnitNear({0, 0, 1}, 1.5, rng);
      pairs.push_back(MakePair({0.02 * U(rng), 0.02 * U(rng), 0.005 * U(rng)}, n,
                               -2e-4 * (1.0 + U(rng)), leaf(rng), leaf(rng)));
    }
    options.tool_leaves_follow_object_leaves = false;
    before = before_clusterer.Cluster(pairs, MakeLeaves(12), MakeLeaves(12), options);
    options.tool_leaves_follow_object_leaves = true;
    after = after_clusterer.Cluster(pairs, MakeLeaves(12), MakeLeaves(12), options);
    ASSERT_EQ(before.size(), after.size());
    std::set<int> object_seen;
    for (std::size_t c = 0; c < after.size(); ++c) {
      EXPECT_EQ(list(before[c].object_triangles), list(after[c].object_triangles));
      const std::set<int> a = list(after[c].tool_triangles);
      for (const int t : before[c].tool_triangles) EXPECT_EQ(a.count(t), 1u);  // nothing lost
      for (const int t : after[c].object_triangles) EXPECT_TRUE(object_seen.insert(t).second);
    }
    // Where no cluster was dropped every pair is kept, and each is held by one cluster.
    if (after_clusterer.dropped_for_capacity() > 0) continue;
    ++checked;
    for (const HullPairContact& p : pairs) {
      EXPECT_TRUE(held(after, p)) << "trial " << trial << " pair " << p.node_A << " " << p.node_B;
    }
  }
  EXPECT_GE(checked, 25);
}

TEST(ContactClustering, LeafSharedByClustersWithDisjointWindowsServesEachOfThem) {
  // Object leaf 0 (one large face) is met by three clusters: A (deepest) and B 5 cm apart along
  // its up normal, whose 2 cm windows are disjoint, and C 5 mm from A along a normal 90° away
  // (no merge), whose window overlaps A's. Shared, the leaf serves A and B and not C; unshared,
  // A alone (the cluster of its deepest pair).
  ClusteringOptions options;
  options.min_extent_m = options.max_extent_m = 0.02;
  const std::vector<HullPairContact> pairs = {
      MakePair({0, 0, 0}, {0, 0, 1}, -3e-4, 0, 0),
      MakePair({0.05, 0, 0}, {0, 0, 1}, -2e-4, 1, 0),
      MakePair({0.005, 0, 1e-3}, {1, 0, 0}, -1e-4, 2, 0),
  };
  const auto object_list = [](const ContactCluster& c) {
    return std::vector<int>(c.object_triangles.begin(), c.object_triangles.end());
  };
  for (const bool share : {false, true}) {
    options.share_leaves_between_disjoint_windows = share;
    ContactClusterer clusterer;
    const auto clusters = clusterer.Cluster(pairs, MakeLeaves(3), MakeLeaves(1), options);
    ASSERT_EQ(clusters.size(), 3u);
    // Well formed; with sharing A and B list the same triangles (their windows are disjoint).
    if (!share) ExpectWellFormed(clusters, options);
    EXPECT_EQ(object_list(clusters[0]), (std::vector<int>{0, 1, 2})) << share;
    EXPECT_EQ(object_list(clusters[1]), share ? (std::vector<int>{0, 1, 2}) : std::vector<int>{})
        << share;
    EXPECT_TRUE(object_list(clusters[2]).empty()) << share;
    // The tool's leaves are one per cluster either way.
    for (const ContactCluster& c : clusters) EXPECT_EQ(c.tool_triangles.size(), 3u);
    ExpectNoTriangleTwice(clusters.subspan(1));  // B and C share nothing
    ExpectNoTriangleTwice(std::array<ContactCluster, 2>{clusters[0], clusters[2]});  // A and C
  }
}

TEST(ContactClustering, ChainOfOverlappingWindowsMergesIntoOneContact) {
  const ClusteringOptions options;
  // 24 pairs 1.5 mm apart over 34.5 mm: pass 1 (5 mm from the running centroid) cuts the chain
  // into pieces whose windows (spread + 1 mm margin) overlap their neighbours'.
  std::vector<HullPairContact> pairs;
  for (int i = 0; i < 24; ++i)
    pairs.push_back(MakePair({1.5e-3 * i, 0, 0}, {0, 0, 1}, -1e-4, i, i));
  ContactClusterer clusterer;
  const auto clusters = clusterer.Cluster(pairs, MakeLeaves(24), MakeLeaves(24), options);
  ASSERT_EQ(clusters.size(), 1u);
  EXPECT_GT(clusterer.stats().clusters_pass1, 1);  // pass 2 did the merging
  ExpectWellFormed(clusters, options);
  const Reference ref = ComputeReference(pairs, options.weight_floor_m);
  EXPECT_NEAR(glm::length(clusters[0].point_W - glm::dvec3(17.25e-3, 0, 0)), 0.0, 1e-12);
  EXPECT_NEAR(glm::length(clusters[0].point_W - ref.point), 0.0, 1e-12);
  EXPECT_NEAR(clusters[0].extent_m, 2.0 * (17.25e-3 + options.texture_margin_m), 1e-12);
  EXPECT_EQ(clusters[0].num_pairs, 24);
  EXPECT_EQ(clusters[0].tool_triangles.size(), 72u);
}

TEST(ContactClustering, SeparatedWindowsAlongAChainStaySeparate) {
  const ClusteringOptions options;
  // 4 mm apart: pass 1 pairs them up, and 2 mm gaps remain between the windows.
  std::vector<HullPairContact> pairs;
  for (int i = 0; i < 12; ++i) pairs.push_back(MakePair({4e-3 * i, 0, 0}, {0, 0, 1}, -1e-4, i, i));
  ContactClusterer clusterer;
  const auto clusters = clusterer.Cluster(pairs, MakeLeaves(12), MakeLeaves(12), options);
  EXPECT_EQ(clusters.size(), 6u);
  EXPECT_EQ(clusterer.stats().clusters_pass1, 6);
  ExpectWellFormed(clusters, options);
}

TEST(ContactClustering, ChainLongerThanTheLargestWindowSplitsWithoutSharingTriangles) {
  const ClusteringOptions options;
  std::vector<HullPairContact> pairs;
  // 30 pairs over 116 mm; tool leaves shared by neighbours (leaf i/2).
  for (int i = 0; i < 30; ++i)
    pairs.push_back(MakePair({4e-3 * i, 0, 0}, {0, 0, 1}, -1e-4 * (1 + i % 3), i / 2, i));
  ContactClusterer clusterer;
  const auto clusters = clusterer.Cluster(pairs, MakeLeaves(15), MakeLeaves(30), options);
  ASSERT_GE(clusters.size(), 3u);
  ASSERT_LE(clusters.size(), static_cast<std::size_t>(kMaxContacts));
  ExpectWellFormed(clusters, options);
  int members = 0;
  std::size_t tool_tris = 0;
  for (const ContactCluster& c : clusters) {
    members += c.num_pairs;
    tool_tris += c.tool_triangles.size();
  }
  EXPECT_EQ(members, 30);
  EXPECT_EQ(tool_tris, 45u);  // each of the 15 tool leaves once
}

TEST(ContactClustering, MoreSeparatedClustersThanMaxContactsKeepsTheDeepestAndCountsDropped) {
  ClusteringOptions options;
  options.max_contacts = 7;
  std::vector<HullPairContact> pairs;
  std::vector<double> depths;
  for (int s = 0; s < 20; ++s) {
    const double d = -1e-4 * ((s * 7) % 20 + 1);  // a permutation of −0.1 … −2 mm
    depths.push_back(d);
    for (int k = 0; k < 3; ++k)
      pairs.push_back(MakePair({0.1 * s, 0.5e-3 * k, 0}, {0, 0, 1}, d, 3 * s + k, 3 * s + k));
  }
  ContactClusterer clusterer;
  const auto clusters = clusterer.Cluster(pairs, MakeLeaves(60), MakeLeaves(60), options);
  ASSERT_EQ(clusters.size(), 7u);
  EXPECT_EQ(clusterer.dropped_for_capacity(), 13);
  EXPECT_EQ(clusterer.merged_for_capacity(), 0);
  ExpectWellFormed(clusters, options);
  std::sort(depths.begin(), depths.end());
  for (int i = 0; i < 7; ++i) EXPECT_EQ(clusters[i].min_signed_distance_m, depths[i]);
}

TEST(ContactClustering, SurplusClustersMergeIntoTheNearestKeptOneWhenTheWindowFits) {
  ClusteringOptions options;
  options.max_contacts = 7;
  std::vector<HullPairContact> pairs;
  std::vector<double> depths;
  for (int s = 0; s < 20; ++s) {
    const double d = -1e-4 * ((s * 7) % 20 + 1);
    depths.push_back(d);
    pairs.push_back(MakePair({8e-3 * s, 0, 0}, {0, 0, 1}, d, s, s));
  }
  ContactClusterer clusterer;
  const auto clusters = clusterer.Cluster(pairs, MakeLeaves(20), MakeLeaves(20), options);
  ASSERT_LE(clusters.size(), 7u);
  EXPECT_EQ(clusterer.stats().clusters_pass2, 20);
  EXPECT_EQ(clusterer.merged_for_capacity() + clusterer.dropped_for_capacity(),
            20 - static_cast<int>(clusters.size()));
  EXPECT_GT(clusterer.merged_for_capacity(), 0);
  ExpectWellFormed(clusters, options);
  int members = 0;
  for (const ContactCluster& c : clusters) members += c.num_pairs;
  EXPECT_EQ(members, 20 - clusterer.dropped_for_capacity());
  std::sort(depths.begin(), depths.end());
  for (std::size_t i = 0; i < clusters.size(); ++i)
    EXPECT_EQ(clusters[i].min_signed_distance_m, depths[i]);
}

TEST(ContactClustering, NonFinitePairsAreSkippedAndCounted) {
  const ClusteringOptions options;
  std::vector<HullPairContact> pairs = {MakePair({0, 0, 0}, {0, 0, 1}, -1e-4, 0, 0)};
  pairs.push_back(MakePair({0, 0, 0}, {0, 0, 1}, kNaN, 1, 1));
  pairs.push_back(MakePair({0, 0, 0}, {0, 0, 1}, -1e-4, 1, 1));
  pairs.back().point_A_W.y = kInf;
  pairs.push_back(MakePair({0, 0, 0}, {0, 0, 1}, -1e-4, 1, 1));
  pairs.back().normal_W = {kNaN, 0, 1};
  pairs.push_back(MakePair({0, 0, 0}, {0, 0, 1}, -1e-4, 1, 1));
  pairs.back().normal_W = {0, 0, 0};
  pairs.push_back(MakePair({0, 0, 0}, {0, 0, 1}, -kInf, 1, 1));
  ContactClusterer clusterer;
  auto clusters = clusterer.Cluster(pairs, MakeLeaves(2), MakeLeaves(2), options);
  ASSERT_EQ(clusters.size(), 1u);
  EXPECT_EQ(clusterer.skipped_nonfinite(), 5);
  EXPECT_EQ(clusters[0].num_pairs, 1);
  ExpectWellFormed(clusters, options);
  clusters = clusterer.Cluster(std::span(pairs).subspan(1), MakeLeaves(2), MakeLeaves(2), options);
  EXPECT_TRUE(clusters.empty());
  EXPECT_EQ(clusterer.skipped_nonfinite(), 5);
}

TEST(ContactClustering, InvalidOptionsGiveNoClustersAndValidateNamesTheField) {
  ClusteringOptions options;
  options.max_normal_angle_deg = kNaN;
  const std::vector<HullPairContact> pairs = {MakePair({0, 0, 0}, {0, 0, 1}, -1e-4, 0, 0)};
  ContactClusterer clusterer;
  EXPECT_TRUE(clusterer.Cluster(pairs, MakeLeaves(1), MakeLeaves(1), options).empty());
  EXPECT_TRUE(clusterer.stats().rejected_options);
  try {
    options.Validate();
    FAIL() << "no throw";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("max_normal_angle_deg"), std::string::npos);
  }
  options = {};
  options.max_extent_m = 1e-3;  // below min_extent_m
  EXPECT_THROW(options.Validate(), std::invalid_argument);
  EXPECT_NO_THROW(ClusteringOptions{}.Validate());
  EXPECT_THROW(ContactClusterer(0), std::invalid_argument);
}

TEST(ContactClustering, CoplanarRestingContactWithEqualDepthsGivesOneFiniteCluster) {
  const ClusteringOptions options;
  std::vector<HullPairContact> pairs;
  for (int i = 0; i < 7; ++i)
    for (int j = 0; j < 7; ++j)
      pairs.push_back(MakePair({0.5e-3 * i, 0.5e-3 * j, 0.02}, {0, 0, 1}, 0.0, 7 * i + j, 0));
  ContactClusterer clusterer;
  const auto clusters = clusterer.Cluster(pairs, MakeLeaves(49), MakeLeaves(1), options);
  ASSERT_EQ(clusters.size(), 1u);
  ExpectWellFormed(clusters, options);
  EXPECT_NEAR(glm::length(clusters[0].point_W - glm::dvec3(1.5e-3, 1.5e-3, 0.02)), 0.0, 1e-15);
  EXPECT_EQ(clusters[0].normal_W, glm::dvec3(0, 0, 1));
  EXPECT_NEAR(clusters[0].extent_m, 2.0 * (1.5e-3 + options.texture_margin_m), 1e-15);
  EXPECT_EQ(clusters[0].min_signed_distance_m, 0.0);
  EXPECT_EQ(clusters[0].object_triangles.size(), 3u);  // the one object leaf, once
}

TEST(ContactClustering, LargeRestingPlateGivesBoundedWindowsWithinCapacity) {
  const ClusteringOptions options;
  std::vector<HullPairContact> pairs;
  for (int i = 0; i < 21; ++i)
    for (int j = 0; j < 21; ++j)
      pairs.push_back(MakePair({5e-3 * i, 5e-3 * j, 0}, {0, 0, 1}, 0.0, 21 * i + j, 21 * i + j));
  ContactClusterer clusterer;
  const auto clusters = clusterer.Cluster(pairs, MakeLeaves(441), MakeLeaves(441), options);
  ASSERT_GE(clusters.size(), 1u);
  ASSERT_LE(clusters.size(), static_cast<std::size_t>(kMaxContacts));
  ExpectWellFormed(clusters, options);
  int members = 0;
  for (const ContactCluster& c : clusters) members += c.num_pairs;
  EXPECT_LE(members, 441);
  EXPECT_EQ(clusterer.merged_for_capacity() + clusterer.dropped_for_capacity(),
            clusterer.stats().clusters_pass2 - static_cast<int>(clusters.size()));
}

TEST(ContactClustering, OppositeNormalsAtOneSpotGiveTwoUnitNormalsNeverZero) {
  const ClusteringOptions options;
  std::vector<HullPairContact> pairs;
  for (int i = 0; i < 5; ++i) {
    pairs.push_back(MakePair({1e-4 * i, 0, 0}, {0, 0, 1}, -1e-4, i, i));
    pairs.push_back(MakePair({1e-4 * i, 0, 0}, {0, 0, -1}, -1e-4, 5 + i, 5 + i));
  }
  ContactClusterer clusterer;
  const auto clusters = clusterer.Cluster(pairs, MakeLeaves(10), MakeLeaves(10), options);
  ASSERT_EQ(clusters.size(), 2u);
  ExpectWellFormed(clusters, options);
  EXPECT_NEAR(std::abs(clusters[0].normal_W.z), 1.0, 1e-15);
  EXPECT_NEAR(clusters[0].normal_W.z + clusters[1].normal_W.z, 0.0, 1e-15);
  EXPECT_EQ(clusters[0].num_pairs, 5);
  EXPECT_EQ(clusters[1].num_pairs, 5);
}

TEST(ContactClustering, EmptyInputGivesNoClusters) {
  ContactClusterer clusterer;
  EXPECT_TRUE(clusterer.Cluster({}, MakeLeaves(1), MakeLeaves(1), {}).empty());
  EXPECT_EQ(clusterer.stats().input_pairs, 0);
}

TEST(ContactClustering, PairsBeyondCapacityKeepTheDeepest) {
  const ClusteringOptions options;
  std::vector<HullPairContact> pairs;
  for (int i = 0; i < 20; ++i)  // depths a permutation; the 8 deepest are −2.0 … −1.3 mm
    pairs.push_back(MakePair({0.1 * i, 0, 0}, {0, 0, 1}, -1e-4 * ((i * 7) % 20 + 1), i, i));
  ContactClusterer clusterer(8, 100);
  const auto clusters = clusterer.Cluster(pairs, MakeLeaves(20), MakeLeaves(20), options);
  EXPECT_EQ(clusterer.stats().skipped_over_capacity, 12);
  ASSERT_EQ(clusters.size(), 8u);
  for (int i = 0; i < 8; ++i)
    EXPECT_NEAR(clusters[i].min_signed_distance_m, -2e-3 + 1e-4 * i, 1e-15);
}

TEST(ContactClustering, NodesWithoutHierarchyFlagTheWholeModelAndBadNodesAreCounted) {
  const ClusteringOptions options;
  const std::vector<HullPairContact> pairs = {MakePair({0, 0, 0}, {0, 0, 1}, -1e-4, -1, 0),
                                              MakePair({1e-3, 0, 0}, {0, 0, 1}, -1e-4, -1, 7)};
  ContactClusterer clusterer;
  const auto clusters = clusterer.Cluster(pairs, ConvexHullHierarchy{}, MakeLeaves(1), options);
  ASSERT_EQ(clusters.size(), 1u);
  EXPECT_TRUE(clusters[0].tool_whole_model);
  EXPECT_FALSE(clusters[0].object_whole_model);
  EXPECT_TRUE(clusters[0].tool_triangles.empty());
  EXPECT_EQ(clusters[0].object_triangles.size(), 3u);
  EXPECT_EQ(clusterer.stats().invalid_nodes, 1);  // object node 7 does not exist
}

TEST(ContactClustering, TriangleStorageOverflowIsTruncatedAndCounted) {
  const ClusteringOptions options;
  std::vector<HullPairContact> pairs;
  for (int i = 0; i < 4; ++i) pairs.push_back(MakePair({1e-3 * i, 0, 0}, {0, 0, 1}, -1e-4, i, i));
  ContactClusterer clusterer(16, 10);
  const auto clusters = clusterer.Cluster(pairs, MakeLeaves(4), MakeLeaves(4), options);
  ASSERT_EQ(clusters.size(), 1u);
  EXPECT_EQ(clusters[0].tool_triangles.size(), 10u);
  EXPECT_EQ(clusters[0].object_triangles.size(), 0u);
  EXPECT_EQ(clusterer.stats().truncated_triangles, 14);
}

TEST(ContactClustering, WeightIsContinuousPositiveAndGrowsWithDepth) {
  const double f = 1e-4;
  EXPECT_EQ(ContactPairWeight(0.0, f), f);
  EXPECT_NEAR(ContactPairWeight(1e-12, f), f, 1e-11);
  EXPECT_GT(ContactPairWeight(-1e-3, f), ContactPairWeight(-1e-4, f));
  EXPECT_GT(ContactPairWeight(1e-4, f), ContactPairWeight(1e-3, f));
  EXPECT_GT(ContactPairWeight(1.0, f), 0.0);
  EXPECT_TRUE(std::isnan(ContactPairWeight(kNaN, f)));
}

TEST(ContactClustering, NoAllocationAfterWarmUp) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> uni(-1.0, 1.0);
  std::vector<HullPairContact> pairs;
  for (int i = 0; i < 300; ++i) {
    pairs.push_back(MakePair({0.02 * uni(rng), 0.02 * uni(rng), 0.0},
                             RandomUnitNear({0, 0, 1}, 1.5, rng), 1e-3 * uni(rng), i % 50, i % 70));
  }
  const ConvexHullHierarchy tool = MakeLeaves(50), object = MakeLeaves(70);
  ClusteringOptions options;
  long before = g_allocations.load();
  ContactClusterer clusterer(512, 4096);
  if (g_allocations.load() == before) {  // a tool (valgrind) intercepts operator new
    GTEST_SKIP() << "the allocation counter sees no allocations: operator new is intercepted";
  }
  const auto first = clusterer.Cluster(pairs, tool, object, options);
  ASSERT_FALSE(first.empty());
  std::shuffle(pairs.begin(), pairs.end(), rng);
  pairs[3].signed_distance_m = kNaN;
  before = g_allocations.load();
  const auto second = clusterer.Cluster(pairs, tool, object, options);
  options.max_contacts = 3;
  const auto third = clusterer.Cluster(pairs, tool, object, options);
  const long after = g_allocations.load();
  EXPECT_EQ(after - before, 0);
  EXPECT_EQ(second.data(), first.data());
  EXPECT_EQ(third.data(), first.data());
  EXPECT_LE(third.size(), 3u);
  ExpectWellFormed(third, options);
}

}  // namespace
}  // namespace ht
