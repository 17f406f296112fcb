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

/// Whether the kept field `f` still holds a contact whose window is `window` with the tool at
/// X_WT: the tool within half the field's travel margin of where it was rendered
/// (DepthFieldEvaluation::within_margin's measure), and the window grown by half the margin
/// within the field's grid.
bool KeptFieldHolds(const DepthField& f, const RigidTransform& X_WT,
                    const ContactWindow& window) noexcept {
  const double half = 0.5 * f.travel_margin_m;
  const Twist dq = PoseDifference(X_WT, f.X_WT0);
  const glm::dvec3 n_W = f.X_WF.rotation * glm::dvec3(0.0, 0.0, 1.0);
  const glm::dvec3 slide_W = dq.linear - glm::dot(dq.linear, n_W) * n_W;
  if (!(glm::length(slide_W) + glm::length(dq.angular) * f.tool_radius_m <= half)) return false;
  const glm::dvec3 c_F = f.X_WF.Inverse() * window.center_W;
  const double reach = 0.5 * window.extent_m + half;
  const double hi_x = (f.nx - 1) * f.cell_m, hi_y = (f.ny - 1) * f.cell_m;
  return c_F.x - reach >= 0.0 && c_F.y - reach >= 0.0 && c_F.x + reach <= hi_x &&
         c_F.y + reach <= hi_y;
}

/// A contact's field cell and travel margin (m); ok false when the window leaves no room.
struct FieldPlan {
  double cell_m = 0.0;
  double margin_m = 0.0;
  bool ok = false;
};

FieldPlan PlanField(const ContactQuery& q, const PipelineOptions& options) noexcept {
  FieldPlan plan;
  const double base_cell = options.window_extent_m / std::max(1, options.grid_resolution);
  if (!(base_cell > 0.0) || q.environment == nullptr) return plan;
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
  if (room < 0.0) return plan;
  plan.cell_m = h;
  plan.margin_m = std::min(room, options.depth_field_margin_m);
  plan.ok = true;
  return plan;
}

/// The lattice the environment already has for the query's direction (within kLatticeTurnRad)
/// and cell `h`, or null.
RemoteStepData::FieldLattice* FindLattice(RemoteStepData& d, const ContactQuery& q,
                                          double h) noexcept {
  const glm::dvec3 n_O = glm::transpose(glm::mat3_cast(q.X_WO.rotation)) * q.window.normal_W;
  for (RemoteStepData::FieldLattice& e : d.field_lattices) {
    if (e.environment == q.environment && e.cell_m == h &&
        glm::dot(e.normal_O, n_O) >= std::cos(kLatticeTurnRad)) {
      return &e;
    }
  }
  return nullptr;
}

/// The first kept field in the pool that still holds a contact with `window` at X_WT: on the
/// lattice `lattice_id` with cell `h`, not `taken` by another contact of the step
/// (KeptFieldHolds); −1 when none.
template <typename Taken>
int FindKeptField(const RemoteStepData& d, std::uint32_t lattice_id, double h,
                  const RigidTransform& X_WT, const ContactWindow& window,
                  const Taken& taken) noexcept {
  for (int k = 0; k < RemoteStepData::kFieldPoolSize; ++k) {
    const DepthField& f = d.field_pool[static_cast<std::size_t>(k)];
    if (!f.prepared || f.lattice_id != lattice_id || f.cell_m != h || taken(k)) continue;
    if (KeptFieldHolds(f, X_WT, window)) return k;
  }
  return -1;
}

/// The pressure law's stride hint for a new field on lattice `lattice_id` around `center_W`: the
/// node stride of the kept field on that lattice whose grid centre is nearest, if it lies within
/// half that grid's side (the field this contact had); 0 when there is none.
std::uint8_t PressureStrideHint(const RemoteStepData& d, std::uint32_t lattice_id,
                                const glm::dvec3& center_W) noexcept {
  std::uint8_t hint = 0;
  double nearest = std::numeric_limits<double>::infinity();
  for (const DepthField& f : d.field_pool) {
    if (!f.prepared || f.lattice_id != lattice_id || f.force_law != ForceLaw::kPressure) continue;
    const glm::dvec3 c =
        f.X_WF * glm::dvec3(0.5 * (f.nx - 1) * f.cell_m, 0.5 * (f.ny - 1) * f.cell_m, 0.0);
    const double gap = glm::length(c - center_W);
    if (gap < nearest && gap <= 0.5 * std::min(f.nx, f.ny) * f.cell_m) {
      nearest = gap;
      hint = static_cast<std::uint8_t>(f.node_stride);
    }
  }
  return hint;
}

}  // namespace

