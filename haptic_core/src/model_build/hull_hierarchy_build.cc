// The convex-hull hierarchy over a coarse mesh (hull_hierarchy_build.h, DESIGN.md §2): the mesh
// grown into convex surface patches, a leaf hull per patch, and the tree over them. The hulls
// themselves: convex_hull_build.cc.
#include "haptic_core/model_build/hull_hierarchy_build.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <glm/common.hpp>
#include <glm/geometric.hpp>
#include <limits>
#include <map>
#include <memory>
#include <queue>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "hull_build_helpers.h"

namespace ht {
namespace {

using hull_build::IsFinite;
using hull_build::PlaneValue;

// A triangle whose doubled area is below this × diagonal² has no usable plane.
constexpr double kDegenerateRelativeArea = 1e-12;

// Unit normal of triangle (a, b, c), counter-clockwise; zero when its doubled area is below
// `min_doubled_area`.
glm::dvec3 TriangleNormal(const glm::dvec3& a, const glm::dvec3& b, const glm::dvec3& c,
                          double min_doubled_area) {
  const glm::dvec3 n = glm::cross(b - a, c - a);
  const double doubled_area = glm::length(n);
  if (!(doubled_area > min_doubled_area)) return glm::dvec3(0.0);
  return n / doubled_area;
}

// Per-triangle data for the patch growing.
struct TriangleInfo {
  glm::dvec3 normal{0.0};  // unit outward normal; zero for a degenerate triangle
  glm::dvec4 plane{0.0};   // (n, d) with n·p − d = 0 on the triangle
  bool degenerate = true;
};

using Point2 = std::array<double, 2>;

double Cross2(const Point2& o, const Point2& a, const Point2& b) {
  return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]);
}

// Convex hull of 2-D points, counter-clockwise, without collinear points (Andrew's monotone
// chain); `points` is reordered.
std::vector<Point2> ConvexHull2d(std::vector<Point2>& points) {
  const std::size_t n = points.size();
  std::sort(points.begin(), points.end());
  if (n < 3) return points;
  std::vector<Point2> hull(2 * n);
  std::size_t k = 0;
  for (std::size_t i = 0; i < n; ++i) {
    while (k >= 2 && Cross2(hull[k - 2], hull[k - 1], points[i]) <= 0.0) --k;
    hull[k++] = points[i];
  }
  for (std::size_t i = n - 1, lower = k + 1; i-- > 0;) {
    while (k >= lower && Cross2(hull[k - 2], hull[k - 1], points[i]) <= 0.0) --k;
    hull[k++] = points[i];
  }
  hull.resize(k - 1);  // the last point repeats the first
  return hull;
}

double PolygonArea2d(const std::vector<Point2>& polygon) {
  double area = 0.0;
  for (std::size_t i = 0; i < polygon.size(); ++i) {
    const Point2& a = polygon[i];
    const Point2& b = polygon[(i + 1) % polygon.size()];
    area += a[0] * b[1] - b[0] * a[1];
  }
  return 0.5 * std::abs(area);
}

