#include "haptic_core/contact_windows.h"

#include <optional>

namespace ht {

int MakeContactQueries(std::span<const ContactCandidate> candidates, double window_extent_m,
                       int grid_resolution, std::span<ContactQuery> out,
                       std::int64_t& bad_windows) noexcept {
  int num_queries = 0;
  for (const ContactCandidate& c : candidates) {
    if (static_cast<std::size_t>(num_queries) == out.size()) break;
    const std::optional<ContactWindow> window =
        c.object == nullptr
            ? std::nullopt
            : ContactWindow::TryMake(c.point_W, c.normal_W, window_extent_m, grid_resolution);
    if (!window) {
      ++bad_windows;
      continue;
    }
    out[num_queries++] = {c.object->model.get(), c.object->X_WO, *window,
                          c.object->stiffness_n_per_m};
  }
  return num_queries;
}

}  // namespace ht
