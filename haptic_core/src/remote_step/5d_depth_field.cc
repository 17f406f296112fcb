// Stage 5d of the remote step (remote_step.h): each contact's depth field, the two surfaces over
// its window grown by the travel margin (depth_field.h).

#include <algorithm>
#include <cmath>
#include <glm/gtc/quaternion.hpp>
#include <limits>

#include "0_remote_step_data.h"
#include "haptic_core/depth_field.h"
#include "haptic_core/penetration_depth.h"

namespace ht {

bool DepthFieldRenderer::Render(const HapticModel& tool, const RigidTransform& X_WT,
                                const ContactQuery& query, int margin_cells, std::uint32_t id,
                                double smooth_max_m, DepthField& out, int subdivision) {
  out.prepared = false;
  ContactWindow w = query.window;
  const int s = std::clamp(subdivision, 1, 4);
  w.resolution *= s;
  const int m = std::max(0, margin_cells) * s;
  const int side = w.resolution + 2 * m;
  if (side > kMaxDepthFieldSide || query.environment == nullptr) return false;
  const double h = w.cell_size_m();
  const std::size_t cells = static_cast<std::size_t>(side) * side;
  out.env_height_m.assign(cells, -std::numeric_limits<float>::infinity());
  out.tool_height_m.assign(cells, std::numeric_limits<float>::infinity());
  SelectPatchTrianglesIn(query.environment_triangles, *query.environment, query.X_WO, w,
                         PatchSide::kEnvironment, (m + 1) * h, env_triangles_, 0.0, nullptr,
                         query.environment_triangles.tree);
  RenderPatchHeightsFast(*query.environment, query.X_WO, env_triangles_, w, PatchSide::kEnvironment,
                         m, out.env_height_m);
  SelectPatchTrianglesIn(query.tool_triangles, tool, X_WT, w, PatchSide::kTool, (m + 1) * h,
                         tool_triangles_, 0.0, nullptr, query.tool_triangles.tree);
  RenderPatchHeightsFast(tool, X_WT, tool_triangles_, w, PatchSide::kTool, m, out.tool_height_m);
  for (float& b : out.env_height_m) {
    if (!std::isfinite(b)) b = std::numeric_limits<float>::quiet_NaN();
  }
  for (float& a : out.tool_height_m) {
    if (!std::isfinite(a)) a = std::numeric_limits<float>::quiet_NaN();
  }
  // F: origin at the grown grid's node (0, 0), the centre of window cell (−m, −m).
  const double offset = (-m + 0.5) * h - 0.5 * w.extent_m;
  out.X_WF.translation = w.center_W + offset * w.axis_u_W + offset * w.axis_v_W;
  out.X_WF.rotation =
      glm::normalize(glm::quat_cast(glm::dmat3(w.axis_u_W, w.axis_v_W, w.normal_W)));
  out.id = id;
  out.cell_m = h;
  out.nx = out.ny = side;
  out.X_WT0 = X_WT;
  out.travel_margin_m = m * h;
  out.smooth_max_m = smooth_max_m;
  return out.Prepare();
}

int RenderContactDepthFields(const HapticModel& tool, const RigidTransform& X_WT,
                             const PipelineOptions& options, RemoteStepData& d) noexcept {
  d.num_fields = 0;
  for (int i = 0; i < d.last_num_queries; ++i) {
    ContactLinearization& lin = d.last_results[static_cast<std::size_t>(i)];
    lin.depth_field_id = 0;
    lin.depth_field_shift_m = 0.0;
    if (!std::isfinite(lin.depth_m)) continue;
    const ContactQuery& q = d.last_queries[static_cast<std::size_t>(i)];
    const double h = q.window.cell_size_m();
    if (!(h > 0.0)) continue;
    const int want = static_cast<int>(std::ceil(options.depth_field_margin_m / h - 1e-9));
    // The finest subdivision whose grid holds the window and the margin, else the coarsest with
    // the margin cut to fit.
    int sub = std::max(1, options.depth_field_subdivision);
    while (sub > 1 && sub * (q.window.resolution + 2 * want) > kMaxDepthFieldSide) --sub;
    const int room = (kMaxDepthFieldSide / sub - q.window.resolution) / 2;
    if (room < 0) continue;
    const int margin = std::min(room, want);
    DepthField& f = d.fields[static_cast<std::size_t>(d.num_fields)];
    bool ok = false;
    try {
      ok = d.field_renderer.Render(tool, X_WT, q, margin, d.last_field_id + 1,
                                   options.depth_field_smooth_max_m, f, sub);
    } catch (...) {  // std::bad_alloc beyond the reserve
      ok = false;
    }
    if (!ok) continue;
    ++d.last_field_id;
    if (d.last_field_id == 0) d.last_field_id = 1;  // 0 means none
    lin.depth_field_id = f.id;
    ++d.num_fields;
  }
  return d.num_fields;
}

}  // namespace ht
