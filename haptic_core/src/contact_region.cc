#include "haptic_core/contact_region.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <glm/geometric.hpp>
#include <optional>
#include <span>
#include <vector>

namespace ht {
namespace {

constexpr int kMaxPolygon = 64;

bool IsLeaf(const HapticModel& m, int node) noexcept {
  return node >= 0 && static_cast<std::size_t>(node) < m.hull_hierarchy.nodes.size() &&
         m.hull_hierarchy.nodes[static_cast<std::size_t>(node)].is_leaf();
}

// Calls visit(polygon, count) with each triangle of `triangles` (indices into `patch_model`'s
// coarse triangles, vertices mapped into the hull's frame by X_HP) clipped to the planes of `hull`
// moved out by `margin` (m), the polygon in the hull's frame. A triangle whose clipped polygon
// would exceed kMaxPolygon vertices, or with a bad index, is skipped.
template <typename Visit>
void ForEachClippedTriangle(const HapticModel& patch_model, std::span<const int> triangles,
                            const RigidTransform& X_HP, const ConvexHull& hull, double margin,
                            Visit&& visit) noexcept {
  if (hull.planes_O.empty()) return;
  const std::size_t num_vertices = patch_model.vertices_O.size();
  std::array<glm::dvec3, kMaxPolygon> a{}, b{};
  for (const int f : triangles) {
    if (f < 0 || static_cast<std::size_t>(f) >= patch_model.triangles.size()) continue;
    const glm::ivec3 t = patch_model.triangles[static_cast<std::size_t>(f)];
    bool bad_index = false;
    for (int c = 0; c < 3; ++c) {
      if (t[c] < 0 || static_cast<std::size_t>(t[c]) >= num_vertices) bad_index = true;
    }
    if (bad_index) continue;
    a[0] = X_HP * patch_model.vertices_O[static_cast<std::size_t>(t[0])];
    a[1] = X_HP * patch_model.vertices_O[static_cast<std::size_t>(t[1])];
    a[2] = X_HP * patch_model.vertices_O[static_cast<std::size_t>(t[2])];
    // Quick tests: wholly outside one plane (nothing), or inside all of them (the whole triangle).
    bool outside = false, crosses = false;
    for (const glm::dvec4& pl : hull.planes_O) {
      const glm::dvec3 n(pl);
      const double d = pl.w + margin;
      const double s0 = glm::dot(n, a[0]) - d, s1 = glm::dot(n, a[1]) - d,
                   s2 = glm::dot(n, a[2]) - d;
      if (s0 > 0.0 && s1 > 0.0 && s2 > 0.0) {
        outside = true;
        break;
      }
      if (s0 > 0.0 || s1 > 0.0 || s2 > 0.0) crosses = true;
    }
    if (outside) continue;
    int count = 3;
    const glm::dvec3* polygon = a.data();
    if (crosses) {
      // Sutherland–Hodgman: keep n·p − d ≤ 0 of every plane. A convex polygon gains at most one
      // vertex per plane.
      glm::dvec3* in = a.data();
      glm::dvec3* out = b.data();
      for (const glm::dvec4& pl : hull.planes_O) {
        if (count + 1 > kMaxPolygon) {
          count = 0;
          break;
        }
        const glm::dvec3 n(pl);
        const double d = pl.w + margin;
        int kept = 0;
        for (int i = 0; i < count; ++i) {
          const glm::dvec3& p = in[i];
          const glm::dvec3& q = in[(i + 1) % count];
          const double sp = glm::dot(n, p) - d, sq = glm::dot(n, q) - d;
          if (sp <= 0.0) out[kept++] = p;
          if ((sp <= 0.0) != (sq <= 0.0)) out[kept++] = p + (sp / (sp - sq)) * (q - p);
        }
        count = kept;
        std::swap(in, out);
        if (count < 3) break;
      }
      if (count < 3) continue;
      polygon = in;
    }
    visit(polygon, count);
  }
}

// Σ over the triangles of `patch` (leaf `patch_node` of `patch_model`, vertices mapped into the
// hull's frame by X_HP) of the area vector of each triangle's part inside the planes of `hull`
// moved out by `margin` (m², the hull's frame).
glm::dvec3 AreaInsideHull(const HapticModel& patch_model, int patch_node,
                          const RigidTransform& X_HP, const ConvexHull& hull,
                          double margin) noexcept {
  glm::dvec3 sum(0.0);
  const HullNode& node = patch_model.hull_hierarchy.nodes[static_cast<std::size_t>(patch_node)];
  ForEachClippedTriangle(patch_model, node.triangles, X_HP, hull, margin,
                         [&](const glm::dvec3* p, int count) {
                           glm::dvec3 area(0.0);
                           for (int i = 1; i + 1 < count; ++i) {
                             area += glm::cross(p[i] - p[0], p[i + 1] - p[0]);
                           }
                           sum += 0.5 * area;
                         });
  return sum;
}

// The box, on the axes u, v (W) from origin_W, of the triangles of `triangles` clipped to `hull`
// widened by `margin`; X_WH maps the hull's frame into W. False when no part is inside.
bool ClippedBox(const HapticModel& patch_model, std::span<const int> triangles,
                const RigidTransform& X_HP, const RigidTransform& X_WH, const ConvexHull& hull,
                double margin, const glm::dvec3& origin_W, const glm::dvec3& u_W,
                const glm::dvec3& v_W, RegionBounds& box) noexcept {
  bool any = false;
  box = {};
  ForEachClippedTriangle(patch_model, triangles, X_HP, hull, margin,
                         [&](const glm::dvec3* p, int count) {
                           for (int i = 0; i < count; ++i) {
                             const glm::dvec3 d = X_WH * p[i] - origin_W;
                             const double u = glm::dot(d, u_W), v = glm::dot(d, v_W);
                             if (!any) {
                               box = {u, u, v, v};
                               any = true;
                             }
                             box.min_u = std::min(box.min_u, u);
                             box.max_u = std::max(box.max_u, u);
                             box.min_v = std::min(box.min_v, v);
                             box.max_v = std::max(box.max_v, v);
                           }
                         });
  return any;
}

}  // namespace

glm::dvec3 LeafPairRegionVector(const HapticModel& tool, const RigidTransform& X_WT, int node_A,
                                const HapticModel& object, const RigidTransform& X_WO, int node_B,
                                double margin_m) noexcept {
  if (!IsLeaf(tool, node_A) || !IsLeaf(object, node_B) || !(margin_m >= 0.0) ||
      !std::isfinite(margin_m)) {
    return glm::dvec3(0.0);
  }
  const RigidTransform X_TO = X_WT.Inverse() * X_WO;
  const RigidTransform X_OT = X_TO.Inverse();
  const ConvexHull& hull_A = tool.hull_hierarchy.nodes[static_cast<std::size_t>(node_A)].hull;
  const ConvexHull& hull_B = object.hull_hierarchy.nodes[static_cast<std::size_t>(node_B)].hull;
  // The object's triangles inside the tool's leaf (in T), the tool's inside the object's (in O).
  const glm::dvec3 object_in_tool_T = AreaInsideHull(object, node_B, X_TO, hull_A, margin_m);
  const glm::dvec3 tool_in_object_O = AreaInsideHull(tool, node_A, X_OT, hull_B, margin_m);
  const glm::dvec3 v = 0.5 * (X_WT.rotation * object_in_tool_T - X_WO.rotation * tool_in_object_O);
  if (!(std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z))) return glm::dvec3(0.0);
  return v;
}