double SegmentDistance2d(const Point2& p, const Point2& a, const Point2& b) {
  const double dx = b[0] - a[0];
  const double dy = b[1] - a[1];
  const double length2 = dx * dx + dy * dy;
  double s = length2 > 0.0 ? ((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / length2 : 0.0;
  s = std::clamp(s, 0.0, 1.0);
  return std::hypot(p[0] - a[0] - s * dx, p[1] - a[1] - s * dy);
}

// Distance from p to the triangle abc (either winding) in the plane; 0 inside.
double TriangleDistance2d(const Point2& p, const std::array<Point2, 3>& t) {
  const double c0 = Cross2(t[0], t[1], p);
  const double c1 = Cross2(t[1], t[2], p);
  const double c2 = Cross2(t[2], t[0], p);
  if ((c0 >= 0.0 && c1 >= 0.0 && c2 >= 0.0) || (c0 <= 0.0 && c1 <= 0.0 && c2 <= 0.0)) return 0.0;
  return std::min({SegmentDistance2d(p, t[0], t[1]), SegmentDistance2d(p, t[1], t[2]),
                   SegmentDistance2d(p, t[2], t[0])});
}

struct GrowLimits {
  double tolerance = 0.0;        // convexity tolerance (m)
  double min_normal_dot = -1.0;  // cos of the largest normal deviation from the seed's
  double max_gap = 0.0;          // largest shadow gap (m); infinity disables
  int max_leaf_triangles = 0;    // 0 = unlimited
};

// Grows convex surface patches over edge adjacency (see the header for the rules).
std::vector<std::vector<int>> GrowConvexPatches(const std::vector<glm::dvec3>& vertices,
                                                const std::vector<glm::ivec3>& triangles,
                                                const std::vector<TriangleInfo>& info,
                                                const GrowLimits& limits) {
  const double tolerance = limits.tolerance;
  const int face_count = static_cast<int>(triangles.size());
  // Edge adjacency: triangles sharing an (unordered) edge are neighbours.
  std::map<std::pair<int, int>, std::vector<int>> edge_faces;
  for (int f = 0; f < face_count; ++f) {
    for (int c = 0; c < 3; ++c) {
      int a = triangles[static_cast<std::size_t>(f)][c];
      int b = triangles[static_cast<std::size_t>(f)][(c + 1) % 3];
      if (a == b) continue;
      if (a > b) std::swap(a, b);
      edge_faces[{a, b}].push_back(f);
    }
  }
  std::vector<std::vector<int>> neighbours(static_cast<std::size_t>(face_count));
  for (const auto& [edge, faces] : edge_faces) {
    for (const int f : faces) {
      for (const int g : faces) {
        if (f != g) neighbours[static_cast<std::size_t>(f)].push_back(g);
      }
    }
  }
  for (auto& list : neighbours) {
    std::sort(list.begin(), list.end());
    list.erase(std::unique(list.begin(), list.end()), list.end());
  }

  std::vector<int> patch_of(static_cast<std::size_t>(face_count), -1);
  std::vector<int> rejected_by(static_cast<std::size_t>(face_count), -1);
  std::vector<int> vertex_in_patch(vertices.size(), -1);
  std::vector<std::vector<int>> patches;
  for (int seed = 0; seed < face_count; ++seed) {
    if (patch_of[static_cast<std::size_t>(seed)] >= 0) continue;
    const int id = static_cast<int>(patches.size());
    std::vector<int> members;
    std::vector<int> patch_vertices;
    std::vector<int> planar_members;  // members with a plane
    glm::dvec3 reference(0.0);        // the seed's normal (first non-degenerate member's)
    glm::dvec3 e1(0.0), e2(0.0);      // a basis of the plane ⟂ reference
    // The patch's shadow on the plane ⟂ reference: its triangles, and their total area.
    std::vector<std::array<Point2, 3>> shadow;
    double shadow_area = 0.0;
    std::vector<Point2> shadow_points;

    const auto project = [&](int v) {
      const glm::dvec3& p = vertices[static_cast<std::size_t>(v)];
      return Point2{glm::dot(p, e1), glm::dot(p, e2)};
    };
    const auto projected = [&](int f) {
      const glm::ivec3& t = triangles[static_cast<std::size_t>(f)];
      return std::array<Point2, 3>{project(t[0]), project(t[1]), project(t[2])};
    };

    const auto add = [&](int f) {
      const TriangleInfo& t = info[static_cast<std::size_t>(f)];
      patch_of[static_cast<std::size_t>(f)] = id;
      members.push_back(f);
      if (!t.degenerate) {
        planar_members.push_back(f);
        if (reference == glm::dvec3(0.0)) {
          reference = t.normal;
          const glm::dvec3 helper =
              std::abs(reference.x) < 0.6 ? glm::dvec3(1, 0, 0) : glm::dvec3(0, 1, 0);
          e1 = glm::normalize(glm::cross(reference, helper));
          e2 = glm::cross(reference, e1);
        }
      }
      if (reference != glm::dvec3(0.0)) {
        shadow.push_back(projected(f));
        const auto& t2 = shadow.back();
        shadow_area += 0.5 * std::abs(Cross2(t2[0], t2[1], t2[2]));
      }
      for (int c = 0; c < 3; ++c) {
        const int v = triangles[static_cast<std::size_t>(f)][c];
        if (vertex_in_patch[static_cast<std::size_t>(v)] != id) {
          vertex_in_patch[static_cast<std::size_t>(v)] = id;
          patch_vertices.push_back(v);
        }
      }
    };
    // kReject: f can never join this patch (the normal and convexity tests only tighten as the
    // patch grows); kNotNow: f fails the gap test, which a later neighbour may fix.
    enum class Verdict { kJoin, kReject, kNotNow };
    const auto can_join = [&](int f) {
      const TriangleInfo& t = info[static_cast<std::size_t>(f)];
      if (!t.degenerate && reference != glm::dvec3(0.0) &&
          !(glm::dot(t.normal, reference) >= limits.min_normal_dot)) {
        return Verdict::kReject;
      }
      // The new triangle's vertices behind every patch plane.
      for (int c = 0; c < 3; ++c) {
        const int v = triangles[static_cast<std::size_t>(f)][c];
        if (vertex_in_patch[static_cast<std::size_t>(v)] == id) continue;
        for (const int g : planar_members) {
          if (PlaneValue(info[static_cast<std::size_t>(g)].plane,
                         vertices[static_cast<std::size_t>(v)]) > tolerance) {
            return Verdict::kReject;
          }
        }
      }
      // Every patch vertex behind the new triangle's plane (its own are on it).
      if (!t.degenerate) {
        for (const int v : patch_vertices) {
          if (PlaneValue(t.plane, vertices[static_cast<std::size_t>(v)]) > tolerance) {
            return Verdict::kReject;
          }
        }
      }
      // Gap: no point of the shadow of the patch's hull (sampled at the midpoints of its edges and
      // at its centroid) farther than max_gap from the shadow of the patch itself.
      if (std::isfinite(limits.max_gap) && reference != glm::dvec3(0.0) && !t.degenerate) {
        shadow_points.clear();
        for (const int v : patch_vertices) shadow_points.push_back(project(v));
        for (int c = 0; c < 3; ++c) {
          shadow_points.push_back(project(triangles[static_cast<std::size_t>(f)][c]));
        }
        const std::vector<Point2> hull = ConvexHull2d(shadow_points);
        const std::array<Point2, 3> candidate = projected(f);
        const double area =
            shadow_area + 0.5 * std::abs(Cross2(candidate[0], candidate[1], candidate[2]));
        // Where the patch's shadow fills its hull's (up to rounding), there is no gap.
        if (hull.size() >= 3 && PolygonArea2d(hull) > area * (1.0 + 1e-9)) {
          const auto gap_at = [&](const Point2& q) {
            double d = TriangleDistance2d(q, candidate);
            for (std::size_t i = 0; i < shadow.size() && d > 0.0; ++i) {
              d = std::min(d, TriangleDistance2d(q, shadow[i]));
            }
            return d;
          };
          Point2 centroid{0.0, 0.0};
          for (std::size_t i = 0; i < hull.size(); ++i) {
            const Point2& a = hull[i];
            const Point2& b = hull[(i + 1) % hull.size()];
            if (gap_at({0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1])}) > limits.max_gap) {
              return Verdict::kNotNow;
            }
            centroid[0] += a[0] / static_cast<double>(hull.size());
            centroid[1] += a[1] / static_cast<double>(hull.size());
          }
          if (gap_at(centroid) > limits.max_gap) return Verdict::kNotNow;
        }
      }
      return Verdict::kJoin;
    };

    // Best-first growth: candidates whose normal is closest to the reference first (degenerate
    // triangles first of all: they cost nothing).
    using Candidate = std::pair<double, int>;
    std::priority_queue<Candidate> frontier;
    const auto push_neighbours = [&](int f) {
      for (const int g : neighbours[static_cast<std::size_t>(f)]) {
        if (patch_of[static_cast<std::size_t>(g)] >= 0 ||
            rejected_by[static_cast<std::size_t>(g)] == id) {
          continue;
        }
        const TriangleInfo& t = info[static_cast<std::size_t>(g)];
        const double score = t.degenerate ? 2.0 : glm::dot(t.normal, reference);
        frontier.emplace(score, -g);  // ties: lower index first
      }
    };
    add(seed);
    push_neighbours(seed);
    while (!frontier.empty()) {
      if (limits.max_leaf_triangles > 0 &&
          static_cast<int>(members.size()) >= limits.max_leaf_triangles) {
        break;
      }
      const int f = -frontier.top().second;
      frontier.pop();
      if (patch_of[static_cast<std::size_t>(f)] >= 0 ||
          rejected_by[static_cast<std::size_t>(f)] == id) {
        continue;
      }
      const Verdict verdict = can_join(f);
      if (verdict == Verdict::kJoin) {
        add(f);
        push_neighbours(f);
      } else if (verdict == Verdict::kReject) {
        rejected_by[static_cast<std::size_t>(f)] = id;
      }  // kNotNow: f comes back when another of its neighbours joins.
    }
    patches.push_back(std::move(members));
  }
  return patches;
}

