#include "haptic_core/contact_windows.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>

namespace ht {

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
