#include "haptic_core/hull_hierarchy.h"

#include <cmath>
#include <cstddef>
#include <glm/geometric.hpp>
#include <limits>
#include <stdexcept>
#include <string>
#include <utility>

namespace ht {
namespace {

bool IsFinite(const glm::dvec3& v) {
  return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}

bool IsFinite(const glm::dvec4& v) {
  return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z) && std::isfinite(v.w);
}

std::string NodeName(std::size_t k) { return "node " + std::to_string(k); }

[[noreturn]] void Fail(const std::string& what) {
  throw std::invalid_argument("ConvexHullHierarchy::Validate: " + what);
}

// Checks one hull on its own: non-empty, finite, unit normals, vertices inside its own planes.
void ValidateHull(const ConvexHull& hull, const std::string& name, double tolerance_m) {
  if (hull.vertices_O.empty()) Fail(name + " has a hull without vertices");
  if (hull.planes_O.empty()) Fail(name + " has a hull without planes");
  if (!IsFinite(hull.center_O)) Fail(name + " has a non-finite hull center");
  for (std::size_t i = 0; i < hull.vertices_O.size(); ++i) {
    if (!IsFinite(hull.vertices_O[i])) {
      Fail(name + " hull vertex " + std::to_string(i) + " is not finite");
    }
  }
  for (std::size_t i = 0; i < hull.planes_O.size(); ++i) {
    const glm::dvec4& plane = hull.planes_O[i];
    if (!IsFinite(plane)) Fail(name + " hull plane " + std::to_string(i) + " is not finite");
    const double length = std::sqrt(plane.x * plane.x + plane.y * plane.y + plane.z * plane.z);
    if (!(std::abs(length - 1.0) <= 1e-6)) {
      Fail(name + " hull plane " + std::to_string(i) + " has a normal of length " +
           std::to_string(length) + ", not 1");
    }
  }
  for (std::size_t i = 0; i < hull.vertices_O.size(); ++i) {
    const double s = hull.SignedDistanceBound(hull.vertices_O[i]);
    if (!(s <= tolerance_m)) {
      Fail(name + " hull vertex " + std::to_string(i) + " lies " + std::to_string(s) +
           " m outside its own hull planes (tolerance " + std::to_string(tolerance_m) + " m)");
    }
  }
}

}  // namespace

double ConvexHull::SignedDistanceBound(const glm::dvec3& p_OQ) const noexcept {
  if (planes_O.empty()) return std::numeric_limits<double>::infinity();
  double bound = -std::numeric_limits<double>::infinity();
  for (const glm::dvec4& plane : planes_O) {
    const double s = plane.x * p_OQ.x + plane.y * p_OQ.y + plane.z * p_OQ.z - plane.w;
    // A NaN query or plane gives NaN, never a false "inside".
    if (std::isnan(s)) return s;
    if (s > bound) bound = s;
  }
  return bound;
}

glm::dvec3 ConvexHull::Support(const glm::dvec3& direction_O) const noexcept {
  if (vertices_O.empty()) return center_O;
  std::size_t best = 0;
  double best_dot = glm::dot(vertices_O[0], direction_O);
  for (std::size_t i = 1; i < vertices_O.size(); ++i) {
    const double s = glm::dot(vertices_O[i], direction_O);
    if (s > best_dot) {
      best_dot = s;
      best = i;
    }
  }
  return vertices_O[best];
}

int ConvexHullHierarchy::LeafCount() const noexcept {
  int count = 0;
  for (const HullNode& node : nodes) {
    if (node.is_leaf()) ++count;
  }
  return count;
}

int ConvexHullHierarchy::Depth() const {
  if (nodes.empty()) return 0;
  // Iterative level-by-level walk with a fixed level budget (no recursion, no unbounded loop on a
  // cyclic tree). Allocates: not meant for the haptic loop.
  const int n = static_cast<int>(nodes.size());
  std::vector<int> level{0};
  std::vector<int> next;
  int depth = 0;
  while (!level.empty() && depth < n) {
    ++depth;
    next.clear();
    for (const int k : level) {
      for (const int c : nodes[static_cast<std::size_t>(k)].children) {
        if (c >= 0 && c < n) next.push_back(c);
      }
    }
    std::swap(level, next);
  }
  return depth;
}