// Hull of one leaf patch: its vertices, with inward copies when it is thinner than `thickness`
// along its mean outward normal.
ConvexHull LeafHull(const std::vector<glm::dvec3>& vertices,
                    const std::vector<glm::ivec3>& triangles, const std::vector<int>& patch,
                    double thickness) {
  std::vector<int> ids;
  glm::dvec3 area_normal_sum(0.0);
  double area_sum = 0.0;
  for (const int f : patch) {
    const glm::ivec3& t = triangles[static_cast<std::size_t>(f)];
    for (int c = 0; c < 3; ++c) ids.push_back(t[c]);
    const glm::dvec3 n = glm::cross(
        vertices[static_cast<std::size_t>(t[1])] - vertices[static_cast<std::size_t>(t[0])],
        vertices[static_cast<std::size_t>(t[2])] - vertices[static_cast<std::size_t>(t[0])]);
    area_normal_sum += n;
    area_sum += glm::length(n);
  }
  std::sort(ids.begin(), ids.end());
  ids.erase(std::unique(ids.begin(), ids.end()), ids.end());
  std::vector<glm::dvec3> points;
  points.reserve(ids.size() * 2);
  for (const int v : ids) points.push_back(vertices[static_cast<std::size_t>(v)]);

  const double sum_length = glm::length(area_normal_sum);
  if (thickness > 0.0 && sum_length > 1e-6 * area_sum && sum_length > 0.0) {
    const glm::dvec3 m = area_normal_sum / sum_length;
    double lo = std::numeric_limits<double>::infinity();
    double hi = -std::numeric_limits<double>::infinity();
    for (const glm::dvec3& p : points) {
      lo = std::min(lo, glm::dot(m, p));
      hi = std::max(hi, glm::dot(m, p));
    }
    if (hi - lo < thickness) {
      const std::size_t count = points.size();
      for (std::size_t i = 0; i < count; ++i) points.push_back(points[i] - thickness * m);
    }
  }
  return ComputeConvexHull(points, thickness);
}

