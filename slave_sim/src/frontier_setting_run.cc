// The speed-vs-error frontier's timed steps of one setting on one scene (frontier_records.h),
// and the poses of its model-prediction measure.

#include <algorithm>
#include <limits>
#include <sstream>

#include "frontier_records.h"
#include "haptic_core/accuracy/mesh_contact_baseline.h"
#include "haptic_core/depth_field.h"
#include "haptic_core/gpu_penetration_depth.h"
#include "haptic_core/remote_step.h"
#include "slave_sim/benchmark_scenes.h"
#include "slave_sim/frontier.h"

namespace ht::frontier {

// Key of a ground-truth window: the pose, the tool's frame, and the window's geometry, bit for
// bit (windows of settings that differ only in grid or backend are one job).
std::string GtKey(int pose, const RigidTransform& X_TFt, const ContactWindow& w, double k) {
  std::ostringstream s;
  s.precision(17);
  s << pose << '|' << X_TFt.translation.x << ',' << X_TFt.translation.y << ','
    << X_TFt.translation.z << '|' << w.center_W.x << ',' << w.center_W.y << ',' << w.center_W.z
    << '|' << w.normal_W.x << ',' << w.normal_W.y << ',' << w.normal_W.z << '|' << w.axis_u_W.x
    << ',' << w.axis_u_W.y << ',' << w.axis_u_W.z << '|' << w.extent_m << '|' << k;
  return s.str();
}

// The displacements of the model-prediction measure: ±a about W's x and y and ±d along them
// (FrontierOptions::prediction_rotation_rad, prediction_translation_m: 1 mrad and 0.1 mm by
// default), about the tool's centre of mass (a tilt of a resting face either way, a slide).
std::vector<Twist> PredictionDisplacements(const FrontierOptions& options) {
  const double a = options.prediction_rotation_rad, d = options.prediction_translation_m;
  std::vector<Twist> out = {Twist{{0, 0, 0}, {a, 0, 0}}, Twist{{0, 0, 0}, {-a, 0, 0}},
                            Twist{{0, 0, 0}, {0, a, 0}}, Twist{{0, 0, 0}, {0, -a, 0}},
                            Twist{{d, 0, 0}, {0, 0, 0}}, Twist{{-d, 0, 0}, {0, 0, 0}},
                            Twist{{0, d, 0}, {0, 0, 0}}, Twist{{0, -d, 0}, {0, 0, 0}}};
  // FrontierOptions::prediction_yaw_rad: a turn about W's z (the seed's Fig. 76 turns so).
  if (options.prediction_yaw_rad > 0.0) {
    out.push_back(Twist{{0, 0, 0}, {0, 0, options.prediction_yaw_rad}});
    out.push_back(Twist{{0, 0, 0}, {0, 0, -options.prediction_yaw_rad}});
  }
  return out;
}

// Every how many poses the prediction measure samples (about 20 poses, 8 displacements each).
std::size_t PredictionStride(std::size_t poses) { return std::max<std::size_t>(1, poses / 20); }

// The displaced tool-mesh poses X_WFt of the prediction measure: each sampled pose's tool (frame
// T, X_TFt from the mesh frame) displaced by each of PredictionDisplacements().
std::vector<RigidTransform> PredictionPoses(const std::vector<RigidTransform>& poses_WFt,
                                            const RigidTransform& X_TFt,
                                            const FrontierOptions& options) {
  std::vector<RigidTransform> out;
  const RigidTransform X_FtT = X_TFt.Inverse();
  for (std::size_t k = 0; k < poses_WFt.size(); k += PredictionStride(poses_WFt.size())) {
    for (const Twist& d : PredictionDisplacements(options)) {
      out.push_back(Displace(poses_WFt[k] * X_FtT, d) * X_TFt);
    }
  }
  return out;
}

// Runs the timed steps of one setting on one scene (single thread).
void RunSetting(const BenchmarkScene& scene, const std::vector<RigidTransform>& poses_WFt,
                const MeshContactBaseline& fcl, bool consecutive, int switch_lag,
                const FrontierOptions& frontier_options, SettingRun& run) {
  const FrontierSetting& st = run.setting;
  run.X_TFt = scene.X_TFt;
  run.tool_coarse_triangles = scene.tool_coarse_triangles;
  run.object_coarse_triangles = scene.object_coarse_triangles;
  const RigidTransform X_FtT = scene.X_TFt.Inverse();
  const TouchableObject& object = scene.haptic.touchables.at(0);
  if (st.method == FrontierMethod::kFullResolutionFcl) {
    run.renderer = "FCL 0.7 (BVH OBBRSS), full-resolution meshes";
    for (const RigidTransform& X_WFt : poses_WFt) {
      const RigidTransform X_WT = X_WFt * X_FtT;
      const MeshContactResult r =
          fcl.Query(X_WFt, object.X_WO, object.stiffness_n_per_m, X_WT.translation);
      PoseRecord p;
      p.timings.collision_us = p.timings.total_us = r.query_us;
      p.timings.leaf_pairs = r.contacts;
      p.F = r.F_T_W;
      p.contacts = r.contacts;
      run.poses.push_back(p);
    }
    return;
  }
  // Sized for the largest window of the setting (windows sized from their clusters keep the cell).
  const int max_resolution =
      std::max(128, WindowResolution(PipelineOptions{}.max_window_extent_m,
                                     PipelineOptions{}.window_extent_m, st.grid));
  std::unique_ptr<PenetrationDepthBackend> backend;
  if (st.backend == "gpu") {
    GpuPenetrationDepthOptions gpu;
    gpu.depth_bits = st.depth_bits;
    gpu.max_resolution = max_resolution;
    try {
      auto g = GpuPenetrationDepthBackend::Create(gpu);
      backend = std::move(g);
    } catch (const std::exception& e) {
      run.skipped = std::string("GPU did not start: ") + e.what();
      return;
    }
  } else {
    backend = std::make_unique<CpuPenetrationDepthBackend>(max_resolution, st.texture_path,
                                                           st.texture_threads);
  }
  run.renderer = backend->description();
  const PipelineOptions options = PipelineOptionsFor(st);
  HapticTexturePipeline pipeline(scene.haptic, options, std::move(backend));
  StepTimings timings;
  for (int i = 0; i < 3 && !poses_WFt.empty(); ++i) {  // warm-up: scratch growth, GPU uploads
    pipeline.Step(poses_WFt.front() * X_FtT, 0, timings);
  }
  std::vector<ContactModel> models;
  models.reserve(poses_WFt.size());
  // Depth fields: each model's fields in a cache as the operator keeps them, and the fields of the
  // poses the prediction measure samples, kept for it.
  const std::size_t stride = PredictionStride(poses_WFt.size());
  DepthFieldCache field_cache(options.depth_fields ? kMaxContacts : 1);
  std::vector<std::vector<DepthField>> kept_fields(options.depth_fields ? poses_WFt.size() : 0);
  const auto take_fields = [&field_cache](std::vector<DepthField> fields) {
    for (DepthField& f : fields) field_cache.Take(f, {});
  };
  for (std::size_t k = 0; k < poses_WFt.size(); ++k) {
    // A spread pose does not follow the last: its contacts start from their own grid alone.
    if (k == 0 || !consecutive) pipeline.ForgetLastStep();
    const ContactModel model = pipeline.Step(poses_WFt[k] * X_FtT, k, timings);
    models.push_back(model);
    PoseRecord p;
    p.timings = timings;
    p.F = model.F_T_W_at_q0;
    if (options.depth_fields) {
      std::vector<DepthField> fields;
      for (const DepthField* f : pipeline.last_depth_fields()) fields.push_back(*f);
      take_fields(fields);
      p.F = EvaluateContactModel(model, poses_WFt[k] * X_FtT, 1.0,
                                 std::numeric_limits<double>::infinity(), &field_cache)
                .F_T_W;
      if (k % stride == 0) kept_fields[k] = std::move(fields);
    }
    for (int c = 0; c < model.num_contacts; ++c) p.contacts += model.contacts[c].depth_m > 0.0;
    run.poses.push_back(p);
    const auto queries = pipeline.last_contact_queries();
    const auto lins = pipeline.last_linearizations();
    for (std::size_t c = 0; c < queries.size(); ++c) {
      ContactRecord r;
      r.pose = static_cast<int>(k);
      r.index = static_cast<int>(c);
      r.query = queries[c];
      r.lin = lins[c];
      run.contacts.push_back(r);
    }
  }
  if (pipeline.backend_failures() > 0) {
    run.note += (run.note.empty() ? "" : "; ") +
                ("backend failed, CPU used: " + pipeline.fallback_reason());
    run.renderer = pipeline.backend().description();
  }
  // The model's prediction, after the timed steps: each sampled pose's model at its displaced
  // poses (PredictionPoses' order), compared with the pipeline truth there in ComputeMetrics.
  for (std::size_t k = 0; k < poses_WFt.size(); k += stride) {
    const RigidTransform X_WT = poses_WFt[k] * X_FtT;
    if (options.depth_fields) take_fields(kept_fields[k]);
    for (const Twist& d : PredictionDisplacements(frontier_options)) {
      run.predicted.push_back(EvaluateContactModel(models[k], Displace(X_WT, d), 1.0,
                                                   std::numeric_limits<double>::infinity(),
                                                   options.depth_fields ? &field_cache : nullptr)
                                  .F_T_W);
    }
  }
  // Model switches along consecutive poses: the model of switch_lag poses earlier at this pose
  // against this pose's own.
  if (switch_lag > 0 && poses_WFt.size() > static_cast<std::size_t>(switch_lag)) {
    std::vector<double> jumps;
    for (std::size_t k = static_cast<std::size_t>(switch_lag); k < poses_WFt.size(); ++k) {
      const RigidTransform X_WT = poses_WFt[k] * X_FtT;
      const Wrench held =
          EvaluateContactModel(models[k - static_cast<std::size_t>(switch_lag)], X_WT).F_T_W;
      jumps.push_back(glm::length(held.force - models[k].F_T_W_at_q0.force));
    }
    run.m.switch_jump_p50_n = Percentile(jumps, 0.5);
    run.m.switch_jump_p99_n = Percentile(jumps, 0.99);
    run.m.switch_jump_max_n = *std::max_element(jumps.begin(), jumps.end());
    run.m.switch_jumps_over_0_2_n = static_cast<int>(
        std::count_if(jumps.begin(), jumps.end(), [](double j) { return j > 0.2; }));
  }
}

}  // namespace ht::frontier
