#include "haptic_core/contact_region.h"

#include <array>
#include <cmath>
#include <cstddef>
#include <glm/geometric.hpp>

namespace ht {
namespace {

constexpr int kMaxPolygon = 64;

bool IsLeaf(const HapticModel& m, int node) noexcept {
  return node >= 0 && static_cast<std::size_t>(node) < m.hull_hierarchy.nodes.size() &&
         m.hull_hierarchy.nodes[static_cast<std::size_t>(node)].is_leaf();
}

// Σ over the triangles of `patch` (leaf `patch_node` of `patch_model`, vertices mapped into the
// hull's frame by X_HP) of the area vector of each triangle's part inside the planes of `hull`
// moved out by `margin` (m², the hull's frame).
glm::dvec3 AreaInsideHull(const HapticModel& patch_model, int patch_node,
                          const RigidTransform& X_HP, const ConvexHull& hull,
                          double margin) noexcept {
  glm::dvec3 sum(0.0);
  const std::size_t num_planes = hull.planes_O.size();
  if (num_planes == 0 || num_planes + 3 > static_cast<std::size_t>(kMaxPolygon)) return sum;
  const HullNode& node = patch_model.hull_hierarchy.nodes[static_cast<std::size_t>(patch_node)];
  const std::size_t num_vertices = patch_model.vertices_O.size();
  std::array<glm::dvec3, kMaxPolygon> a{}, b{};
  for (const int f : node.triangles) {
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
    if (crosses) {
      // Sutherland–Hodgman: keep n·p − d ≤ 0 of every plane.
      glm::dvec3* in = a.data();
      glm::dvec3* out = b.data();
      for (const glm::dvec4& pl : hull.planes_O) {
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
      if (in != a.data()) {
        for (int i = 0; i < count; ++i) a[static_cast<std::size_t>(i)] = in[i];
      }
    }
    glm::dvec3 area(0.0);
    for (int i = 1; i + 1 < count; ++i) area += glm::cross(a[i] - a[0], a[i + 1] - a[0]);
    sum += 0.5 * area;
  }
  return sum;
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

}  // namespace ht
