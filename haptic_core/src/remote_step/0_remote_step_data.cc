// The remote step's constant model and its data block (0_remote_step_data.h), built once by
// HapticTexturePipeline's constructor.

#include "0_remote_step_data.h"

#include <algorithm>
#include <optional>

namespace ht {

RemoteStepModel::RemoteStepModel(const HapticScene& scene) {
  const std::size_t models = scene.touchables.size() + 1;
  // The hull of each model without hierarchy whose coarse mesh is convex (within a micrometre:
  // the procedural models' caps are fans of coplanar triangles), computed once: windows on its
  // contact region use it (with its triangle list), and the free
  // space around the tool takes it, or a hierarchy's root, as the whole model's hull.
  whole_hulls.resize(models);
  whole_triangles.resize(models);
  root_hulls.assign(models, nullptr);
  for (std::size_t i = 0; i < models; ++i) {
    const HapticModel& model = i == 0 ? *scene.tool : *scene.touchables[i - 1].model;
    if (!model.hull_hierarchy.nodes.empty()) {
      root_hulls[i] = &model.hull_hierarchy.nodes[0].hull;
      continue;
    }
    std::optional<ConvexHull> hull = ConvexMeshHull(model, 1e-6);
    if (!hull) continue;
    whole_hulls[i] = std::move(*hull);
    root_hulls[i] = &whole_hulls[i];
    whole_triangles[i].resize(model.triangles.size());
    for (std::size_t t = 0; t < model.triangles.size(); ++t)
      whole_triangles[i][t] = static_cast<int>(t);
  }
  // The coarse query's bounds (their root spheres are the broad phase's).
  tool_bounds = HullBounds::Of(*scene.tool);
  object_bounds.reserve(scene.touchables.size());
  for (const TouchableObject& t : scene.touchables)
    object_bounds.push_back(HullBounds::Of(*t.model));
  // The texture stage's box trees (null for models the scan costs less on).
  tool_tree = TriangleBoxTree::ForModel(*scene.tool);
  object_trees.reserve(scene.touchables.size());
  for (const TouchableObject& t : scene.touchables) {
    object_trees.push_back(TriangleBoxTree::ForModel(*t.model));
  }
}

RemoteStepData::RemoteStepData(const HapticScene& scene, const PipelineOptions& options,
                               int kept_field_resolution)
    :  // Stage 5b's buffers (about 10 MB at 8192 triangles) only where it runs.
      refiner(options.depth_refinement, options.refine_depth ? 8192 : 0) {
  for (std::size_t k = 0; k < field_pool.size(); ++k) field_pool_fields[k] = &field_pool[k];
  // Stage 5c renders whole windows, up to the largest.
  region_solver = std::make_unique<TexturePenetrationSolver>(
      std::max({128, options.grid_resolution, options.max_window_resolution()}), 4096,
      TextureStagePath::kFast);
  sharing_occupancy.assign(
      static_cast<std::size_t>(kMaxContacts) * kMaxSharingBlocks * kMaxSharingBlocks, 0);
  reachable_pairs.resize(static_cast<std::size_t>(clusterer.max_pairs()));
  pair_bounds.resize(static_cast<std::size_t>(clusterer.max_pairs()));
  candidate_triangles.resize(static_cast<std::size_t>(2 * clusterer.max_triangles()));
  free_space_gaps.assign(scene.touchables.size(), 0.0);
  queries.reserve(scene.touchables.size());
  for (std::size_t i = 0; i < scene.touchables.size(); ++i) {
    queries.emplace_back();
    // The coarse query's traversal on the texture stage's threads too (the same pairs).
    queries.back().SetThreads(options.texture_threads);
  }
  if (options.depth_fields) {
    for (DepthField& f : field_pool) {
      f.Reserve();
      // Prepare's scratch, which the operator's copies never need.
      f.row_coefficients_m.reserve(4 * static_cast<std::size_t>(kMaxDepthFieldSide) *
                                   kMaxDepthFieldSide);
    }
  }
  // Stage 5a's copies of the kept contacts' fields, whatever the backend (a GPU backend that
  // falls back to the CPU keeps fields from then on).
  {
    const auto r = static_cast<std::size_t>(kept_field_resolution);
    base_field_store.resize(kMaxContacts * r * r);
  }
}

}  // namespace ht