struct TreeBuilder {
  std::vector<ConvexHull> leaf_hulls;
  std::vector<std::vector<int>> leaf_triangles;
  double thickness = 0.0;
  ConvexHullHierarchy result;

  // Builds the subtree over leaves[begin, end); returns its node index.
  int Build(std::vector<int>& leaves, std::size_t begin, std::size_t end) {
    const int index = static_cast<int>(result.nodes.size());
    result.nodes.emplace_back();
    if (end - begin == 1) {
      const auto leaf = static_cast<std::size_t>(leaves[begin]);
      result.nodes[static_cast<std::size_t>(index)].hull = std::move(leaf_hulls[leaf]);
      result.nodes[static_cast<std::size_t>(index)].triangles = std::move(leaf_triangles[leaf]);
      return index;
    }
    glm::dvec3 lo(std::numeric_limits<double>::infinity());
    glm::dvec3 hi(-std::numeric_limits<double>::infinity());
    for (std::size_t i = begin; i < end; ++i) {
      const glm::dvec3& c = leaf_hulls[static_cast<std::size_t>(leaves[i])].center_O;
      lo = glm::min(lo, c);
      hi = glm::max(hi, c);
    }
    const glm::dvec3 extent = hi - lo;
    int axis = 0;
    if (extent.y > extent[axis]) axis = 1;
    if (extent.z > extent[axis]) axis = 2;
    const std::size_t mid = begin + (end - begin) / 2;
    std::nth_element(leaves.begin() + static_cast<std::ptrdiff_t>(begin),
                     leaves.begin() + static_cast<std::ptrdiff_t>(mid),
                     leaves.begin() + static_cast<std::ptrdiff_t>(end), [&](int a, int b) {
                       const double ca = leaf_hulls[static_cast<std::size_t>(a)].center_O[axis];
                       const double cb = leaf_hulls[static_cast<std::size_t>(b)].center_O[axis];
                       return ca < cb || (ca == cb && a < b);
                     });
    const int left = Build(leaves, begin, mid);
    const int right = Build(leaves, mid, end);
    std::vector<glm::dvec3> points = result.nodes[static_cast<std::size_t>(left)].hull.vertices_O;
    const auto& right_vertices = result.nodes[static_cast<std::size_t>(right)].hull.vertices_O;
    points.insert(points.end(), right_vertices.begin(), right_vertices.end());
    HullNode& node = result.nodes[static_cast<std::size_t>(index)];
    node.children[0] = left;
    node.children[1] = right;
    node.hull = ComputeConvexHull(points, thickness);
    return index;
  }
};

