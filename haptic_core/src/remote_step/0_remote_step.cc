// The remote step (remote_step.h) as its list of stages; each stage's work is in the file named
// after it, numbered in stage order (1_broad_phase ... 6_contact_assembly); the options' checks
// are in 0_pipeline_options.cc.

#include <algorithm>
#include <chrono>
#include <cmath>
#include <glm/geometric.hpp>
#include <glm/trigonometric.hpp>
#include <limits>
#include <optional>
#include <stdexcept>
#include <string>
#include <thread>

#include "0_remote_step_data.h"
#include "haptic_core/broad_phase.h"
#include "haptic_core/connected_contacts.h"
#include "haptic_core/contact_assembly.h"
#include "haptic_core/contact_region.h"
#include "haptic_core/remote_step.h"

namespace ht {

HapticTexturePipeline::HapticTexturePipeline(const HapticScene& scene,
                                             const PipelineOptions& options,
                                             std::unique_ptr<PenetrationDepthBackend> backend)
    : scene_(scene), options_(options), backend_(std::move(backend)) {
  options_.Validate();
  if (!scene.tool) throw std::invalid_argument("scene '" + scene.name + "' has no tool");
  if (glm::length(scene.tool->center_of_mass_O) > 1e-9) {
    throw std::invalid_argument("tool model '" + scene.tool->name +
                                "' must have its centre of mass at its frame origin");
  }
  for (const auto& t : scene.touchables) {
    if (!t.model) throw std::invalid_argument("scene '" + scene.name + "' has an empty touchable");
  }
  model_ = std::make_unique<const RemoteStepModel>(scene);
  data_ = std::make_unique<RemoteStepData>(scene, options_, KeptFieldResolution());
  if (!backend_) backend_ = MakeCpuBackend();
  // What the backend keeps per model (the GPU's uploads) for this scene's models, now.
  backend_->UseScene(scene);
  // Stages 5a and 5c read stage 5's base render instead of rendering the base pose again.
  if (ReusesBaseRender()) backend_->set_keep_base_overlap(KeptFieldResolution());
  // What a failing GPU backend falls back on, ready before the first step (LinearizeContacts).
  if (backend_->name() != "cpu") {
    cpu_fallback_ = MakeCpuBackend();
    cpu_fallback_->set_keep_base_overlap(KeptFieldResolution());
  }
  fallback_reason_.reserve(kMaxFallbackReason);
}

HapticTexturePipeline::~HapticTexturePipeline() = default;
HapticTexturePipeline::HapticTexturePipeline(HapticTexturePipeline&&) noexcept = default;

ContactModel HapticTexturePipeline::Step(const RigidTransform& X_WT, std::uint64_t seq,
                                         StepTimings& timings, const Twist& V_WT_W) noexcept {
  RemoteStepData& d = *data_;
  using Clock = std::chrono::steady_clock;
  const auto us = [](Clock::duration elapsed) {
    return std::chrono::duration<double, std::micro>(elapsed).count();
  };
  const auto t0 = Clock::now();
  ContactModel model;
  model.X_WT0 = X_WT;
  model.tool_state_seq = seq;
  timings = {};
  d.last_num_queries = 0;
  if (!IsFiniteRigidTransform(X_WT)) return model;

  // Stages 1–3: broad phase, hull proximity, contact clustering.
  FindContactCandidates(X_WT, V_WT_W, timings);
  const auto t1 = Clock::now();
  // Stage 4: one window per cluster. The batch lives in the data block, so that
  // last_contact_queries() can show it after the step.
  d.last_num_queries =
      MakeContactQueries({d.candidates.data(), static_cast<std::size_t>(d.num_candidates)},
                         options_.window_extent_m, options_.max_window_extent_m,
                         options_.grid_resolution, d.last_queries, d.step_faults.bad_windows);
  // The step from kept fields: the last full step's contacts, each linearized from its field at
  // this pose, while their fields hold them (no render); else stages 5–5d.
  if (options_.depth_fields && TakeStepFromKeptFields(X_WT, options_, d)) {
    ++d.step_faults.steps_from_kept_fields;
  } else {
    RunTextureStages(X_WT);
  }
  // Stage 6: the contact model.
  AssembleContactModel(last_linearizations(), model);
  const auto t2 = Clock::now();
  timings.collision_us = us(t1 - t0);
  timings.texture_us = us(t2 - t1);
  timings.total_us = us(t2 - t0);
  return model;
}

void HapticTexturePipeline::RunTextureStages(const RigidTransform& X_WT) noexcept {
  RemoteStepData& d = *data_;
  std::copy_n(d.last_queries.begin(), d.last_num_queries, d.full_stage4_queries.begin());
  d.full_stage4_count = d.last_num_queries;
  // Stage 5: texture penetration depth and its gradient, linearized, for the whole batch.
  LinearizeContacts(X_WT, d.last_num_queries);
  for (int i = 0; i < d.last_num_queries; ++i) {
    d.base_fields[static_cast<std::size_t>(i)] =
        ReusesBaseRender() ? backend_->base_overlap(static_cast<std::size_t>(i))
                           : std::span<const float>{};
  }
  // Stage 5a: a window whose overlap is in separated regions becomes one window per region.
  d.last_num_queries = SplitSeparatedOverlap(X_WT, d.last_num_queries);
  // Stage 5a's weights (its birth ramp and bridge fade): a region other than its window's
  // deepest fades in with its overlap and out as it joins a deeper one.
  for (int k = 0; k < d.split_count; ++k) {
    d.last_results[static_cast<std::size_t>(d.split_first + k)].stiffness_n_per_m *=
        d.split_weights[static_cast<std::size_t>(k)];
  }
  // Stage 5b: δ refined to the finest texture level. Not with depth fields: stage 5d gives each
  // contact its field's δ and ∇δ.
  if (options_.refine_depth && !options_.depth_fields) {
    d.refiner.BeginStep();
    for (int i = 0; i < d.last_num_queries; ++i) {
      d.refiner.Refine(*scene_.tool, X_WT, d.last_queries[i],
                       {d.last_samples.data() + static_cast<std::size_t>(i) * kGradientSamples,
                        static_cast<std::size_t>(kGradientSamples)},
                       d.last_results[i]);
    }
  }
  // A face resting on ridges: the bearing edge's slope instead of the secant across the V.
  for (int i = 0; i < d.last_num_queries; ++i) {
    UseBearingEdgeRotationSlope(
        d.last_queries[i].window,
        {d.last_samples.data() + static_cast<std::size_t>(i) * kGradientSamples,
         static_cast<std::size_t>(kGradientSamples)},
        X_WT.translation, d.last_results[i]);
  }
  // The grazing guard: a δ its coarse geometry cannot hold is the sideways overlap along a
  // grazing direction, not a penetration; the contact is left out of the model (its linearization
  // reads −∞, as a contact whose patches do not overlap).
  d.step_faults.grazing_dropped +=
      DropGrazingContacts({d.last_queries.data(), static_cast<std::size_t>(d.last_num_queries)},
                          {d.last_results.data(), static_cast<std::size_t>(d.last_num_queries)});
  // Stage 5c: contacts whose overlaps are one region share one penalty.
  ShareConnectedContacts(X_WT, d.last_num_queries);
  // Stage 5d: each contact's depth field, the two surfaces over its window and travel margin.
  // Each contact that has a field is linearized from it: the tangent of the depth the operator's
  // loop evaluates.
  if (options_.depth_fields) {
    RenderContactDepthFields(*scene_.tool, X_WT, options_, d);
    LinearizeFromDepthFields(X_WT, d);
    RecordFullStep(d);
  } else {
    d.num_fields = 0;
    d.full_valid = false;
  }
}

void HapticTexturePipeline::FindContactCandidates(const RigidTransform& X_WT, const Twist& V_WT_W,
                                                  StepTimings& timings) noexcept {
  RemoteStepData& d = *data_;
  const RemoteStepModel& m = *model_;
  d.num_candidates = 0;
  std::size_t triangles_used = 0;
  // A copy of a cluster's list into d.candidate_triangles, or All() where the side has no list
  // (no hierarchy) or it does not fit.
  // A cluster's triangles as a candidate's subset, with its model's box tree (for All()).
  const auto keep_list = [&](std::span<const int> list, bool whole_model,
                             const TriangleBoxTree* tree) {
    TriangleSubset subset = TriangleSubset::All();
    if (!whole_model) {
      if (list.size() > d.candidate_triangles.size() - triangles_used) {
        ++d.step_faults.triangle_lists_overflowed;
      } else {
        int* first = d.candidate_triangles.data() + triangles_used;
        std::copy(list.begin(), list.end(), first);
        triangles_used += list.size();
        subset = TriangleSubset::Of({first, list.size()});
      }
    }
    subset.tree = tree;
    return subset;
  };
  const HapticModel& tool = *scene_.tool;
  // Speculative contacts (PipelineOptions::speculative_lead_s): the most any tool point can close
  // within the lead time widens the coarse query; each separated pair is then judged by its own
  // closing speed.
  const bool speculate = options_.speculative_lead_s > 0.0 &&
                         options_.max_speculative_margin_m > 0.0 && IsFinite(V_WT_W) &&
                         (V_WT_W.linear != glm::dvec3(0.0) || V_WT_W.angular != glm::dvec3(0.0));
  const double floor_m = options_.speculative_floor_m;
  // The broad phase's spheres: the coarse bounds' roots (tool in T, each object in its O).
  const glm::dvec4& tool_sphere_O = m.tool_bounds.spheres_O[0];
  const double speculative_bound = std::max(
      floor_m,
      !speculate ? 0.0
                 : std::min(options_.max_speculative_margin_m,
                            options_.speculative_lead_s *
                                (glm::length(V_WT_W.linear) +
                                 glm::length(V_WT_W.angular) *
                                     (glm::length(glm::dvec3(tool_sphere_O)) + tool_sphere_O.w))));
  // A separated pair's margin beyond its reach: the lead's at its closing speed, at least
  // `object_floor_m` (the floor, for an object the tool touches nowhere; 0 beside a touching
  // pair, where a separated one would only join its cluster and widen its window).
  const auto speculative_margin = [&](const HullPairContact& p, double object_floor_m) {
    if (!speculate) return object_floor_m;
    const glm::dvec3 v_A =
        V_WT_W.linear + glm::cross(V_WT_W.angular, p.point_A_W - X_WT.translation);
    const double closing = -glm::dot(v_A, p.normal_W);
    return std::max(object_floor_m, closing > 0.0 ? std::min(options_.max_speculative_margin_m,
                                                             options_.speculative_lead_s * closing)
                                                  : 0.0);
  };
  // Free space (StepTimings::free_space_clearance_m): the tolerance a later step could use at most.
  const double most_speculative = std::max(
      floor_m,
      options_.speculative_lead_s > 0.0 ? std::max(0.0, options_.max_speculative_margin_m) : 0.0);
  // What a model pair's separation leaves of free space: less its reaches and the tolerance.
  const auto free_space = [&](double separation_m, const HapticModel& object_model) {
    return separation_m - (tool.OutwardReach() + object_model.OutwardReach() +
                           options_.proximity_margin_m + most_speculative);
  };
  double clearance = std::numeric_limits<double>::infinity();
  bool any_passed = false;
  int num_floor_candidates = 0;
  std::fill(d.free_space_gaps.begin(), d.free_space_gaps.end(),
            std::numeric_limits<double>::quiet_NaN());
  for (std::size_t k = 0; k < scene_.touchables.size(); ++k) {
    const TouchableObject& object = scene_.touchables[k];
    const double reach = tool.OutwardReach() + object.model->OutwardReach();
    ProximityQueryOptions query;
    query.tolerance_m = reach + options_.proximity_margin_m + speculative_bound;
    // 1. Broad phase: bounding spheres in W (the objects may move between steps).
    const double gap =
        BoundingSphereGap(tool_sphere_O, X_WT, m.object_bounds[k].spheres_O[0], object.X_WO);
    if (gap > query.tolerance_m) {
      ++timings.broad_phase_culled;
      clearance = std::min(clearance, free_space(gap, *object.model));
      continue;
    }
    // 2. Hull proximity: leaf hull pairs within the tolerance.
    query.time_budget_us = options_.collision_budget_us;
    ProximityQueryStats stats;
    std::span<const HullPairContact> pairs = d.queries[k].Query(
        tool, m.tool_bounds, X_WT, *object.model, m.object_bounds[k], object.X_WO, query, &stats);
    if (pairs.empty() && !stats.budget_exhausted && stats.invalid_input == 0) {
      // Nothing within the tolerance: its free space is taken after the loop, and only when no
      // object had a pair (the clearance is 0 otherwise; the hull bound is not free).
      d.free_space_gaps[k] = gap;
    } else {
      any_passed = true;
    }
    ++timings.convex_pairs;
    timings.leaf_pairs += static_cast<int>(pairs.size());
    timings.collision_budget_exhausted |= stats.budget_exhausted;
    // Each pair's two leaves' own texture reach, once, for two uses: a separated pair
    // beyond it cannot touch through the textures and starts no cluster (it would only add a
    // window with no overlap); and the grazing guard's bound of a pair is its hull penetration
    // plus that reach plus a cell (a cluster takes its members' largest).
    const double cell = options_.window_extent_m / options_.grid_resolution;
    // The floor for this object's separated pairs: PipelineOptions::speculative_floor_m where the
    // tool touches it nowhere (no pair within its textures' reach), else 0.
    const bool touching =
        floor_m > 0.0 && std::any_of(pairs.begin(), pairs.end(), [&](const HullPairContact& p) {
          return p.signed_distance_m <=
                 m.tool_bounds.Reach(p.node_A) + m.object_bounds[k].Reach(p.node_B);
        });
    const double object_floor_m = touching ? 0.0 : floor_m;
    std::size_t kept = 0;
    for (const HullPairContact& p : pairs) {
      if (kept == d.reachable_pairs.size()) break;
      const double pair_reach = m.tool_bounds.Reach(p.node_A) + m.object_bounds[k].Reach(p.node_B);
      if (p.signed_distance_m > pair_reach) {
        if (p.signed_distance_m > pair_reach + speculative_margin(p, object_floor_m)) {
          ++d.step_faults.unreachable_pairs;
          continue;
        }
        ++d.step_faults.speculative_pairs;
      }
      d.pair_bounds[kept] = std::max(0.0, -p.signed_distance_m) + pair_reach + cell;
      d.reachable_pairs[kept++] = p;
    }
    pairs = {d.reachable_pairs.data(), kept};
    const std::span<const double> pair_bounds(d.pair_bounds.data(), kept);
    if (pairs.empty()) continue;
    // 3. Contact clustering: one window per cluster, sized from its members' spread between the
    // pipeline's smallest and largest window; clusters whose windows would overlap merge while
    // the merged window fits, so that a texture region is rarely rendered in two windows.
    ClusteringOptions clustering;
    clustering.merge_distance_m = options_.clustering_distance_m;
    clustering.max_normal_angle_deg = kClusteringAngleDeg;
    clustering.texture_margin_m = reach;
    clustering.min_extent_m = options_.window_extent_m;
    clustering.max_extent_m = options_.max_window_extent_m;
    clustering.max_contacts = options_.max_contacts;
    clustering.share_leaves_between_disjoint_windows = true;
    const std::span<const ContactCluster> clusters = d.clusterer.Cluster(
        pairs, tool.hull_hierarchy, object.model->hull_hierarchy, clustering, pair_bounds);
    timings.clusters += static_cast<int>(clusters.size());
    // An object kept by the floor alone waits until every touching object has its candidates.
    const bool floor_only = object_floor_m > 0.0;
    for (const ContactCluster& c : clusters) {
      if (floor_only ? num_floor_candidates < options_.max_contacts
                     : d.num_candidates < options_.max_contacts) {
        const glm::dvec3 normal_W = c.normal_W;
        const double bound = std::isfinite(c.depth_bound_m)
                                 ? c.depth_bound_m
                                 : std::max(0.0, -c.min_signed_distance_m) + reach + cell;
        double extent = c.extent_m;
        glm::dvec3 point_W = c.point_W;
        if (c.tool_whole_model && c.object_whole_model && c.num_pairs == 1) {
          RegionWindow(X_WT, k, normal_W, reach, point_W, extent);
        }
        const ContactCandidate candidate{
            &object,
            point_W,
            normal_W,
            extent,
            bound,
            keep_list(c.object_triangles, c.object_whole_model, m.object_trees[k].get()),
            keep_list(c.tool_triangles, c.tool_whole_model, m.tool_tree.get())};
        if (floor_only) {
          d.floor_candidates[static_cast<std::size_t>(num_floor_candidates++)] = candidate;
        } else {
          d.candidates[static_cast<std::size_t>(d.num_candidates++)] = candidate;
        }
      }
    }
  }
  for (int i = 0; i < num_floor_candidates && d.num_candidates < options_.max_contacts; ++i) {
    d.candidates[static_cast<std::size_t>(d.num_candidates++)] =
        d.floor_candidates[static_cast<std::size_t>(i)];
  }
  if (!any_passed) {
    // Every object culled or without a pair: each of the latter's free space is its whole hulls'
    // separation (or the spheres' gap, whichever bound is larger) beyond the largest tolerance.
    for (std::size_t k = 0; k < scene_.touchables.size(); ++k) {
      if (std::isnan(d.free_space_gaps[k])) continue;
      const TouchableObject& object = scene_.touchables[k];
      double separation = d.free_space_gaps[k];
      if (m.root_hulls[0] != nullptr && m.root_hulls[k + 1] != nullptr) {
        separation = std::max(separation, HullSeparationBound(*m.root_hulls[0], X_WT,
                                                              *m.root_hulls[k + 1], object.X_WO));
      }
      clearance = std::min(clearance, free_space(separation, *object.model));
    }
  }
  timings.free_space_clearance_m = any_passed ? 0.0 : std::max(0.0, clearance);
}

double HapticTexturePipeline::ToolMotionBound(const RigidTransform& X_WT_a,
                                              const RigidTransform& X_WT_b) const noexcept {
  const RemoteStepModel& m = *model_;
  if (!IsFiniteRigidTransform(X_WT_a) || !IsFiniteRigidTransform(X_WT_b)) {
    return std::numeric_limits<double>::infinity();
  }
  const glm::dvec3 c_O(m.tool_bounds.spheres_O[0]);
  const double moved = glm::length(X_WT_b * c_O - X_WT_a * c_O);
  // ‖(R_b − R_a)·u‖ = 2·sin(θ/2)·|u| = 2·|vec(q_a⁻¹·q_b)|·|u| for unit quaternions.
  const glm::dquat q = glm::inverse(X_WT_a.rotation) * X_WT_b.rotation;
  const double turned =
      2.0 * glm::length(glm::dvec3(q.x, q.y, q.z)) / std::max(1e-300, glm::length(q));
  return moved + turned * m.tool_bounds.spheres_O[0].w;
}

void HapticTexturePipeline::RegionWindow(const RigidTransform& X_WT, std::size_t k,
                                         const glm::dvec3& normal_W, double texture_margin_m,
                                         glm::dvec3& point_W, double& extent_m) noexcept {
  RemoteStepData& d = *data_;
  const RemoteStepModel& m = *model_;
  const ConvexHull& hull_A = m.whole_hulls[0];
  const ConvexHull& hull_B = m.whole_hulls[k + 1];
  if (hull_A.planes_O.empty() || hull_B.planes_O.empty()) return;
  const std::optional<ContactWindow> axes =
      ContactWindow::TryMake(point_W, normal_W, options_.window_extent_m, 2);
  if (!axes) return;
  const TouchableObject& object = scene_.touchables[k];
  const double pair_reach = m.tool_bounds.Reach(-1) + m.object_bounds[k].Reach(-1);
  RegionBounds b;
  if (!PairRegionBounds(*scene_.tool, X_WT, hull_A, m.whole_triangles[0], *object.model,
                        object.X_WO, hull_B, m.whole_triangles[k + 1], pair_reach, point_W,
                        axes->axis_u_W, axes->axis_v_W, b)) {
    return;
  }
  point_W +=
      0.5 * (b.min_u + b.max_u) * axes->axis_u_W + 0.5 * (b.min_v + b.max_v) * axes->axis_v_W;
  extent_m = std::max(b.max_u - b.min_u, b.max_v - b.min_v) + 2.0 * texture_margin_m;
  ++d.step_faults.region_windows;
}

std::unique_ptr<PenetrationDepthBackend> HapticTexturePipeline::MakeCpuBackend() const {
  return std::make_unique<CpuPenetrationDepthBackend>(
      options_.max_window_resolution(), TextureStagePath::kFast, options_.texture_threads);
}

void HapticTexturePipeline::LinearizeContacts(const RigidTransform& X_WT, int n) noexcept {
  RemoteStepData& d = *data_;
  if (n == 0) return;
  const HapticModel& tool = *scene_.tool;
  const std::span<const ContactQuery> batch(d.last_queries.data(), static_cast<std::size_t>(n));
  const std::span<ContactLinearization> batch_out(d.last_results.data(),
                                                  static_cast<std::size_t>(n));
  const std::size_t per = kGradientSamples;
  const std::span<DepthSample> samples_out(d.last_samples.data(),
                                           static_cast<std::size_t>(n) * per);
  // The GPU backend encodes one window extent and grid per batch: with windows sized from their
  // clusters, one batch per size (the CPU backend takes them mixed).
  bool mixed = false;
  for (int i = 1; i < n; ++i) {
    mixed = mixed || d.last_queries[i].window.resolution != d.last_queries[0].window.resolution ||
            d.last_queries[i].window.extent_m != d.last_queries[0].window.extent_m;
  }
  if (mixed && backend_->name() == "gpu") {
    bool ok = true;
    std::array<bool, kMaxContacts> done{};
    for (int first = 0; first < n && ok; ++first) {
      if (done[first]) continue;
      const ContactWindow& w = d.last_queries[first].window;
      int m = 0;
      for (int i = first; i < n; ++i) {
        if (done[i] || d.last_queries[i].window.resolution != w.resolution ||
            d.last_queries[i].window.extent_m != w.extent_m) {
          continue;
        }
        done[i] = true;
        d.size_index[m] = i;
        d.size_queries[m++] = d.last_queries[i];
      }
      const auto count = static_cast<std::size_t>(m);
      ok = backend_->LinearizeBatch(tool, X_WT, {d.size_queries.data(), count},
                                    {d.size_results.data(), count},
                                    {d.size_samples.data(), count * per});
      for (int k = 0; ok && k < m; ++k) {
        d.last_results[d.size_index[k]] = d.size_results[k];
        std::copy_n(d.size_samples.data() + static_cast<std::size_t>(k) * per, per,
                    d.last_samples.data() + static_cast<std::size_t>(d.size_index[k]) * per);
      }
    }
    if (ok) return;
  } else if (backend_->LinearizeBatch(tool, X_WT, batch, batch_out, samples_out)) {
    return;
  }
  // The GPU failed (context lost, GL error): this step and all later ones on the CPU.
  if (backend_failures_++ == 0) {
    // Within the reserved capacity: no allocation.
    const auto append = [this](std::string_view text) {
      fallback_reason_.append(text.substr(
          0, std::min(text.size(), fallback_reason_.capacity() - fallback_reason_.size())));
    };
    append(backend_->name());
    append(": ");
    append(backend_->last_error());
  }
  if (cpu_fallback_) backend_ = std::move(cpu_fallback_);
  backend_->LinearizeBatch(tool, X_WT, batch, batch_out, samples_out);
}

void HapticTexturePipeline::ShareConnectedContacts(const RigidTransform& X_WT, int n) noexcept {
  RemoteStepData& d = *data_;
  if (n < 2) return;
  ContactSharingOptions sharing;  // its link, fade and temperature at their defaults
  sharing.max_normal_angle_deg = kClusteringAngleDeg;
  d.step_faults.shared_contacts += ht::ShareConnectedContacts(
      *scene_.tool, X_WT, {d.last_queries.data(), static_cast<std::size_t>(n)},
      {d.last_results.data(), static_cast<std::size_t>(n)}, sharing, *d.region_solver,
      d.sharing_occupancy, std::span<const int>(d.split_family.data(), static_cast<std::size_t>(n)),
      std::span<const std::span<const float>>(d.base_fields.data(), static_cast<std::size_t>(n)));
}

int HapticTexturePipeline::KeptFieldResolution() const noexcept {
  return std::min(options_.max_window_resolution(), kMaxKeptFieldResolution);
}

bool HapticTexturePipeline::ReusesBaseRender() const noexcept { return backend_->name() == "cpu"; }

const HapticTexturePipeline::StepFaults& HapticTexturePipeline::step_faults() const noexcept {
  return data_->step_faults;
}

std::span<const ContactQuery> HapticTexturePipeline::last_contact_queries() const noexcept {
  return {data_->last_queries.data(), static_cast<std::size_t>(data_->last_num_queries)};
}

std::span<const ContactLinearization> HapticTexturePipeline::last_linearizations() const noexcept {
  return {data_->last_results.data(), static_cast<std::size_t>(data_->last_num_queries)};
}

std::span<const DepthField* const> HapticTexturePipeline::last_depth_fields() const noexcept {
  return {data_->fields.data(), static_cast<std::size_t>(data_->num_fields)};
}

std::span<const DepthField* const> HapticTexturePipeline::kept_depth_fields() const noexcept {
  return {data_->field_pool_fields.data(), data_->field_pool_fields.size()};
}

std::span<const DepthSample> HapticTexturePipeline::last_depth_samples() const noexcept {
  return {data_->last_samples.data(), static_cast<std::size_t>(data_->last_num_queries) *
                                          static_cast<std::size_t>(kGradientSamples)};
}

const DepthRefinementCounters& HapticTexturePipeline::depth_refinement_counters() const noexcept {
  return data_->refiner.counters();
}

void HapticTexturePipeline::SetDepthFields(bool on) {
  if (on && !options_.depth_fields) {
    for (DepthField& f : data_->field_pool) {
      f.Reserve();
      f.row_coefficients_m.reserve(4 * static_cast<std::size_t>(kMaxDepthFieldSide) *
                                   kMaxDepthFieldSide);
      f.prepared = false;  // none reused from before
    }
  }
  options_.depth_fields = on;
}

void HapticTexturePipeline::ForgetLastStep() noexcept {
  data_->refiner.ForgetLastStep();
  for (DepthField& f : data_->field_pool) f.prepared = false;  // none reused
  data_->full_valid = false;
}

}  // namespace ht
