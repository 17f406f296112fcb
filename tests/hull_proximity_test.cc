// Tests of the proximity query between convex-hull hierarchies (haptic_core/hull_proximity.h).
// Independent routes: FCL's mesh-mesh distance and collision on the same coarse triangles
// (object level), libccd's MPR intersection test on every leaf pair grown by ε (leaf level, brute
// force over all pairs), and for each separated pair an optimality certificate (the witness points
// lie on the hulls and the hulls' support planes along the normal are as far apart as the points).

#include "haptic_core/hull_proximity.h"

#include <ccd/ccd.h>
#include <fcl/fcl.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <glm/geometric.hpp>
#include <glm/gtc/quaternion.hpp>
#include <iostream>
#include <limits>
#include <memory>
#include <numbers>
#include <random>
#include <set>
#include <utility>
#include <vector>

#include "haptic_core/accuracy/fcl_mesh.h"
#include "haptic_core/demo/procedural_models.h"
#include "haptic_core/model_build/hull_hierarchy_build.h"

namespace ht {
namespace {

struct Mesh {
  std::vector<glm::dvec3> vertices;
  std::vector<glm::ivec3> triangles;
};

// Axis-aligned box of half sizes h centred at the origin, 12 triangles, CCW from outside.
Mesh MakeBox(glm::dvec3 h) {
  Mesh m;
  for (int i = 0; i < 8; ++i) {
    m.vertices.push_back(h * glm::dvec3((i & 1) ? 1 : -1, (i & 2) ? 1 : -1, (i & 4) ? 1 : -1));
  }
  const int quads[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4},
                           {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  for (const auto& q : quads) {
    m.triangles.emplace_back(q[0], q[1], q[2]);
    m.triangles.emplace_back(q[0], q[2], q[3]);
  }
  return m;
}

// An L-shaped closed prism, arms 40 mm long and 12 mm wide, 10 mm thick (z from −5 to 5 mm),
// frame at the L's corner region centre: 24 triangles, one reflex edge.
Mesh MakeLBlock() {
  const std::vector<glm::dvec2> poly = {{0, 0}, {4, 0}, {4, 1.2}, {1.2, 1.2}, {1.2, 4}, {0, 4}};
  const std::vector<glm::ivec3> cap = {{0, 1, 2}, {0, 2, 3}, {0, 3, 4}, {0, 4, 5}};
  Mesh m;
  const int n = static_cast<int>(poly.size());
  for (const auto& p : poly)
    m.vertices.emplace_back(0.01 * p.x - 0.015, 0.01 * p.y - 0.015, -0.005);
  for (const auto& p : poly) m.vertices.emplace_back(0.01 * p.x - 0.015, 0.01 * p.y - 0.015, 0.005);
  for (const auto& t : cap) {
    m.triangles.emplace_back(t[0], t[2], t[1]);
    m.triangles.emplace_back(t[0] + n, t[1] + n, t[2] + n);
  }
  for (int i = 0; i < n; ++i) {
    const int j = (i + 1) % n;
    m.triangles.emplace_back(i, j, j + n);
    m.triangles.emplace_back(i, j + n, i + n);
  }
  return m;
}

// Torus around z: major radius R, minor radius r, nu × nv quads (2·nu·nv triangles).
Mesh MakeTorus(int nu, int nv, double R, double r) {
  Mesh m;
  for (int i = 0; i < nu; ++i) {
    for (int j = 0; j < nv; ++j) {
      const double u = 2.0 * std::numbers::pi * i / nu, v = 2.0 * std::numbers::pi * j / nv;
      m.vertices.emplace_back((R + r * std::cos(v)) * std::cos(u),
                              (R + r * std::cos(v)) * std::sin(u), r * std::sin(v));
    }
  }
  const auto id = [&](int i, int j) { return (i % nu) * nv + (j % nv); };
  for (int i = 0; i < nu; ++i) {
    for (int j = 0; j < nv; ++j) {
      m.triangles.emplace_back(id(i, j), id(i + 1, j), id(i + 1, j + 1));
      m.triangles.emplace_back(id(i, j), id(i + 1, j + 1), id(i, j + 1));
    }
  }
  return m;
}

// A HapticModel holding only what the query reads: coarse mesh, hierarchy, root hull vertices.
HapticModel MakeModel(const Mesh& mesh, const HullHierarchyParams& params = {}) {
  HapticModel m;
  m.name = "test";
  m.vertices_O = mesh.vertices;
  m.triangles = mesh.triangles;
  m.hull_hierarchy = BuildConvexHullHierarchy(mesh.vertices, mesh.triangles, params);
  m.hull_vertices_O = m.hull_hierarchy.nodes[0].hull.vertices_O;
  return m;
}

RigidTransform Pose(glm::dvec3 p, glm::dquat R = glm::dquat(1, 0, 0, 0)) {
  return {p, glm::normalize(R)};
}

glm::dquat AxisAngle(glm::dvec3 axis, double angle) {
  return glm::angleAxis(angle, glm::normalize(axis));
}

// ---------------------------------------------------------------------------------------------
// Checks every returned pair: finite, unit normal, witness relation p_A − p_B = sd·n, both
// witness points on (or, penetrating, at the support plane of) their hulls; for separated pairs
// the optimality certificate: the support planes along n are sd apart (a separating-axis lower
// bound equal to the points' distance).
double SupportValue(const ConvexHull& hull, const RigidTransform& X_WO, const glm::dvec3& d_W) {
  const glm::dvec3 d_O = glm::conjugate(X_WO.rotation) * d_W;
  double best = -std::numeric_limits<double>::infinity();
  for (const auto& v : hull.vertices_O) best = std::max(best, glm::dot(v, d_O));
  return best + glm::dot(d_W, X_WO.translation);
}

const ConvexHull& LeafHull(const HapticModel& m, int node, ConvexHull* single) {
  if (node >= 0) return m.hull_hierarchy.nodes[static_cast<std::size_t>(node)].hull;
  single->vertices_O = m.hull_vertices_O;
  return *single;
}

void CheckPairs(std::span<const HullPairContact> pairs, const HapticModel& A,
                const RigidTransform& X_WA, const HapticModel& B, const RigidTransform& X_WB,
                double eps) {
  for (const auto& c : pairs) {
    ASSERT_TRUE(std::isfinite(c.signed_distance_m));
    ASSERT_NEAR(glm::length(c.normal_W), 1.0, 1e-12);
    ASSERT_LE(c.signed_distance_m, eps + 1e-12);
    const glm::dvec3 gap = c.point_A_W - c.point_B_W - c.signed_distance_m * c.normal_W;
    ASSERT_LE(glm::length(gap), 1e-10) << "sd " << c.signed_distance_m;
    ConvexHull sa, sb;
    const ConvexHull& hA = LeafHull(A, c.node_A, &sa);
    const ConvexHull& hB = LeafHull(B, c.node_B, &sb);
    // Support planes along n: h_B(n) + h_A(−n) is the overlap; −overlap = sd.
    const double sd_axis =
        -(SupportValue(hB, X_WB, c.normal_W) + SupportValue(hA, X_WA, -c.normal_W));
    ASSERT_NEAR(sd_axis, c.signed_distance_m, 1e-10);
    if (c.signed_distance_m > 1e-12 && c.node_A >= 0 && c.node_B >= 0) {
      // Witness points on their hulls (planes are a containment test).
      ASSERT_LE(hA.SignedDistanceBound(X_WA.Inverse() * c.point_A_W), 1e-10);
      ASSERT_LE(hB.SignedDistanceBound(X_WB.Inverse() * c.point_B_W), 1e-10);
    }
  }
}

// libccd MPR intersection of two leaf hulls, A's grown by `grow` (m): the brute-force leaf test.
struct CcdObj {
  const ConvexHull* hull;
  RigidTransform X_WO;
  double grow;
};
void CcdSupport(const void* obj, const ccd_vec3_t* dir, ccd_vec3_t* out) {
  const auto* o = static_cast<const CcdObj*>(obj);
  const glm::dvec3 d_W(ccdVec3X(dir), ccdVec3Y(dir), ccdVec3Z(dir));
  glm::dvec3 p = o->X_WO * o->hull->Support(glm::conjugate(o->X_WO.rotation) * d_W);
  const double len = glm::length(d_W);
  if (len > 0.0) p += (o->grow / len) * d_W;
  ccdVec3Set(out, p.x, p.y, p.z);
}
void CcdCenter(const void* obj, ccd_vec3_t* out) {
  const auto* o = static_cast<const CcdObj*>(obj);
  const glm::dvec3 c = o->X_WO * o->hull->center_O;
  ccdVec3Set(out, c.x, c.y, c.z);
}
bool CcdIntersect(const ConvexHull& a, const RigidTransform& X_WA, const ConvexHull& b,
                  const RigidTransform& X_WB, double grow) {
  CcdObj oa{&a, X_WA, grow}, ob{&b, X_WB, 0.0};
  ccd_t ccd;
  CCD_INIT(&ccd);
  ccd.support1 = ccd.support2 = CcdSupport;
  ccd.center1 = ccd.center2 = CcdCenter;
  ccd.mpr_tolerance = 1e-12;
  ccd.max_iterations = 500;
  return ccdMPRIntersect(&oa, &ob, &ccd) != 0;
}

std::vector<int> Leaves(const HapticModel& m) {
  std::vector<int> out;
  for (std::size_t i = 0; i < m.hull_hierarchy.nodes.size(); ++i) {
    if (m.hull_hierarchy.nodes[i].is_leaf()) out.push_back(static_cast<int>(i));
  }
  return out;
}

// The largest distance from a point of a leaf's hull to the leaf's own triangles is at most the
// hull's diameter (its vertices are patch vertices or inward copies): a rigorous, loose bound on
// how much closer hulls can be than the meshes.
double MaxLeafDiameter(const HapticModel& m) {
  double d = 0.0;
  for (int leaf : Leaves(m)) {
    const auto& v = m.hull_hierarchy.nodes[static_cast<std::size_t>(leaf)].hull.vertices_O;
    for (const auto& p : v) {
      for (const auto& q : v) d = std::max(d, glm::length(p - q));
    }
  }
  return d;
}

glm::dquat RandomRotation(std::mt19937_64& rng) {
  std::normal_distribution<double> g;
  return glm::normalize(glm::dquat(g(rng), g(rng), g(rng), g(rng)));
}

class TorusLBlock : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    torus_ = new HapticModel(MakeModel(MakeTorus(22, 12, 0.05, 0.015)));  // 528 triangles
    block_ = new HapticModel(MakeModel(MakeLBlock()));
    torus_bounds_ = new HullBounds(HullBounds::Of(*torus_));
    block_bounds_ = new HullBounds(HullBounds::Of(*block_));
  }
  static void TearDownTestSuite() {
    delete torus_;
    delete block_;
    delete torus_bounds_;
    delete block_bounds_;
  }
  // A random pose of the L-block near the torus tube.
  static RigidTransform RandomPose(std::mt19937_64& rng) {
    std::uniform_real_distribution<double> angle(0.0, 2.0 * std::numbers::pi), radial(0.02, 0.09),
        height(-0.035, 0.035);
    const double a = angle(rng), r = radial(rng);
    return Pose({r * std::cos(a), r * std::sin(a), height(rng)}, RandomRotation(rng));
  }
  static HapticModel* torus_;
  static HapticModel* block_;
  // The models' bounds, built once as the remote step builds its scene's.
  static HullBounds* torus_bounds_;
  static HullBounds* block_bounds_;
};
HapticModel* TorusLBlock::torus_ = nullptr;
HapticModel* TorusLBlock::block_ = nullptr;
HullBounds* TorusLBlock::torus_bounds_ = nullptr;
HullBounds* TorusLBlock::block_bounds_ = nullptr;

// Check 1 (object level, against FCL on the same coarse triangles, 2000 random poses):
// FCL within ε (triangles collide, or mesh distance ≤ ε) ⇒ our query finds pairs (hulls contain
// their triangles), and then our minimum signed distance ≤ FCL's distance (+1e-9). The converse
// holds only up to how far leaf hulls reach beyond their triangles: when we find pairs and FCL
// does not, FCL's distance exceeds our minimum by at most the largest leaf-hull diameter. The
// figures (how often each case happens, the distribution of FCL − ours) are printed.
TEST_F(TorusLBlock, AgreesWithFclMeshDistanceAtRandomPoses) {
  const HapticModel& A = *block_;
  const HapticModel& B = *torus_;
  std::cout << "torus: " << B.triangles.size() << " triangles, " << Leaves(B).size()
            << " leaves; L-block: " << A.triangles.size() << " triangles, " << Leaves(A).size()
            << " leaves\n";
  const double eps = 2e-3;
  const double reach = std::max(MaxLeafDiameter(A), MaxLeafDiameter(B));
  auto fa = MakeFclMesh({A.vertices_O, A.triangles}, "coarse");
  auto fb = MakeFclMesh({B.vertices_O, B.triangles}, "coarse");
  const RigidTransform X_WB = Pose({0, 0, 0});
  fcl::CollisionObjectd ob(fb, ToFcl(X_WB));
  HullProximityQuery query;
  ProximityQueryOptions opt;
  opt.tolerance_m = eps;
  std::mt19937_64 rng(7);
  int both = 0, neither = 0, ours_only = 0, fcl_only = 0, colliding = 0, separated_compared = 0;
  std::vector<double> excess;  // FCL distance − our min distance, FCL separated and we found pairs
  for (int k = 0; k < 2000; ++k) {
    const RigidTransform X_WA = RandomPose(rng);
    fcl::CollisionObjectd oa(fa, ToFcl(X_WA));
    fcl::CollisionRequestd creq;
    fcl::CollisionResultd cres;
    fcl::collide(&oa, &ob, creq, cres);
    const bool collide = cres.isCollision();
    double d_fcl = 0.0;
    if (!collide) {
      fcl::DistanceRequestd dreq;
      dreq.rel_err = 0.0;
      dreq.abs_err = 0.0;
      fcl::DistanceResultd dres;
      fcl::distance(&oa, &ob, dreq, dres);
      d_fcl = dres.min_distance;
    }
    ProximityQueryStats st;
    const auto pairs = query.Query(A, *block_bounds_, X_WA, B, *torus_bounds_, X_WB, opt, &st);
    CheckPairs(pairs, A, X_WA, B, X_WB, eps);
    const bool fcl_near = collide || d_fcl <= eps;
    const bool ours_near = !pairs.empty();
    double ours_min = std::numeric_limits<double>::infinity();
    for (const auto& c : pairs) ours_min = std::min(ours_min, c.signed_distance_m);
    colliding += collide;
    if (fcl_near && ours_near) ++both;
    if (!fcl_near && !ours_near) ++neither;
    if (ours_near && !fcl_near) ++ours_only;
    if (fcl_near && !ours_near) ++fcl_only;
    ASSERT_FALSE(fcl_near && !ours_near) << "pose " << k << " fcl distance " << d_fcl;
    if (collide) {
      ASSERT_LE(ours_min, 1e-9) << "pose " << k;
    } else if (ours_near) {
      ++separated_compared;
      ASSERT_LE(ours_min, d_fcl + 1e-9) << "pose " << k;
      ASSERT_LE(d_fcl - ours_min, reach) << "pose " << k;
      excess.push_back(d_fcl - ours_min);
    }
  }
  std::sort(excess.begin(), excess.end());
  auto pct = [&](double q) {
    return excess.empty()
               ? 0.0
               : excess[static_cast<std::size_t>(q * static_cast<double>(excess.size() - 1))];
  };
  int exact = 0;
  for (double e : excess) exact += e <= 1e-9;
  std::cout << "2000 poses, eps " << eps << " m: both near " << both << " (FCL colliding "
            << colliding << "), neither " << neither << ", ours only " << ours_only << ", FCL only "
            << fcl_only << "\n  separated & compared " << separated_compared
            << ": FCL − ours ≤ 1e-9 in " << exact << "; median " << pct(0.5) << " m, p90 "
            << pct(0.9) << " m, max " << pct(1.0) << " m (bound: largest leaf diameter " << reach
            << " m)\n";
  EXPECT_EQ(fcl_only, 0);
  EXPECT_GT(both, 100);
  EXPECT_GT(neither, 100);
}

// Leaf level, brute force: at 300 random poses, every leaf pair whose hulls intersect when A's is
// grown by ε − 1e-9 (libccd MPR) is reported, and every reported pair intersects when grown by
// ε + 1e-9: the traversal's culling loses nothing and reports nothing extra.
TEST_F(TorusLBlock, FindsExactlyTheLeafPairsWithinToleranceByBruteForce) {
  const HapticModel& A = *block_;
  const HapticModel& B = *torus_;
  const double eps = 3e-3;
  const auto leaves_A = Leaves(A), leaves_B = Leaves(B);
  HullProximityQuery query;
  ProximityQueryOptions opt;
  opt.tolerance_m = eps;
  std::mt19937_64 rng(11);
  const RigidTransform X_WB = Pose({0.001, -0.002, 0.0}, AxisAngle({1, 2, 3}, 0.3));
  RigidTransform previous;
  int total_pairs = 0, fronts = 0;
  for (int k = 0; k < 300; ++k) {
    // Every other pose a small step from the one before, so that the query also starts from its
    // previous front (temporal coherence), after jumps as well as small moves.
    RigidTransform X_WA = RandomPose(rng);
    if (k % 2 == 1) {
      X_WA = previous;
      X_WA.translation += 2e-4 * glm::dvec3(std::cos(k), std::sin(k), 0.5);
    }
    previous = X_WA;
    ProximityQueryStats st;
    const auto pairs = query.Query(A, *block_bounds_, X_WA, B, *torus_bounds_, X_WB, opt, &st);
    fronts += st.front_pairs > 0;
    std::set<std::pair<int, int>> ours;
    for (const auto& c : pairs) ours.emplace(c.node_A, c.node_B);
    ASSERT_EQ(ours.size(), pairs.size()) << "a pair reported twice";
    total_pairs += static_cast<int>(pairs.size());
    for (int a : leaves_A) {
      for (int b : leaves_B) {
        const auto& ha = A.hull_hierarchy.nodes[static_cast<std::size_t>(a)].hull;
        const auto& hb = B.hull_hierarchy.nodes[static_cast<std::size_t>(b)].hull;
        const bool in = ours.count({a, b}) > 0;
        if (CcdIntersect(ha, X_WA, hb, X_WB, eps - 1e-9)) {
          ASSERT_TRUE(in) << "pose " << k << " missed leaf pair " << a << "," << b;
        }
        if (in) {
          ASSERT_TRUE(CcdIntersect(ha, X_WA, hb, X_WB, eps + 1e-9))
              << "pose " << k << " extra leaf pair " << a << "," << b;
        }
      }
    }
  }
  std::cout << "300 poses: " << total_pairs
            << " leaf pairs reported, all confirmed by brute force; " << fronts
            << " queries started from the previous front\n";
  EXPECT_GT(total_pairs, 100);
  EXPECT_GE(fronts, 150);
}

// Check 3: time and work budgets. A tiny budget stops early (budget_exhausted) with a subset of the
// full answer whose pairs are identical to the full query's; no budget gives the full set; with
// half the node-pair tests the full query needed, best-first order has already found the deepest
// pair.
TEST_F(TorusLBlock, BudgetsReturnValidSubsetsDeepestFirst) {
  const HapticModel& A = *block_;
  const HapticModel& B = *torus_;
  HullProximityQuery query;
  std::mt19937_64 rng(3);
  int checked = 0, deepest_found[2] = {0, 0};
  for (int k = 0; k < 400 && checked < 60; ++k) {
    const RigidTransform X_WA = RandomPose(rng);
    ProximityQueryOptions opt;
    opt.tolerance_m = 2e-3;
    opt.temporal_coherence = false;
    ProximityQueryStats full_st;
    const auto full_span = query.Query(A, *block_bounds_, X_WA, *torus_, *torus_bounds_,
                                       RigidTransform{}, opt, &full_st);
    const std::vector<HullPairContact> full(full_span.begin(), full_span.end());
    EXPECT_FALSE(full_st.budget_exhausted);
    if (full.size() < 4) continue;
    ++checked;
    auto same = [](const HullPairContact& x, const HullPairContact& y) {
      return x.node_A == y.node_A && x.node_B == y.node_B &&
             x.signed_distance_m == y.signed_distance_m;
    };
    // Tiny time budget.
    ProximityQueryOptions tiny = opt;
    tiny.time_budget_us = 1e-3;
    ProximityQueryStats st;
    auto sub = query.Query(A, *block_bounds_, X_WA, B, *torus_bounds_, RigidTransform{}, tiny, &st);
    EXPECT_TRUE(st.budget_exhausted);
    EXPECT_LE(sub.size(), full.size());
    for (const auto& c : sub) {
      EXPECT_TRUE(std::any_of(full.begin(), full.end(), [&](auto& f) { return same(f, c); }));
    }
    // Large time budget: the full set.
    ProximityQueryOptions large = opt;
    large.time_budget_us = 1e6;
    auto all =
        query.Query(A, *block_bounds_, X_WA, B, *torus_bounds_, RigidTransform{}, large, &st);
    EXPECT_FALSE(st.budget_exhausted);
    ASSERT_EQ(all.size(), full.size());
    for (std::size_t i = 0; i < all.size(); ++i) EXPECT_TRUE(same(all[i], full[i]));
    // The work of a traversal with a budget that never runs out (a budget keeps the exact
    // internal distances, so its count differs from the unlimited one's).
    const int budget_work = st.node_pairs_tested;
    // Half and three quarters of that work: valid subsets; count how often they hold the
    // deepest pair.
    for (int q = 0; q < 2; ++q) {
      ProximityQueryOptions part_opt = opt;
      part_opt.max_node_pair_tests = std::max(1, budget_work * (2 + q) / 4);
      auto part =
          query.Query(A, *block_bounds_, X_WA, B, *torus_bounds_, RigidTransform{}, part_opt, &st);
      EXPECT_TRUE(st.budget_exhausted);
      for (const auto& c : part) {
        EXPECT_TRUE(std::any_of(full.begin(), full.end(), [&](auto& f) { return same(f, c); }));
      }
      deepest_found[q] += !part.empty() && same(part[0], full[0]);
    }
  }
  std::cout << checked << " poses with >= 4 pairs: the deepest pair found within 1/2 of the "
            << "node-pair tests in " << deepest_found[0] << ", within 3/4 in " << deepest_found[1]
            << "\n";
  EXPECT_GE(checked, 20);
  EXPECT_GE(deepest_found[0], checked * 3 / 4);
  EXPECT_GE(deepest_found[1], checked * 9 / 10);
}

// Check 4: temporal coherence (previous pairs warm-start GJK and add their old normal as a
// candidate direction; pairs found beyond ε are first tested along their old separating
// direction) reports the same pairs along a smooth trajectory; separated distances agree to 1e-9,
// and a penetrating pair's depth estimate can only get shallower, i.e. closer to the true depth
// (one more candidate direction; every candidate's overlap bounds the depth from above).
TEST_F(TorusLBlock, TemporalCoherenceGivesTheSamePairs) {
  const HapticModel& A = *block_;
  const HapticModel& B = *torus_;
  HullProximityQuery with, without;
  ProximityQueryOptions on, off;
  on.tolerance_m = off.tolerance_m = 2e-3;
  on.temporal_coherence = true;
  off.temporal_coherence = false;
  int hits = 0, culls = 0, fronts = 0, pairs_total = 0;
  for (int k = 0; k < 400; ++k) {
    const double t = k * 0.005;
    const RigidTransform X_WA = Pose({0.05 * std::cos(t), 0.05 * std::sin(t), 0.019 - 0.00001 * k},
                                     AxisAngle({std::sin(t), 1, 0.3}, t));
    ProximityQueryStats st;
    auto a = with.Query(A, *block_bounds_, X_WA, B, *torus_bounds_, RigidTransform{}, on, &st);
    hits += st.coherent_hits;
    culls += st.coherent_culls;
    ProximityQueryStats st_off;
    auto b =
        without.Query(A, *block_bounds_, X_WA, B, *torus_bounds_, RigidTransform{}, off, &st_off);
    ASSERT_EQ(st_off.coherent_culls, 0);
    ASSERT_EQ(st_off.front_pairs, 0);
    fronts += st.front_pairs > 0;
    ASSERT_EQ(a.size(), b.size()) << "frame " << k;
    pairs_total += static_cast<int>(a.size());
    std::vector<HullPairContact> sa(a.begin(), a.end()), sb(b.begin(), b.end());
    auto by_id = [](const HullPairContact& x, const HullPairContact& y) {
      return std::pair(x.node_A, x.node_B) < std::pair(y.node_A, y.node_B);
    };
    std::sort(sa.begin(), sa.end(), by_id);
    std::sort(sb.begin(), sb.end(), by_id);
    for (std::size_t i = 0; i < sa.size(); ++i) {
      ASSERT_EQ(sa[i].node_A, sb[i].node_A);
      ASSERT_EQ(sa[i].node_B, sb[i].node_B);
      if (sb[i].signed_distance_m > 1e-9) {
        EXPECT_NEAR(sa[i].signed_distance_m, sb[i].signed_distance_m, 1e-9);
      } else {
        EXPECT_GE(sa[i].signed_distance_m, sb[i].signed_distance_m - 1e-12);
      }
    }
  }
  std::cout << "400 frames: " << pairs_total << " pairs, " << hits << " coherent hits, " << culls
            << " leaf pairs dropped along their previous separating direction, " << fronts
            << " frames started from the previous front\n";
  EXPECT_GT(pairs_total, 400);
  EXPECT_GT(hits, pairs_total / 2);
  EXPECT_GT(culls, 0);
  EXPECT_GT(fronts, 300);
}

// Temporal coherence holds between calls on the same bounds only: a model rebuilt (a coarser
// torus, with fewer hull nodes than the front's pairs name) comes with new bounds, and the query
// starts from the roots instead of the old front and reports what a fresh query does. Bounds that
// do not fit their model are refused.
TEST_F(TorusLBlock, NewBoundsStartFromTheRoots) {
  const HapticModel& A = *block_;
  HapticModel B = *torus_;
  HullProximityQuery coherent_query, fresh_query;
  ProximityQueryOptions opt;
  opt.tolerance_m = 3e-3;
  const RigidTransform X_WA = Pose({0.05, 0.0, 0.017}, AxisAngle({0, 1, 0.2}, 0.4));
  ProximityQueryStats st;
  const HullBounds old_bounds = HullBounds::Of(B);
  ASSERT_FALSE(
      coherent_query.Query(A, *block_bounds_, X_WA, B, old_bounds, RigidTransform{}, opt, &st)
          .empty());
  coherent_query.Query(A, *block_bounds_, X_WA, B, old_bounds, RigidTransform{}, opt, &st);
  ASSERT_GT(st.front_pairs, 0);  // the second call started from the first one's front
  const std::size_t old_nodes = B.hull_hierarchy.nodes.size();
  B = MakeModel(MakeTorus(10, 6, 0.05, 0.015));  // the same address, a smaller hierarchy
  ASSERT_LT(B.hull_hierarchy.nodes.size(), old_nodes);
  // The old bounds no longer fit: refused, with nothing reported.
  EXPECT_TRUE(
      coherent_query.Query(A, *block_bounds_, X_WA, B, old_bounds, RigidTransform{}, opt, &st)
          .empty());
  EXPECT_EQ(st.invalid_input, 1);
  const HullBounds new_bounds = HullBounds::Of(B);
  EXPECT_NE(new_bounds.id, old_bounds.id);
  const auto got =
      coherent_query.Query(A, *block_bounds_, X_WA, B, new_bounds, RigidTransform{}, opt, &st);
  EXPECT_EQ(st.front_pairs, 0);
  const std::vector<HullPairContact> mine(got.begin(), got.end());
  const auto want = fresh_query.Query(A, X_WA, B, RigidTransform{}, opt);
  ASSERT_EQ(mine.size(), want.size());
  ASSERT_FALSE(want.empty());
  for (std::size_t i = 0; i < want.size(); ++i) {
    EXPECT_EQ(mine[i].node_A, want[i].node_A);
    EXPECT_EQ(mine[i].node_B, want[i].node_B);
    EXPECT_NEAR(mine[i].signed_distance_m, want[i].signed_distance_m, 1e-12);
  }
}

// ---------------------------------------------------------------------------------------------
// Hard cases (DESIGN.md §8). Boxes are convex: one node each.

HullPairContact Only(std::span<const HullPairContact> pairs) {
  EXPECT_EQ(pairs.size(), 1u);
  return pairs.empty() ? HullPairContact{} : pairs[0];
}

// Face-face coplanar resting contact: two 20 mm cubes stacked exactly → distance 0 (within
// 1e-12), normal +z (a face normal gives zero overlap exactly). With 0.5 mm gap → 0.5 mm exactly
// (GJK), normal +z; with 0.5 mm overlap → −0.5 mm exactly.
TEST(HullProximityHardCases, FaceFaceRestingContact) {
  const HapticModel box = MakeModel(MakeBox({0.01, 0.01, 0.01}));
  HullProximityQuery q;
  ProximityQueryOptions opt;
  opt.tolerance_m = 1e-3;
  for (double gap : {0.0, 5e-4, -5e-4}) {
    const RigidTransform X_WA = Pose({0.003, -0.002, 0.02 + gap});
    const auto c = Only(q.Query(box, X_WA, box, RigidTransform{}, opt));
    EXPECT_NEAR(c.signed_distance_m, gap, 1e-12) << gap;
    EXPECT_NEAR(c.normal_W.z, 1.0, 1e-9) << gap;
    CheckPairs(q.Query(box, X_WA, box, RigidTransform{}, opt), box, X_WA, box, RigidTransform{},
               opt.tolerance_m);
  }
  // ε = 0: exact touching is reported (distance 0), a 1 µm gap is not.
  opt.tolerance_m = 0.0;
  EXPECT_EQ(q.Query(box, Pose({0, 0, 0.02}), box, RigidTransform{}, opt).size(), 1u);
  EXPECT_EQ(q.Query(box, Pose({0, 0, 0.020001}), box, RigidTransform{}, opt).size(), 0u);
}

// Edge-edge crossing: A's bottom edge along x, B's top edge along y (both cubes turned 45°).
// Separated by 1 mm → 1 mm exactly, normal +z. Overlapping by 1 mm → the depth is found along
// +z by MPR (no face normal realizes it): −1 mm within 1e-6; never shallower than −1 mm.
TEST(HullProximityHardCases, EdgeEdgeCrossing) {
  const HapticModel box = MakeModel(MakeBox({0.01, 0.01, 0.01}));
  const double h = 0.01 * std::sqrt(2.0);
  const RigidTransform X_WB = Pose({0, 0, 0}, AxisAngle({0, 1, 0}, std::numbers::pi / 4));
  HullProximityQuery q;
  // One query along the sequence, with coherence (the bounds built once): the touching pose
  // takes the separated pose's normal as a candidate.
  const HullBounds bounds = HullBounds::Of(box);
  ProximityQueryOptions opt;
  opt.tolerance_m = 2e-3;
  for (double gap : {1e-3, 0.0, -1e-3}) {
    const RigidTransform X_WA =
        Pose({0, 0, 2 * h + gap}, AxisAngle({1, 0, 0}, std::numbers::pi / 4));
    const auto pairs = q.Query(box, bounds, X_WA, box, bounds, X_WB, opt);
    const auto c = Only(pairs);
    CheckPairs(pairs, box, X_WA, box, X_WB, opt.tolerance_m);
    if (gap >= 0) {
      EXPECT_NEAR(c.signed_distance_m, gap, 1e-12);
    } else {
      EXPECT_NEAR(c.signed_distance_m, gap, 1e-6);
    }
    EXPECT_NEAR(c.normal_W.z, 1.0, 1e-6) << gap;
    std::cout << "edge-edge gap " << gap << ": sd " << c.signed_distance_m << " n (" << c.normal_W.x
              << ", " << c.normal_W.y << ", " << c.normal_W.z << ")\n";
  }
  // A fresh query at the touching pose (no coherence: no earlier normal to take): MPR finds no
  // overlap on a touching pair and the face normals give a face diagonal's 7 mm; the hulls moved
  // a hair apart give GJK's normal, +z, with the overlap of the pair as posed.
  for (const double turn : {0.0, 0.3, 1.1}) {
    const RigidTransform X_WA = Pose(
        {0, 0, 2 * h}, AxisAngle({0, 0, 1}, turn) * AxisAngle({1, 0, 0}, std::numbers::pi / 4));
    HullProximityQuery fresh;
    const auto pairs = fresh.Query(box, X_WA, box, X_WB, opt);
    const auto c = Only(pairs);
    CheckPairs(pairs, box, X_WA, box, X_WB, opt.tolerance_m);
    EXPECT_NEAR(c.signed_distance_m, 0.0, 1e-9) << turn;
    EXPECT_NEAR(c.normal_W.z, 1.0, 1e-6) << turn;
    std::cout << "fresh edge-edge touching, turn " << turn << ": sd " << c.signed_distance_m
              << " n (" << c.normal_W.x << ", " << c.normal_W.y << ", " << c.normal_W.z << ")\n";
  }
}

// Vertex-face: A's corner pointing down onto B's top face. Gap ±0.5 mm → ±0.5 mm exactly
// (GJK when separated; B's face normal when penetrating), normal +z.
TEST(HullProximityHardCases, VertexFace) {
  const HapticModel box = MakeModel(MakeBox({0.01, 0.01, 0.01}));
  // Rotate so that the (−1,−1,−1) corner points along −z.
  const glm::dvec3 from = glm::normalize(glm::dvec3(-1, -1, -1)), to(0, 0, -1);
  const glm::dquat R = AxisAngle(glm::cross(from, to), std::acos(glm::dot(from, to)));
  const double corner = 0.01 * std::sqrt(3.0);
  HullProximityQuery q;
  ProximityQueryOptions opt;
  opt.tolerance_m = 1e-3;
  for (double gap : {5e-4, 0.0, -5e-4}) {
    const RigidTransform X_WA = Pose({0.002, 0.001, 0.01 + corner + gap}, R);
    const auto pairs = q.Query(box, X_WA, box, RigidTransform{}, opt);
    const auto c = Only(pairs);
    CheckPairs(pairs, box, X_WA, box, RigidTransform{}, opt.tolerance_m);
    EXPECT_NEAR(c.signed_distance_m, gap, 1e-12);
    EXPECT_NEAR(c.normal_W.z, 1.0, 1e-9);
    EXPECT_NEAR(c.point_A_W.z, 0.01 + gap, 1e-9);
  }
}

// Sliver triangle (1e-9 m high) and a flat patch (a square of two coplanar triangles): the
// builder thickens them inward, so each is a thin slab leaf. A cube resting 0.2 mm above: finite,
// unit normal +z, distance 0.2 mm (GJK); pushed 0.2 mm in: −0.2 mm (the slab's face normal).
TEST(HullProximityHardCases, SliverAndFlatLeaves) {
  Mesh sliver;
  sliver.vertices = {{-0.02, 0, 0}, {0.02, 0, 0}, {0.0, 1e-9, 0}};
  sliver.triangles = {{0, 1, 2}};
  Mesh flat;
  flat.vertices = {{-0.02, -0.02, 0}, {0.02, -0.02, 0}, {0.02, 0.02, 0}, {-0.02, 0.02, 0}};
  flat.triangles = {{0, 1, 2}, {0, 2, 3}};
  const HapticModel box = MakeModel(MakeBox({0.005, 0.005, 0.005}));
  for (const Mesh* m : {&sliver, &flat}) {
    const HapticModel B = MakeModel(*m);
    HullProximityQuery q;
    ProximityQueryOptions opt;
    opt.tolerance_m = 1e-3;
    for (double gap : {2e-4, -2e-4}) {
      const RigidTransform X_WA = Pose({0.001, 0.0, 0.005 + gap});
      const auto pairs = q.Query(box, X_WA, B, RigidTransform{}, opt);
      const auto c = Only(pairs);
      CheckPairs(pairs, box, X_WA, B, RigidTransform{}, opt.tolerance_m);
      EXPECT_NEAR(c.signed_distance_m, gap, 1e-9) << (m == &sliver ? "sliver" : "flat");
      EXPECT_NEAR(c.normal_W.z, 1.0, 1e-9);
    }
  }
}

// Deep penetration: a 20 mm cube at the centre of a 100 mm cube → −60 mm (it leaves through the
// nearest face: 50 + 10 mm), along a face normal; finite.
TEST(HullProximityHardCases, DeepPenetration) {
  const HapticModel small = MakeModel(MakeBox({0.01, 0.01, 0.01}));
  const HapticModel big = MakeModel(MakeBox({0.05, 0.05, 0.05}));
  HullProximityQuery q;
  ProximityQueryOptions opt;
  const auto pairs = q.Query(small, Pose({0, 0, 0.001}), big, RigidTransform{}, opt);
  const auto c = Only(pairs);
  CheckPairs(pairs, small, Pose({0, 0, 0.001}), big, RigidTransform{}, 0.0);
  EXPECT_NEAR(c.signed_distance_m, -0.059, 1e-12);
  EXPECT_NEAR(c.normal_W.z, 1.0, 1e-12);
}

// Normal flipping: a 4 mm cube slides down through a 2 mm plate. Above the plate's mid-plane the
// normal is +z and the depth grows; below it, −z; the signed distance is continuous through the
// flip (−(1 + 2 + ... ) mm at the mid-plane from either side: 3 mm = 1 mm + 2 mm half sizes) and
// at the mid-plane exactly one of ±z is chosen (the first candidate of least overlap).
TEST(HullProximityHardCases, NormalFlipsThroughThinPlate) {
  const HapticModel cube = MakeModel(MakeBox({0.002, 0.002, 0.002}));
  const HapticModel plate = MakeModel(MakeBox({0.05, 0.05, 0.001}));
  HullProximityQuery q;
  ProximityQueryOptions opt;
  opt.tolerance_m = 1e-3;
  for (int k = -35; k <= 35; ++k) {
    const double z = k * 1e-4;  // cube centre, −3.5 … 3.5 mm
    const auto pairs = q.Query(cube, Pose({0.01, 0, z}), plate, RigidTransform{}, opt);
    const auto c = Only(pairs);
    CheckPairs(pairs, cube, Pose({0.01, 0, z}), plate, RigidTransform{}, opt.tolerance_m);
    const double expected = std::abs(z) - 0.003;
    EXPECT_NEAR(c.signed_distance_m, expected, 1e-12) << z;
    if (k > 0) {
      EXPECT_NEAR(c.normal_W.z, 1.0, 1e-12) << z;
    }
    if (k < 0) {
      EXPECT_NEAR(c.normal_W.z, -1.0, 1e-12) << z;
    }
    if (k == 0) {
      EXPECT_NEAR(std::abs(c.normal_W.z), 1.0, 1e-12);
    }
  }
}

// Check 5: a model without hierarchy (the procedural ridged block, convex, 16 triangles) uses its
// hull_vertices_O as one leaf (node −1): 1 mm above a cube → 1 mm; resting on the torus, its pairs
// name node −1 on A's side.
TEST(HullProximityHardCases, SingleHullModels) {
  const HapticModel block = MakeRidgedBlock();  // half extents 20 × 20 × 10 mm
  ASSERT_TRUE(block.hull_hierarchy.nodes.empty());
  const HapticModel box = MakeModel(MakeBox({0.01, 0.01, 0.01}));
  HullProximityQuery q;
  ProximityQueryOptions opt;
  opt.tolerance_m = 2e-3;
  const auto pairs = q.Query(block, Pose({0, 0, 0.021}), box, RigidTransform{}, opt);
  const auto c = Only(pairs);
  EXPECT_EQ(c.node_A, -1);
  EXPECT_NEAR(c.signed_distance_m, 1e-3, 1e-12);
  EXPECT_NEAR(c.normal_W.z, 1.0, 1e-12);
  // Both single: the block against itself, penetrating 1 mm (no planes: MPR's direction).
  const auto both = q.Query(block, Pose({0, 0, 0.019}), block, RigidTransform{}, opt);
  const auto d = Only(both);
  EXPECT_EQ(d.node_A, -1);
  EXPECT_EQ(d.node_B, -1);
  EXPECT_NEAR(d.signed_distance_m, -1e-3, 1e-6);
  EXPECT_NEAR(std::abs(d.normal_W.z), 1.0, 1e-6);
  // Against a hierarchy.
  const HapticModel torus = MakeModel(MakeTorus(22, 12, 0.05, 0.015));
  const auto t = q.Query(block, Pose({0.05, 0, 0.015 + 0.01 - 1e-4}), torus, RigidTransform{}, opt);
  ASSERT_FALSE(t.empty());
  for (const auto& p : t) EXPECT_EQ(p.node_A, -1);
  CheckPairs(t, block, Pose({0.05, 0, 0.015 + 0.01 - 1e-4}), torus, RigidTransform{},
             opt.tolerance_m);
}

// Bad input never throws: NaN or infinite poses, a NaN or negative tolerance → no pairs, counted.
// A capacity of 2 keeps the 2 deepest of more pairs and counts the rest as dropped.
TEST(HullProximityHardCases, BadInputAndCapacity) {
  const HapticModel box = MakeModel(MakeBox({0.01, 0.01, 0.01}));
  HullProximityQuery q(2);
  ProximityQueryOptions opt;
  ProximityQueryStats st;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  EXPECT_TRUE(q.Query(box, Pose({nan, 0, 0}), box, RigidTransform{}, opt, &st).empty());
  EXPECT_EQ(st.invalid_input, 1);
  RigidTransform inf_rot;
  inf_rot.rotation.w = std::numeric_limits<double>::infinity();
  EXPECT_TRUE(q.Query(box, inf_rot, box, RigidTransform{}, opt, &st).empty());
  opt.tolerance_m = nan;
  EXPECT_TRUE(q.Query(box, RigidTransform{}, box, RigidTransform{}, opt, &st).empty());
  opt.tolerance_m = -1.0;
  EXPECT_TRUE(q.Query(box, RigidTransform{}, box, RigidTransform{}, opt, &st).empty());
  EXPECT_EQ(st.invalid_input, 1);
  EXPECT_THROW(HullProximityQuery(0), std::invalid_argument);

  // The L-block lying on the torus gives several pairs; keep 2.
  const HapticModel torus = MakeModel(MakeTorus(22, 12, 0.05, 0.015));
  const HapticModel lblock = MakeModel(MakeLBlock());
  ProximityQueryOptions o;
  o.tolerance_m = 3e-3;
  HullProximityQuery full;
  const RigidTransform X_WA = Pose({0.05, 0.0, 0.019});
  const auto all_span = full.Query(lblock, X_WA, torus, RigidTransform{}, o);
  const std::vector<HullPairContact> all(all_span.begin(), all_span.end());
  ASSERT_GT(all.size(), 2u);
  const auto kept = q.Query(lblock, X_WA, torus, RigidTransform{}, o, &st);
  ASSERT_EQ(kept.size(), 2u);
  EXPECT_EQ(st.pairs_dropped, static_cast<int>(all.size()) - 2);
  EXPECT_EQ(kept[0].signed_distance_m, all[0].signed_distance_m);
  EXPECT_EQ(kept[1].signed_distance_m, all[1].signed_distance_m);
}

// Bounding spheres contain their hulls' vertices.
TEST(HullProximityHardCases, BoundingSpheresContainHulls) {
  const HapticModel torus = MakeModel(MakeTorus(22, 12, 0.05, 0.015));
  const HullBounds q = HullBounds::Of(torus);
  for (std::size_t i = 0; i < torus.hull_hierarchy.nodes.size(); ++i) {
    const glm::dvec4 s = q.Sphere(static_cast<int>(i));
    for (const auto& v : torus.hull_hierarchy.nodes[i].hull.vertices_O) {
      EXPECT_LE(glm::length(v - glm::dvec3(s)), s.w * (1 + 1e-12));
    }
  }
}

// Oriented boxes contain their hulls' vertices and have orthonormal axes; on a torus, whose
// patches are tilted every way, the principal axes give a smaller box than the model's own axes on
// most nodes.
TEST(HullProximityHardCases, OrientedBoxesContainHulls) {
  const HapticModel torus = MakeModel(MakeTorus(22, 12, 0.05, 0.015));
  const HullBounds q = HullBounds::Of(torus);
  int tighter = 0;
  for (std::size_t i = 0; i < torus.hull_hierarchy.nodes.size(); ++i) {
    const OrientedBox& b = q.Box(static_cast<int>(i));
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) {
        EXPECT_NEAR(glm::dot(b.axes_O[r], b.axes_O[c]), r == c ? 1.0 : 0.0, 1e-12);
      }
    }
    glm::dvec3 lo(1e30), hi(-1e30);
    for (const auto& v : torus.hull_hierarchy.nodes[i].hull.vertices_O) {
      for (int c = 0; c < 3; ++c) {
        EXPECT_LE(std::abs(glm::dot(v - b.center_O, b.axes_O[c])), b.half_extents_m[c]);
      }
      lo = glm::min(lo, v);
      hi = glm::max(hi, v);
    }
    const glm::dvec3 aabb = hi - lo;
    const double box_volume = 8.0 * b.half_extents_m.x * b.half_extents_m.y * b.half_extents_m.z;
    tighter += box_volume < aabb.x * aabb.y * aabb.z;
  }
  // Principal axes beat the model's axes on most of a torus's nodes (tilted patches).
  EXPECT_GT(tighter, static_cast<int>(torus.hull_hierarchy.nodes.size()) / 2);
  EXPECT_THROW(q.Box(static_cast<int>(torus.hull_hierarchy.nodes.size())), std::out_of_range);
}

}  // namespace
}  // namespace ht