bool DepthFieldRenderer::Render(const HapticModel& tool, const RigidTransform& X_WT,
                                const ContactQuery& query, const DepthFieldLattice& lattice,
                                double margin_m, std::uint32_t id, double smooth_max_m,
                                DepthField& out, ForceLaw law, double pressure_area_m2,
                                std::uint8_t stride_hint) {
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
  out.force_law = law;
  out.pressure_area_m2 = pressure_area_m2;
  out.stride_hint = law == ForceLaw::kPressure ? stride_hint : 0;
  return out.Prepare();
}

double ToolContactArea(const HapticModel& tool) noexcept {
  if (tool.vertices_O.empty()) return 0.0;
  glm::dvec3 lo = tool.vertices_O.front(), hi = lo;
  for (const glm::dvec3& p : tool.vertices_O) {
    lo = glm::min(lo, p);
    hi = glm::max(hi, p);
  }
  const glm::dvec3 e = hi - lo;
  return std::max({e.x * e.y, e.y * e.z, e.z * e.x});
}

int RenderContactDepthFields(const HapticModel& tool, const RigidTransform& X_WT,
                             const PipelineOptions& options, RemoteStepData& d) noexcept {
  d.num_fields = 0;
  const std::uint64_t step = ++d.field_step;
  for (int i = 0; i < d.last_num_queries; ++i) {
    ContactLinearization& lin = d.last_results[static_cast<std::size_t>(i)];
    lin.depth_field_id = 0;
    lin.depth_field_shift_m = 0.0;
    d.contact_field_slot[static_cast<std::size_t>(i)] = -1;
    if (!std::isfinite(lin.depth_m)) continue;
    const ContactQuery& q = d.last_queries[static_cast<std::size_t>(i)];
    const FieldPlan plan = PlanField(q, options);
    if (!plan.ok) continue;
    const double h = plan.cell_m;
    const double margin = plan.margin_m;
    const glm::dmat3 R_WO = glm::mat3_cast(q.X_WO.rotation);
    const glm::dmat3 R_OW = glm::transpose(R_WO);
    RemoteStepData::FieldLattice* lattice = FindLattice(d, q, h);
    if (lattice == nullptr) {
      // The window's axes, kept in the environment's frame.
      lattice = &*std::min_element(
          d.field_lattices.begin(), d.field_lattices.end(),
          [](const auto& a, const auto& b) noexcept { return a.last_used < b.last_used; });
      lattice->environment = q.environment;
      lattice->cell_m = h;
      lattice->normal_O = R_OW * q.window.normal_W;
      lattice->axis_u_O = R_OW * q.window.axis_u_W;
      lattice->axis_v_O = R_OW * q.window.axis_v_W;
      lattice->id = ++d.last_lattice_id;
    }
    lattice->last_used = ++d.field_lattice_clock;
    // A kept field that still holds this contact: on this lattice, not taken by another contact
    // of this step, its grid around the window grown by half its margin, and the tool within
    // half its margin of where the field was rendered.
    int slot = FindKeptField(d, lattice->id, h, X_WT, q.window, [&](int k) {
      return d.field_used_at[static_cast<std::size_t>(k)] == step;
    });
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
      const std::uint8_t hint = options.force_law == ForceLaw::kPressure
                                    ? PressureStrideHint(d, lattice->id, q.window.center_W)
                                    : std::uint8_t{0};
      DepthField& f = d.field_pool[static_cast<std::size_t>(slot)];
      bool ok = false;
      try {
        double area = 0.0;
        if (options.force_law == ForceLaw::kPressure) {
          if (d.pressure_area_tool != &tool) {
            d.pressure_area_tool = &tool;
            d.tool_contact_area_m2 = ToolContactArea(tool);
          }
          // From the object's own k (before stage 5c's share), so that k_p = s·k / A_ref takes
          // the share s in both cases.
          area = options.pressure_stiffness_n_per_m3 > 0.0
                     ? q.stiffness_n_per_m / options.pressure_stiffness_n_per_m3
                     : d.tool_contact_area_m2;
        }
        ok = d.field_renderer.Render(tool, X_WT, q, L, margin, d.last_field_id + 1,
                                     options.depth_field_smooth_max_m, f, options.force_law, area,
                                     hint);
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
    d.contact_field_slot[static_cast<std::size_t>(i)] = slot;
    const DepthField& f = d.field_pool[static_cast<std::size_t>(slot)];
    lin.depth_field_id = f.id;
    d.fields[static_cast<std::size_t>(d.num_fields++)] = &f;
  }
  return d.num_fields;
}

void LinearizeFromDepthFields(const RigidTransform& X_WT, RemoteStepData& d) noexcept {
  for (int i = 0; i < d.last_num_queries; ++i) {
    const int slot = d.contact_field_slot[static_cast<std::size_t>(i)];
    if (slot < 0) continue;
    const DepthFieldEvaluation e =
        DepthFieldDepthAt(d.field_pool[static_cast<std::size_t>(slot)], X_WT);
    if (!e.valid || !std::isfinite(e.depth_m)) continue;
    ContactLinearization& lin = d.last_results[static_cast<std::size_t>(i)];
    lin.depth_m = e.depth_m;
    lin.gradient = e.gradient;
  }
}

void RecordFullStep(RemoteStepData& d) noexcept {
  const int n = d.last_num_queries;
  d.full_count = n;
  bool valid = true;
  for (int i = 0; i < n; ++i) {
    const auto k = static_cast<std::size_t>(i);
    ContactQuery q = d.last_queries[k];
    // The lists live in the coarse stages' storage, which the next step overwrites.
    q.environment_triangles = TriangleSubset::All();
    q.tool_triangles = TriangleSubset::All();
    d.full_queries[k] = q;
    d.full_results[k] = d.last_results[k];
    // A contact without a field (no overlap on its window, dropped by the grazing guard, or no
    // field made) could change with the pose in a way no field tells: the next step is a full one.
    valid = valid && d.contact_field_slot[k] >= 0;
  }
  d.full_valid = valid;
}

bool TakeStepFromKeptFields(const RigidTransform& X_WT, const PipelineOptions& options,
                            RemoteStepData& d) noexcept {
  const int n4 = d.last_num_queries;
  // Without contacts there is nothing to take (and stages 5–5d have nothing to do).
  if (!d.full_valid || d.full_count == 0 || n4 != d.full_stage4_count) return false;
  // Each contact takes the field stage 5d would give it (its window: this step's for the
  // stage-4 contacts, the last full step's for stage 5a's), and every contact must have one.
  std::array<bool, RemoteStepData::kFieldPoolSize> taken{};
  std::array<RemoteStepData::FieldLattice*, kMaxContacts> lattices{};
  std::array<int, kMaxContacts> slots{};
  for (int i = 0; i < d.full_count; ++i) {
    const auto k = static_cast<std::size_t>(i);
    const ContactQuery& q = i < n4 ? d.last_queries[k] : d.full_queries[k];
    if (i < n4) {
      const ContactQuery& p = d.full_stage4_queries[k];
      if (q.environment != p.environment || q.X_WO.translation != p.X_WO.translation ||
          q.X_WO.rotation != p.X_WO.rotation) {
        return false;
      }
    }
    const FieldPlan plan = PlanField(q, options);
    if (!plan.ok) return false;
    RemoteStepData::FieldLattice* lattice = FindLattice(d, q, plan.cell_m);
    if (lattice == nullptr) return false;
    const int slot = FindKeptField(d, lattice->id, plan.cell_m, X_WT, q.window,
                                   [&](int s) { return taken[static_cast<std::size_t>(s)]; });
    if (slot < 0) return false;
    taken[static_cast<std::size_t>(slot)] = true;
    lattices[k] = lattice;
    slots[k] = slot;
    d.field_evaluations[k] = DepthFieldDepthAt(d.field_pool[static_cast<std::size_t>(slot)], X_WT);
    if (!d.field_evaluations[k].valid || !std::isfinite(d.field_evaluations[k].depth_m)) {
      return false;
    }
  }
  const std::uint64_t step = ++d.field_step;
  d.last_num_queries = d.full_count;
  d.num_fields = 0;
  for (int i = 0; i < d.full_count; ++i) {
    const auto k = static_cast<std::size_t>(i);
    const int slot = slots[k];
    const DepthField& f = d.field_pool[static_cast<std::size_t>(slot)];
    lattices[k]->last_used = ++d.field_lattice_clock;
    d.last_queries[k] = d.full_queries[k];
    ContactLinearization& lin = d.last_results[k];
    lin = d.full_results[k];
    lin.depth_m = d.field_evaluations[k].depth_m;
    lin.gradient = d.field_evaluations[k].gradient;
    lin.depth_field_id = f.id;
    d.contact_field_slot[k] = slot;
    d.field_used_at[static_cast<std::size_t>(slot)] = step;
    d.fields[static_cast<std::size_t>(d.num_fields++)] = &f;
  }
  return true;
}

}  // namespace ht
