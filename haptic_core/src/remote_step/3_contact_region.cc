#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <glm/geometric.hpp>
#include <glm/gtc/quaternion.hpp>
#include <limits>
#include <optional>
#include <span>
#include <vector>

#include "haptic_core/contact_region.h"

namespace ht {
namespace {

constexpr int kMaxPolygon = 64;

bool IsLeaf(const HapticModel& m, int node) noexcept {
  return node >= 0 && static_cast<std::size_t>(node) < m.hull_hierarchy.nodes.size() &&
         m.hull_hierarchy.nodes[static_cast<std::size_t>(node)].is_leaf();
}

// Shortcuts keep ForEachClippedTriangle's results bit for bit while skipping work that cannot
// change them (each is conservative by kSkipSlackM plus a relative part, some eight orders of
// magnitude above the rounding of the sums it guards for coordinates, offsets and margins below
// about 10⁵ m; a non-finite pose or margin visits nothing):
// - Far triangles: with at most kMaxFarPlanes hull planes, the planes are moved into the patch
//   model's frame once per call, and a triangle whose three corners lie beyond one of them by the
//   slack is skipped before its corners are transformed (the exact test would find it outside that
//   plane too).
// - Planes far from the whole patch: with more planes than that, the patch's bounding sphere
//   (its corners', taken once per call) sorts them: a plane the sphere lies inside by the slack is
//   idle for every triangle (dropped from every test below), and one it lies beyond by the slack
//   has every triangle outside (nothing to visit).
// - Idle planes: Sutherland–Hodgman runs only over the planes some corner of the triangle lies
//   beyond or within the slack of. A plane that has every corner inside by the slack has every
//   point of the clipped polygon (convex combinations of the corners) inside too, so its pass
//   would copy the polygon unchanged. Likewise a pass whose plane has every vertex of the
//   polygon so far inside (n·p − d ≤ 0, computed as the pass would) is skipped exactly.
constexpr double kSkipSlackM = 1e-9;
constexpr double kSkipSlackRelative = 1e-9;
constexpr int kMaxFarPlanes = 32;
constexpr int kMaxActivePlanes = 256;
constexpr int kMaxNearPlanes = 256;

// The far-triangle shortcut: the hull's planes moved out by `margin` and into the patch's frame P
// (n_P = R_HPᵀ·n, d_P = d + margin − n·p_HP), each pushed out by the slack, for hulls of at most
// kMaxFarPlanes planes (count 0 otherwise, or when not `enabled`).
struct FarPlanes {
  std::array<glm::dvec4, kMaxFarPlanes> planes_P{};
  int count = 0;
  int last_culled = 0;  ///< tried first: neighbouring triangles tend to share it

  FarPlanes(const ConvexHull& hull, const RigidTransform& X_HP, double margin, double slack,
            bool enabled) noexcept {
    if (!enabled || hull.planes_O.size() > static_cast<std::size_t>(kMaxFarPlanes)) return;
    count = static_cast<int>(hull.planes_O.size());
    const glm::dquat R_PH = glm::conjugate(X_HP.rotation);
    for (int k = 0; k < count; ++k) {
      const glm::dvec4& pl = hull.planes_O[static_cast<std::size_t>(k)];
      const glm::dvec3 n(pl);
      const double d_P = pl.w + margin - glm::dot(n, X_HP.translation);
      planes_P[static_cast<std::size_t>(k)] =
          glm::dvec4(R_PH * n, d_P + slack * (1.0 + std::abs(d_P)));
    }
  }

