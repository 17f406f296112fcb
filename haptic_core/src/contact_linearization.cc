#include "haptic_core/contact_linearization.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace ht {

Wrench PenaltyWrench(double depth_m, const PenetrationGradient& J,
                     double stiffness_n_per_m) noexcept {
  if (!(depth_m > 0.0) || !std::isfinite(depth_m)) return {};
  const double s = -stiffness_n_per_m * depth_m;
  return {s * J.d_translation_W, s * J.d_rotation_W};
}

TexturePenetrationSolver::TexturePenetrationSolver(int max_resolution, int max_triangles) {
  const size_t cells = static_cast<size_t>(max_resolution) * max_resolution;
  env_heights_.reserve(cells);
  tool_heights_.reserve(cells);
  env_triangles_.reserve(static_cast<size_t>(max_triangles));
  tool_triangles_.reserve(static_cast<size_t>(max_triangles));
}

void TexturePenetrationSolver::RenderEnvironment(const HapticModel& environment,
                                                 const RigidTransform& X_WE,
                                                 const ContactWindow& w) noexcept {
  const size_t cells = static_cast<size_t>(w.resolution) * w.resolution;
  env_heights_.assign(cells, -std::numeric_limits<float>::infinity());
  SelectPatchTriangles(environment, X_WE, w, PatchSide::kEnvironment, w.cell_size_m(),
                       env_triangles_);
  RenderPatchHeights(environment, X_WE, env_triangles_, w, PatchSide::kEnvironment, env_heights_);
}

DepthSample TexturePenetrationSolver::EvaluateTool(const HapticModel& tool,
                                                   const RigidTransform& X_WT,
                                                   const ContactWindow& w) noexcept {
  const size_t cells = static_cast<size_t>(w.resolution) * w.resolution;
  tool_heights_.assign(cells, std::numeric_limits<float>::infinity());
  RenderPatchHeights(tool, X_WT, tool_triangles_, w, PatchSide::kTool, tool_heights_);
  return DirectionalPenetrationDepth(env_heights_, tool_heights_);
}

DepthSample TexturePenetrationSolver::Depth(const HapticModel& tool, const RigidTransform& X_WT,
                                            const HapticModel& environment,
                                            const RigidTransform& X_WE,
                                            const ContactWindow& w) noexcept {
  RenderEnvironment(environment, X_WE, w);
  SelectPatchTriangles(tool, X_WT, w, PatchSide::kTool, w.cell_size_m(), tool_triangles_);
  return EvaluateTool(tool, X_WT, w);
}

ContactLinearization TexturePenetrationSolver::Linearize(
    const HapticModel& tool, const RigidTransform& X_WT, const HapticModel& environment,
    const RigidTransform& X_WE, const ContactWindow& w, double stiffness_n_per_m) noexcept {
  ContactLinearization out;
  out.stiffness_n_per_m = stiffness_n_per_m;
  out.normal_W = w.normal_W;
  out.point_W = w.center_W;

  const double h_x = w.cell_size_m();
  const double h_theta = h_x / (0.5 * w.extent_m);
  double tool_radius = 0.0;
  for (const auto& v : tool.vertices_O) tool_radius = std::max(tool_radius, glm::length(v));

  RenderEnvironment(environment, X_WE, w);
  // Tool triangles are chosen once with a margin that covers every perturbed pose.
  SelectPatchTriangles(tool, X_WT, w, PatchSide::kTool, 2.0 * h_x + h_theta * tool_radius,
                       tool_triangles_);
  const DepthSample base = EvaluateTool(tool, X_WT, w);
  out.depth_m = base.depth_m;
  if (base.cell < 0) return out;
  out.point_W = w.CellCenter(base.cell);

  const auto central = [&](const Twist& step, double h) {
    const DepthSample plus = EvaluateTool(tool, Displace(X_WT, step), w);
    const DepthSample minus = EvaluateTool(tool, Displace(X_WT, {-step.linear, -step.angular}), w);
    if (plus.cell >= 0 && minus.cell >= 0) return (plus.depth_m - minus.depth_m) / (2.0 * h);
    ++faults_.missing_overlap;
    if (plus.cell >= 0) return (plus.depth_m - base.depth_m) / h;
    if (minus.cell >= 0) return (base.depth_m - minus.depth_m) / h;
    return 0.0;
  };
  const glm::dvec3 u = w.axis_u_W, v = w.axis_v_W, n = w.normal_W;
  const double g_u = central({h_x * u, glm::dvec3(0.0)}, h_x);
  const double g_v = central({h_x * v, glm::dvec3(0.0)}, h_x);
  const double r_u = central({glm::dvec3(0.0), h_theta * u}, h_theta);
  const double r_v = central({glm::dvec3(0.0), h_theta * v}, h_theta);
  const double r_n = central({glm::dvec3(0.0), h_theta * n}, h_theta);
  // Moving the tool along +n lifts every tool height by the same amount: ∂δ/∂x_n = −1 exactly.
  out.gradient.d_translation_W = g_u * u + g_v * v - n;
  out.gradient.d_rotation_W = r_u * u + r_v * v + r_n * n;
  return out;
}

}  // namespace ht