std::optional<ConvexHull> ConvexMeshHull(const HapticModel& model, double tolerance_m) {
  ConvexHull hull;
  const std::vector<glm::dvec3>& vertices =
      model.hull_vertices_O.empty() ? model.vertices_O : model.hull_vertices_O;
  if (vertices.empty() || model.triangles.empty() || !(tolerance_m >= 0.0)) return std::nullopt;
  hull.vertices_O = vertices;
  for (const glm::dvec3& p : vertices) hull.center_O += p;
  hull.center_O /= static_cast<double>(vertices.size());
  for (const glm::ivec3& t : model.triangles) {
    for (int c = 0; c < 3; ++c) {
      if (t[c] < 0 || static_cast<std::size_t>(t[c]) >= model.vertices_O.size()) {
        return std::nullopt;
      }
    }
    const glm::dvec3& p0 = model.vertices_O[static_cast<std::size_t>(t[0])];
    const glm::dvec3 n = glm::cross(model.vertices_O[static_cast<std::size_t>(t[1])] - p0,
                                    model.vertices_O[static_cast<std::size_t>(t[2])] - p0);
    const double len = glm::length(n);
    if (!(len > 0.0) || !std::isfinite(len)) continue;  // a degenerate triangle has no plane
    const glm::dvec3 unit = n / len;
    const double d = glm::dot(unit, p0);
    const bool known =
        std::any_of(hull.planes_O.begin(), hull.planes_O.end(), [&](const glm::dvec4& q) {
          return glm::length(glm::dvec3(q) - unit) < 1e-9 && std::abs(q.w - d) <= tolerance_m;
        });
    if (!known) hull.planes_O.emplace_back(unit, d);
  }
  // Convex: every vertex of the mesh on the inner side of every face plane.
  for (const glm::dvec4& q : hull.planes_O) {
    for (const glm::dvec3& p : model.vertices_O) {
      if (glm::dot(glm::dvec3(q), p) - q.w > tolerance_m) return std::nullopt;
    }
  }
  if (hull.planes_O.empty()) return std::nullopt;
  return hull;
}

