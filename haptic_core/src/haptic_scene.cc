#include "haptic_core/haptic_scene.h"

#include <chrono>
#include <cmath>
#include <optional>
#include <stdexcept>
#include <string>

#include "haptic_core/procedural_models.h"

namespace ht {

HapticScene MakeBlockOnGearScene() {
  HapticScene scene;
  scene.name = "block_on_gear";
  const RidgedBlockParams block_params;
  const RidgedGearParams gear_params;
  scene.tool = std::make_shared<const HapticModel>(MakeRidgedBlock(block_params));
  TouchableObject gear;
  gear.model = std::make_shared<const HapticModel>(MakeRidgedGear(gear_params));
  gear.X_WO = RigidTransform::Identity();
  gear.stiffness_n_per_m = 8000.0;
  scene.touchables.push_back(gear);
  scene.X_WT_home = BlockOnGearHomePose();
  return scene;
}

HapticScene MakeStiffWallScene() {
  HapticScene scene;
  scene.name = "stiff_wall";
  scene.tool = std::make_shared<const HapticModel>(MakeRidgedBlock(RidgedBlockParams{}));
  const glm::dvec3 half{0.06, 0.06, 0.01};
  TouchableObject wall;
  // MakeTexturedBox puts its (here flat) texture on the bottom face; turned over, that face is
  // the top, at z = the gear's radius.
  wall.model = std::make_shared<const HapticModel>(MakeTexturedBox(
      half, [](double, double) { return 0.0; }, 16, 2.0, "stiff_wall"));
  wall.X_WO.translation = {0.0, 0.0, RidgedGearParams{}.radius_m - half.z};
  wall.X_WO.rotation = glm::angleAxis(M_PI, glm::dvec3(1.0, 0.0, 0.0));
  wall.stiffness_n_per_m = 40000.0;
  scene.touchables.push_back(wall);
  scene.X_WT_home = BlockOnGearHomePose();
  return scene;
}

RigidTransform BlockOnGearHomePose() {
  RigidTransform X_WT;
  X_WT.translation = {0.0, 0.0,
                      RidgedGearParams{}.radius_m + RidgedBlockParams{}.half_extents_m.z + 0.5e-3};
  return X_WT;
}

void PipelineOptions::Validate() const {
  if (grid_resolution < 2 || grid_resolution > 1024) {
    throw std::invalid_argument("grid resolution must be in [2, 1024], got " +
                                std::to_string(grid_resolution));
  }
  if (!(window_extent_m > 0.0) || !std::isfinite(window_extent_m)) {
    throw std::invalid_argument("window extent must be positive, got " +
                                std::to_string(window_extent_m));
  }
  if (!(proximity_margin_m >= 0.0) || !std::isfinite(proximity_margin_m)) {
    throw std::invalid_argument("proximity margin must be >= 0, got " +
                                std::to_string(proximity_margin_m));
  }
}

HapticTexturePipeline::HapticTexturePipeline(const HapticScene& scene,
                                             const PipelineOptions& options,
                                             std::unique_ptr<PenetrationDepthBackend> backend)
    : scene_(scene), options_(options), backend_(std::move(backend)) {
  options_.Validate();
  queries_.reserve(scene.touchables.size());
  for (std::size_t i = 0; i < scene.touchables.size(); ++i) queries_.emplace_back();
  if (!backend_) backend_ = std::make_unique<CpuPenetrationDepthBackend>(options_.grid_resolution);
  if (!scene.tool) throw std::invalid_argument("scene '" + scene.name + "' has no tool");
  if (glm::length(scene.tool->center_of_mass_O) > 1e-9) {
    throw std::invalid_argument("tool model '" + scene.tool->name +
                                "' must have its centre of mass at its frame origin");
  }
  for (const auto& t : scene.touchables) {
    if (!t.model) throw std::invalid_argument("scene '" + scene.name + "' has an empty touchable");
  }
  // Broad-phase spheres: the root bounding spheres the proximity queries use anyway. Asking each
  // query for both of its models here also fills its cache, so the first step does not.
  object_spheres_O_.reserve(scene.touchables.size());
  tool_sphere_O_ = HullProximityQuery().BoundingSphere(*scene.tool, 0);
  for (std::size_t i = 0; i < scene.touchables.size(); ++i) {
    object_spheres_O_.push_back(queries_[i].BoundingSphere(*scene.touchables[i].model, 0));
    queries_[i].BoundingSphere(*scene.tool, 0);
  }
}

ContactModel HapticTexturePipeline::Step(const RigidTransform& X_WT, std::uint64_t seq,
                                         StepTimings& timings) {
  using Clock = std::chrono::steady_clock;
  const auto us = [](Clock::duration d) {
    return std::chrono::duration<double, std::micro>(d).count();
  };
  const auto t0 = Clock::now();
  ContactModel model;
  model.X_WT0 = X_WT;
  model.tool_state_seq = seq;
  timings = {};
  last_num_queries_ = 0;
  if (!IsFiniteRigidTransform(X_WT)) return model;

  const HapticModel& tool = *scene_.tool;
  struct Candidate {
    const TouchableObject* object;
    glm::dvec3 point_W;
    glm::dvec3 normal_W;
  };
  std::array<Candidate, kMaxContacts> candidates{};
  int num_candidates = 0;
  for (std::size_t k = 0; k < scene_.touchables.size(); ++k) {
    const TouchableObject& object = scene_.touchables[k];
    const double reach = tool.OutwardReach() + object.model->OutwardReach();
    ProximityQueryOptions query;
    query.tolerance_m = reach + options_.proximity_margin_m;
    // Broad phase: bounding spheres in W (the objects may move between steps).
    const glm::dvec4& object_sphere_O = object_spheres_O_[k];
    const double gap =
        glm::length(X_WT * glm::dvec3(tool_sphere_O_) - object.X_WO * glm::dvec3(object_sphere_O)) -
        tool_sphere_O_.w - object_sphere_O.w;
    if (gap > query.tolerance_m) {
      ++timings.broad_phase_culled;
      continue;
    }
    query.time_budget_us = options_.collision_budget_us;
    ProximityQueryStats stats;
    const std::span<const HullPairContact> pairs =
        queries_[k].Query(tool, X_WT, *object.model, object.X_WO, query, &stats);
    ++timings.convex_pairs;
    timings.leaf_pairs += static_cast<int>(pairs.size());
    timings.collision_budget_exhausted |= stats.budget_exhausted;
    if (pairs.empty()) continue;
    // One window per cluster, all of the pipeline's window size: clusters whose windows would
    // overlap merge, so no texture region is rendered in two windows.
    ClusteringOptions clustering;
    clustering.merge_distance_m = options_.clustering_distance_m;
    clustering.max_normal_angle_deg = options_.clustering_angle_deg;
    clustering.texture_margin_m = reach;
    clustering.min_extent_m = clustering.max_extent_m = options_.window_extent_m;
    clustering.max_contacts = kMaxContacts;
    const std::span<const ContactCluster> clusters =
        clusterer_.Cluster(pairs, tool.hull_hierarchy, object.model->hull_hierarchy, clustering);
    timings.clusters += static_cast<int>(clusters.size());
    for (const ContactCluster& c : clusters) {
      if (num_candidates < kMaxContacts) {
        candidates[num_candidates++] = {&object, c.point_W, c.normal_W};
      }
    }
  }
  const auto t1 = Clock::now();

  // The batch lives in members, so that last_contact_queries() can show it after the step.
  std::array<ContactQuery, kMaxContacts>& queries = last_queries_;
  std::array<ContactLinearization, kMaxContacts>& results = last_results_;
  int num_queries = 0;
  for (int i = 0; i < num_candidates; ++i) {
    const Candidate& c = candidates[i];
    // A cluster with a non-finite point or a degenerate normal is a fault of the coarse stage:
    // counted and skipped; the step goes on (nothing in the step throws).
    const std::optional<ContactWindow> window = ContactWindow::TryMake(
        c.point_W, c.normal_W, options_.window_extent_m, options_.grid_resolution);
    if (!window) {
      ++step_faults_.bad_windows;
      continue;
    }
    queries[num_queries++] = {c.object->model.get(), c.object->X_WO, *window,
                              c.object->stiffness_n_per_m};
  }
  last_num_queries_ = num_queries;
  const std::span<const ContactQuery> batch(queries.data(), num_queries);
  const std::span<ContactLinearization> batch_out(results.data(), num_queries);
  if (num_queries > 0 && !backend_->LinearizeBatch(tool, X_WT, batch, batch_out)) {
    // The GPU failed (context lost, GL error): this step and all later ones on the CPU.
    if (backend_failures_++ == 0) {
      fallback_reason_ = std::string(backend_->name()) + ": " + backend_->last_error();
    }
    backend_ = std::make_unique<CpuPenetrationDepthBackend>(options_.grid_resolution);
    backend_->LinearizeBatch(tool, X_WT, batch, batch_out);
  }
  for (int i = 0; i < num_queries; ++i) {
    const ContactLinearization& lin = results[i];
    if (!std::isfinite(lin.depth_m)) continue;  // no overlap of the patches on the window
    model.contacts[model.num_contacts++] = lin;
    model.F_T_W_at_q0 += PenaltyWrench(lin.depth_m, lin.gradient, lin.stiffness_n_per_m);
  }
  const auto t2 = Clock::now();
  timings.collision_us = us(t1 - t0);
  timings.texture_us = us(t2 - t1);
  timings.total_us = us(t2 - t0);
  return model;
}

}  // namespace ht
