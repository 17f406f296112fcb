// Tests of the convex-hull hierarchy (haptic_core/hull_hierarchy.h) and its builder
// (haptic_core/model_build/hull_hierarchy_build.h). Properties are checked by routes independent
// of the code under test: leaf convexity from the triangles' own planes, containment through both
// the planes and the support function, and distances against a brute-force hull (every triple of
// points whose plane has all points on one side) with an exact point-triangle distance.

#include "haptic_core/hull_hierarchy.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <functional>
#include <glm/common.hpp>
#include <glm/geometric.hpp>
#include <glm/vec3.hpp>
#include <iostream>
#include <limits>
#include <map>
#include <numbers>
#include <random>
#include <set>
#include <stdexcept>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include "haptic_core/demo/procedural_models.h"
#include "haptic_core/model_build/hull_hierarchy_build.h"

namespace ht {
namespace {

struct Mesh {
  std::vector<glm::dvec3> vertices;
  std::vector<glm::ivec3> triangles;
};

// Axis-aligned cube of half size h centred at `c`, 12 triangles, counter-clockwise from outside.
Mesh MakeCube(double h, glm::dvec3 c = glm::dvec3(0.0)) {
  Mesh m;
  for (int i = 0; i < 8; ++i) {
    m.vertices.push_back(c + h * glm::dvec3((i & 1) ? 1 : -1, (i & 2) ? 1 : -1, (i & 4) ? 1 : -1));
  }
  // Quads (counter-clockwise from outside) split into two triangles each.
  const int quads[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4},
                           {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  for (const auto& q : quads) {
    m.triangles.emplace_back(q[0], q[1], q[2]);
    m.triangles.emplace_back(q[0], q[2], q[3]);
  }
  return m;
}

// A closed prism around z: `n` sides of radius r, length len; caps as fans around their centres.
// 4n triangles (n = 400 gives the 1,600 of the seed's coarse gear).
Mesh MakePrism(int n, double r, double len) {
  Mesh m;
  for (int i = 0; i < n; ++i) {
    const double a = 2.0 * std::numbers::pi * i / n;
    m.vertices.emplace_back(r * std::cos(a), r * std::sin(a), -0.5 * len);
    m.vertices.emplace_back(r * std::cos(a), r * std::sin(a), 0.5 * len);
  }
  const int bottom = static_cast<int>(m.vertices.size());
  m.vertices.emplace_back(0, 0, -0.5 * len);
  m.vertices.emplace_back(0, 0, 0.5 * len);
  const int top = bottom + 1;
  for (int i = 0; i < n; ++i) {
    const int j = (i + 1) % n;
    const int b0 = 2 * i, t0 = 2 * i + 1, b1 = 2 * j, t1 = 2 * j + 1;
    m.triangles.emplace_back(b0, b1, t1);
    m.triangles.emplace_back(b0, t1, t0);
    m.triangles.emplace_back(bottom, b1, b0);
    m.triangles.emplace_back(top, t0, t1);
  }
  return m;
}

// Extrudes a polygon (counter-clockwise seen from +z) from z = 0 to z = height; `cap` triangulates
// the polygon (indices into it, counter-clockwise from +z).
Mesh Extrude(const std::vector<glm::dvec3>& polygon, const std::vector<glm::ivec3>& cap,
             double height) {
  Mesh m;
  const int n = static_cast<int>(polygon.size());
  for (const auto& p : polygon) m.vertices.emplace_back(p.x, p.y, 0.0);
  for (const auto& p : polygon) m.vertices.emplace_back(p.x, p.y, height);
  for (const auto& t : cap) {
    m.triangles.emplace_back(t[0], t[2], t[1]);              // bottom, seen from −z
    m.triangles.emplace_back(t[0] + n, t[1] + n, t[2] + n);  // top
  }
  for (int i = 0; i < n; ++i) {
    const int j = (i + 1) % n;
    m.triangles.emplace_back(i, j, j + n);
    m.triangles.emplace_back(i, j + n, i + n);
  }
  return m;
}

// An L-shaped closed polyhedron (one reflex edge): 24 triangles.
Mesh MakeLShape() {
  const std::vector<glm::dvec3> polygon = {{0, 0, 0}, {2, 0, 0}, {2, 1, 0}, {1, 1, 0},
                                           {1, 2, 0}, {0, 2, 0}, {0, 1, 0}};
  const std::vector<glm::ivec3> cap = {{0, 1, 2}, {0, 2, 3}, {0, 3, 6}, {6, 3, 4}, {6, 4, 5}};
  Mesh m = Extrude(polygon, cap, 0.5);
  for (auto& v : m.vertices) v *= 0.01;  // 2 cm across
  return m;
}

// Torus around z: major radius R, minor radius r, nu × nv quads (2·nu·nv triangles); the minor
// radius may vary with (u, v) through `wrinkle` (a relative factor).
Mesh MakeTorus(int nu, int nv, double R, double r,
               const std::function<double(double, double)>& wrinkle = nullptr) {
  Mesh m;
  for (int i = 0; i < nu; ++i) {
    for (int j = 0; j < nv; ++j) {
      const double u = 2.0 * std::numbers::pi * i / nu;
      const double v = 2.0 * std::numbers::pi * j / nv;
      const double rr = r * (wrinkle ? wrinkle(u, v) : 1.0);
      m.vertices.emplace_back((R + rr * std::cos(v)) * std::cos(u),
                              (R + rr * std::cos(v)) * std::sin(u), rr * std::sin(v));
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

// A closed washer around z (an annulus extruded along z): n segments, radii ri < ro, height hz.
// Its top and bottom faces are flat annuli: convex, but their hulls are disks over the hole.
Mesh MakeWasher(int n, double ri, double ro, double hz) {
  Mesh m;
  for (int i = 0; i < n; ++i) {
    const double a = 2.0 * std::numbers::pi * i / n;
    const glm::dvec3 d(std::cos(a), std::sin(a), 0.0);
    m.vertices.push_back(ro * d);                         // 4i: outer bottom
    m.vertices.push_back(ro * d + glm::dvec3(0, 0, hz));  // 4i+1: outer top
    m.vertices.push_back(ri * d);                         // 4i+2: inner bottom
    m.vertices.push_back(ri * d + glm::dvec3(0, 0, hz));  // 4i+3: inner top
  }
  for (int i = 0; i < n; ++i) {
    const int j = (i + 1) % n;
    const int ob0 = 4 * i, ot0 = 4 * i + 1, ib0 = 4 * i + 2, it0 = 4 * i + 3;
    const int ob1 = 4 * j, ot1 = 4 * j + 1, ib1 = 4 * j + 2, it1 = 4 * j + 3;
    m.triangles.emplace_back(ob0, ob1, ot1);  // outer wall
    m.triangles.emplace_back(ob0, ot1, ot0);
    m.triangles.emplace_back(ib0, it1, ib1);  // inner wall, facing the axis
    m.triangles.emplace_back(ib0, it0, it1);
    m.triangles.emplace_back(it0, ot0, ot1);  // top
    m.triangles.emplace_back(it0, ot1, it1);
    m.triangles.emplace_back(ib0, ob1, ob0);  // bottom
    m.triangles.emplace_back(ib0, ib1, ob1);
  }
  return m;
}

double SignedVolume(const Mesh& m) {
  double v = 0.0;
  for (const auto& t : m.triangles) {
    v += glm::dot(m.vertices[t[0]], glm::cross(m.vertices[t[1]], m.vertices[t[2]])) / 6.0;
  }
  return v;
}

double Diagonal(const std::vector<glm::dvec3>& points) {
  glm::dvec3 lo(std::numeric_limits<double>::infinity());
  glm::dvec3 hi(-std::numeric_limits<double>::infinity());
  for (const auto& p : points) {
    lo = glm::min(lo, p);
    hi = glm::max(hi, p);
  }
  return glm::length(hi - lo);
}

// Closest point on triangle abc to p (Ericson, Real-Time Collision Detection, §5.1.5).
glm::dvec3 ClosestPointOnTriangle(const glm::dvec3& p, const glm::dvec3& a, const glm::dvec3& b,
                                  const glm::dvec3& c) {
  const glm::dvec3 ab = b - a, ac = c - a, ap = p - a;
  const double d1 = glm::dot(ab, ap), d2 = glm::dot(ac, ap);
  if (d1 <= 0 && d2 <= 0) return a;
  const glm::dvec3 bp = p - b;
  const double d3 = glm::dot(ab, bp), d4 = glm::dot(ac, bp);
  if (d3 >= 0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return a + ab * (d1 / (d1 - d3));
  const glm::dvec3 cp = p - c;
  const double d5 = glm::dot(ab, cp), d6 = glm::dot(ac, cp);
  if (d6 >= 0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return a + ac * (d2 / (d2 - d6));
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
  }
  const double denom = 1.0 / (va + vb + vc);
  return a + ab * (vb * denom) + ac * (vc * denom);
}

// Brute-force hull faces of a point set in general position: triples whose plane has every point
// on its inner side, oriented outward.
std::vector<glm::ivec3> BruteForceHullFaces(const std::vector<glm::dvec3>& pts) {
  std::vector<glm::ivec3> faces;
  const int n = static_cast<int>(pts.size());
  for (int i = 0; i < n; ++i) {
    for (int j = i + 1; j < n; ++j) {
      for (int k = j + 1; k < n; ++k) {
        const glm::dvec3 nrm = glm::cross(pts[j] - pts[i], pts[k] - pts[i]);
        if (glm::length(nrm) < 1e-12) continue;
        int above = 0, below = 0;
        for (int q = 0; q < n; ++q) {
          const double s = glm::dot(nrm, pts[q] - pts[i]);
          if (s > 1e-12) ++above;
          if (s < -1e-12) ++below;
        }
        if (above == 0) faces.emplace_back(i, j, k);
        if (below == 0) faces.emplace_back(i, k, j);
      }
    }
  }
  return faces;
}

// True Euclidean distance from q to the hull given by brute-force faces (0 inside).
double DistanceToHull(const glm::dvec3& q, const std::vector<glm::dvec3>& pts,
                      const std::vector<glm::ivec3>& faces) {
  bool inside = true;
  double best = std::numeric_limits<double>::infinity();
  for (const auto& f : faces) {
    const glm::dvec3 nrm = glm::cross(pts[f[1]] - pts[f[0]], pts[f[2]] - pts[f[0]]);
    if (glm::dot(nrm, q - pts[f[0]]) > 0) inside = false;
    best =
        std::min(best, glm::length(q - ClosestPointOnTriangle(q, pts[f[0]], pts[f[1]], pts[f[2]])));
  }
  return inside ? 0.0 : best;
}

// Hull sanity independent of the builder: finite, unit normals, vertices inside their planes.
void ExpectWellFormed(const ConvexHull& hull, double tol) {
  ASSERT_FALSE(hull.vertices_O.empty());
  ASSERT_GE(hull.planes_O.size(), 4u);
  for (const auto& v : hull.vertices_O) {
    ASSERT_TRUE(std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z));
    EXPECT_LE(hull.SignedDistanceBound(v), tol);
  }
  for (const auto& p : hull.planes_O) {
    ASSERT_TRUE(std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z) &&
                std::isfinite(p.w));
    EXPECT_NEAR(glm::length(glm::dvec3(p)), 1.0, 1e-9);
  }
  EXPECT_LE(hull.SignedDistanceBound(hull.center_O), tol);
}

// Width of the hull along unit direction n, from the support function.
double Width(const ConvexHull& hull, const glm::dvec3& n) {
  return glm::dot(hull.Support(n), n) + glm::dot(hull.Support(-n), -n);
}

// Leaf convexity, checked from scratch: every vertex of the leaf's triangles on or behind every
// leaf triangle's plane (within tol), and the leaf's triangles connected through shared edges.
void ExpectLeavesAreConvexConnectedPatches(const Mesh& m, const ConvexHullHierarchy& h,
                                           double tol) {
  for (std::size_t k = 0; k < h.nodes.size(); ++k) {
    const HullNode& node = h.nodes[k];
    if (!node.is_leaf()) continue;
    std::set<int> verts;
    for (int f : node.triangles) {
      for (int c = 0; c < 3; ++c) verts.insert(m.triangles[f][c]);
    }
    for (int f : node.triangles) {
      const auto& t = m.triangles[f];
      const glm::dvec3 a = m.vertices[t[0]];
      const glm::dvec3 nrm = glm::cross(m.vertices[t[1]] - a, m.vertices[t[2]] - a);
      if (glm::length(nrm) == 0.0) continue;
      const glm::dvec3 n = glm::normalize(nrm);
      for (int v : verts) {
        EXPECT_LE(glm::dot(n, m.vertices[v] - a), tol)
            << "leaf " << k << ": vertex " << v << " in front of triangle " << f;
      }
    }
    // Connectivity through edges (breadth-first over the leaf's own triangles).
    std::map<std::pair<int, int>, std::vector<int>> edges;
    for (int f : node.triangles) {
      for (int c = 0; c < 3; ++c) {
        int a = m.triangles[f][c], b = m.triangles[f][(c + 1) % 3];
        edges[{std::min(a, b), std::max(a, b)}].push_back(f);
      }
    }
    std::set<int> reached{node.triangles[0]};
    std::vector<int> queue{node.triangles[0]};
    while (!queue.empty()) {
      const int f = queue.back();
      queue.pop_back();
      for (int c = 0; c < 3; ++c) {
        int a = m.triangles[f][c], b = m.triangles[f][(c + 1) % 3];
        for (int g : edges[{std::min(a, b), std::max(a, b)}]) {
          if (reached.insert(g).second) queue.push_back(g);
        }
      }
    }
    EXPECT_EQ(reached.size(), node.triangles.size()) << "leaf " << k << " is not edge-connected";
  }
}

// Every node's hull contains every vertex of its subtree's triangles, through the planes and
// through the support function in random directions (a route that does not use the planes).
void ExpectNodesBoundSubtrees(const Mesh& m, const ConvexHullHierarchy& h, double tol) {
  std::mt19937 rng(7);
  std::normal_distribution<double> g;
  std::vector<glm::dvec3> dirs;
  for (int i = 0; i < 64; ++i) dirs.push_back(glm::normalize(glm::dvec3(g(rng), g(rng), g(rng))));
  std::function<std::vector<int>(int)> subtree_vertices = [&](int k) {
    const HullNode& node = h.nodes[k];
    std::vector<int> out;
    if (node.is_leaf()) {
      for (int f : node.triangles) {
        for (int c = 0; c < 3; ++c) out.push_back(m.triangles[f][c]);
      }
    } else {
      for (int c : node.children) {
        auto sub = subtree_vertices(c);
        out.insert(out.end(), sub.begin(), sub.end());
      }
    }
    const ConvexHull& hull = node.hull;
    for (int v : out) {
      const glm::dvec3& p = m.vertices[v];
      EXPECT_LE(hull.SignedDistanceBound(p), tol) << "node " << k << " vertex " << v;
      for (const auto& d : dirs) {
        EXPECT_LE(glm::dot(d, p), glm::dot(d, hull.Support(d)) + tol) << "node " << k;
      }
    }
    return out;
  };
  subtree_vertices(0);
}

void ExpectBalancedBinaryTree(const ConvexHullHierarchy& h) {
  const int leaves = h.LeafCount();
  EXPECT_EQ(static_cast<int>(h.nodes.size()), 2 * leaves - 1);
  EXPECT_LE(h.Depth(), static_cast<int>(std::ceil(std::log2(leaves))) + 1);
}

void ExpectThrowsWith(const std::function<void()>& f, const std::string& part) {
  try {
    f();
    ADD_FAILURE() << "no exception; expected one mentioning \"" << part << "\"";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find(part), std::string::npos) << e.what();
  }
}

// ---------------------------------------------------------------------------------------------
// ComputeConvexHull

TEST(ComputeConvexHull, RandomPointsDistanceBoundNeverExceedsTrueDistance) {
  std::mt19937 rng(42);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int trial = 0; trial < 5; ++trial) {
    std::vector<glm::dvec3> pts;
    for (int i = 0; i < 14; ++i) pts.emplace_back(u(rng), 0.5 * u(rng), 0.3 * u(rng) + 2.0);
    const ConvexHull hull = ComputeConvexHull(pts, 0.0);
    ExpectWellFormed(hull, 1e-12);
    const auto faces = BruteForceHullFaces(pts);
    ASSERT_FALSE(faces.empty());

    // Vertices are exactly the extreme points (those on a brute-force face).
    std::set<std::tuple<double, double, double>> extreme, got;
    for (const auto& f : faces) {
      for (int c = 0; c < 3; ++c) extreme.emplace(pts[f[c]].x, pts[f[c]].y, pts[f[c]].z);
    }
    for (const auto& v : hull.vertices_O) got.emplace(v.x, v.y, v.z);
    EXPECT_EQ(got, extreme);

    for (const auto& p : pts) EXPECT_LE(hull.SignedDistanceBound(p), 0.0);
    for (int i = 0; i < 2000; ++i) {
      const glm::dvec3 q(2.5 * u(rng), 1.5 * u(rng), 2.0 + 1.5 * u(rng));
      const double bound = hull.SignedDistanceBound(q);
      const double dist = DistanceToHull(q, pts, faces);
      EXPECT_LE(bound, dist + 1e-12) << "q = " << q.x << " " << q.y << " " << q.z;
      if (bound > 1e-12) {
        EXPECT_GT(dist, 0.0);
      }
      if (dist == 0.0) {
        EXPECT_LE(bound, 1e-12);
      }
    }
    // Straight out of a face's centroid the bound is the distance.
    for (const auto& f : faces) {
      const glm::dvec3 n = glm::normalize(glm::cross(pts[f[1]] - pts[f[0]], pts[f[2]] - pts[f[0]]));
      const glm::dvec3 q = (pts[f[0]] + pts[f[1]] + pts[f[2]]) / 3.0 + 0.01 * n;
      EXPECT_NEAR(hull.SignedDistanceBound(q), DistanceToHull(q, pts, faces), 1e-9);
    }
  }
}

TEST(ComputeConvexHull, SupportIsTheFarthestInputPoint) {
  std::mt19937 rng(3);
  std::normal_distribution<double> g;
  std::vector<glm::dvec3> pts;
  for (int i = 0; i < 200; ++i) pts.emplace_back(g(rng), g(rng), g(rng));
  const ConvexHull hull = ComputeConvexHull(pts, 0.0);
  EXPECT_LT(hull.vertices_O.size(), pts.size());
  for (int i = 0; i < 500; ++i) {
    const glm::dvec3 d(g(rng), g(rng), g(rng));
    double best = -std::numeric_limits<double>::infinity();
    for (const auto& p : pts) best = std::max(best, glm::dot(d, p));
    EXPECT_DOUBLE_EQ(glm::dot(d, hull.Support(d)), best);
  }
}

TEST(ComputeConvexHull, SingleTriangleGivesAThinSlabOfTheRequestedThickness) {
  const std::vector<glm::dvec3> tri = {{0, 0, 1}, {1, 0, 1}, {0, 1, 1.5}};
  const ConvexHull hull = ComputeConvexHull(tri, 0.01);
  ExpectWellFormed(hull, 1e-12);
  for (const auto& p : tri) EXPECT_LE(hull.SignedDistanceBound(p), 0.0);
  const glm::dvec3 n = glm::normalize(glm::cross(tri[1] - tri[0], tri[2] - tri[0]));
  EXPECT_NEAR(Width(hull, n), 0.01, 1e-9);
  // A point 0.1 above the triangle's middle is 0.1 − 0.005 from the slab.
  const glm::dvec3 mid = (tri[0] + tri[1] + tri[2]) / 3.0;
  EXPECT_NEAR(hull.SignedDistanceBound(mid + 0.1 * n), 0.095, 1e-9);
}

TEST(ComputeConvexHull, CoplanarPointsWithoutThicknessGiveAFiniteFlatHull) {
  std::vector<glm::dvec3> pts;
  const glm::dvec3 e1 = glm::normalize(glm::dvec3(1, 1, 0)),
                   e2 = glm::normalize(glm::dvec3(0, 1, 1));
  for (int i = 0; i < 5; ++i) {
    for (int j = 0; j < 5; ++j) pts.push_back(glm::dvec3(3, -2, 1) + 0.1 * i * e1 + 0.1 * j * e2);
  }
  const ConvexHull hull = ComputeConvexHull(pts, 0.0);
  ExpectWellFormed(hull, 1e-12);
  for (const auto& p : pts) EXPECT_LE(hull.SignedDistanceBound(p), 1e-15);
  const glm::dvec3 n = glm::normalize(glm::cross(e1, e2));
  EXPECT_GT(Width(hull, n), 0.0);
  EXPECT_LT(Width(hull, n), 1e-6);
  const glm::dvec3 corner = pts.front();
  EXPECT_NEAR(hull.SignedDistanceBound(corner + 0.2 * n), 0.2, 1e-6);
}

TEST(ComputeConvexHull, CollinearAndCoincidentPointsGiveFiniteHulls) {
  std::vector<glm::dvec3> line;
  for (int i = 0; i < 10; ++i) line.push_back(glm::dvec3(1, 2, 3) + 0.05 * i * glm::dvec3(1, 2, 2));
  for (double thickness : {0.0, 1e-3}) {
    const ConvexHull hull = ComputeConvexHull(line, thickness);
    ExpectWellFormed(hull, 1e-12);
    for (const auto& p : line) EXPECT_LE(hull.SignedDistanceBound(p), 1e-15);
    EXPECT_NEAR(hull.SignedDistanceBound(line.back() + glm::dvec3(1, 2, 2)), 3.0, 1e-3);
  }
  const std::vector<glm::dvec3> same(5, glm::dvec3(0.5, -1, 2));
  const ConvexHull point = ComputeConvexHull(same, 0.0);
  ASSERT_EQ(point.vertices_O.size(), 1u);
  EXPECT_EQ(point.vertices_O[0], same[0]);
  EXPECT_EQ(point.planes_O.size(), 6u);
  EXPECT_DOUBLE_EQ(point.SignedDistanceBound(same[0]), 0.0);
  EXPECT_DOUBLE_EQ(point.SignedDistanceBound(same[0] + glm::dvec3(0, 0, 2)), 2.0);
  const ConvexHull cube = ComputeConvexHull(same, 0.01);
  ExpectWellFormed(cube, 1e-12);
  EXPECT_NEAR(Width(cube, glm::dvec3(1, 0, 0)), 0.01, 1e-12);
  EXPECT_LE(cube.SignedDistanceBound(same[0]), -0.005 + 1e-12);
}

TEST(ComputeConvexHull, RejectsBadInput) {
  ExpectThrowsWith([] { ComputeConvexHull({}, 0.0); }, "no points");
  ExpectThrowsWith([] { ComputeConvexHull({{0, 0, std::nan("")}}, 0.0); }, "point 0");
  ExpectThrowsWith([] { ComputeConvexHull({{0, 0, 0}}, -1.0); }, "thickness_m");
  ExpectThrowsWith([] { ComputeConvexHull({{0, 0, 0}}, std::nan("")); }, "thickness_m");
}

TEST(ConvexHull, EmptyHullIsOutsideEverywhereAndSupportFallsBackToCenter) {
  ConvexHull empty;
  empty.center_O = glm::dvec3(1, 2, 3);
  EXPECT_EQ(empty.SignedDistanceBound(glm::dvec3(0.0)), std::numeric_limits<double>::infinity());
  EXPECT_EQ(empty.Support(glm::dvec3(1, 0, 0)), glm::dvec3(1, 2, 3));
  const ConvexHull hull = ComputeConvexHull(MakeCube(1.0).vertices, 0.0);
  EXPECT_TRUE(std::isnan(hull.SignedDistanceBound(glm::dvec3(std::nan(""), 0, 0))));
}

// ---------------------------------------------------------------------------------------------
// BuildConvexHullHierarchy

TEST(BuildConvexHullHierarchy, CubeIsOneNode) {
  const Mesh m = MakeCube(0.02);
  ASSERT_GT(SignedVolume(m), 0.0);
  const ConvexHullHierarchy h = BuildConvexHullHierarchy(m.vertices, m.triangles);
  ASSERT_EQ(h.nodes.size(), 1u);
  EXPECT_TRUE(h.nodes[0].is_leaf());
  EXPECT_EQ(h.nodes[0].triangles.size(), 12u);
  EXPECT_EQ(h.nodes[0].hull.vertices_O.size(), 8u);
  EXPECT_EQ(h.nodes[0].hull.planes_O.size(), 6u);  // coplanar facets merged
  EXPECT_EQ(h.LeafCount(), 1);
  EXPECT_EQ(h.Depth(), 1);
  EXPECT_NO_THROW(h.Validate(m.vertices, m.triangles, 0.0));
  // The planes are the cube's faces: a point 1 cm above the top is 1 cm away.
  EXPECT_NEAR(h.nodes[0].hull.SignedDistanceBound(glm::dvec3(0, 0, 0.03)), 0.01, 1e-15);
}

TEST(BuildConvexHullHierarchy, GearLikePrismOf1600TrianglesIsOneNode) {
  const Mesh m = MakePrism(400, 0.025, 0.06);
  ASSERT_EQ(m.triangles.size(), 1600u);
  ASSERT_GT(SignedVolume(m), 0.0);
  const ConvexHullHierarchy h = BuildConvexHullHierarchy(m.vertices, m.triangles);
  ASSERT_EQ(h.nodes.size(), 1u);
  EXPECT_EQ(h.nodes[0].triangles.size(), 1600u);
  EXPECT_EQ(h.nodes[0].hull.vertices_O.size(), 800u);  // the centres of the caps are not extreme
  EXPECT_NO_THROW(h.Validate(m.vertices, m.triangles, 0.0));
}

TEST(BuildConvexHullHierarchy, ProjectRidgedBlockAndGearAreOneNodeEach) {
  // The seed's convex models (Table 6: block 1 BV, gear 1 BV) as procedural_models.h builds them.
  RidgedBlockParams block_params;
  block_params.texture_size = 16;
  const HapticModel block = MakeRidgedBlock(block_params);
  const ConvexHullHierarchy hb = BuildConvexHullHierarchy(block.vertices_O, block.triangles);
  EXPECT_EQ(hb.nodes.size(), 1u);
  EXPECT_NO_THROW(hb.Validate(block.vertices_O, block.triangles, 1e-12));
  RidgedGearParams gear_params;
  gear_params.texture_size = 16;
  const HapticModel gear = MakeRidgedGear(gear_params);
  EXPECT_EQ(gear.triangles.size(), 1600u);
  const ConvexHullHierarchy hg = BuildConvexHullHierarchy(gear.vertices_O, gear.triangles);
  EXPECT_EQ(hg.nodes.size(), 1u);
  EXPECT_NO_THROW(hg.Validate(gear.vertices_O, gear.triangles, 1e-12));
}

TEST(BuildConvexHullHierarchy, MaxLeafTrianglesSplitsEvenAConvexMesh) {
  const Mesh m = MakePrism(16, 0.025, 0.06);
  HullHierarchyParams params;
  params.max_leaf_triangles = 5;
  const ConvexHullHierarchy h = BuildConvexHullHierarchy(m.vertices, m.triangles, params);
  EXPECT_GT(h.LeafCount(), 1);
  for (const auto& node : h.nodes) EXPECT_LE(node.triangles.size(), 5u);
  EXPECT_NO_THROW(h.Validate(m.vertices, m.triangles, 1e-12));
  ExpectBalancedBinaryTree(h);
}

TEST(BuildConvexHullHierarchy, LShapeSplitsIntoConvexPatchesThatTheTreeBounds) {
  const Mesh m = MakeLShape();
  ASSERT_EQ(m.triangles.size(), 24u);
  ASSERT_GT(SignedVolume(m), 0.0);
  const ConvexHullHierarchy h = BuildConvexHullHierarchy(m.vertices, m.triangles);
  EXPECT_GE(h.LeafCount(), 2);
  const double tol = 1e-9 * Diagonal(m.vertices);
  EXPECT_NO_THROW(h.Validate(m.vertices, m.triangles, tol));
  ExpectLeavesAreConvexConnectedPatches(m, h, 1e-3 * Diagonal(m.vertices));
  ExpectNodesBoundSubtrees(m, h, tol);
  ExpectBalancedBinaryTree(h);
  // The root hull is the hull of the whole L: it contains the notch's corner, which no leaf does
  // more than a leaf thickness deep.
  const glm::dvec3 notch(0.015, 0.015, 0.0025);
  EXPECT_LE(h.nodes[0].hull.SignedDistanceBound(notch), 0.0);
}

TEST(BuildConvexHullHierarchy, TorusGivesManyConvexLeavesAndTightHulls) {
  const Mesh m = MakeTorus(19, 14, 0.03, 0.01);  // 532 triangles, as the seed's coarse torus
  ASSERT_EQ(m.triangles.size(), 532u);
  ASSERT_GT(SignedVolume(m), 0.0);
  const auto start = std::chrono::steady_clock::now();
  const ConvexHullHierarchy h = BuildConvexHullHierarchy(m.vertices, m.triangles);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::cout << "torus 532 triangles: " << h.LeafCount() << " leaves, " << h.nodes.size()
            << " nodes, depth " << h.Depth() << ", " << seconds * 1e3 << " ms\n";
  EXPECT_GT(h.LeafCount(), 10);
  EXPECT_LT(h.LeafCount(), 532);
  const double tol = 1e-9 * Diagonal(m.vertices);
  EXPECT_NO_THROW(h.Validate(m.vertices, m.triangles, tol));
  ExpectLeavesAreConvexConnectedPatches(m, h, 1e-3 * Diagonal(m.vertices));
  ExpectNodesBoundSubtrees(m, h, tol);
  ExpectBalancedBinaryTree(h);
  // Leaf hulls stay close to their patches: none reaches the centre of the hole (2 cm from the
  // surface), although the root's hull (the hull of the whole torus) contains it.
  EXPECT_LE(h.nodes[0].hull.SignedDistanceBound(glm::dvec3(0.0)), 0.0);
  for (const auto& node : h.nodes) {
    if (node.is_leaf()) {
      EXPECT_GT(node.hull.SignedDistanceBound(glm::dvec3(0.0)), 0.0);
    }
  }
}

TEST(BuildConvexHullHierarchy, ShadowGapKeepsLeafHullsOffTheHoleOfAWasher) {
  const Mesh m = MakeWasher(24, 0.02, 0.03, 0.01);
  ASSERT_GT(SignedVolume(m), 0.0);
  const glm::dvec3 hole_top(0.0, 0.0, 0.01 - 1e-5);  // just under the top face, mid-hole
  const auto leaves_over_hole = [&](const ConvexHullHierarchy& h) {
    int count = 0;
    for (const auto& node : h.nodes) {
      if (node.is_leaf() && node.hull.SignedDistanceBound(hole_top) <= 0.0) ++count;
    }
    return count;
  };
  HullHierarchyParams no_gap_limit;
  no_gap_limit.max_shadow_gap_m = std::numeric_limits<double>::infinity();
  const ConvexHullHierarchy loose = BuildConvexHullHierarchy(m.vertices, m.triangles, no_gap_limit);
  EXPECT_GE(leaves_over_hole(loose), 1);  // the whole top annulus is one leaf: a disk
  const ConvexHullHierarchy h = BuildConvexHullHierarchy(m.vertices, m.triangles);
  EXPECT_EQ(leaves_over_hole(h), 0);
  const double tol = 1e-9 * Diagonal(m.vertices);
  EXPECT_NO_THROW(h.Validate(m.vertices, m.triangles, tol));
  ExpectLeavesAreConvexConnectedPatches(m, h, 1e-3 * Diagonal(m.vertices));
  ExpectNodesBoundSubtrees(m, h, tol);
}

TEST(BuildConvexHullHierarchy, WrinkledTorusOf720TrianglesBuildsFast) {
  const Mesh m = MakeTorus(24, 15, 0.03, 0.01,
                           [](double u, double v) { return 1.0 + 0.1 * std::sin(5 * u + 3 * v); });
  ASSERT_EQ(m.triangles.size(), 720u);
  const auto start = std::chrono::steady_clock::now();
  const ConvexHullHierarchy h = BuildConvexHullHierarchy(m.vertices, m.triangles);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::cout << "wrinkled torus 720 triangles: " << h.LeafCount() << " leaves, " << h.nodes.size()
            << " nodes, depth " << h.Depth() << ", " << seconds * 1e3 << " ms\n";
  EXPECT_LT(seconds, 2.0);
  const double tol = 1e-9 * Diagonal(m.vertices);
  EXPECT_NO_THROW(h.Validate(m.vertices, m.triangles, tol));
  ExpectLeavesAreConvexConnectedPatches(m, h, 1e-3 * Diagonal(m.vertices));
  ExpectBalancedBinaryTree(h);
}

TEST(BuildConvexHullHierarchy, SeparateCubesNeverShareALeaf) {
  Mesh m = MakeCube(0.01);
  const Mesh other = MakeCube(0.01, glm::dvec3(0.05, 0, 0));
  for (const auto& t : other.triangles) m.triangles.push_back(t + glm::ivec3(8));
  m.vertices.insert(m.vertices.end(), other.vertices.begin(), other.vertices.end());
  const ConvexHullHierarchy h = BuildConvexHullHierarchy(m.vertices, m.triangles);
  EXPECT_GE(h.LeafCount(), 2);
  for (const auto& node : h.nodes) {
    if (!node.is_leaf()) continue;
    const bool first = node.triangles[0] < 12;
    for (int f : node.triangles) EXPECT_EQ(f < 12, first);
  }
  EXPECT_NO_THROW(h.Validate(m.vertices, m.triangles, 1e-12));
  ExpectLeavesAreConvexConnectedPatches(m, h, 1e-3 * Diagonal(m.vertices));
}

TEST(BuildConvexHullHierarchy, FlatPatchesGetInwardThicknessOnly) {
  // One triangle, normal +z: one leaf whose hull's top face is the triangle's plane and which
  // extends one leaf thickness below it.
  const std::vector<glm::dvec3> v = {{0, 0, 0.01}, {0.02, 0, 0.01}, {0, 0.02, 0.01}};
  const std::vector<glm::ivec3> t = {{0, 1, 2}};
  HullHierarchyParams params;
  params.leaf_thickness_m = 1e-3;
  const ConvexHullHierarchy h = BuildConvexHullHierarchy(v, t, params);
  ASSERT_EQ(h.nodes.size(), 1u);
  const ConvexHull& hull = h.nodes[0].hull;
  ExpectWellFormed(hull, 1e-15);
  EXPECT_DOUBLE_EQ(hull.Support(glm::dvec3(0, 0, 1)).z, 0.01);
  EXPECT_NEAR(hull.Support(glm::dvec3(0, 0, -1)).z, 0.009, 1e-15);
  EXPECT_NO_THROW(h.Validate(v, t, 0.0));

  // A flat square (two triangles) with the automatic thickness: also one node.
  const std::vector<glm::dvec3> sq = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};
  const std::vector<glm::ivec3> st = {{0, 1, 2}, {0, 2, 3}};
  const ConvexHullHierarchy hs = BuildConvexHullHierarchy(sq, st);
  ASSERT_EQ(hs.nodes.size(), 1u);
  EXPECT_NEAR(Width(hs.nodes[0].hull, glm::dvec3(0, 0, 1)), 1e-3 * std::sqrt(2.0), 1e-15);
  EXPECT_NO_THROW(hs.Validate(sq, st, 0.0));
}

TEST(BuildConvexHullHierarchy, DegenerateTrianglesDoNotBreakTheBuild) {
  Mesh m = MakeLShape();
  m.triangles.emplace_back(0, 0, 0);  // a point
  m.triangles.emplace_back(0, 1, 1);  // a segment
  m.triangles.emplace_back(3, 3, 3);
  const ConvexHullHierarchy h = BuildConvexHullHierarchy(m.vertices, m.triangles);
  EXPECT_NO_THROW(h.Validate(m.vertices, m.triangles, 1e-12));
  // All points equal: a single leaf, finite.
  const std::vector<glm::dvec3> same(3, glm::dvec3(1, 1, 1));
  const ConvexHullHierarchy hp = BuildConvexHullHierarchy(same, {{0, 1, 2}});
  ASSERT_EQ(hp.nodes.size(), 1u);
  EXPECT_NO_THROW(hp.Validate(same, {{0, 1, 2}}, 0.0));
}

TEST(BuildConvexHullHierarchy, RejectsBadInput) {
  const Mesh m = MakeCube(1.0);
  ExpectThrowsWith([&] { BuildConvexHullHierarchy(m.vertices, {}); }, "no triangles");
  ExpectThrowsWith([&] { BuildConvexHullHierarchy(m.vertices, {{0, 1, 8}}); }, "vertex 8");
  ExpectThrowsWith([&] { BuildConvexHullHierarchy(m.vertices, {{0, -1, 2}}); }, "vertex -1");
  ExpectThrowsWith([&] { BuildConvexHullHierarchy({}, {{0, 1, 2}}); }, "vertex 0");
  auto bad = m.vertices;
  bad[3].y = std::nan("");
  ExpectThrowsWith([&] { BuildConvexHullHierarchy(bad, m.triangles); }, "vertex 3");
  bad[3].y = std::numeric_limits<double>::infinity();
  ExpectThrowsWith([&] { BuildConvexHullHierarchy(bad, m.triangles); }, "not finite");
  HullHierarchyParams p;
  p.convexity_tolerance_m = -1.0;
  ExpectThrowsWith([&] { BuildConvexHullHierarchy(m.vertices, m.triangles, p); },
                   "convexity_tolerance_m");
  p = {};
  p.leaf_thickness_m = std::nan("");
  ExpectThrowsWith([&] { BuildConvexHullHierarchy(m.vertices, m.triangles, p); },
                   "leaf_thickness_m");
  p = {};
  p.max_leaf_triangles = -2;
  ExpectThrowsWith([&] { BuildConvexHullHierarchy(m.vertices, m.triangles, p); },
                   "max_leaf_triangles");
  p = {};
  p.max_normal_deviation_deg = 0.0;
  ExpectThrowsWith([&] { BuildConvexHullHierarchy(m.vertices, m.triangles, p); },
                   "max_normal_deviation_deg");
  p = {};
  p.max_shadow_gap_m = -1.0;
  ExpectThrowsWith([&] { BuildConvexHullHierarchy(m.vertices, m.triangles, p); },
                   "max_shadow_gap_m");
}

// ---------------------------------------------------------------------------------------------
// ConvexHullHierarchy::Validate

class ValidateTest : public ::testing::Test {
 protected:
  void SetUp() override {
    mesh_ = MakeTorus(12, 8, 0.03, 0.01);
    good_ = BuildConvexHullHierarchy(mesh_.vertices, mesh_.triangles);
    ASSERT_GE(good_.LeafCount(), 3);
    ASSERT_NO_THROW(good_.Validate(mesh_.vertices, mesh_.triangles, 1e-12));
  }
  int FirstLeaf(int skip = 0) const {
    for (std::size_t k = 0; k < good_.nodes.size(); ++k) {
      if (good_.nodes[k].is_leaf() && skip-- == 0) return static_cast<int>(k);
    }
    return -1;
  }
  void ExpectInvalid(const ConvexHullHierarchy& h, const std::string& part) const {
    ExpectThrowsWith([&] { h.Validate(mesh_.vertices, mesh_.triangles, 1e-9); }, part);
  }
  Mesh mesh_;
  ConvexHullHierarchy good_;
};

TEST_F(ValidateTest, DetectsATriangleInNoLeafOrInTwo) {
  ConvexHullHierarchy h = good_;
  int leaf = -1;
  for (std::size_t k = 0; k < h.nodes.size(); ++k) {
    if (h.nodes[k].is_leaf() && h.nodes[k].triangles.size() >= 2) leaf = static_cast<int>(k);
  }
  ASSERT_GE(leaf, 0);
  h.nodes[leaf].triangles.pop_back();
  ExpectInvalid(h, "in no leaf");

  h = good_;
  const int other = FirstLeaf() == leaf ? FirstLeaf(1) : FirstLeaf();
  h.nodes[other].triangles.push_back(h.nodes[leaf].triangles[0]);
  ExpectInvalid(h, "two leaves");

  h = good_;
  h.nodes[leaf].triangles.clear();
  ExpectInvalid(h, "leaf without triangles");
  h = good_;
  h.nodes[leaf].triangles.push_back(-5);
  ExpectInvalid(h, "out of range");
  h = good_;
  h.nodes[0].triangles.push_back(0);
  ExpectInvalid(h, "internal but holds triangles");
}

TEST_F(ValidateTest, DetectsBrokenTreeStructure) {
  ConvexHullHierarchy h = good_;
  h.nodes[0].children[1] = 0;
  ExpectInvalid(h, "reached twice");
  h = good_;
  h.nodes[0].children[1] = static_cast<int>(h.nodes.size());
  ExpectInvalid(h, "out of range");
  h = good_;
  h.nodes[0].children[1] = -1;
  ExpectInvalid(h, "exactly one child");
  h = good_;
  h.nodes.push_back(h.nodes[FirstLeaf()]);
  ExpectInvalid(h, "not reachable");
  h = good_;
  h.nodes.clear();
  ExpectInvalid(h, "empty");
  EXPECT_EQ(h.Depth(), 0);
  EXPECT_EQ(h.LeafCount(), 0);
}

TEST_F(ValidateTest, DetectsHullsThatDoNotBound) {
  // A leaf hull pushed in by 1 mm along one face no longer holds its triangles' vertices...
  ConvexHullHierarchy h = good_;
  const int leaf = FirstLeaf();
  for (auto& plane : h.nodes[leaf].hull.planes_O) plane.w -= 1e-3;
  ExpectInvalid(h, "outside");
  // ... and a root hull shrunk likewise no longer holds its children.
  h = good_;
  for (auto& plane : h.nodes[0].hull.planes_O) plane.w -= 1e-3;
  ExpectInvalid(h, "node 0");
  h = good_;
  h.nodes[leaf].hull.vertices_O[0].x = std::nan("");
  ExpectInvalid(h, "not finite");
  h = good_;
  h.nodes[leaf].hull.planes_O[0] *= 2.0;
  ExpectInvalid(h, "length");
  ExpectThrowsWith([&] { good_.Validate(mesh_.vertices, mesh_.triangles, -1.0); }, "tolerance");
}

}  // namespace
}  // namespace ht
