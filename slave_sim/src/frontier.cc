#include "slave_sim/frontier.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <fstream>
#include <limits>
#include <memory>
#include <mutex>
#include <numbers>
#include <sstream>
#include <stdexcept>
#include <thread>

#include "codecs/glb_writer.h"
#include "haptic_core/accuracy/contact_patch_truth.h"
#include "haptic_core/accuracy/mesh_contact_baseline.h"
#include "haptic_core/gpu_penetration_depth.h"
#include "haptic_core/haptic_scene.h"
#include "haptic_core/model_build/surface_error.h"
#include "haptic_core/remote_step.h"
#include "slave_sim/benchmark_scenes.h"

namespace ht {

namespace {

using Clock = std::chrono::steady_clock;

double Seconds(Clock::time_point since) {
  return std::chrono::duration<double>(Clock::now() - since).count();
}

double Percentile(std::vector<double> v, double q) {
  if (v.empty()) return std::numeric_limits<double>::quiet_NaN();
  std::sort(v.begin(), v.end());
  const double pos = q * static_cast<double>(v.size() - 1);
  const auto i = static_cast<std::size_t>(pos);
  const double f = pos - static_cast<double>(i);
  return i + 1 < v.size() ? v[i] * (1.0 - f) + v[i + 1] * f : v[i];
}

// One ground-truth window: inputs and result.
struct GtJob {
  RigidTransform X_WT, X_TFt, X_WFe;
  ContactWindow window;
  double stiffness = 0.0;
  GroundTruthContact result;
};

// One contact (window) of a setting at a pose.
struct ContactRecord {
  int pose = 0;
  int index = 0;
  ContactQuery query;
  ContactLinearization lin;
  int gt = -1;  // into the scene's GtJob list
};

struct PoseRecord {
  StepTimings timings;
  Wrench F;          // the method's wrench on the tool at its centre of mass, in W
  int contacts = 0;  // contacts with δ > 0
};

struct Metrics {
  double collision_p50 = 0, collision_p95 = 0, texture_p50 = 0, texture_p95 = 0, total_p50 = 0,
         total_p95 = 0;
  double contacts_mean = 0, leaf_pairs_mean = 0;
  double force_rel_rms = 0, torque_rel_rms = 0;
  double force_rel_p50 = 0;  // median over poses of |F − F_gt| / |F_gt|
  double dir_p50_deg = 0, dir_p95_deg = 0;
  double delta_p50_um = 0, delta_p95_um = 0;
  int windows = 0, missed = 0, invented = 0, poses_missed = 0, poses_invented = 0;
  // Against the pipeline truth (contact_patch_truth.h, issue 31), which owns its contacts.
  double pipeline_force_rel_rms = 0, pipeline_torque_rel_rms = 0;
  double volume_dir_p50_deg = 0, volume_dir_p95_deg = 0, volume_arm_rel_p50 = 0;
  int poses_truth_without_force = 0, poses_force_without_truth = 0;
  // The contact model's prediction (issue 31, change 5): every PredictionStride()-th pose's model
  // evaluated at its displaced poses (PredictionDisplacements) against the pipeline truth there
  // (what the operator's loop renders between two models); relative RMS over those poses and
  // displacements. NaN for the baselines, which send no model.
  double prediction_force_rel_rms = std::numeric_limits<double>::quiet_NaN();
  double prediction_torque_rel_rms = std::numeric_limits<double>::quiet_NaN();
  // Model switches along consecutive trace rows (FrontierOptions::trace_from_s): |F| of the
  // jump the operator's loop meets when the model made switch_lag rows earlier, evaluated at this
  // row's pose, gives way to this row's model (N): p50, p99, max and how many exceed 0.2 N. NaN
  // (and 0) without consecutive poses.
  double switch_jump_p50_n = std::numeric_limits<double>::quiet_NaN();
  double switch_jump_p99_n = std::numeric_limits<double>::quiet_NaN();
  double switch_jump_max_n = std::numeric_limits<double>::quiet_NaN();
  int switch_jumps_over_0_2_n = 0;
  bool pareto = false;
};

struct SettingRun {
  FrontierSetting setting;
  std::string renderer;
  std::string skipped;  // why the setting did not run ("" when it did)
  std::string note;
  RigidTransform X_TFt;
  std::int64_t tool_coarse_triangles = 0, object_coarse_triangles = 0;
  /// How far the full-resolution surfaces lie from the models this setting built
  /// (MeasureSurfaceError; tool's mesh in T).
  SurfaceErrorReport tool_surface, object_surface;
  /// At the truth patches (with force) of the poses where this setting gives no force: the
  /// models' surface error within kLocalSurfaceRadiusM of each patch's centre, the p99 distance
  /// and the p99 outside (m), tool side and object side, one entry per patch.
  std::vector<double> local_tool_p99_m, local_object_p99_m, local_tool_outside_m,
      local_object_outside_m;
  std::vector<PoseRecord> poses;
  std::vector<ContactRecord> contacts;
  /// The contact models' wrenches at PredictionPoses() (empty for the baselines).
  std::vector<Wrench> predicted;
  Metrics m;
};

// Radius (m) of the neighbourhood of a truth patch whose surface error the summary reports for
// the poses a setting gives no force at.
constexpr double kLocalSurfaceRadiusM = 2e-3;

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

class PartialFile {
 public:
  explicit PartialFile(std::string path) : path_(std::move(path)), tmp_(path_ + ".partial") {
    out_.open(tmp_);
    if (!out_) throw std::runtime_error("cannot write " + tmp_);
  }
  std::ofstream& out() { return out_; }
  void Commit() {
    out_.flush();
    if (!out_) throw std::runtime_error("cannot write " + tmp_);
    out_.close();
    std::filesystem::rename(tmp_, path_);
  }
  ~PartialFile() {
    if (out_.is_open()) {
      out_.close();
      std::error_code ec;
      std::filesystem::remove(tmp_, ec);
    }
  }

