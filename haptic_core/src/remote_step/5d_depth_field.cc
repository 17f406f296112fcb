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

namespace {

/// x less the nearest whole multiple of h, in [−h/2, h/2].
double NearestRemainder(double x, double h) noexcept { return x - h * std::round(x / h); }

/// How far (rad) a contact window's normal may turn from a lattice's before the contact gets a
/// lattice of its own: within it the field's direction is the lattice's (its depth along the
/// window's own normal differs by at most 1 − cos 0.1 = 0.5 %).
constexpr double kLatticeTurnRad = 0.1;

/// The least travel margin (m) a field keeps before its cell is made coarser to fit the grid.
constexpr double kDepthFieldKeptMarginM = 2e-3;

}  // namespace

bool DepthFieldRenderer::Render(const HapticModel& tool, const RigidTransform& X_WT,
                                const ContactQuery& query, const DepthFieldLattice& lattice,
                                double margin_m, std::uint32_t id, double smooth_max_m,
                                DepthField& out) {
  out.prepared = false;
  const double h = lattice.cell_m;
  if (!(h > 0.0) || !std::isfinite(h) || query.environment == nullptr ||
      !(query.window.extent_m > 0.0) || !IsFiniteRigidTransform(query.X_WO) ||
      !IsFiniteRigidTransform(X_WT)) {
    return false;
  }
  const glm::dvec3 u = lattice.axis_u_W, v = lattice.axis_v_W, n = lattice.normal_W;
  const int m = std::max(0, static_cast<int>(std::ceil(std::max(margin_m, 0.0) / h - 1e-9)));
  const int r = std::max(2, static_cast<int>(std::ceil(query.window.extent_m / h - 1e-9)));
  const int side = r + 2 * m;
  if (side > kMaxDepthFieldSide) return false;
  // The environment's nodes: the lattice through the environment's origin, so that a node reads
  // the same point of the environment in every field on this lattice. Node (0, 0) is the
  // lattice point nearest where the window grown by the margin starts.
  const glm::dvec3 p_O = query.X_WO.translation;
  const glm::dvec3 c = query.window.center_W - p_O;
  const double start = (-m + 0.5) - 0.5 * r;  // node (0, 0) from the centre (cells)
  const double i_lo = std::floor(glm::dot(c, u) / h + start + 0.5);
  const double j_lo = std::floor(glm::dot(c, v) / h + start + 0.5);
  const glm::dvec3 F0 = p_O + i_lo * h * u + j_lo * h * v + glm::dot(c, n) * n;
  ContactWindow w = query.window;
  w.axis_u_W = u;
  w.axis_v_W = v;
  w.normal_W = n;
  w.resolution = r;
  w.extent_m = r * h;
  w.center_W = F0 - start * h * (u + v);
  // The tool's nodes: the lattice through the tool's centre of mass, with the same axes.
  const glm::dvec3 t = F0 - X_WT.translation;
  const double du = NearestRemainder(-glm::dot(t, u), h);
  const double dv = NearestRemainder(-glm::dot(t, v), h);
  ContactWindow w_tool = w;
  w_tool.center_W += du * u + dv * v;
  const std::size_t cells = static_cast<std::size_t>(side) * side;
  out.env_height_m.assign(cells, -std::numeric_limits<float>::infinity());
  out.tool_height_m.assign(cells, std::numeric_limits<float>::infinity());
  SelectPatchTrianglesIn(query.environment_triangles, *query.environment, query.X_WO, w,
                         PatchSide::kEnvironment, (m + 1) * h, env_triangles_,
                         kPatchFacingThreshold - kDepthFieldFacingThreshold, nullptr,
                         query.environment_triangles.tree);
  RenderPatchHeightsFast(*query.environment, query.X_WO, env_triangles_, w, PatchSide::kEnvironment,
                         m, out.env_height_m);
  SelectPatchTrianglesIn(query.tool_triangles, tool, X_WT, w_tool, PatchSide::kTool, (m + 1) * h,
                         tool_triangles_, 0.0, nullptr, query.tool_triangles.tree);
  RenderPatchHeightsFast(tool, X_WT, tool_triangles_, w_tool, PatchSide::kTool, m,
                         out.tool_height_m);
  for (float& b : out.env_height_m) {
    if (!std::isfinite(b)) b = std::numeric_limits<float>::quiet_NaN();
  }
  ExtendDepthMapEdges(side, side, kDepthFieldEdgeNodes, out.env_height_m, edge_scratch_);
  LimitDepthMapDescent(side, side, h, kDepthFieldMaxDescentSlope, out.env_height_m);
  for (float& a : out.tool_height_m) {
    if (!std::isfinite(a)) a = std::numeric_limits<float>::quiet_NaN();
  }
  out.X_WF.translation = F0;
  out.X_WF.rotation = glm::normalize(glm::quat_cast(glm::dmat3(u, v, n)));
  out.id = id;
  out.cell_m = h;
  out.nx = out.ny = side;
  out.tool_offset_u_m = du;
  out.tool_offset_v_m = dv;
  out.lattice_id = lattice.id;
  out.lattice_i0 = static_cast<std::int32_t>(i_lo);
  out.lattice_j0 = static_cast<std::int32_t>(j_lo);
  out.tool_lattice_i0 = static_cast<std::int32_t>(-std::round(-glm::dot(t, u) / h));
  out.tool_lattice_j0 = static_cast<std::int32_t>(-std::round(-glm::dot(t, v) / h));
  out.X_WT0 = X_WT;
  out.travel_margin_m = m * h;
  out.smooth_max_m = smooth_max_m;
  return out.Prepare();
}