void ConvexHullHierarchy::Validate(const std::vector<glm::dvec3>& vertices_O,
                                   const std::vector<glm::ivec3>& triangles,
                                   double tolerance_m) const {
  if (!(tolerance_m >= 0.0) || !std::isfinite(tolerance_m)) {
    Fail("tolerance_m must be finite and non-negative, got " + std::to_string(tolerance_m));
  }
  const std::size_t vertex_count = vertices_O.size();
  for (std::size_t f = 0; f < triangles.size(); ++f) {
    for (int c = 0; c < 3; ++c) {
      const int v = triangles[f][c];
      if (v < 0 || static_cast<std::size_t>(v) >= vertex_count) {
        Fail("triangle " + std::to_string(f) + " indexes vertex " + std::to_string(v) + " of " +
             std::to_string(vertex_count));
      }
    }
  }
  if (nodes.empty()) {
    if (!triangles.empty()) {
      Fail("the hierarchy is empty but the mesh has " + std::to_string(triangles.size()) +
           " triangles");
    }
    return;
  }

  // Structure: child indices valid, every node reached exactly once from the root (a tree).
  const std::size_t n = nodes.size();
  std::vector<int> parent(n, -2);  // -2: not reached yet; -1: the root.
  parent[0] = -1;
  std::vector<std::size_t> stack{0};
  while (!stack.empty()) {
    const std::size_t k = stack.back();
    stack.pop_back();
    const HullNode& node = nodes[k];
    const bool leaf0 = node.children[0] < 0;
    const bool leaf1 = node.children[1] < 0;
    if (leaf0 != leaf1) Fail(NodeName(k) + " has exactly one child");
    if (leaf0) {
      if (node.children[0] != -1 || node.children[1] != -1) {
        Fail(NodeName(k) + " has a negative child index other than -1");
      }
      continue;
    }
    for (const int c : node.children) {
      if (static_cast<std::size_t>(c) >= n) {
        Fail(NodeName(k) + " has child index " + std::to_string(c) + " out of range (" +
             std::to_string(n) + " nodes)");
      }
      if (parent[static_cast<std::size_t>(c)] != -2) {
        Fail(NodeName(static_cast<std::size_t>(c)) + " is reached twice (from " + NodeName(k) +
             "): a cycle or a shared child");
      }
      parent[static_cast<std::size_t>(c)] = static_cast<int>(k);
      stack.push_back(static_cast<std::size_t>(c));
    }
  }
  for (std::size_t k = 0; k < n; ++k) {
    if (parent[k] == -2) Fail(NodeName(k) + " is not reachable from the root");
  }

  // Each hull on its own, and the triangle partition.
  std::vector<int> owner(triangles.size(), -1);
  for (std::size_t k = 0; k < n; ++k) {
    const HullNode& node = nodes[k];
    ValidateHull(node.hull, NodeName(k), tolerance_m);
    if (!node.is_leaf()) {
      if (!node.triangles.empty()) Fail(NodeName(k) + " is internal but holds triangles");
      continue;
    }
    if (node.triangles.empty()) Fail(NodeName(k) + " is a leaf without triangles");
    for (const int f : node.triangles) {
      if (f < 0 || static_cast<std::size_t>(f) >= triangles.size()) {
        Fail(NodeName(k) + " holds triangle index " + std::to_string(f) + " out of range (" +
             std::to_string(triangles.size()) + " triangles)");
      }
      int& o = owner[static_cast<std::size_t>(f)];
      if (o >= 0) {
        Fail("triangle " + std::to_string(f) + " is in two leaves (" +
             NodeName(static_cast<std::size_t>(o)) + " and " + NodeName(k) + ")");
      }
      o = static_cast<int>(k);
    }
  }
  for (std::size_t f = 0; f < triangles.size(); ++f) {
    if (owner[f] < 0) Fail("triangle " + std::to_string(f) + " is in no leaf");
  }

  // Leaf hulls bound their triangles.
  for (std::size_t f = 0; f < triangles.size(); ++f) {
    const auto k = static_cast<std::size_t>(owner[f]);
    for (int c = 0; c < 3; ++c) {
      const int v = triangles[f][c];
      const double s = nodes[k].hull.SignedDistanceBound(vertices_O[static_cast<std::size_t>(v)]);
      if (!(s <= tolerance_m)) {
        Fail("vertex " + std::to_string(v) + " of triangle " + std::to_string(f) + " lies " +
             std::to_string(s) + " m outside the hull of leaf " + NodeName(k) + " (tolerance " +
             std::to_string(tolerance_m) + " m)");
      }
    }
  }

  // Nesting: every child hull inside its parent hull.
  for (std::size_t k = 0; k < n; ++k) {
    const HullNode& node = nodes[k];
    if (node.is_leaf()) continue;
    for (const int c : node.children) {
      const ConvexHull& child = nodes[static_cast<std::size_t>(c)].hull;
      for (std::size_t i = 0; i < child.vertices_O.size(); ++i) {
        const double s = node.hull.SignedDistanceBound(child.vertices_O[i]);
        if (!(s <= tolerance_m)) {
          Fail("hull vertex " + std::to_string(i) + " of " + NodeName(static_cast<std::size_t>(c)) +
               " lies " + std::to_string(s) + " m outside the hull of its parent " + NodeName(k) +
               " (tolerance " + std::to_string(tolerance_m) + " m)");
        }
      }
    }
  }
}

}  // namespace ht