bool PairRegionBounds(const HapticModel& tool, const RigidTransform& X_WT, const ConvexHull& hull_A,
                      std::span<const int> triangles_A, const HapticModel& object,
                      const RigidTransform& X_WO, const ConvexHull& hull_B,
                      std::span<const int> triangles_B, double margin_m, const glm::dvec3& origin_W,
                      const glm::dvec3& u_W, const glm::dvec3& v_W, RegionBounds& out) noexcept {
  out = {};
  if (!(margin_m >= 0.0) || !std::isfinite(margin_m)) return false;
  const RigidTransform X_TO = X_WT.Inverse() * X_WO;
  const RigidTransform X_OT = X_TO.Inverse();
  RegionBounds object_part, tool_part;
  // The object's triangles inside the tool's hull (clipped in T), the tool's inside the object's.
  if (!ClippedBox(object, triangles_B, X_TO, X_WT, hull_A, margin_m, origin_W, u_W, v_W,
                  object_part) ||
      !ClippedBox(tool, triangles_A, X_OT, X_WO, hull_B, margin_m, origin_W, u_W, v_W, tool_part)) {
    return false;
  }
  // Where both parts are: the overlap of the two boxes (their union if they miss each other).
  out.min_u = std::max(object_part.min_u, tool_part.min_u);
  out.max_u = std::min(object_part.max_u, tool_part.max_u);
  out.min_v = std::max(object_part.min_v, tool_part.min_v);
  out.max_v = std::min(object_part.max_v, tool_part.max_v);
  if (!(out.min_u <= out.max_u && out.min_v <= out.max_v)) {
    out.min_u = std::min(object_part.min_u, tool_part.min_u);
    out.max_u = std::max(object_part.max_u, tool_part.max_u);
    out.min_v = std::min(object_part.min_v, tool_part.min_v);
    out.max_v = std::max(object_part.max_v, tool_part.max_v);
  }
  return std::isfinite(out.min_u) && std::isfinite(out.max_u) && std::isfinite(out.min_v) &&
         std::isfinite(out.max_v);
}

}  // namespace ht
