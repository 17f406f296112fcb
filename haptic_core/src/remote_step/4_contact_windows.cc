#include <algorithm>
#include <cmath>
#include <glm/geometric.hpp>
#include <limits>
#include <optional>
#include <stdexcept>
#include <string>

#include "haptic_core/contact_linearization.h"
#include "haptic_core/contact_windows.h"

namespace ht {

namespace {

// What is wrong with a window's arguments (nullptr when nothing): the one rule TryMake and Make
// share.
const char* WindowProblem(const glm::dvec3& center_W, const glm::dvec3& normal_W, double extent_m,
                          int resolution) noexcept {
  const double len = glm::length(normal_W);
  if (!std::isfinite(len) || !(len > 1e-12)) return "normal must be finite and non-zero";
  if (!std::isfinite(center_W.x) || !std::isfinite(center_W.y) || !std::isfinite(center_W.z)) {
    return "centre must be finite";
  }
  if (!(extent_m > 0.0) || !std::isfinite(extent_m)) return "extent must be positive";
  if (resolution < 2 || resolution > 1024) return "resolution must be in [2, 1024]";
  return nullptr;
}

}  // namespace

std::optional<ContactWindow> ContactWindow::TryMake(const glm::dvec3& center_W,
                                                    const glm::dvec3& normal_W, double extent_m,
                                                    int resolution) noexcept {
  if (WindowProblem(center_W, normal_W, extent_m, resolution) != nullptr) return std::nullopt;
  ContactWindow w;
  w.center_W = center_W;
  w.normal_W = normal_W / glm::length(normal_W);
  const glm::dvec3 ref = std::abs(w.normal_W.x) < 0.9 ? glm::dvec3(1, 0, 0) : glm::dvec3(0, 1, 0);
  w.axis_u_W = glm::normalize(ref - glm::dot(ref, w.normal_W) * w.normal_W);
  w.axis_v_W = glm::cross(w.normal_W, w.axis_u_W);
  w.extent_m = extent_m;
  w.resolution = resolution;
  return w;
}

ContactWindow ContactWindow::Make(const glm::dvec3& center_W, const glm::dvec3& normal_W,
                                  double extent_m, int resolution) {
  if (const char* problem = WindowProblem(center_W, normal_W, extent_m, resolution)) {
    throw std::invalid_argument(std::string("ContactWindow: ") + problem + " (extent " +
                                std::to_string(extent_m) + ", resolution " +
                                std::to_string(resolution) + ")");
  }
  return *TryMake(center_W, normal_W, extent_m, resolution);
}

glm::dvec3 ContactWindow::CellCenter(int index) const noexcept {
  const int i = index % resolution, j = index / resolution;
  const double s = ((i + 0.5) / resolution - 0.5) * extent_m;
  const double t = ((j + 0.5) / resolution - 0.5) * extent_m;
  return center_W + s * axis_u_W + t * axis_v_W;
}

int WindowResolution(double side_m, double window_extent_m, int grid_resolution) noexcept {
  return std::min(1024,
                  static_cast<int>(std::ceil(grid_resolution * side_m / window_extent_m - 1e-9)));
}

int MakeContactQueries(std::span<const ContactCandidate> candidates, double window_extent_m,
                       double max_window_extent_m, int grid_resolution, std::span<ContactQuery> out,
                       std::int64_t& bad_windows) noexcept {
  int num_queries = 0;
  for (const ContactCandidate& c : candidates) {
    if (static_cast<std::size_t>(num_queries) == out.size()) break;
    const double side = std::clamp(std::isfinite(c.extent_m) ? c.extent_m : 0.0, window_extent_m,
                                   std::max(window_extent_m, max_window_extent_m));
    const int n = WindowResolution(side, window_extent_m, grid_resolution);
    const std::optional<ContactWindow> window =
        c.object == nullptr ? std::nullopt : ContactWindow::TryMake(c.point_W, c.normal_W, side, n);
    if (!window) {
      ++bad_windows;
      continue;
    }
    out[num_queries++] = {
        c.object->model.get(), c.object->X_WO,     *window,         c.object->stiffness_n_per_m,
        c.depth_bound_m,       c.object_triangles, c.tool_triangles};
  }
  return num_queries;
}

int DropGrazingContacts(std::span<const ContactQuery> queries,
                        std::span<ContactLinearization> results) noexcept {
  int dropped = 0;
  const std::size_t n = std::min(queries.size(), results.size());
  for (std::size_t i = 0; i < n; ++i) {
    if (results[i].depth_m > queries[i].depth_bound_m) {
      results[i].depth_m = -std::numeric_limits<double>::infinity();
      ++dropped;
    }
  }
  return dropped;
}

}  // namespace ht
