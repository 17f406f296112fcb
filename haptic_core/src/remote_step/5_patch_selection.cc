// Stage 5's choice of the coarse triangles a window renders (penetration_depth.h):
// SelectPatchTriangles and its subset form, and the box tree over a model's triangles that
// narrows the scan (TriangleBoxTree).

#include <algorithm>
#include <cmath>
#include <glm/geometric.hpp>
#include <glm/gtc/quaternion.hpp>
#include <limits>
#include <memory>
#include <numeric>
#include <span>
#include <vector>

#include "haptic_core/penetration_depth.h"

namespace ht {

namespace {

// True when the corners' coordinates a, b, c along an axis all lie below −limit or all above
// +limit: the triangle misses the slab |x| ≤ limit.
[[gnu::always_inline]] inline bool MissesSlab(double a, double b, double c, double limit) noexcept {
  return std::max({a, b, c}) < -limit || std::min({a, b, c}) > limit;
}

// SelectPatchTriangles' tests of triangle f, cheapest and most selective first: the extent along
// u (from `along_u`, each vertex's p·u + ou, when given), then v, then n, then the facing test.
[[gnu::always_inline]] inline bool PatchTriangleTest(
    const HapticModel& model, int f, const glm::dvec3& u_O, const glm::dvec3& v_O,
    const glm::dvec3& n_O, double ou, double ov, double on, double half, double depth_limit,
    PatchSide side, double threshold, const double* along_u, double margin_per_radius) noexcept {
  const glm::dvec3* vertices = model.vertices_O.data();
  const glm::ivec3 t = model.triangles[static_cast<std::size_t>(f)];
  if (margin_per_radius > 0.0) {
    // The triangle's own margin: its farthest corner from the model's origin (every point of
    // the triangle is at most that far).
    const double r = std::sqrt(std::max({glm::dot(vertices[t[0]], vertices[t[0]]),
                                         glm::dot(vertices[t[1]], vertices[t[1]]),
                                         glm::dot(vertices[t[2]], vertices[t[2]])}));
    half += margin_per_radius * r;
    depth_limit += margin_per_radius * r;
  }
  double s0, s1, s2;
  if (along_u != nullptr) {
    s0 = along_u[t[0]];
    s1 = along_u[t[1]];
    s2 = along_u[t[2]];
  } else {
    s0 = glm::dot(vertices[t[0]], u_O) + ou;
    s1 = glm::dot(vertices[t[1]], u_O) + ou;
    s2 = glm::dot(vertices[t[2]], u_O) + ou;
  }
  if (MissesSlab(s0, s1, s2, half)) return false;
  const glm::dvec3& p0 = vertices[t[0]];
  const glm::dvec3& p1 = vertices[t[1]];
  const glm::dvec3& p2 = vertices[t[2]];
  const double t0 = glm::dot(p0, v_O) + ov, t1 = glm::dot(p1, v_O) + ov,
               t2 = glm::dot(p2, v_O) + ov;
  if (MissesSlab(t0, t1, t2, half)) return false;
  const double d0 = glm::dot(p0, n_O) + on, d1 = glm::dot(p1, n_O) + on,
               d2 = glm::dot(p2, n_O) + on;
  if (MissesSlab(d0, d1, d2, depth_limit)) return false;
  const glm::dvec3 cr = glm::cross(p1 - p0, p2 - p0);
  const double area2 = glm::length(cr);
  if (!(area2 > 0.0)) return false;
  const double facing = glm::dot(cr, n_O) / area2;
  return !(side == PatchSide::kEnvironment ? facing <= threshold : facing >= -threshold);
}

// PatchTriangleTest on a tree's record of the triangle: the same tests on the same doubles (the
// record's corners, cross product, its length and the radius are the scan's own expressions), the
// facing test first, as it needs no corner projection. The tests are pure, so their order does
// not change which triangles pass.
[[gnu::always_inline]] inline bool PatchRecordTest(const TriangleBoxTree::Triangle& t,
                                                   const glm::dvec3& u_O, const glm::dvec3& v_O,
                                                   const glm::dvec3& n_O, double ou, double ov,
                                                   double on, double half, double depth_limit,
                                                   PatchSide side, double threshold,
                                                   double margin_per_radius) noexcept {
  const double area2 = t.cross_length;
  if (!(area2 > 0.0)) return false;
  const double facing = glm::dot(t.cross_O, n_O) / area2;
  if (side == PatchSide::kEnvironment ? facing <= threshold : facing >= -threshold) return false;
  if (margin_per_radius > 0.0) {
    half += margin_per_radius * t.radius_m;
    depth_limit += margin_per_radius * t.radius_m;
  }
  const double s0 = glm::dot(t.p0_O, u_O) + ou, s1 = glm::dot(t.p1_O, u_O) + ou,
               s2 = glm::dot(t.p2_O, u_O) + ou;
  if (MissesSlab(s0, s1, s2, half)) return false;
  const double t0 = glm::dot(t.p0_O, v_O) + ov, t1 = glm::dot(t.p1_O, v_O) + ov,
               t2 = glm::dot(t.p2_O, v_O) + ov;
  if (MissesSlab(t0, t1, t2, half)) return false;
  const double d0 = glm::dot(t.p0_O, n_O) + on, d1 = glm::dot(t.p1_O, n_O) + on,
               d2 = glm::dot(t.p2_O, n_O) + on;
  return !MissesSlab(d0, d1, d2, depth_limit);
}

// SelectPatchTriangles, and with `subset` (not all) the same tests on its listed triangles only
// (SelectPatchTrianglesIn).
void SelectPatchTrianglesImpl(const HapticModel& model, const RigidTransform& X_WO,
                              const ContactWindow& w, PatchSide side, double margin_m,
                              std::vector<int>& out, double facing_slack,
                              std::vector<double>* vertex_scratch, const TriangleBoxTree* tree,
                              double margin_per_radius, TriangleSubset subset) noexcept {
  out.clear();
  const double half = 0.5 * w.extent_m + margin_m;
  const double depth_limit = w.depth_range_m() + margin_m;
  const double threshold = kPatchFacingThreshold - facing_slack;
  // The window's axes in O, once (as RenderPatchHeightsFast): a vertex's window coordinates are
  // p_O·a_O + (t − c)·a. The tests run cheapest and most selective first (the extent along u, then
  // v, then n), so that the many triangles far from the window cost nine multiply-adds each; the
  // facing test (a square root) only runs for those near it. A pre-filter: a rounding difference
  // from the world-frame arithmetic can only move triangles at the margin's edge, which draw
  // nothing inside the window.
  const glm::dquat q_inv = glm::conjugate(X_WO.rotation);
  const glm::dvec3 u_O = q_inv * w.axis_u_W, v_O = q_inv * w.axis_v_W, n_O = q_inv * w.normal_W;
  const glm::dvec3 offset = X_WO.translation - w.center_W;
  const double ou = glm::dot(offset, w.axis_u_W), ov = glm::dot(offset, w.axis_v_W),
               on = glm::dot(offset, w.normal_W);
  const int nf = static_cast<int>(model.triangles.size());
  if (!subset.all) {
    for (const int f : subset.indices) {
      if (f >= 0 && f < nf &&
          PatchTriangleTest(model, f, u_O, v_O, n_O, ou, ov, on, half, depth_limit, side, threshold,
                            nullptr, margin_per_radius)) {
        out.push_back(f);
      }
    }
    std::sort(out.begin(), out.end());
    return;
  }
  const glm::dvec3* vertices = model.vertices_O.data();
  if (tree == nullptr) tree = subset.tree;
  if (tree != nullptr && tree->Fits(model)) {
    // The leaves whose boxes reach the window, then the same tests on their triangles, in
    // increasing order. A box's extent along an axis a is c·a ± |a|·half; the slack (10⁻¹² of
    // the magnitudes) far exceeds the rounding of that and of a corner's p·a + offset, so a box
    // is passed over only where each of its triangles fails the same test below.
    const std::span<const TriangleBoxTree::Node> nodes = tree->nodes();
    const std::span<const TriangleBoxTree::Triangle> records = tree->triangles();
    const glm::dvec3 abs_u = glm::abs(u_O), abs_v = glm::abs(v_O), abs_n = glm::abs(n_O);
    const auto misses = [margin_per_radius](const TriangleBoxTree::Node& node,
                                            const glm::dvec3& axis, const glm::dvec3& abs_axis,
                                            double plane_offset, double limit) {
      if (margin_per_radius > 0.0) {  // the largest of the node's triangles' own margins
        limit += margin_per_radius * (glm::length(node.center_O) + glm::length(node.half_O)) *
                 (1.0 + 1e-12);
      }
      const double c = glm::dot(node.center_O, axis) + plane_offset;
      const double r = glm::dot(node.half_O, abs_axis);
      const glm::dvec3 ac = glm::abs(node.center_O);
      const double slack = 1e-12 * (ac.x + ac.y + ac.z + node.half_O.x + node.half_O.y +
                                    node.half_O.z + std::abs(plane_offset) + limit) +
                           1e-300;
      return c + r + slack < -limit || c - r - slack > limit;
    };
    constexpr int kStack = 64;  // the tree's depth is at most log2(#F / 8) + 2
    int stack[kStack];
    int top = 0;
    if (!nodes.empty()) stack[top++] = 0;
    while (top > 0) {
      const int index = stack[--top];
      const TriangleBoxTree::Node& node = nodes[static_cast<std::size_t>(index)];
      if (misses(node, u_O, abs_u, ou, half) || misses(node, v_O, abs_v, ov, half) ||
          misses(node, n_O, abs_n, on, depth_limit)) {
        continue;
      }
      if (node.second < 0) {
        for (int k = node.begin; k < node.end; ++k) {
          const TriangleBoxTree::Triangle& record = records[static_cast<std::size_t>(k)];
          if (PatchRecordTest(record, u_O, v_O, n_O, ou, ov, on, half, depth_limit, side, threshold,
                              margin_per_radius)) {
            out.push_back(record.index);
          }
        }
      } else if (top + 2 <= kStack) {
        stack[top++] = node.second;
        stack[top++] = index + 1;
      }
    }
    std::sort(out.begin(), out.end());
    return;
  }
  // With room in the scratch, each vertex's coordinate along u once (the same double as per
  // triangle below, so the same triangles): a vertex is shared by about six triangles.
  const std::size_t nv = model.vertices_O.size();
  double* along_u = nullptr;
  if (vertex_scratch != nullptr && vertex_scratch->capacity() >= nv) {
    vertex_scratch->resize(nv);
    along_u = vertex_scratch->data();
    for (std::size_t k = 0; k < nv; ++k) along_u[k] = glm::dot(vertices[k], u_O) + ou;
  }
  for (int f = 0; f < nf; ++f) {
    if (PatchTriangleTest(model, f, u_O, v_O, n_O, ou, ov, on, half, depth_limit, side, threshold,
                          along_u, margin_per_radius)) {
      out.push_back(f);
    }
  }
}

}  // namespace

void SelectPatchTriangles(const HapticModel& model, const RigidTransform& X_WO,
                          const ContactWindow& w, PatchSide side, double margin_m,
                          std::vector<int>& out, double facing_slack,
                          std::vector<double>* vertex_scratch, const TriangleBoxTree* tree,
                          double margin_per_radius) noexcept {
  SelectPatchTrianglesImpl(model, X_WO, w, side, margin_m, out, facing_slack, vertex_scratch, tree,
                           margin_per_radius, TriangleSubset::All());
}

void SelectPatchTrianglesIn(TriangleSubset subset, const HapticModel& model,
                            const RigidTransform& X_WO, const ContactWindow& w, PatchSide side,
                            double margin_m, std::vector<int>& out, double facing_slack,
                            std::vector<double>* vertex_scratch, const TriangleBoxTree* tree,
                            double margin_per_radius) noexcept {
  SelectPatchTrianglesImpl(model, X_WO, w, side, margin_m, out, facing_slack, vertex_scratch, tree,
                           margin_per_radius, subset);
}

namespace {

int TreeDepth(std::span<const TriangleBoxTree::Node> nodes, int index) noexcept {
  const TriangleBoxTree::Node& node = nodes[static_cast<std::size_t>(index)];
  if (node.second < 0) return 1;
  return 1 + std::max(TreeDepth(nodes, index + 1), TreeDepth(nodes, node.second));
}

}  // namespace

void TriangleBoxTree::Clear() noexcept {
  nodes_.clear();
  triangles_data_.clear();
  vertex_count_ = triangle_count_ = 0;
  built_ = false;
}

void TriangleBoxTree::Build(const HapticModel& model) {
  Clear();
  const std::size_t nf = model.triangles.size();
  std::vector<int> order(nf);  // the triangles, permuted into leaf order by BuildNode
  std::vector<glm::dvec3> centroids(nf);
  for (std::size_t f = 0; f < nf; ++f) {
    order[f] = static_cast<int>(f);
    const glm::ivec3 t = model.triangles[f];
    centroids[f] = (model.vertices_O[static_cast<std::size_t>(t[0])] +
                    model.vertices_O[static_cast<std::size_t>(t[1])] +
                    model.vertices_O[static_cast<std::size_t>(t[2])]) /
                   3.0;
  }
  nodes_.reserve(nf / (kLeafTriangles / 2) + 1);
  if (nf > 0) BuildNode(model, centroids, order, 0, static_cast<int>(nf));
  triangles_data_.resize(nf);
  for (std::size_t k = 0; k < nf; ++k) {
    const glm::ivec3 t = model.triangles[static_cast<std::size_t>(order[k])];
    Triangle& r = triangles_data_[k];
    r.index = order[k];
    r.p0_O = model.vertices_O[static_cast<std::size_t>(t[0])];
    r.p1_O = model.vertices_O[static_cast<std::size_t>(t[1])];
    r.p2_O = model.vertices_O[static_cast<std::size_t>(t[2])];
    r.cross_O = glm::cross(r.p1_O - r.p0_O, r.p2_O - r.p0_O);
    r.cross_length = glm::length(r.cross_O);
    r.radius_m = std::sqrt(
        std::max({glm::dot(r.p0_O, r.p0_O), glm::dot(r.p1_O, r.p1_O), glm::dot(r.p2_O, r.p2_O)}));
  }
  // Median splits keep the depth near log2(#F / 8); SelectPatchTriangles walks with a stack of
  // 64, which a depth of 60 cannot overflow.
  if (!nodes_.empty() && TreeDepth(nodes_, 0) > 60) {
    Clear();
    return;
  }
  vertex_count_ = model.vertices_O.size();
  triangle_count_ = nf;
  built_ = true;
}

std::unique_ptr<TriangleBoxTree> TriangleBoxTree::ForModel(const HapticModel& model) {
  if (model.triangles.size() < kMinTriangles) return nullptr;
  auto tree = std::make_unique<TriangleBoxTree>();
  tree->Build(model);
  return tree;
}

int TriangleBoxTree::BuildNode(const HapticModel& model, const std::vector<glm::dvec3>& centroids,
                               std::vector<int>& order, int begin, int end) {
  glm::dvec3 lo(std::numeric_limits<double>::infinity());
  glm::dvec3 hi(-std::numeric_limits<double>::infinity());
  for (int k = begin; k < end; ++k) {
    const glm::ivec3 t =
        model.triangles[static_cast<std::size_t>(order[static_cast<std::size_t>(k)])];
    for (int c = 0; c < 3; ++c) {
      const glm::dvec3& p = model.vertices_O[static_cast<std::size_t>(t[c])];
      lo = glm::min(lo, p);
      hi = glm::max(hi, p);
    }
  }
  const int index = static_cast<int>(nodes_.size());
  Node node;
  node.center_O = 0.5 * (lo + hi);
  node.half_O = 0.5 * (hi - lo);
  node.half_O += 1e-12 * (glm::abs(node.center_O) + node.half_O);
  node.begin = begin;
  node.end = end;
  nodes_.push_back(node);
  if (end - begin <= kLeafTriangles) return index;
  const glm::dvec3 size = hi - lo;
  const int axis = size.x >= size.y && size.x >= size.z ? 0 : (size.y >= size.z ? 1 : 2);
  const int mid = begin + (end - begin) / 2;
  std::nth_element(order.begin() + begin, order.begin() + mid, order.begin() + end,
                   [&](int a, int b) {
                     const double ca = centroids[static_cast<std::size_t>(a)][axis];
                     const double cb = centroids[static_cast<std::size_t>(b)][axis];
                     return ca < cb || (ca == cb && a < b);
                   });
  BuildNode(model, centroids, order, begin, mid);
  const int second = BuildNode(model, centroids, order, mid, end);
  nodes_[static_cast<std::size_t>(index)].second = second;
  return index;
}

bool TriangleBoxTree::Fits(const HapticModel& model) const noexcept {
  return built_ && vertex_count_ == model.vertices_O.size() &&
         triangle_count_ == model.triangles.size();
}

}  // namespace ht