  // Whether the corners p0..p2 (frame P) all lie beyond one of the planes.
  bool Culls(const glm::dvec3& p0, const glm::dvec3& p1, const glm::dvec3& p2) noexcept {
    for (int j = 0; j < count; ++j) {
      const int k = j == 0 ? last_culled : (j <= last_culled ? j - 1 : j);
      const glm::dvec4& pl = planes_P[static_cast<std::size_t>(k)];
      const glm::dvec3 n(pl);
      if (glm::dot(n, p0) > pl.w && glm::dot(n, p1) > pl.w && glm::dot(n, p2) > pl.w) {
        last_culled = k;
        return true;
      }
    }
    return false;
  }
};

// The planes-far-from-the-patch shortcut: the planes of `hull` (moved out by `margin`) that the
// bounding sphere of `triangles`' corners, mapped by X_HP, is neither inside of nor beyond by the
// slack, in order, into `near`. Returns false when the sphere lies beyond a plane or no corner is
// valid (no triangle has a part inside); num_near is −1 (test every plane) when the sphere is not
// finite or more than kMaxNearPlanes planes are near.
bool SelectNearPlanes(const HapticModel& patch_model, std::span<const int> triangles,
                      const RigidTransform& X_HP, const ConvexHull& hull, double margin,
                      double slack, std::array<int, kMaxNearPlanes>& near, int& num_near) noexcept {
  num_near = -1;
  glm::dvec3 lo(std::numeric_limits<double>::infinity()), hi(-lo);
  for (const int f : triangles) {
    if (f < 0 || static_cast<std::size_t>(f) >= patch_model.triangles.size()) continue;
    const glm::ivec3 t = patch_model.triangles[static_cast<std::size_t>(f)];
    for (int c = 0; c < 3; ++c) {
      if (t[c] < 0 || static_cast<std::size_t>(t[c]) >= patch_model.vertices_O.size()) continue;
      const glm::dvec3& p = patch_model.vertices_O[static_cast<std::size_t>(t[c])];
      lo = glm::min(lo, p);
      hi = glm::max(hi, p);
    }
  }
  if (!(lo.x <= hi.x && lo.y <= hi.y && lo.z <= hi.z)) return false;
  const double radius = 0.5 * glm::length(hi - lo);
  const glm::dvec3 center_H = X_HP * (0.5 * (lo + hi));
  if (!std::isfinite(radius) || !std::isfinite(center_H.x) || !std::isfinite(center_H.y) ||
      !std::isfinite(center_H.z)) {
    return true;
  }
  int listed = 0;
  for (std::size_t k = 0; k < hull.planes_O.size(); ++k) {
    const glm::dvec4& pl = hull.planes_O[k];
    const double d = pl.w + margin;
    const double s_center = glm::dot(glm::dvec3(pl), center_H) - d;
    const double guard = radius + slack * (1.0 + std::abs(d) + radius);
    if (s_center > guard) return false;  // every corner beyond this plane: nothing inside
    if (s_center < -guard) continue;     // every corner inside by the slack: idle
    if (listed == kMaxNearPlanes) return true;
    near[static_cast<std::size_t>(listed++)] = static_cast<int>(k);
  }
  num_near = listed;
  return true;
}

// Sutherland–Hodgman: clips the convex polygon in[0, count) to n·p − d ≤ 0 of the planes
// hull.planes_O[plane(pass)] (moved out by `margin`), pass = 0..passes−1, ping-ponging between
// `in` and `out` (kMaxPolygon each; `side` as scratch). A convex polygon gains at most one vertex
// a plane; the polygon is dropped (count 0) where another plane could overflow it. Returns the
// clipped polygon and sets `count` (below 3: nothing left).
template <typename PlaneOfPass>
const glm::dvec3* ClipPolygon(const ConvexHull& hull, double margin, int passes,
                              PlaneOfPass&& plane, glm::dvec3* in, glm::dvec3* out, double* side,
                              int& count) noexcept {
  for (int pass = 0; pass < passes; ++pass) {
    if (count + 1 > kMaxPolygon) {
      count = 0;
      break;
    }
    const glm::dvec4& pl = hull.planes_O[static_cast<std::size_t>(plane(pass))];
    const glm::dvec3 n(pl);
    const double d = pl.w + margin;
    // Each vertex's side once; a plane every vertex is inside of would copy the polygon.
    bool cuts = false;
    for (int i = 0; i < count; ++i) {
      side[i] = glm::dot(n, in[i]) - d;
      cuts = cuts || !(side[i] <= 0.0);
    }
    if (!cuts) continue;
    int kept = 0;
    for (int i = 0; i < count; ++i) {
      const int j = i + 1 == count ? 0 : i + 1;
      const double sp = side[i], sq = side[j];
      if (sp <= 0.0) out[kept++] = in[i];
      if ((sp <= 0.0) != (sq <= 0.0)) out[kept++] = in[i] + (sp / (sp - sq)) * (in[j] - in[i]);
    }
    count = kept;
    std::swap(in, out);
    if (count < 3) break;
  }
  return in;
}

// Calls visit(polygon, count) with each triangle of `triangles` (indices into `patch_model`'s
// coarse triangles, vertices mapped into the hull's frame by X_HP) clipped to the planes of `hull`
// moved out by `margin`, the polygon in the hull's frame. A triangle whose clipped polygon
// would exceed kMaxPolygon vertices, or with a bad index, is skipped.
template <typename Visit>
void ForEachClippedTriangle(const HapticModel& patch_model, std::span<const int> triangles,
                            const RigidTransform& X_HP, const ConvexHull& hull, double margin,
                            Visit&& visit) noexcept {
  if (hull.planes_O.empty() || !std::isfinite(margin) || !IsFinite(X_HP)) return;
  const std::size_t num_vertices = patch_model.vertices_O.size();
  const std::size_t num_planes = hull.planes_O.size();
  const double slack =
      kSkipSlackM + kSkipSlackRelative * (glm::length(X_HP.translation) + std::abs(margin));
  // The frame shortcuts assume X_HP rotates (a unit quaternion, as poses composed from unit
  // ones are to rounding); the idle-plane one works on the transformed corners and holds anyway.
  const glm::dquat& q_HP = X_HP.rotation;
  const double norm2 = q_HP.w * q_HP.w + q_HP.x * q_HP.x + q_HP.y * q_HP.y + q_HP.z * q_HP.z;
  const bool rotates = std::abs(norm2 - 1.0) <= 1e-12;
  FarPlanes far(hull, X_HP, margin, slack, rotates);
  std::array<int, kMaxNearPlanes> near{};
  int num_near = -1;  // −1: every plane
  if (rotates && far.count == 0 &&
      !SelectNearPlanes(patch_model, triangles, X_HP, hull, margin, slack, near, num_near)) {
    return;
  }
  const int num_tested = num_near < 0 ? static_cast<int>(num_planes) : num_near;
  std::array<glm::dvec3, kMaxPolygon> a{}, b{};
  std::array<double, kMaxPolygon> side{};
  std::array<int, kMaxActivePlanes> active{};
  for (const int f : triangles) {
    if (f < 0 || static_cast<std::size_t>(f) >= patch_model.triangles.size()) continue;
    const glm::ivec3 t = patch_model.triangles[static_cast<std::size_t>(f)];
    bool bad_index = false;
    for (int c = 0; c < 3; ++c) {
      if (t[c] < 0 || static_cast<std::size_t>(t[c]) >= num_vertices) bad_index = true;
    }
    if (bad_index) continue;
    const glm::dvec3& p0 = patch_model.vertices_O[static_cast<std::size_t>(t[0])];
    const glm::dvec3& p1 = patch_model.vertices_O[static_cast<std::size_t>(t[1])];
    const glm::dvec3& p2 = patch_model.vertices_O[static_cast<std::size_t>(t[2])];
    if (far.Culls(p0, p1, p2)) continue;
    a[0] = X_HP * p0;
    a[1] = X_HP * p1;
    a[2] = X_HP * p2;
    // Quick tests: wholly outside one plane (nothing), or inside all of them (the whole triangle);
    // and the planes some corner is beyond or near (the others' passes would copy the polygon).
    bool outside = false, crosses = false;
    int num_active = 0;
    int last_active = -1;
    for (int tested = 0; tested < num_tested && !outside; ++tested) {
      const int k = num_near < 0 ? tested : near[static_cast<std::size_t>(tested)];
      const glm::dvec4& pl = hull.planes_O[static_cast<std::size_t>(k)];
      const glm::dvec3 n(pl);
      const double d = pl.w + margin;
      const double s0 = glm::dot(n, a[0]) - d, s1 = glm::dot(n, a[1]) - d,
                   s2 = glm::dot(n, a[2]) - d;
      outside = s0 > 0.0 && s1 > 0.0 && s2 > 0.0;
      crosses = crosses || s0 > 0.0 || s1 > 0.0 || s2 > 0.0;
      // Idle only when every corner is inside by the slack (a NaN leaves the plane active).
      const double idle_below = -slack * (1.0 + std::abs(d));
      if (!(s0 <= idle_below && s1 <= idle_below && s2 <= idle_below)) {
        if (num_active < kMaxActivePlanes) active[static_cast<std::size_t>(num_active)] = k;
        ++num_active;
        last_active = k;
      }
    }
    if (outside) continue;
    int count = 3;
    const glm::dvec3* polygon = a.data();
    if (crosses) {
      // Over the active planes only (all of them if there are too many to list).
      const bool listed = num_active <= kMaxActivePlanes;
      polygon = ClipPolygon(
          hull, margin, listed ? num_active : static_cast<int>(num_planes),
          [&](int pass) { return listed ? active[static_cast<std::size_t>(pass)] : pass; },
          a.data(), b.data(), side.data(), count);
      // A full polygon meets the size check again at any idle plane after the last active one.
      if (listed && count + 1 > kMaxPolygon && last_active + 1 < static_cast<int>(num_planes)) {
        count = 0;
      }
      if (count < 3) continue;
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
