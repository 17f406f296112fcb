// Convex hulls (hull_hierarchy_build.h, ComputeConvexHull): qhull's reentrant C API, the planes'
// offsets fitted so that every input point lies on or behind them, a thin point set thickened,
// and degenerate sets given an axis-aligned box. The hierarchy over a mesh:
// hull_hierarchy_build.cc.
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <glm/common.hpp>
#include <glm/geometric.hpp>
#include <limits>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "haptic_core/model_build/hull_hierarchy_build.h"
#include "hull_build_helpers.h"

// qhull's reentrant C API (DEPENDENCIES.md trap 2: its C++ API does not compile as C++20). Its
// headers define macros (True, False, FORALLfacets, ...): include them last.
extern "C" {
#include <libqhull_r/qhull_ra.h>
}

namespace ht {
namespace {

using hull_build::IsFinite;
using hull_build::PlaneValue;

// Thinnest extent, relative to the largest, that qhull is given without thickening.
constexpr double kMinRelativeThickness = 1e-7;

// What one qhull run returned: indices of the hull vertices into its input, and the facet planes
// (outward unit normal, offset d with n·p − d ≤ 0 inside).
struct QhullOutput {
  bool ok = false;
  std::vector<int> vertex_ids;
  std::vector<glm::dvec4> planes;
};

// Runs qhull on `coords` (3 × n, centred near the origin for precision) with `options` after
// "qhull". Messages go to /dev/null: a failure is handled by the caller's fallbacks.
QhullOutput RunQhull(std::vector<double>& coords, const char* options) {
  QhullOutput out;
  const int n = static_cast<int>(coords.size() / 3);
  auto qh_storage = std::make_unique<qhT>();
  qhT* qh = qh_storage.get();
  FILE* errfile = std::fopen("/dev/null", "w");
  qh_zero(qh, errfile);
  std::string command = std::string("qhull ") + options;
  std::vector<char> command_buffer(command.begin(), command.end());
  command_buffer.push_back('\0');
  const int exitcode = qh_new_qhull(qh, 3, n, coords.data(), /*ismalloc=*/0, command_buffer.data(),
                                    /*outfile=*/nullptr, errfile);
  if (exitcode == 0 && qh->hull_dim == 3) {
    vertexT* vertex;
    facetT* facet;
    FORALLvertices {
      const int id = qh_pointid(qh, vertex->point);
      if (id >= 0 && id < n) out.vertex_ids.push_back(id);
    }
    FORALLfacets {
      if (facet->visible) continue;
      out.planes.emplace_back(facet->normal[0], facet->normal[1], facet->normal[2], -facet->offset);
    }
    out.ok = out.vertex_ids.size() >= 4 && out.planes.size() >= 4;
  }
  qh_freeqhull(qh, !qh_ALL);
  int curlong = 0;
  int totlong = 0;
  qh_memfreeshort(qh, &curlong, &totlong);
  if (errfile != nullptr) std::fclose(errfile);
  return out;
}

// Sets every plane's offset to the largest n·p over `points` (so all of them satisfy it exactly),
// renormalizes the normal, and drops planes whose normal is not finite.
std::vector<glm::dvec4> FitPlaneOffsets(const std::vector<glm::dvec4>& planes,
                                        const std::vector<glm::dvec3>& points) {
  std::vector<glm::dvec4> fitted;
  fitted.reserve(planes.size());
  for (const glm::dvec4& plane : planes) {
    glm::dvec3 n(plane.x, plane.y, plane.z);
    const double length = glm::length(n);
    if (!(length > 0.5) || !std::isfinite(length)) continue;
    n /= length;
    glm::dvec4 p(n, 0.0);
    double d = -std::numeric_limits<double>::infinity();
    for (const glm::dvec3& q : points) d = std::max(d, PlaneValue(p, q));
    p.w = d;
    fitted.push_back(p);
  }
  return fitted;
}

glm::dvec3 Centroid(const std::vector<glm::dvec3>& points) {
  glm::dvec3 sum(0.0);
  for (const glm::dvec3& p : points) sum += p;
  return sum / static_cast<double>(points.size());
}

// The box spanned by `points` along the orthonormal `axes`: always finite, always containing the
// points. Coincident corners are kept once (a single point gives one vertex).
ConvexHull AxesBox(const std::vector<glm::dvec3>& points, const std::array<glm::dvec3, 3>& axes) {
  std::array<double, 3> lo{};
  std::array<double, 3> hi{};
  for (int k = 0; k < 3; ++k) {
    lo[k] = std::numeric_limits<double>::infinity();
    hi[k] = -std::numeric_limits<double>::infinity();
    for (const glm::dvec3& p : points) {
      const double s = glm::dot(axes[k], p);
      lo[k] = std::min(lo[k], s);
      hi[k] = std::max(hi[k], s);
    }
  }
  ConvexHull hull;
  for (int corner = 0; corner < 8; ++corner) {
    glm::dvec3 v(0.0);
    for (int k = 0; k < 3; ++k) v += axes[k] * (((corner >> k) & 1) != 0 ? hi[k] : lo[k]);
    if (std::find(hull.vertices_O.begin(), hull.vertices_O.end(), v) == hull.vertices_O.end()) {
      hull.vertices_O.push_back(v);
    }
  }
  std::vector<glm::dvec4> planes;
  for (int k = 0; k < 3; ++k) {
    planes.emplace_back(axes[k], 0.0);
    planes.emplace_back(-axes[k], 0.0);
  }
  // Offsets from the input points and the corners both, so that both satisfy every plane.
  std::vector<glm::dvec3> all = points;
  all.insert(all.end(), hull.vertices_O.begin(), hull.vertices_O.end());
  hull.planes_O = FitPlaneOffsets(planes, all);
  hull.center_O = Centroid(hull.vertices_O);
  return hull;
}

}  // namespace

ConvexHull ComputeConvexHull(const std::vector<glm::dvec3>& points_O, double thickness_m) {
  if (points_O.empty()) throw std::invalid_argument("ComputeConvexHull: no points");
  if (!(thickness_m >= 0.0) || !std::isfinite(thickness_m)) {
    throw std::invalid_argument(
        "ComputeConvexHull: thickness_m must be finite and non-negative, "
        "got " +
        std::to_string(thickness_m));
  }
  for (std::size_t i = 0; i < points_O.size(); ++i) {
    if (!IsFinite(points_O[i])) {
      throw std::invalid_argument("ComputeConvexHull: point " + std::to_string(i) +
                                  " is not finite");
    }
  }

  // Principal axes and extents.
  const glm::dvec3 centroid = Centroid(points_O);
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
  for (const glm::dvec3& p : points_O) {
    const Eigen::Vector3d d(p.x - centroid.x, p.y - centroid.y, p.z - centroid.z);
    covariance += d * d.transpose();
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(covariance);
  std::array<glm::dvec3, 3> axes{glm::dvec3(1, 0, 0), glm::dvec3(0, 1, 0), glm::dvec3(0, 0, 1)};
  if (solver.info() == Eigen::Success) {
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d e = solver.eigenvectors().col(k).normalized();
      if (std::isfinite(e.x()) && std::isfinite(e.y()) && std::isfinite(e.z())) {
        axes[static_cast<std::size_t>(k)] = glm::dvec3(e.x(), e.y(), e.z());
      }
    }
    // Re-orthonormalize (the eigenvectors are orthonormal up to rounding).
    axes[0] = glm::normalize(axes[0]);
    axes[1] = glm::normalize(axes[1] - glm::dot(axes[1], axes[0]) * axes[0]);
    axes[2] = glm::cross(axes[0], axes[1]);
  }
  std::array<double, 3> extent{};
  double largest = 0.0;
  for (int k = 0; k < 3; ++k) {
    double lo = std::numeric_limits<double>::infinity();
    double hi = -std::numeric_limits<double>::infinity();
    for (const glm::dvec3& p : points_O) {
      lo = std::min(lo, glm::dot(axes[static_cast<std::size_t>(k)], p - centroid));
      hi = std::max(hi, glm::dot(axes[static_cast<std::size_t>(k)], p - centroid));
    }
    extent[static_cast<std::size_t>(k)] = hi - lo;
    largest = std::max(largest, hi - lo);
  }
  if (largest == 0.0) {
    // All points coincide: the eigenvectors of a zero matrix mean nothing; use O's axes.
    axes = {glm::dvec3(1, 0, 0), glm::dvec3(0, 1, 0), glm::dvec3(0, 0, 1)};
  }
  const double t = std::max(thickness_m, kMinRelativeThickness * largest);
  if (!(t > 0.0)) {
    // All points coincide and no thickness was asked for: the point itself, six planes through it.
    return AxesBox(points_O, {glm::dvec3(1, 0, 0), glm::dvec3(0, 1, 0), glm::dvec3(0, 0, 1)});
  }

  // Thicken along the thin principal axes.
  std::vector<glm::dvec3> points = points_O;
  for (int k = 0; k < 3; ++k) {
    // (The slack keeps a set that was thickened to exactly t by the caller from being thickened
    // again for a rounding difference.)
    if (!(extent[static_cast<std::size_t>(k)] < (1.0 - 1e-6) * t)) continue;
    const glm::dvec3 offset = 0.5 * t * axes[static_cast<std::size_t>(k)];
    const std::size_t count = points.size();
    points.reserve(2 * count);
    for (std::size_t i = 0; i < count; ++i) {
      points.push_back(points[i] + offset);
      points[i] -= offset;
    }
  }

  // qhull on centred coordinates; joggled input if that fails.
  std::vector<double> coords;
  coords.reserve(points.size() * 3);
  for (const glm::dvec3& p : points) {
    coords.push_back(p.x - centroid.x);
    coords.push_back(p.y - centroid.y);
    coords.push_back(p.z - centroid.z);
  }
  QhullOutput out = RunQhull(coords, "");
  if (!out.ok) out = RunQhull(coords, "QJ");
  if (!out.ok) {
    points.insert(points.end(), points_O.begin(), points_O.end());
    return AxesBox(points, axes);
  }

  ConvexHull hull;
  std::sort(out.vertex_ids.begin(), out.vertex_ids.end());
  out.vertex_ids.erase(std::unique(out.vertex_ids.begin(), out.vertex_ids.end()),
                       out.vertex_ids.end());
  hull.vertices_O.reserve(out.vertex_ids.size());
  for (const int id : out.vertex_ids)
    hull.vertices_O.push_back(points[static_cast<std::size_t>(id)]);
  // Offsets over the thickened points and the input points both: the input points lie midway
  // between thickened copies, so they are inside anyway, but this makes it exact.
  std::vector<glm::dvec3> all = points;
  if (points.size() != points_O.size()) all.insert(all.end(), points_O.begin(), points_O.end());
  hull.planes_O = FitPlaneOffsets(out.planes, all);
  if (hull.planes_O.size() < 4) return AxesBox(all, axes);
  hull.center_O = Centroid(hull.vertices_O);
  return hull;
}

}  // namespace ht