int RenderContactDepthFields(const HapticModel& tool, const RigidTransform& X_WT,
                             const PipelineOptions& options, RemoteStepData& d) noexcept {
  d.num_fields = 0;
  const std::uint64_t step = ++d.field_step;
  const double base_cell = options.window_extent_m / std::max(1, options.grid_resolution);
  for (int i = 0; i < d.last_num_queries; ++i) {
    ContactLinearization& lin = d.last_results[static_cast<std::size_t>(i)];
    lin.depth_field_id = 0;
    lin.depth_field_shift_m = 0.0;
    if (!std::isfinite(lin.depth_m)) continue;
    const ContactQuery& q = d.last_queries[static_cast<std::size_t>(i)];
    if (!(base_cell > 0.0) || q.environment == nullptr) continue;
    // The subdivision's cell while its grid holds the window and a margin of at least
    // kDepthFieldKeptMarginM (or the margin asked, if less), the margin cut to what fits; else
    // coarser cells. A fine cell beyond part of the margin beats a coarse one within all of it:
    // the field is evaluated beyond its margin too, and the step renders a new one once the
    // tool has moved half of it.
    int sub = std::clamp(options.depth_field_subdivision, 1, 4);
    const double least = std::min(options.depth_field_margin_m, kDepthFieldKeptMarginM);
    const auto side_at = [&](int s) {
      const double h = base_cell / s;
      return std::ceil(q.window.extent_m / h - 1e-9) + 2.0 * std::ceil(least / h - 1e-9);
    };
    while (sub > 1 && side_at(sub) > kMaxDepthFieldSide) --sub;
    const double h = base_cell / sub;
    // Whole cells on each side (Render rounds the margin up to cells).
    const double room = std::floor(0.5 * (kMaxDepthFieldSide -
                                          std::max(2.0, std::ceil(q.window.extent_m / h - 1e-9)))) *
                        h;
    if (room < 0.0) continue;
    const double margin = std::min(room, options.depth_field_margin_m);
    // The lattice: one the environment already has for this direction and cell, else the
    // window's axes, kept in the environment's frame.
    const glm::dmat3 R_WO = glm::mat3_cast(q.X_WO.rotation);
    const glm::dmat3 R_OW = glm::transpose(R_WO);
    const glm::dvec3 n_O = R_OW * q.window.normal_W;
    RemoteStepData::FieldLattice* lattice = nullptr;
    for (RemoteStepData::FieldLattice& e : d.field_lattices) {
      if (e.environment == q.environment && e.cell_m == h &&
          glm::dot(e.normal_O, n_O) >= std::cos(kLatticeTurnRad)) {
        lattice = &e;
        break;
      }
    }
    if (lattice == nullptr) {
      lattice = &*std::min_element(
          d.field_lattices.begin(), d.field_lattices.end(),
          [](const auto& a, const auto& b) noexcept { return a.last_used < b.last_used; });
      lattice->environment = q.environment;
      lattice->cell_m = h;
      lattice->normal_O = n_O;
      lattice->axis_u_O = R_OW * q.window.axis_u_W;
      lattice->axis_v_O = R_OW * q.window.axis_v_W;
      lattice->id = ++d.last_lattice_id;
    }
    lattice->last_used = ++d.field_lattice_clock;
    // A kept field that still holds this contact: on this lattice, not taken by another contact
    // of this step, its grid around the window grown by half its margin, and the tool within
    // half its margin of where the field was rendered.
    int slot = -1;
    for (int k = 0; k < RemoteStepData::kFieldPoolSize && slot < 0; ++k) {
      const DepthField& f = d.field_pool[static_cast<std::size_t>(k)];
      if (!f.prepared || f.lattice_id != lattice->id || f.cell_m != h ||
          d.field_used_at[static_cast<std::size_t>(k)] == step) {
        continue;
      }
      const double half = 0.5 * f.travel_margin_m;
      const Twist dq = PoseDifference(X_WT, f.X_WT0);
      const glm::dvec3 n_W = f.X_WF.rotation * glm::dvec3(0.0, 0.0, 1.0);
      const glm::dvec3 slide_W = dq.linear - glm::dot(dq.linear, n_W) * n_W;
      if (glm::length(slide_W) + glm::length(dq.angular) * f.tool_radius_m > half) continue;
      const glm::dvec3 c_F = f.X_WF.Inverse() * q.window.center_W;
      const double reach = 0.5 * q.window.extent_m + half;
      const double hi_x = (f.nx - 1) * f.cell_m, hi_y = (f.ny - 1) * f.cell_m;
      if (c_F.x - reach < 0.0 || c_F.y - reach < 0.0 || c_F.x + reach > hi_x ||
          c_F.y + reach > hi_y) {
        continue;
      }
      slot = k;
    }
    if (slot < 0) {
      // A new render, into the least recently used slot this step has not taken.
      std::uint64_t oldest = ~std::uint64_t{0};
      for (int k = 0; k < RemoteStepData::kFieldPoolSize; ++k) {
        const std::uint64_t used = d.field_used_at[static_cast<std::size_t>(k)];
        if (used != step && used < oldest) {
          oldest = used;
          slot = k;
        }
      }
      if (slot < 0) continue;
      const DepthFieldLattice L{R_WO * lattice->axis_u_O, R_WO * lattice->axis_v_O,
                                R_WO * lattice->normal_O, h, lattice->id};
      DepthField& f = d.field_pool[static_cast<std::size_t>(slot)];
      bool ok = false;
      try {
        ok = d.field_renderer.Render(tool, X_WT, q, L, margin, d.last_field_id + 1,
                                     options.depth_field_smooth_max_m, f);
      } catch (...) {  // std::bad_alloc beyond the reserve
        ok = false;
      }
      if (!ok) {
        f.prepared = false;
        continue;
      }
      ++d.last_field_id;
      if (d.last_field_id == 0) d.last_field_id = 1;  // 0 means none
    }
    d.field_used_at[static_cast<std::size_t>(slot)] = step;
    const DepthField& f = d.field_pool[static_cast<std::size_t>(slot)];
    lin.depth_field_id = f.id;
    d.fields[static_cast<std::size_t>(d.num_fields++)] = &f;
  }
  return d.num_fields;
}

}  // namespace ht