void CheckLength(double value, const char* name) {
  if (!(value >= 0.0) || !std::isfinite(value)) {
    throw std::invalid_argument(std::string("BuildConvexHullHierarchy: ") + name +
                                " must be finite and non-negative, got " + std::to_string(value));
  }
}

}  // namespace

ConvexHullHierarchy BuildConvexHullHierarchy(const std::vector<glm::dvec3>& vertices_O,
                                             const std::vector<glm::ivec3>& triangles,
                                             const HullHierarchyParams& params) {
  CheckLength(params.convexity_tolerance_m, "convexity_tolerance_m");
  CheckLength(params.leaf_thickness_m, "leaf_thickness_m");
  if (params.max_leaf_triangles < 0) {
    throw std::invalid_argument(
        "BuildConvexHullHierarchy: max_leaf_triangles must be >= 0 (0 = unlimited), got " +
        std::to_string(params.max_leaf_triangles));
  }
  if (!(params.max_normal_deviation_deg > 0.0 && params.max_normal_deviation_deg <= 180.0)) {
    throw std::invalid_argument(
        "BuildConvexHullHierarchy: max_normal_deviation_deg must be in (0, 180], got " +
        std::to_string(params.max_normal_deviation_deg));
  }
  if (!(params.max_shadow_gap_m >= 0.0)) {
    throw std::invalid_argument(
        "BuildConvexHullHierarchy: max_shadow_gap_m must be non-negative (infinity disables), "
        "got " +
        std::to_string(params.max_shadow_gap_m));
  }
  if (triangles.empty()) throw std::invalid_argument("BuildConvexHullHierarchy: no triangles");
  const std::size_t vertex_count = vertices_O.size();
  std::vector<char> used(vertex_count, 0);
  for (std::size_t f = 0; f < triangles.size(); ++f) {
    for (int c = 0; c < 3; ++c) {
      const int v = triangles[f][c];
      if (v < 0 || static_cast<std::size_t>(v) >= vertex_count) {
        throw std::invalid_argument("BuildConvexHullHierarchy: triangle " + std::to_string(f) +
                                    " indexes vertex " + std::to_string(v) + " of " +
                                    std::to_string(vertex_count));
      }
      if (!IsFinite(vertices_O[static_cast<std::size_t>(v)])) {
        throw std::invalid_argument("BuildConvexHullHierarchy: vertex " + std::to_string(v) +
                                    " (of triangle " + std::to_string(f) + ") is not finite");
      }
      used[static_cast<std::size_t>(v)] = 1;
    }
  }

  // Scale, tolerance, per-triangle planes.
  glm::dvec3 lo(std::numeric_limits<double>::infinity());
  glm::dvec3 hi(-std::numeric_limits<double>::infinity());
  std::vector<int> used_vertices;
  for (std::size_t v = 0; v < vertex_count; ++v) {
    if (used[v] == 0) continue;
    used_vertices.push_back(static_cast<int>(v));
    lo = glm::min(lo, vertices_O[v]);
    hi = glm::max(hi, vertices_O[v]);
  }
  const double diagonal = glm::length(hi - lo);
  const double tolerance =
      params.convexity_tolerance_m > 0.0 ? params.convexity_tolerance_m : 1e-3 * diagonal;
  const double thickness = params.leaf_thickness_m > 0.0 ? params.leaf_thickness_m : tolerance;
  const double min_doubled_area = kDegenerateRelativeArea * diagonal * diagonal;
  std::vector<TriangleInfo> info(triangles.size());
  for (std::size_t f = 0; f < triangles.size(); ++f) {
    const glm::dvec3& a = vertices_O[static_cast<std::size_t>(triangles[f][0])];
    const glm::dvec3 n =
        TriangleNormal(a, vertices_O[static_cast<std::size_t>(triangles[f][1])],
                       vertices_O[static_cast<std::size_t>(triangles[f][2])], min_doubled_area);
    info[f].degenerate = n == glm::dvec3(0.0);
    info[f].normal = n;
    info[f].plane = glm::dvec4(n, glm::dot(n, a));
  }

  // 1. The whole mesh convex: one node.
  const int face_count = static_cast<int>(triangles.size());
  const bool within_leaf_limit =
      params.max_leaf_triangles == 0 || face_count <= params.max_leaf_triangles;
  bool convex = within_leaf_limit;
  for (std::size_t f = 0; convex && f < triangles.size(); ++f) {
    if (info[f].degenerate) continue;
    for (const int v : used_vertices) {
      if (PlaneValue(info[f].plane, vertices_O[static_cast<std::size_t>(v)]) > tolerance) {
        convex = false;
        break;
      }
    }
  }
  std::vector<std::vector<int>> patches;
  if (convex) {
    patches.emplace_back(static_cast<std::size_t>(face_count));
    for (int f = 0; f < face_count; ++f) patches[0][static_cast<std::size_t>(f)] = f;
  } else {
    // 2. Convex surface patches.
    const double pi = std::acos(-1.0);
    GrowLimits limits;
    limits.tolerance = tolerance;
    limits.min_normal_dot = std::cos(params.max_normal_deviation_deg * pi / 180.0) - 1e-9;
    limits.max_gap = params.max_shadow_gap_m > 0.0 ? params.max_shadow_gap_m : 0.02 * diagonal;
    limits.max_leaf_triangles = params.max_leaf_triangles;
    patches = GrowConvexPatches(vertices_O, triangles, info, limits);
  }

  // 3. Leaf hulls, then the tree over them.
  TreeBuilder builder;
  builder.thickness = thickness;
  builder.leaf_hulls.reserve(patches.size());
  for (const auto& patch : patches) {
    builder.leaf_hulls.push_back(LeafHull(vertices_O, triangles, patch, thickness));
  }
  builder.leaf_triangles = std::move(patches);
  std::vector<int> leaves(builder.leaf_hulls.size());
  for (std::size_t i = 0; i < leaves.size(); ++i) leaves[i] = static_cast<int>(i);
  builder.result.nodes.reserve(2 * leaves.size());
  builder.Build(leaves, 0, leaves.size());
  return std::move(builder.result);
}

}  // namespace ht
