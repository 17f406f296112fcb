// Stage 2's bounds per hull node (hull_proximity.h): bounding spheres, oriented boxes
// (Gottschalk, Lin & Manocha 1996) and the texture's outward reach (HullBounds::Of).
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <atomic>
#include <cmath>
#include <glm/geometric.hpp>
#include <limits>

#include "haptic_core/hull_proximity.h"

namespace ht {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// Per node of `model`'s hierarchy (or one value for a model without one): the largest positive
// level-0 texture height over the node's triangles, each triangle's texel box grown by a texel
// (bilinear samples reach that far), capped at the model's OutwardReach(). A triangle whose box
// touches a wrapped border counts the cap. Allocates `out`.
void ComputeNodeReach(const HapticModel& model, std::vector<double>& out) {
  const double cap = model.OutwardReach();
  const auto& nodes = model.hull_hierarchy.nodes;
  out.assign(std::max<std::size_t>(nodes.size(), 1), cap);
  if (nodes.empty()) return;
  const bool have_texture = !model.texture.empty();
  const std::size_t nf = model.triangles.size();
  std::vector<double> tri(nf, 0.0);
  if (have_texture && model.corner_uvs.size() >= 3 * nf && model.textured.size() >= nf) {
    const HeightFieldLevel& L = model.texture.level(0);
    for (std::size_t f = 0; f < nf; ++f) {
      if (model.textured[f] == 0) continue;
      float umin = 1e30f, umax = -1e30f, vmin = 1e30f, vmax = -1e30f;
      for (int c = 0; c < 3; ++c) {
        const glm::vec2 uv = model.corner_uvs[3 * f + c];
        umin = std::min(umin, uv.x);
        umax = std::max(umax, uv.x);
        vmin = std::min(vmin, uv.y);
        vmax = std::max(vmax, uv.y);
      }
      if (!(std::isfinite(umin) && std::isfinite(umax) && std::isfinite(vmin) &&
            std::isfinite(vmax))) {
        tri[f] = cap;
        continue;
      }
      const int x0 = static_cast<int>(std::floor(umin * static_cast<float>(L.width) - 0.5f)) - 1;
      const int x1 = static_cast<int>(std::ceil(umax * static_cast<float>(L.width) - 0.5f)) + 1;
      const int y0 = static_cast<int>(std::floor(vmin * static_cast<float>(L.height) - 0.5f)) - 1;
      const int y1 = static_cast<int>(std::ceil(vmax * static_cast<float>(L.height) - 0.5f)) + 1;
      if ((model.texture.wrap_u() && (x0 < 0 || x1 >= L.width)) ||
          (model.texture.wrap_v() && (y0 < 0 || y1 >= L.height))) {
        tri[f] = cap;
        continue;
      }
      double h = 0.0;
      for (int y = std::max(y0, 0); y <= std::min(y1, L.height - 1); ++y) {
        const float* row = &L.texels[static_cast<std::size_t>(y) * L.width];
        for (int x = std::max(x0, 0); x <= std::min(x1, L.width - 1); ++x) {
          h = std::max(h, static_cast<double>(row[x]));
        }
      }
      tri[f] = std::min(h, cap);
    }
  }
  // Leaves from their triangles; internal nodes from their children (pre-order: children come
  // after their parent, so a reverse sweep sees them first).
  for (std::size_t k = nodes.size(); k-- > 0;) {
    const HullNode& node = nodes[k];
    double r = 0.0;
    if (node.is_leaf()) {
      for (const int f : node.triangles) {
        if (f >= 0 && static_cast<std::size_t>(f) < nf) r = std::max(r, tri[f]);
      }
    } else {
      for (const int child : node.children) {
        if (child > static_cast<int>(k) && static_cast<std::size_t>(child) < nodes.size()) {
          r = std::max(r, out[static_cast<std::size_t>(child)]);
        } else {
          r = cap;  // not pre-order: stay conservative
        }
      }
    }
    out[k] = std::min(r, cap);
  }
}

// The box of `vertices` (frame O) along their principal axes (the eigenvectors of their
// covariance; Gottschalk, Lin & Manocha 1996), its extents the vertices' range along each axis,
// padded by 1e-9 of the box's size (and 1e-12 m) so that rounding in the query's box tests can
// never leave a vertex outside. No vertices: a box too big to cull anything.
OrientedBox FitOrientedBox(const std::vector<glm::dvec3>& vertices) {
  OrientedBox box;
  if (vertices.empty()) {  // a box that culls nothing
    box.half_extents_m = glm::dvec3(1e30);
    return box;
  }
  glm::dvec3 mean(0.0);
  for (const glm::dvec3& v : vertices) mean += v;
  mean /= static_cast<double>(vertices.size());
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
  for (const glm::dvec3& v : vertices) {
    const Eigen::Vector3d d(v.x - mean.x, v.y - mean.y, v.z - mean.z);
    covariance += d * d.transpose();
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(covariance);
  glm::dmat3 axes(1.0);
  if (solver.info() == Eigen::Success && solver.eigenvectors().allFinite()) {
    const Eigen::Matrix3d& e = solver.eigenvectors();
    for (int c = 0; c < 3; ++c) axes[c] = glm::normalize(glm::dvec3(e(0, c), e(1, c), e(2, c)));
    axes[2] = glm::normalize(glm::cross(axes[0], axes[1]));  // orthonormal to rounding
    axes[1] = glm::cross(axes[2], axes[0]);
  }
  glm::dvec3 lo(kInf), hi(-kInf);
  for (const glm::dvec3& v : vertices) {
    for (int c = 0; c < 3; ++c) {
      const double s = glm::dot(v, axes[c]);
      lo[c] = std::min(lo[c], s);
      hi[c] = std::max(hi[c], s);
    }
  }
  const glm::dvec3 mid = 0.5 * (lo + hi), half = 0.5 * (hi - lo);
  const double size = std::max({half.x, half.y, half.z, glm::length(mean)});
  box.axes_O = axes;
  box.center_O = mid.x * axes[0] + mid.y * axes[1] + mid.z * axes[2];
  box.half_extents_m = half + glm::dvec3(1e-9 * size + 1e-12);
  return box;
}

}  // namespace

HullBounds HullBounds::Of(const HapticModel& model) {
  static std::atomic<std::uint64_t> next_id{1};
  const auto& nodes = model.hull_hierarchy.nodes;
  auto sphere = [](const std::vector<glm::dvec3>& vertices, const glm::dvec3* center) {
    glm::dvec3 c(0.0);
    if (center != nullptr) {
      c = *center;
    } else if (!vertices.empty()) {
      for (const auto& v : vertices) c += v;
      c /= static_cast<double>(vertices.size());
    }
    double r2 = 0.0;
    for (const auto& v : vertices) r2 = std::max(r2, glm::dot(v - c, v - c));
    return glm::dvec4(c, std::sqrt(r2));
  };
  HullBounds b;
  if (nodes.empty()) {
    b.spheres_O.push_back(sphere(model.hull_vertices_O, nullptr));
    b.boxes_O.push_back(FitOrientedBox(model.hull_vertices_O));
  } else {
    b.spheres_O.reserve(nodes.size());
    b.boxes_O.reserve(nodes.size());
    for (const HullNode& node : nodes) {
      b.spheres_O.push_back(sphere(node.hull.vertices_O, &node.hull.center_O));
      b.boxes_O.push_back(FitOrientedBox(node.hull.vertices_O));
    }
  }
  ComputeNodeReach(model, b.reach_m);
  b.id = next_id.fetch_add(1, std::memory_order_relaxed);
  return b;
}

bool HullBounds::Fits(const HapticModel& model) const noexcept {
  const std::size_t n = std::max<std::size_t>(model.hull_hierarchy.nodes.size(), 1);
  return spheres_O.size() == n && boxes_O.size() == n && reach_m.size() == n;
}

}  // namespace ht