 private:
  std::string path_, tmp_;
  std::ofstream out_;
};

double AngleDeg(const glm::dvec3& a, const glm::dvec3& b) {
  const double c = glm::dot(a, b) / (glm::length(a) * glm::length(b));
  return std::acos(std::clamp(c, -1.0, 1.0)) * 180.0 / std::numbers::pi;
}

std::string Fmt(double v, int precision = 4) {
  if (!std::isfinite(v)) return "nan";
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*g", precision, v);
  return buf;
}

std::string MachineLine() {
  std::string cpu = "unknown CPU";
  std::ifstream info("/proc/cpuinfo");
  for (std::string line; std::getline(info, line);) {
    if (line.rfind("model name", 0) == 0) {
      cpu = line.substr(line.find(':') + 2);
      break;
    }
  }
  return cpu + ", " + std::to_string(std::thread::hardware_concurrency()) + " hardware threads";
}

// Runs the timed steps of one setting on one scene (single thread).
double SquaredNorm(const glm::dvec3& v) { return glm::dot(v, v); }

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
  const int max_resolution = std::max(
      128, WindowResolution(st.max_window_extent_m > 0.0 ? st.max_window_extent_m
                                                         : PipelineOptions{}.max_window_extent_m,
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
    backend = std::make_unique<CpuPenetrationDepthBackend>(
        max_resolution, st.texture_path, st.texture_threads, st.rotation_gradient);
  }
  run.renderer = backend->description();
  const PipelineOptions options = PipelineOptionsFor(st);
  HapticTexturePipeline pipeline(scene.haptic, options, std::move(backend));
  StepTimings timings;
  for (int i = 0; i < 3 && !poses_WFt.empty(); ++i) {  // warm-up: caches, GPU uploads
    pipeline.Step(poses_WFt.front() * X_FtT, 0, timings);
  }
  std::vector<ContactModel> models;
  models.reserve(poses_WFt.size());
  for (std::size_t k = 0; k < poses_WFt.size(); ++k) {
    // A spread pose does not follow the last: its contacts start from their own grid alone.
    if (k == 0 || !consecutive) pipeline.ForgetLastStep();
    const ContactModel model = pipeline.Step(poses_WFt[k] * X_FtT, k, timings);
    models.push_back(model);
    PoseRecord p;
    p.timings = timings;
    p.F = model.F_T_W_at_q0;
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
  const std::size_t stride = PredictionStride(poses_WFt.size());
  for (std::size_t k = 0; k < poses_WFt.size(); k += stride) {
    const RigidTransform X_WT = poses_WFt[k] * X_FtT;
    for (const Twist& d : PredictionDisplacements(frontier_options)) {
      run.predicted.push_back(EvaluateContactModel(models[k], Displace(X_WT, d)).F_T_W);
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

// Computes every job's ground truth on `threads` threads, with progress.
void RunGroundTruth(const BenchmarkScene& scene, const RayCastSurface& tool,
                    const RayCastSurface& object, std::vector<GtJob>& jobs,
                    const FrontierOptions& options) {
  std::atomic<std::size_t> next{0}, finished{0};
  const auto t0 = Clock::now();
  const auto worker = [&](bool reporter) {
    GroundTruthDepthSolver solver(tool, object, options.ground_truth);
    double last_report = 0.0;
    for (std::size_t i; (i = next.fetch_add(1)) < jobs.size();) {
      GtJob& j = jobs[i];
      j.result = solver.Linearize(j.X_WT, j.X_TFt, j.X_WFe, j.window, j.stiffness);
      const std::size_t f = ++finished;
      if (reporter && options.progress && Seconds(t0) - last_report > 5.0) {
        last_report = Seconds(t0);
        const double left =
            last_report / static_cast<double>(f) * static_cast<double>(jobs.size() - f);
        std::fprintf(stderr, "[frontier] %s: ground truth %zu/%zu windows, about %.0f s left\n",
                     scene.name.c_str(), f, jobs.size(), left);
      }
    }
  };
  const int n = std::max(1, options.threads);
  std::vector<std::thread> pool;
  for (int t = 1; t < n; ++t) pool.emplace_back(worker, false);
  worker(true);
  for (std::thread& t : pool) t.join();
}

// The pipeline truth of every pose (ContactPatchTruth, one per thread), with progress.
void RunPipelineTruth(const BenchmarkScene& scene, const RayCastSurface& tool,
                      const RayCastSurface& object, const std::vector<RigidTransform>& poses_WFt,
                      const FrontierOptions& options, std::vector<PoseTruth>& out) {
  out.assign(poses_WFt.size(), PoseTruth{});
  const TouchableObject& target = scene.haptic.touchables.at(0);
  const RigidTransform X_FtT = scene.X_TFt.Inverse();
  ContactPatchTruthOptions truth_options;
  truth_options.depth = options.ground_truth;
  const PipelineOptions pipeline;  // the method's clustering distance
  truth_options.merge_distance_m = pipeline.clustering_distance_m;
  // The patches' normal angle stays ContactPatchTruthOptions' 30° (the method's clustering angle
  // until issue 32's thirty-third stop, 60° since): the measure does not move with the method.
  truth_options.share_fade_m = options.truth_share_fade_m;
  truth_options.tilt_lift_m = options.truth_tilt_lift_m;
  if (!options.truth_merge_patches) {
    truth_options.macro_normal_radius_m = 0.0;
    truth_options.depth_along_macro_normal = false;
    truth_options.overlap_merge_angle_deg = 0.0;
    truth_options.minor_patch_fraction = 0.0;
  }
  std::atomic<std::size_t> next{0}, finished{0};
  const auto t0 = Clock::now();
  std::exception_ptr failure;
  std::mutex failure_mutex;
  const auto worker = [&](bool reporter) {
    try {
      ContactPatchTruth truth(*scene.tool_mesh_Ft, *scene.object_mesh_Fe, tool, object,
                              truth_options);
      double last_report = 0.0;
      for (std::size_t i; (i = next.fetch_add(1)) < poses_WFt.size();) {
        out[i] = truth.At(poses_WFt[i] * X_FtT, scene.X_TFt, target.X_WO, target.stiffness_n_per_m);
        const std::size_t f = ++finished;
        if (reporter && options.progress && Seconds(t0) - last_report > 5.0) {
          last_report = Seconds(t0);
          const double left =
              last_report / static_cast<double>(f) * static_cast<double>(poses_WFt.size() - f);
          std::fprintf(stderr, "[frontier] %s: pipeline truth %zu/%zu poses, about %.0f s left\n",
                       scene.name.c_str(), f, poses_WFt.size(), left);
        }
      }
    } catch (...) {
      const std::lock_guard<std::mutex> lock(failure_mutex);
      if (!failure) failure = std::current_exception();
      next = poses_WFt.size();
    }
  };
  const int n = std::max(1, options.threads);
  std::vector<std::thread> pool;
  for (int t = 1; t < n; ++t) pool.emplace_back(worker, false);
  worker(true);
  for (std::thread& t : pool) t.join();
  if (failure) std::rethrow_exception(failure);
}

void ComputeMetrics(SettingRun& run, const std::vector<GtJob>& jobs,
                    const std::vector<Wrench>& reference_gt, const std::vector<bool>& touching,
                    const std::vector<PoseTruth>& pipeline) {
  Metrics& m = run.m;
  std::vector<double> coll, tex, tot, dir, derr, rel;
  double contacts = 0, leaf = 0;
  for (const PoseRecord& p : run.poses) {
    coll.push_back(p.timings.collision_us);
    tex.push_back(p.timings.texture_us);
    tot.push_back(p.timings.total_us);
    contacts += p.contacts;
    leaf += p.timings.leaf_pairs;
  }
  const double n = std::max<double>(1.0, static_cast<double>(run.poses.size()));
  m.collision_p50 = Percentile(coll, 0.5);
  m.collision_p95 = Percentile(coll, 0.95);
  m.texture_p50 = Percentile(tex, 0.5);
  m.texture_p95 = Percentile(tex, 0.95);
  m.total_p50 = Percentile(tot, 0.5);
  m.total_p95 = Percentile(tot, 0.95);
  m.contacts_mean = contacts / n;
  m.leaf_pairs_mean = leaf / n;
  // The truth per pose: the ground truth on this setting's own windows (the baselines, which
  // have none, against the default setting's).
  std::vector<Wrench> gt(run.poses.size());
  const bool own = run.setting.method == FrontierMethod::kTexture;
  if (own) {
    for (const ContactRecord& c : run.contacts) gt[c.pose] += jobs[c.gt].result.F_T_W;
  } else {
    gt = reference_gt;
  }
  double fe = 0, fg = 0, te = 0, tg = 0;
  for (std::size_t k = 0; k < run.poses.size(); ++k) {
    const Wrench& F = run.poses[k].F;
    const Wrench& G = gt[k];
    fe += glm::dot(F.force - G.force, F.force - G.force);
    fg += glm::dot(G.force, G.force);
    te += glm::dot(F.torque - G.torque, F.torque - G.torque);
    tg += glm::dot(G.torque, G.torque);
    if (glm::length(G.force) > 1e-9 && glm::length(F.force) > 1e-9) {
      dir.push_back(AngleDeg(F.force, G.force));
    }
    if (glm::length(G.force) > 1e-9) {
      rel.push_back(glm::length(F.force - G.force) / glm::length(G.force));
    }
    const bool method_contact = run.poses[k].contacts > 0;
    if (k < touching.size()) {
      m.poses_missed += touching[k] && !method_contact;
      m.poses_invented += !touching[k] && method_contact;
    }
  }
  // The pipeline truth (T1) and the volume truth (T2), per pose.
  double pfe = 0, pfg = 0, pte = 0, ptg = 0;
  std::vector<double> vdir, varm;
  for (std::size_t k = 0; k < run.poses.size() && k < pipeline.size(); ++k) {
    const Wrench& F = run.poses[k].F;
    const PoseTruth& t = pipeline[k];
    const Wrench& G = t.F_T_W;
    pfe += glm::dot(F.force - G.force, F.force - G.force);
    pfg += glm::dot(G.force, G.force);
    pte += glm::dot(F.torque - G.torque, F.torque - G.torque);
    ptg += glm::dot(G.torque, G.torque);
    const bool force = glm::length(F.force) > 1e-9;
    m.poses_truth_without_force += t.pairs > 0 && !force;
    m.poses_force_without_truth += t.pairs == 0 && force;
    const double gx = glm::length(t.dV_dx_W);
    if (force && gx > 0.0) {
      vdir.push_back(AngleDeg(F.force, -t.dV_dx_W));
      const double arm_gt = glm::length(t.dV_dtheta_W) / gx;
      const double arm = glm::length(F.torque) / glm::length(F.force);
      if (arm_gt > 0.0) varm.push_back(std::abs(arm - arm_gt) / arm_gt);
    }
  }
  const double nan = std::numeric_limits<double>::quiet_NaN();
  m.pipeline_force_rel_rms = pfg > 0 ? std::sqrt(pfe / pfg) : nan;
  m.pipeline_torque_rel_rms = ptg > 0 ? std::sqrt(pte / ptg) : nan;
  m.volume_dir_p50_deg = Percentile(vdir, 0.5);
  m.volume_dir_p95_deg = Percentile(vdir, 0.95);
  m.volume_arm_rel_p50 = Percentile(varm, 0.5);
  m.force_rel_rms = fg > 0 ? std::sqrt(fe / fg) : std::numeric_limits<double>::quiet_NaN();
  m.torque_rel_rms = tg > 0 ? std::sqrt(te / tg) : std::numeric_limits<double>::quiet_NaN();
  m.force_rel_p50 = Percentile(rel, 0.5);
  m.dir_p50_deg = Percentile(dir, 0.5);
  m.dir_p95_deg = Percentile(dir, 0.95);
  for (const ContactRecord& c : run.contacts) {
    const double d = c.lin.depth_m, g = jobs[c.gt].result.linearization.depth_m;
    ++m.windows;
    const bool dc = std::isfinite(d) && d > 0.0, gc = std::isfinite(g) && g > 0.0;
    m.missed += gc && !dc;
    m.invented += dc && !gc;
    if ((dc || gc) && std::isfinite(d) && std::isfinite(g)) derr.push_back(std::abs(d - g) * 1e6);
  }
  m.delta_p50_um = Percentile(derr, 0.5);
  m.delta_p95_um = Percentile(derr, 0.95);
}

void MarkPareto(std::vector<SettingRun>& runs) {
  for (SettingRun& a : runs) {
    if (!a.skipped.empty() || !std::isfinite(a.m.pipeline_force_rel_rms)) continue;
    a.m.pareto = true;
    for (const SettingRun& b : runs) {
      if (&a == &b || !b.skipped.empty() || !std::isfinite(b.m.pipeline_force_rel_rms)) continue;
      const bool no_worse = b.m.total_p50 <= a.m.total_p50 &&
                            b.m.pipeline_force_rel_rms <= a.m.pipeline_force_rel_rms;
      const bool better =
          b.m.total_p50 < a.m.total_p50 || b.m.pipeline_force_rel_rms < a.m.pipeline_force_rel_rms;
      if (no_worse && better) a.m.pareto = false;
    }
  }
}

void WriteQuat(std::ostream& o, const RigidTransform& X) {
  o << X.translation.x << ',' << X.translation.y << ',' << X.translation.z << ',' << X.rotation.w
    << ',' << X.rotation.x << ',' << X.rotation.y << ',' << X.rotation.z;
}

void WriteWrench(std::ostream& o, const Wrench& F) {
  o << F.force.x << ',' << F.force.y << ',' << F.force.z << ',' << F.torque.x << ',' << F.torque.y
    << ',' << F.torque.z;
}

// The seed's timing figures for a scene (seed §19.5.2), for summary.md.
std::string SeedFigures(const std::string& scene) {
  if (scene == "fig77") {
    return "5-10 ms per frame (100-200 Hz), about 104 pairs clustered into up to 7 contacts, on "
           "this scene";
  }
  if (scene == "hammer_torus") {
    return "the seed gives no timing for this scene; on its other complex-contact scene (file on "
           "CAD part) 5-10 ms per frame (100-200 Hz)";
  }
  return "about 2 ms per step (about 500 Hz) with one contact";
}

// A benchmark scene built at one model setting, with what the surface-error figures need once
// per build: the full-resolution tool mesh moved into T (the tool model's frame) and both models'
// MeasureSurfaceError.
struct BuiltBenchmark {
  BenchmarkScene scene;
  TriangleMesh tool_mesh_T;
  SurfaceErrorReport tool_surface, object_surface;
};

BuiltBenchmark MakeBuiltBenchmark(BenchmarkScene scene) {
  BuiltBenchmark b{std::move(scene), {}, {}, {}};
  b.tool_mesh_T = *b.scene.tool_mesh_Ft;
  for (glm::dvec3& v : b.tool_mesh_T.vertices) v = b.scene.X_TFt * v;
  b.tool_surface = MeasureSurfaceError(*b.scene.haptic.tool, b.tool_mesh_T);
  b.object_surface =
      MeasureSurfaceError(*b.scene.haptic.touchables.at(0).model, *b.scene.object_mesh_Fe);
  return b;
}

// Where the truth pushes and `run` does not: the models' surface error within
// kLocalSurfaceRadiusM of each truth patch (with force) of the poses where it gives no force
// (SettingRun::local_*). `poses_WFt` are the tool mesh's poses, `pipeline` their truths.
void AddLocalSurfaceErrors(const BuiltBenchmark& b, const std::vector<RigidTransform>& poses_WFt,
                           const std::vector<PoseTruth>& pipeline, SettingRun& run) {
  const BenchmarkScene& sc = b.scene;
  const RigidTransform X_OW = sc.haptic.touchables.at(0).X_WO.Inverse();
  SurfaceErrorParams local;
  local.samples = 1024;
  local.region_radius_m = kLocalSurfaceRadiusM;
  for (std::size_t k = 0; k < run.poses.size() && k < pipeline.size(); ++k) {
    if (glm::length(run.poses[k].F.force) > 1e-9) continue;
    const RigidTransform X_TW = (poses_WFt[k] * sc.X_TFt.Inverse()).Inverse();
    for (const TruthPatch& patch : pipeline[k].patches) {
      if (!(glm::length(patch.contact.F_T_W.force) > 1e-9)) continue;
      try {
        local.region_center_O = X_TW * patch.window.center_W;
        const SurfaceErrorReport t = MeasureSurfaceError(*sc.haptic.tool, b.tool_mesh_T, local);
        local.region_center_O = X_OW * patch.window.center_W;
        const SurfaceErrorReport o =
            MeasureSurfaceError(*sc.haptic.touchables.at(0).model, *sc.object_mesh_Fe, local);
        run.local_tool_p99_m.push_back(t.p99_m);
        run.local_object_p99_m.push_back(o.p99_m);
        run.local_tool_outside_m.push_back(t.outside_p99_m);
        run.local_object_outside_m.push_back(o.outside_p99_m);
      } catch (const std::invalid_argument&) {
        // No full-resolution surface within the radius on one side: not measured.
      }
    }
  }
}

struct SceneReport {
  std::string name, tool_file, object_file, mesh_note, pose_source;
  std::int64_t tool_full = 0, object_full = 0;
  int poses = 0, touching = 0;
  std::vector<SettingRun> runs;
  // Ground truth figures.
  std::size_t gt_windows = 0, gt_converged = 0;
  double gt_change_max_m = 0, gt_seconds = 0;
  long long gt_rays = 0;
  std::vector<int> gt_m;
  // Pipeline truth figures.
  int truth_patches = 0, truth_poses_intersecting = 0, truth_poses_zero = 0;
  int truth_pairs_truncated = 0;
  int truth_patches_merged = 0, truth_patches_shared = 0;
  double truth_seconds = 0;
  long long truth_rays = 0;
  std::vector<double> truth_extents_mm;
};

}  // namespace

void RunSpeedErrorFrontier(const FrontierOptions& options) {
  if (options.out_dir.empty()) throw std::invalid_argument("--out DIR is required");
  options.ground_truth.Validate();
  std::vector<std::string> scenes = options.scenes;
  if (scenes.empty()) {
    scenes = options.quick ? std::vector<std::string>{"fig75", "fig76"} : BenchmarkSceneNames();
  }
  for (const std::string& s : scenes) {
    const auto& known = BenchmarkSceneNames();
    if (std::find(known.begin(), known.end(), s) == known.end()) {
      std::string list;
      for (const std::string& k : known) list += (list.empty() ? "" : ", ") + k;
      throw std::invalid_argument("unknown scene '" + s + "' (known: " + list + ")");
    }
  }
  for (const auto& [scene, path] : options.traces) {
    if (std::find(scenes.begin(), scenes.end(), scene) == scenes.end()) {
      throw std::invalid_argument("--trace names scene '" + scene + "', which is not run");
    }
    if (!std::filesystem::exists(path)) {
      throw std::invalid_argument("--trace " + scene + "=" + path + ": no such file");
    }
  }
  const int pose_count = options.poses > 0 ? options.poses : (options.quick ? 12 : 200);
  std::vector<FrontierSetting> settings = FrontierSettings(options.quick, options.gpu);
  if (!options.settings.empty()) {
    std::string known;
    for (const FrontierSetting& st : settings) known += (known.empty() ? "" : ", ") + st.name;
    for (const std::string& want : options.settings) {
      if (std::none_of(settings.begin(), settings.end(),
                       [&](const FrontierSetting& st) { return st.name == want; })) {
        throw std::invalid_argument("unknown setting '" + want + "' (known here: " + known + ")");
      }
    }
    std::erase_if(settings, [&](const FrontierSetting& st) {
      return std::find(options.settings.begin(), options.settings.end(), st.name) ==
             options.settings.end();
    });
  }
  std::filesystem::create_directories(options.out_dir + "/meshes");
  // Nothing of an earlier run may be taken for this one's.
  for (const char* f :
       {"summary.md", "frontier.csv", "contacts.csv", "patches.csv", "frontier.png"}) {
    std::filesystem::remove(options.out_dir + "/" + f);
  }
  const HapticModelCache cache(options.cache_dir);
  const auto t_start = Clock::now();
  const auto say = [&](const char* fmt, auto... args) {
    if (!options.progress) return;
    std::fprintf(stderr, "[frontier] ");
    std::fprintf(stderr, fmt, args...);
    std::fprintf(stderr, "\n");
  };

  PartialFile contacts_csv(options.out_dir + "/contacts.csv");
  std::ostream& cc = contacts_csv.out();
  cc.precision(10);
  cc << "scene,setting,pose_id,contact,tool,object,tool_px,tool_py,tool_pz,tool_qw,tool_qx,"
        "tool_qy,tool_qz,obj_px,obj_py,obj_pz,obj_qw,obj_qx,obj_qy,obj_qz,window_cx,window_cy,"
        "window_cz,window_nx,window_ny,window_nz,window_ux,window_uy,window_uz,window_extent_m,"
        "grid,stiffness_n_per_m,delta_m,delta_gt_m,fx,fy,fz,tx,ty,tz,fx_gt,fy_gt,fz_gt,tx_gt,"
        "ty_gt,tz_gt,tool_com_x,tool_com_y,tool_com_z,gt_samples_per_side,gt_converged\n";

  PartialFile patches_csv(options.out_dir + "/patches.csv");
  std::ostream& pc = patches_csv.out();
  pc.precision(10);
  pc << "scene,pose_id,patch,tool,object,tool_px,tool_py,tool_pz,tool_qw,tool_qx,tool_qy,tool_qz,"
        "obj_px,obj_py,obj_pz,obj_qw,obj_qx,obj_qy,obj_qz,window_cx,window_cy,window_cz,"
        "window_nx,window_ny,window_nz,window_ux,window_uy,window_uz,window_extent_m,delta_gt_m,"
        "fx_gt,fy_gt,fz_gt,tx_gt,ty_gt,tz_gt,tool_com_x,tool_com_y,tool_com_z,stiffness_n_per_m,"
        "gradient_step_m,pairs,tool_inside_area_m2,object_inside_area_m2,dV_dx,dV_dy,dV_dz,"
        "dV_dthx,dV_dthy,dV_dthz,gt_samples_per_side,gt_converged,share,gap_to_neighbour_m,"
        "tilt_step_rad\n";
  std::vector<SceneReport> reports;
  const int total_units = static_cast<int>(scenes.size() * settings.size());
  int units_done = 0;
  for (const std::string& name : scenes) {
    SceneReport rep;
    rep.name = name;
    say("%s: building the models (cache: %s)", name.c_str(),
        options.cache_dir.empty() ? "none" : options.cache_dir.c_str());
    std::map<std::tuple<int, double, bool>, std::unique_ptr<BuiltBenchmark>> built;
    const auto built_for = [&](const BenchmarkModelSettings& b) -> const BuiltBenchmark& {
      auto& slot = built[{b.texture_size, b.coarse_scale, b.textured}];
      if (!slot) {
        try {
          slot = std::make_unique<BuiltBenchmark>(
              MakeBuiltBenchmark(MakeBenchmarkScene(name, b, cache)));
        } catch (const std::exception& e) {
          throw std::runtime_error("scene " + name + " (texture " + std::to_string(b.texture_size) +
                                   ", coarse x" + Fmt(b.coarse_scale) + "): " + e.what());
        }
      }
      return *slot;
    };
    const BenchmarkScene& ref = built_for({}).scene;
    rep.tool_file = ref.tool_name + ".glb";
    rep.object_file = ref.object_name + ".glb";
    rep.tool_full = static_cast<std::int64_t>(ref.tool_mesh_Ft->triangles.size());
    rep.object_full = static_cast<std::int64_t>(ref.object_mesh_Fe->triangles.size());
    for (const auto& [file, mesh] : {std::pair{rep.tool_file, ref.tool_mesh_Ft},
                                     std::pair{rep.object_file, ref.object_mesh_Fe}}) {
      const std::string path = options.out_dir + "/meshes/" + file;
      if (!std::filesystem::exists(path)) {
        WriteGlb(path + ".partial",
                 {{file.substr(0, file.size() - 4), *mesh, glm::dmat4(1.0), ""}});
        std::filesystem::rename(path + ".partial", path);
      }
    }
    rep.mesh_note =
        (name == "fig75" || name == "fig76")
            ? "procedural (haptic_core/demo/procedural_models.h), the same code that makes "
              "the haptic models; also written by `slave_sim seed-models`"
            : "procedural seed analogues (haptic_core/demo/seed_models.h), as written by "
              "`slave_sim seed-models`; the haptic models are decimated and baked "
              "from them through the model cache";
    std::vector<RigidTransform> poses;
    const auto trace = options.traces.find(name);
    const bool consecutive = trace != options.traces.end() && options.trace_from_s >= 0.0;
    if (trace != options.traces.end()) {
      poses = PosesFromTrace(trace->second, ref, pose_count, options.trace_from_s);
      rep.pose_source = "rows in contact of the run trace " + trace->second;
    } else {
      say("%s: finding %d in-contact poses on the full-resolution meshes", name.c_str(),
          pose_count);
      poses = ScriptedContactPoses(ref, pose_count);
      rep.pose_source =
          "scripted motion (ScriptedContactPoses): lowered until the full-resolution meshes touch, "
          "then pressed 0.02-0.4 mm further";
    }
    if (poses.empty()) throw std::runtime_error("scene " + name + ": no in-contact pose found");
    rep.poses = static_cast<int>(poses.size());
    const RigidTransform X_WFe = ref.haptic.touchables.at(0).X_WO;
    const MeshContactBaseline fcl(*ref.tool_mesh_Ft, *ref.object_mesh_Fe);
    std::vector<bool> touching;
    for (const RigidTransform& X : poses) touching.push_back(fcl.Intersects(X, X_WFe));
    rep.touching = static_cast<int>(std::count(touching.begin(), touching.end(), true));

    // Timed steps, one setting after the other, on this thread alone.
    std::vector<GtJob> jobs;
    std::map<std::string, int> job_index;
    for (const FrontierSetting& st : settings) {
      SettingRun run;
      run.setting = st;
      ++units_done;
      if (st.product_models || options.on_product_models) {
        const BenchmarkModelSettings product = ProductModelSettings(name);
        run.setting.texture_size = product.texture_size;
        run.setting.coarse_scale = product.coarse_scale;
      }
      const FrontierSetting& st_run = run.setting;
      if (st_run.coarse_scale != 1.0 && name == "fig76") {
        run.skipped = "the striped blocks are boxes of 16 coarse triangles at every scale";
      } else {
        BenchmarkModelSettings b;
        b.texture_size = st_run.texture_size;
        b.coarse_scale = st_run.coarse_scale;
        b.textured = st.method != FrontierMethod::kCoarseOnly;
        const BuiltBenchmark& models = built_for(b);
        const BenchmarkScene& scene = models.scene;
        if (!scene.texture_note.empty()) run.note = "texture sizes " + scene.texture_note;
        run.tool_surface = models.tool_surface;
        run.object_surface = models.object_surface;
        const auto t0 = Clock::now();
        RunSetting(scene, poses, fcl, consecutive, consecutive ? options.switch_lag_rows : 0,
                   options, run);
        for (ContactRecord& c : run.contacts) {
          const std::string key =
              GtKey(c.pose, run.X_TFt, c.query.window, c.query.stiffness_n_per_m);
          auto [it, fresh] = job_index.try_emplace(key, static_cast<int>(jobs.size()));
          if (fresh) {
            GtJob j;
            j.X_WT = poses[c.pose] * run.X_TFt.Inverse();
            j.X_TFt = run.X_TFt;
            j.X_WFe = c.query.X_WO;
            j.window = c.query.window;
            j.stiffness = c.query.stiffness_n_per_m;
            jobs.push_back(j);
          }
          c.gt = it->second;
        }
        say("%s: setting %d/%d done (%s, %.1f s)%s%s", name.c_str(), units_done, total_units,
            st.name.c_str(), Seconds(t0),
            run.skipped.empty() ? "" : ": skipped: ", run.skipped.c_str());
      }
      rep.runs.push_back(std::move(run));
    }
    // The ground truth of every distinct window, on all threads.
    say("%s: ground truth of %zu windows on %d thread(s)", name.c_str(), jobs.size(),
        options.threads);
    const auto t_gt = Clock::now();
    const RayCastSurface tool_rays(*ref.tool_mesh_Ft);
    const RayCastSurface object_rays(*ref.object_mesh_Fe);
    RunGroundTruth(ref, tool_rays, object_rays, jobs, options);
    rep.gt_seconds = Seconds(t_gt);
    // The pipeline truth of every pose: from the full-resolution meshes alone.
    say("%s: pipeline truth of %zu poses on %d thread(s)", name.c_str(), poses.size(),
        options.threads);
    const auto t_truth = Clock::now();
    std::vector<PoseTruth> pipeline;
    RunPipelineTruth(ref, tool_rays, object_rays, poses, options, pipeline);
    // The truth at the prediction measure's displaced poses.
    std::vector<PoseTruth> displaced_truth;
    if (options.model_prediction) {
      const std::vector<RigidTransform> displaced = PredictionPoses(poses, ref.X_TFt, options);
      say("%s: pipeline truth of %zu displaced poses (model prediction)", name.c_str(),
          displaced.size());
      RunPipelineTruth(ref, tool_rays, object_rays, displaced, options, displaced_truth);
    }
    rep.truth_seconds = Seconds(t_truth);
    for (std::size_t k = 0; k < pipeline.size(); ++k) {
      const PoseTruth& t = pipeline[k];
      rep.truth_patches += static_cast<int>(t.patches.size());
      rep.truth_poses_intersecting += t.pairs > 0;
      rep.truth_poses_zero += t.pairs > 0 && !(glm::length(t.F_T_W.force) > 0.0);
      rep.truth_pairs_truncated += t.pairs_truncated;
      rep.truth_patches_merged += t.patches_merged;
      rep.truth_patches_shared += t.patches_shared;
      rep.truth_rays += t.rays;
      for (std::size_t q = 0; q < t.patches.size(); ++q) {
        const TruthPatch& patch = t.patches[q];
        rep.truth_extents_mm.push_back(patch.window.extent_m * 1e3);
        const ContactWindow& w = patch.window;
        const ContactLinearization& lin = patch.contact.linearization;
        pc << name << ',' << k << ',' << q << ',' << rep.tool_file << ',' << rep.object_file << ',';
        WriteQuat(pc, poses[k]);
        pc << ',';
        WriteQuat(pc, ref.haptic.touchables.at(0).X_WO);
        pc << ',' << w.center_W.x << ',' << w.center_W.y << ',' << w.center_W.z << ','
           << w.normal_W.x << ',' << w.normal_W.y << ',' << w.normal_W.z << ',' << w.axis_u_W.x
           << ',' << w.axis_u_W.y << ',' << w.axis_u_W.z << ',' << w.extent_m << ',' << lin.depth_m
           << ',';
        WriteWrench(pc, patch.contact.F_T_W);
        const glm::dvec3 com_W = poses[k] * ref.X_TFt.Inverse().translation;
        const glm::dvec3 gx = 0.5 * (patch.dV_dx_tool_W + patch.dV_dx_environment_W);
        const glm::dvec3 gt = 0.5 * (patch.dV_dtheta_tool_W + patch.dV_dtheta_environment_W);
        pc << ',' << com_W.x << ',' << com_W.y << ',' << com_W.z << ','
           << ref.haptic.touchables.at(0).stiffness_n_per_m << ',' << patch.gradient_step_m << ','
           << patch.pairs << ',' << patch.tool_inside_area_m2 << ','
           << patch.environment_inside_area_m2 << ',' << gx.x << ',' << gx.y << ',' << gx.z << ','
           << gt.x << ',' << gt.y << ',' << gt.z << ',' << patch.contact.base.samples_per_side
           << ',' << (patch.contact.base.converged ? 1 : 0) << ',' << patch.share << ','
           << patch.gap_to_neighbour_m << ',' << patch.tilt_step_rad << '\n';
      }
    }
    rep.gt_windows = jobs.size();
    for (const GtJob& j : jobs) {
      rep.gt_converged += j.result.base.converged;
      if (std::isfinite(j.result.base.change_m)) {
        rep.gt_change_max_m = std::max(rep.gt_change_max_m, j.result.base.change_m);
      }
      rep.gt_rays += j.result.rays;
      rep.gt_m.push_back(j.result.base.samples_per_side);
    }
    // The default setting's ground truth per pose: the truth for the baselines.
    std::vector<Wrench> reference_gt(poses.size());
    for (const ContactRecord& c : rep.runs.front().contacts) {
      reference_gt[c.pose] += jobs[c.gt].result.F_T_W;
    }
    for (SettingRun& run : rep.runs) {
      if (!run.skipped.empty()) continue;
      ComputeMetrics(run, jobs, reference_gt, touching, pipeline);
      if (run.setting.method != FrontierMethod::kCoarseOnly) {
        const auto found = built.find({run.setting.texture_size, run.setting.coarse_scale, true});
        if (found != built.end() && found->second) {
          AddLocalSurfaceErrors(*found->second, poses, pipeline, run);
        }
      }
      if (run.predicted.size() == displaced_truth.size() && !run.predicted.empty()) {
        double fe = 0, fr = 0, te = 0, tr = 0;
        for (std::size_t i = 0; i < displaced_truth.size(); ++i) {
          const Wrench& F = run.predicted[i];
          const Wrench& G = displaced_truth[i].F_T_W;
          fe += SquaredNorm(F.force - G.force);
          fr += SquaredNorm(G.force);
          te += SquaredNorm(F.torque - G.torque);
          tr += SquaredNorm(G.torque);
        }
        const double nan = std::numeric_limits<double>::quiet_NaN();
        run.m.prediction_force_rel_rms = fr > 0 ? std::sqrt(fe / fr) : nan;
        run.m.prediction_torque_rel_rms = tr > 0 ? std::sqrt(te / tr) : nan;
      }
      const glm::dvec3 com_shift = run.X_TFt.Inverse().translation;
      for (const ContactRecord& c : run.contacts) {
        const GtJob& j = jobs[c.gt];
        const ContactWindow& w = c.query.window;
        cc << name << ',' << run.setting.name << ',' << c.pose << ',' << c.index << ','
           << rep.tool_file << ',' << rep.object_file << ',';
        WriteQuat(cc, poses[c.pose]);
        cc << ',';
        WriteQuat(cc, c.query.X_WO);
        cc << ',' << w.center_W.x << ',' << w.center_W.y << ',' << w.center_W.z << ','
           << w.normal_W.x << ',' << w.normal_W.y << ',' << w.normal_W.z << ',' << w.axis_u_W.x
           << ',' << w.axis_u_W.y << ',' << w.axis_u_W.z << ',' << w.extent_m << ',' << w.resolution
           << ',' << c.query.stiffness_n_per_m << ',' << c.lin.depth_m << ','
           << j.result.linearization.depth_m << ',';
        // As the model gives it at q0 (its kink planes may blend there: ContactDepthAt).
        PenetrationGradient J_q0;
        const double depth_q0 = ContactDepthAt(c.lin, Twist{}, &J_q0);
        WriteWrench(cc, PenaltyWrench(depth_q0, J_q0, c.lin.stiffness_n_per_m));
        cc << ',';
        WriteWrench(cc, j.result.F_T_W);
        const glm::dvec3 com_W = poses[c.pose] * com_shift;
        cc << ',' << com_W.x << ',' << com_W.y << ',' << com_W.z << ','
           << j.result.base.samples_per_side << ',' << (j.result.base.converged ? 1 : 0) << '\n';
      }
    }
    MarkPareto(rep.runs);
    say("%s: done (%.0f s so far)", name.c_str(), Seconds(t_start));
    reports.push_back(std::move(rep));
  }
  contacts_csv.Commit();
  patches_csv.Commit();

  // frontier.csv
  {
    PartialFile f(options.out_dir + "/frontier.csv");
    std::ostream& o = f.out();
    o << "scene,setting,method,backend,renderer,grid,texture_size,coarse_scale,depth_bits,"
         "tool_coarse_triangles,object_coarse_triangles,poses,contacts_mean,leaf_pairs_mean,"
         "collision_p50_us,collision_p95_us,texture_p50_us,texture_p95_us,total_p50_us,"
         "total_p95_us,force_rel_rms,force_rel_p50,torque_rel_rms,force_dir_p50_deg,force_dir_p95_"
         "deg,"
         "delta_err_p50_um,delta_err_p95_um,windows,contacts_missed,contacts_invented,"
         "poses_missed,poses_invented,pipeline_force_rel_rms,pipeline_torque_rel_rms,"
         "volume_dir_p50_deg,volume_dir_p95_deg,volume_arm_rel_p50,poses_truth_without_force,"
         "poses_force_without_truth,prediction_force_rel_rms,prediction_torque_rel_rms,"
         "tool_surface_p99_um,object_surface_p99_um,tool_surface_outside_p99_um,"
         "object_surface_outside_p99_um,tool_surface_share_outside,"
         "object_surface_share_outside,switch_jump_p50_n,switch_jump_p99_n,switch_jump_max_n,"
         "switch_jumps_over_0_2_n,pareto,"
         "skipped\n";
    for (const SceneReport& rep : reports) {
      for (const SettingRun& r : rep.runs) {
        const FrontierSetting& s = r.setting;
        const auto clean = [](std::string t) {
          std::replace(t.begin(), t.end(), ',', ';');
          std::replace(t.begin(), t.end(), '\n', ' ');
          return t;
        };
        const Metrics& m = r.m;
        std::vector<std::string> cells = {
            rep.name,
            s.name,
            FrontierMethodName(s.method),
            s.method == FrontierMethod::kFullResolutionFcl ? "cpu" : s.backend,
            clean(r.renderer),
            std::to_string(s.grid),
            std::to_string(s.texture_size),
            Fmt(s.coarse_scale),
            std::to_string(s.backend == "gpu" ? s.depth_bits : 32),
            std::to_string(r.tool_coarse_triangles),
            std::to_string(r.object_coarse_triangles)};
        if (r.skipped.empty()) {
          for (const std::string& c : {std::to_string(r.poses.size()),
                                       Fmt(m.contacts_mean),
                                       Fmt(m.leaf_pairs_mean),
                                       Fmt(m.collision_p50),
                                       Fmt(m.collision_p95),
                                       Fmt(m.texture_p50),
                                       Fmt(m.texture_p95),
                                       Fmt(m.total_p50),
                                       Fmt(m.total_p95),
                                       Fmt(m.force_rel_rms),
                                       Fmt(m.force_rel_p50),
                                       Fmt(m.torque_rel_rms),
                                       Fmt(m.dir_p50_deg),
                                       Fmt(m.dir_p95_deg),
                                       Fmt(m.delta_p50_um),
                                       Fmt(m.delta_p95_um),
                                       std::to_string(m.windows),
                                       std::to_string(m.missed),
                                       std::to_string(m.invented),
                                       std::to_string(m.poses_missed),
                                       std::to_string(m.poses_invented),
                                       Fmt(m.pipeline_force_rel_rms),
                                       Fmt(m.pipeline_torque_rel_rms),
                                       Fmt(m.volume_dir_p50_deg),
                                       Fmt(m.volume_dir_p95_deg),
                                       Fmt(m.volume_arm_rel_p50),
                                       std::to_string(m.poses_truth_without_force),
                                       std::to_string(m.poses_force_without_truth),
                                       Fmt(m.prediction_force_rel_rms),
                                       Fmt(m.prediction_torque_rel_rms),
                                       Fmt(r.tool_surface.p99_m * 1e6),
                                       Fmt(r.object_surface.p99_m * 1e6),
                                       Fmt(r.tool_surface.outside_p99_m * 1e6),
                                       Fmt(r.object_surface.outside_p99_m * 1e6),
                                       Fmt(r.tool_surface.share_outside),
                                       Fmt(r.object_surface.share_outside),
                                       Fmt(m.switch_jump_p50_n),
                                       Fmt(m.switch_jump_p99_n),
                                       Fmt(m.switch_jump_max_n),
                                       std::to_string(m.switch_jumps_over_0_2_n),
                                       std::string(m.pareto ? "1" : "0"),
                                       std::string()}) {
            cells.push_back(c);
          }
        } else {
          cells.resize(cells.size() + 41);
          cells.push_back(clean(r.skipped));
        }
        for (std::size_t i = 0; i < cells.size(); ++i) o << (i ? "," : "") << cells[i];
        o << '\n';
      }
    }
    f.Commit();
  }

  // frontier.png
  std::string plot_note;
  if (!options.plot_script.empty()) {
    const std::string cmd = "/usr/bin/python3 '" + options.plot_script + "' '" + options.out_dir +
                            "/frontier.csv' '" + options.out_dir + "/frontier.png'";
    const int rc = std::system(cmd.c_str());
    if (rc != 0) {
      plot_note =
          "frontier.png was not written (`" + cmd + "` exited with " + std::to_string(rc) +
          "; it needs /usr/bin/python3 with matplotlib: apt-get install python3-matplotlib)";
      say("%s", plot_note.c_str());
    }
  } else {
    plot_note = "frontier.png was not written (no plot script given)";
  }

  // summary.md, last.
  PartialFile sm(options.out_dir + "/summary.md");
  std::ostream& s = sm.out();
  s << "# Speed against error: the frontier\n\n";
  s << "Command: `" << options.command_line << "`  \n";
  s << "Machine: " << MachineLine() << "; total " << Fmt(Seconds(t_start), 3) << " s.  \n";
  s << "Timed steps run one at a time on one thread (settings named threads2 on two: the texture "
       "stage and the coarse query); "
       "the ground truth afterwards on "
    << options.threads << ".\n\n";
  s << "Two measures of error, each named where it is used (issue 31):\n\n"
       "- **Pipeline truth (T1)**, the headline measure: from the **full-resolution** meshes "
       "alone, at each pose, the intersecting triangle pairs (FCL) grouped into contact patches "
       "(connected regions at the method's clustering distance and angle, then merged where two "
       "would measure one interpenetration twice: a textured face's flanks, overlapping windows, "
       "slivers at an edge); per patch its direction n, the flatter surface's normal averaged over "
       "5 mm (texture finer than that does not tilt it; else −∇V, the area-weighted normals of "
       "the surfaces inside the other solid, V the patch's intersection volume), its centre "
       "(their area centroid) and a window holding their projection; `--truth-no-merge` gives "
       "the truth before issue 32's third stop (no merges, n = −∇V); δ_gt and ∇δ_gt on that window "
       "by Embree ray casting (the method's facing and "
       "box rules), gradient steps at texel scale (0.1 mm); Φ_gt = Σ −k δ_gt ∇δ_gt. It owns its "
       "contacts: a method's window in the wrong place or along the wrong n, or a contact in no "
       "window, is error. `pipeline force / torque err` is the relative RMS "
       "√(Σ|F − F_gt|²/Σ|F_gt|²) over the poses. patches.csv lists every patch.\n"
       "- **Volume truth (T2)**, independent of the force law: the angle between the method's "
       "force and −∇_x V (summed over the pose's patches; poses where both are non-zero) and the "
       "relative error of the lever arm |τ|/|F| against |∇_θ V|/|∇_x V| (torques about the tool's "
       "centre of mass). `truth w/o force`: poses whose full-resolution meshes intersect where "
       "the method gives no force; `force w/o truth`: the converse.\n"
       "- **Texture-stage measure** (the earlier one, kept): the ground truth on each setting's "
       "**own** windows (the same centre, n and box), its gradient at the 50×50 grid's step "
       "table, so it isolates what the texture and the grid lose inside a window; the two "
       "baselines, which have no windows, against the default setting's. `texture-stage force "
       "err` (RMS; pose p50), torque, direction and δ errors and missed / invented windows use "
       "it; poses missed / invented are against FCL's intersection test.\n"
       "- **Model prediction** (issue 31, change 5), what the operator's 1 kHz loop renders "
       "between two models: the contact models of about 20 poses spread evenly, evaluated "
    << Fmt(options.prediction_rotation_rad * 1e3, 3) << " mrad either way about W's x and y and "
    << Fmt(options.prediction_translation_m * 1e3, 3)
    << " mm either way along them (`--prediction-rotation-mrad`, `--prediction-translation-mm`), "
       "against the **pipeline "
       "truth** at those displaced poses; `model prediction F / τ err` is the relative RMS over "
       "them. A face resting on ridges tilted past its V's vertex gets the other edge's torque "
       "only from a model that carries the kink.\n\n"
       "Pareto and the fastest setting within 5 % use the pipeline truth.\n\n";
  if (!plot_note.empty()) s << plot_note << "\n\n";
  for (const SceneReport& rep : reports) {
    s << "## " << rep.name << "\n\n";
    s << "- Meshes: `meshes/" << rep.tool_file << "` (tool, " << rep.tool_full
      << " triangles) and `meshes/" << rep.object_file << "` (object, " << rep.object_full
      << " triangles): " << rep.mesh_note << ".\n";
    s << "- Poses: " << rep.poses << ", from " << rep.pose_source << "; " << rep.touching
      << " of them intersect at full resolution (FCL).\n";
    const int m50 =
        static_cast<int>(Percentile(std::vector<double>(rep.gt_m.begin(), rep.gt_m.end()), 0.5));
    const int mmax = rep.gt_m.empty() ? 0 : *std::max_element(rep.gt_m.begin(), rep.gt_m.end());
    s << "- Texture-stage ground truth: " << rep.gt_windows << " distinct windows, "
      << rep.gt_converged << " converged (δ changed by < "
      << Fmt(options.ground_truth.tolerance_m * 1e6, 3)
      << " µm when M doubled); M×M samples with M from " << options.ground_truth.initial_samples
      << " (p50 " << m50 << ", max " << mmax << ", cap " << options.ground_truth.max_samples
      << "), each grid refined locally from its " << options.ground_truth.refine_seeds
      << " best cells down to " << Fmt(options.ground_truth.refine_step_m * 1e9, 3)
      << " nm; largest last change " << Fmt(rep.gt_change_max_m * 1e6, 3) << " µm; " << rep.gt_rays
      << " rays in " << Fmt(rep.gt_seconds, 3) << " s.\n";
    s << "- Pipeline truth: " << rep.truth_poses_intersecting << " of " << rep.poses
      << " poses intersect at full resolution; " << rep.truth_patches
      << " patches (window side p50 " << Fmt(Percentile(rep.truth_extents_mm, 0.5), 3)
      << " mm, max "
      << Fmt(rep.truth_extents_mm.empty()
                 ? 0.0
                 : *std::max_element(rep.truth_extents_mm.begin(), rep.truth_extents_mm.end()),
             3)
      << " mm; " << rep.truth_patches_merged
      << (options.truth_merge_patches
              ? " more merged into them: neighbours on one face at the 5 mm scale, overlapping "
                "windows within 60°, or slivers at a patch's edge"
              : " merged: --truth-no-merge")
      << "); "
      << (options.truth_share_fade_m > 0.0
              ? std::to_string(rep.truth_patches_shared) +
                    " patches share their penalty with a neighbour within the clustering distance "
                    "plus " +
                    Fmt(options.truth_share_fade_m * 1e3, 3) + " mm"
              : std::string("patches never share (--truth-share-fade-mm 0)"))
      << "; tilt steps "
      << (options.truth_tilt_lift_m > 0.0
              ? "lift the window's edge by " + Fmt(options.truth_tilt_lift_m * 1e6, 3) +
                    " um (--truth-tilt-lift-um)"
              : std::string("lift the window's edge by a texel step"))
      << "; intersecting poses with a zero truth: " << rep.truth_poses_zero
      << "; pair lists cut at the cap: " << rep.truth_pairs_truncated << "; " << rep.truth_rays
      << " rays in " << Fmt(rep.truth_seconds, 3) << " s.\n\n";
    s << "| setting | method | backend | N | texture | coarse | leaf pairs / contacts | step p50 / "
         "p95 (ms) | collision p50 | texture p50 | **pipeline force err** | pipeline torque err | "
         "volume dir p50 / p95 (°) | arm err p50 | truth w/o force / force w/o truth | "
         "model prediction F / τ err | texture-stage force err (RMS; pose p50) | texture-stage "
         "torque err | texture-stage dir "
         "p50 / p95 (°) | δ err p50 / p95 (µm) | missed / invented | Pareto |\n";
    s << "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
         "\n";
    const SettingRun* fastest = nullptr;
    const SettingRun* def = nullptr;
    for (const SettingRun& r : rep.runs) {
      const FrontierSetting& st = r.setting;
      if (st.name == "default") def = &r;
      s << "| " << st.name << " | " << FrontierMethodName(st.method) << " | "
        << (st.backend == "gpu" ? "gpu " + std::to_string(st.depth_bits) + "-bit" : "cpu") << " | "
        << st.grid << " | "
        << (st.texture_size == 0 ? std::string("auto") : std::to_string(st.texture_size)) << " | ×"
        << Fmt(st.coarse_scale) << " | ";
      if (!r.skipped.empty()) {
        s << "skipped: " << r.skipped << " |||||||||||||||\n";
        continue;
      }
      const Metrics& m = r.m;
      s << Fmt(m.leaf_pairs_mean, 3) << " / " << Fmt(m.contacts_mean, 3) << " | "
        << Fmt(m.total_p50 / 1e3, 3) << " / " << Fmt(m.total_p95 / 1e3, 3) << " | "
        << Fmt(m.collision_p50 / 1e3, 3) << " | " << Fmt(m.texture_p50 / 1e3, 3) << " | **"
        << Fmt(100 * m.pipeline_force_rel_rms, 3) << " %** | "
        << Fmt(100 * m.pipeline_torque_rel_rms, 3) << " % | " << Fmt(m.volume_dir_p50_deg, 3)
        << " / " << Fmt(m.volume_dir_p95_deg, 3) << " | " << Fmt(100 * m.volume_arm_rel_p50, 3)
        << " % | " << m.poses_truth_without_force << " / " << m.poses_force_without_truth << " | "
        << (std::isfinite(m.prediction_force_rel_rms)
                ? Fmt(100 * m.prediction_force_rel_rms, 3) + " / " +
                      Fmt(100 * m.prediction_torque_rel_rms, 3) + " %"
                : std::string("—"))
        << " | " << Fmt(100 * m.force_rel_rms, 3) << " %; " << Fmt(100 * m.force_rel_p50, 3)
        << " % | " << Fmt(100 * m.torque_rel_rms, 3) << " % | " << Fmt(m.dir_p50_deg, 3) << " / "
        << Fmt(m.dir_p95_deg, 3) << " | " << Fmt(m.delta_p50_um, 3) << " / "
        << Fmt(m.delta_p95_um, 3) << " | " << m.missed << " / " << m.invented << " (poses "
        << m.poses_missed << " / " << m.poses_invented << ") | " << (m.pareto ? "yes" : "")
        << " |\n";
      if (m.pipeline_force_rel_rms <= 0.05 && (!fastest || m.total_p50 < fastest->m.total_p50)) {
        fastest = &r;
      }
    }
    s << "\n";
    for (const SettingRun& r : rep.runs) {  // e.g. a GPU that failed mid-run
      if (!r.note.empty()) s << "Note on " << r.setting.name << ": " << r.note << ".\n";
    }
    s << "Surface error of the built models (MeasureSurfaceError: full-resolution points against "
         "the textured coarse model, tool / object; p99 distance, p99 and share of points lying "
         "outside the model by more than "
      << Fmt(SurfaceErrorParams{}.outside_threshold_m * 1e6, 3)
      << " µm, where the method reads the depth low):";
    for (const SettingRun& r : rep.runs) {
      if (!r.skipped.empty() || r.tool_surface.samples == 0) continue;
      s << " " << r.setting.name << " " << Fmt(r.tool_surface.p99_m * 1e6, 3) << " / "
        << Fmt(r.object_surface.p99_m * 1e6, 3) << " µm, outside "
        << Fmt(r.tool_surface.outside_p99_m * 1e6, 3) << " / "
        << Fmt(r.object_surface.outside_p99_m * 1e6, 3) << " µm, "
        << Fmt(100 * r.tool_surface.share_outside, 3) << " / "
        << Fmt(100 * r.object_surface.share_outside, 3) << " %;";
    }
    s << "\n\n";
    for (const SettingRun& r : rep.runs) {
      if (r.local_tool_p99_m.empty()) continue;
      const std::vector<double>&t = r.local_tool_p99_m, &o = r.local_object_p99_m,
            &to = r.local_tool_outside_m, &oo = r.local_object_outside_m;
      s << "Near the truth patches of the poses where " << r.setting.name << " gives no force ("
        << t.size() << " patches, within " << Fmt(kLocalSurfaceRadiusM * 1e3, 3)
        << " mm of each centre): surface error p99, median "
        << "over the patches / largest, tool " << Fmt(Percentile(t, 0.5) * 1e6, 3) << " / "
        << Fmt(Percentile(t, 1.0) * 1e6, 3) << " µm, object " << Fmt(Percentile(o, 0.5) * 1e6, 3)
        << " / " << Fmt(Percentile(o, 1.0) * 1e6, 3) << " µm; outside p99 tool "
        << Fmt(Percentile(to, 0.5) * 1e6, 3) << " / " << Fmt(Percentile(to, 1.0) * 1e6, 3)
        << " µm, object " << Fmt(Percentile(oo, 0.5) * 1e6, 3) << " / "
        << Fmt(Percentile(oo, 1.0) * 1e6, 3) << " µm.\n";
    }
    s << "\n";
    if (fastest) {
      s << "Fastest setting with pipeline force error ≤ 5 %: **" << fastest->setting.name << "**, "
        << Fmt(fastest->m.total_p50 / 1e3, 3) << " ms per step (p50), "
        << Fmt(fastest->m.contacts_mean, 3) << " contacts per step, "
        << Fmt(fastest->m.contacts_mean > 0
                   ? fastest->m.texture_p50 / 1e3 / fastest->m.contacts_mean
                   : 0.0,
               3)
        << " ms of texture stage per contact; seed (2004 GPU): about 2 ms per contact, "
        << SeedFigures(rep.name) << ".\n";
    } else {
      const SettingRun* best = nullptr;
      for (const SettingRun& r : rep.runs) {
        if (r.skipped.empty() && std::isfinite(r.m.pipeline_force_rel_rms) &&
            (!best || r.m.pipeline_force_rel_rms < best->m.pipeline_force_rel_rms)) {
          best = &r;
        }
      }
      s << "No setting reached a pipeline force error of 5 % or less on this scene";
      if (best) {
        s << "; the most accurate was **" << best->setting.name << "** ("
          << Fmt(100 * best->m.pipeline_force_rel_rms, 3) << " %, "
          << Fmt(best->m.total_p50 / 1e3, 3) << " ms per step)";
      }
      s << ". Seed (2004 GPU): about 2 ms per contact; " << SeedFigures(rep.name) << ".\n";
    }
    if (def && def->skipped.empty()) {
      s << "The default setting (N = 50, 1024² textures, the seed's coarse counts, CPU) is "
        << (def->m.pareto ? "on" : "not on")
        << " the Pareto frontier here: " << Fmt(def->m.total_p50 / 1e3, 3) << " ms per step at "
        << Fmt(100 * def->m.pipeline_force_rel_rms, 3) << " % pipeline force error ("
        << Fmt(100 * def->m.force_rel_rms, 3) << " % on the texture-stage measure), volume "
        << "direction error p95 " << Fmt(def->m.volume_dir_p95_deg, 3) << "°.\n";
    }
    s << "\n";
  }
  sm.Commit();
  say("wrote %s/{frontier.csv,contacts.csv,patches.csv,summary.md%s,meshes/} in %.0f s",
      options.out_dir.c_str(), plot_note.empty() ? ",frontier.png" : "", Seconds(t_start));
}

}  // namespace ht
