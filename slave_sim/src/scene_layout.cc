// The scene as the remote node offers it at join: the block-on-gear demo's meshes for streaming,
// and the layout every Welcome carries (targets, their bounds and clear approach heights).
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <vector>

#include "codecs/draco_mesh_codec.h"
#include "haptic_core/demo/procedural_models.h"
#include "haptic_core/hull_proximity.h"
#include "slave_sim/remote_node.h"

namespace ht {

namespace {

/// The centre of an object's top (W, m): its coarse triangles that face up (normal within 25° of
/// up_W) with every corner within `tolerance_m` below the highest vertex `top_W` form its top; the
/// area-weighted centre of their corners' centroids, brought onto the triangle under it (seen
/// along up_W) at that triangle's height. The highest vertex when no triangle is under that
/// centre (a ring's top, a ridge's two flanks) or the top has no area. A flat plate's top is then
/// its face's middle, not the corner that happens to come first.
glm::dvec3 TopCentre(const HapticModel& model, const RigidTransform& X_WO, const glm::dvec3& up_W,
                     const glm::dvec3& top_W, double tolerance_m) {
  const double top = glm::dot(top_W, up_W);
  const double cos_max = std::cos(25.0 * 3.14159265358979323846 / 180.0);
  std::vector<std::array<glm::dvec3, 3>> faces;
  glm::dvec3 weighted(0.0);
  double area = 0.0;
  for (const glm::ivec3& t : model.triangles) {
    const std::array<glm::dvec3, 3> p{X_WO * model.vertices_O[static_cast<std::size_t>(t[0])],
                                      X_WO * model.vertices_O[static_cast<std::size_t>(t[1])],
                                      X_WO * model.vertices_O[static_cast<std::size_t>(t[2])]};
    const glm::dvec3 n = glm::cross(p[1] - p[0], p[2] - p[0]);
    const double a = 0.5 * glm::length(n);
    if (!(a > 0.0) || glm::dot(n, up_W) < cos_max * 2.0 * a) continue;
    bool near_top = true;
    for (const glm::dvec3& q : p) near_top = near_top && glm::dot(q, up_W) >= top - tolerance_m;
    if (!near_top) continue;
    faces.push_back(p);
    weighted += a * (p[0] + p[1] + p[2]) / 3.0;
    area += a;
  }
  if (!(area > 0.0)) return top_W;
  const glm::dvec3 c = weighted / area;
  for (const auto& p : faces) {
    // c projected along up_W onto the triangle's plane; inside when its barycentric weights are.
    const glm::dvec3 n = glm::normalize(glm::cross(p[1] - p[0], p[2] - p[0]));
    const glm::dvec3 q = c + up_W * (glm::dot(p[0] - c, n) / glm::dot(up_W, n));
    const glm::dvec3 e0 = p[1] - p[0], e1 = p[2] - p[0], w = q - p[0];
    const double d00 = glm::dot(e0, e0), d01 = glm::dot(e0, e1), d11 = glm::dot(e1, e1);
    const double d20 = glm::dot(w, e0), d21 = glm::dot(w, e1);
    const double det = d00 * d11 - d01 * d01;
    if (!(det > 0.0)) continue;
    const double v = (d11 * d20 - d01 * d21) / det, u = (d00 * d21 - d01 * d20) / det;
    constexpr double kOnEdge = 1e-9;
    if (v >= -kOnEdge && u >= -kOnEdge && u + v <= 1.0 + kOnEdge) return q;
  }
  return top_W;
}

}  // namespace

DisplayStream BlockOnGearDisplayStream(const HapticScene& scene) {
  const TriangleMesh gear = MakeRidgedGearFullResolution();
  std::vector<const TriangleMesh*> objects(scene.touchables.size(), nullptr);
  // The gear's own mesh where the object is the gear (the stiff wall shows its coarse mesh).
  for (std::size_t k = 0; k < objects.size(); ++k) {
    if (scene.touchables[k].model && scene.touchables[k].model->name == "ridged_gear") {
      objects[k] = &gear;
    }
  }
  return MakeDisplayStream(scene, MakeRidgedBlockFullResolution(), RigidTransform::Identity(),
                           objects);
}

wire::SceneLayout MakeSceneLayout(const HapticScene& scene) {
  wire::SceneLayout layout;
  layout.X_WT_home = scene.X_WT_home;
  if (scene.tool) {
    layout.tool_mass_kg = scene.tool->mass_kg;
    layout.tool_inertia_diagonal_T = scene.tool->inertia_diagonal_O;
    for (const glm::dvec3& p_T : scene.tool->vertices_O) {
      layout.tool_extent_down_m = std::max(layout.tool_extent_down_m, -p_T.z);
    }
  }
  const glm::dvec3 up_W = scene.X_WT_home.rotation * glm::dvec3(0.0, 0.0, 1.0);
  std::vector<std::pair<double, wire::WelcomeTarget>> all;
  for (const TouchableObject& object : scene.touchables) {
    if (!object.model || object.model->vertices_O.empty()) continue;
    wire::WelcomeTarget t;
    t.box_min_W = glm::dvec3(std::numeric_limits<double>::infinity());
    t.box_max_W = -t.box_min_W;
    double top = -std::numeric_limits<double>::infinity();
    for (const glm::dvec3& p_O : object.model->vertices_O) {
      const glm::dvec3 p_W = object.X_WO * p_O;
      t.box_min_W = glm::min(t.box_min_W, p_W);
      t.box_max_W = glm::max(t.box_max_W, p_W);
      if (glm::dot(p_W, up_W) > top) {
        top = glm::dot(p_W, up_W);
        t.top_W = p_W;
      }
    }
    // The top's centre, where the explore experiment presses: within 1 mm (or 2 % of the
    // object's height) of the highest vertex.
    const double height = glm::dot(t.box_max_W - t.box_min_W, glm::abs(up_W));
    t.top_W = TopCentre(*object.model, object.X_WO, up_W, t.top_W, std::max(1e-3, 0.02 * height));
    // The textured surface reaches beyond the coarse mesh by up to the texture's outward reach.
    const double reach = object.model->OutwardReach();
    t.box_min_W -= glm::dvec3(reach);
    t.box_max_W += glm::dvec3(reach);
    all.emplace_back(glm::length(t.box_max_W - t.box_min_W), t);
  }
  std::stable_sort(all.begin(), all.end(),
                   [](const auto& a, const auto& b) { return a.first > b.first; });
  // Where the tool, centred over a target's top at the home orientation, touches nothing: from
  // just above the top (by the texture's reach, at most 2 cm, plus 1 cm) up in doubling steps,
  // checked with the coarse proximity query against every touchable at tolerance
  // min(reach, 2 cm) + 1 mm; the home height (clear of everything) at worst.
  HullProximityQuery query(16);
  // The models' bounds, built once for every check below.
  const HullBounds tool_bounds = scene.tool ? HullBounds::Of(*scene.tool) : HullBounds{};
  std::vector<HullBounds> object_bounds;
  object_bounds.reserve(scene.touchables.size());
  for (const TouchableObject& o : scene.touchables) {
    object_bounds.push_back(o.model ? HullBounds::Of(*o.model) : HullBounds{});
  }
  const auto clear = [&](const RigidTransform& X_WT) {
    for (std::size_t k = 0; k < scene.touchables.size(); ++k) {
      const TouchableObject& o = scene.touchables[k];
      if (!o.model) continue;
      ProximityQueryOptions options;
      options.tolerance_m = std::min(o.model->OutwardReach(), 0.02) + 1e-3;
      options.max_pairs = 1;
      options.temporal_coherence = false;
      if (!query.Query(*scene.tool, tool_bounds, X_WT, *o.model, object_bounds[k], o.X_WO, options)
               .empty()) {
        return false;
      }
    }
    return true;
  };
  const double home_height = glm::dot(scene.X_WT_home.translation, up_W);
  for (const auto& [size, target] : all) {
    if (layout.num_targets >= wire::kMaxWelcomeTargets) break;
    wire::WelcomeTarget t = target;
    const double top = glm::dot(t.top_W, up_W);
    const double reach = glm::dot(t.box_max_W - t.top_W, up_W);  // ≈ the texture's reach
    double height = layout.tool_extent_down_m + std::clamp(reach, 0.0, 0.02) + 0.01;
    for (double step = 0.01; scene.tool && top + height < home_height; step *= 2.0) {
      RigidTransform X_WT = scene.X_WT_home;
      X_WT.translation = t.top_W + height * up_W;
      if (clear(X_WT)) break;
      height = std::min(height + step, home_height - top);
    }
    t.approach_m = std::max(0.0, height);
    layout.targets[layout.num_targets++] = t;
  }
  return layout;
}

}  // namespace ht
