// The speed-vs-error frontier's records (frontier.h): what a run measures per setting, contact
// and scene, and the writers of its files. Internal to slave_sim/src (frontier.cc runs the
// sweep, frontier_setting_run.cc one setting's timed steps, frontier_metrics.cc the metrics,
// frontier_report.cc writes frontier.csv and summary.md, the CSV rows and headers).
#pragma once

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <limits>
#include <ostream>
#include <stdexcept>
#include <string>
#include <vector>

#include "haptic_core/accuracy/contact_patch_truth.h"
#include "haptic_core/accuracy/ground_truth_depth.h"
#include "haptic_core/accuracy/mesh_contact_baseline.h"
#include "haptic_core/model_build/surface_error.h"
#include "haptic_core/remote_step.h"
#include "slave_sim/benchmark_scenes.h"
#include "slave_sim/frontier.h"

namespace ht::frontier {

using Clock = std::chrono::steady_clock;

inline double Seconds(Clock::time_point since) {
  return std::chrono::duration<double>(Clock::now() - since).count();
}

inline double Percentile(std::vector<double> v, double q) {
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
  // Against the pipeline truth (contact_patch_truth.h), which owns its contacts.
  double pipeline_force_rel_rms = 0, pipeline_torque_rel_rms = 0;
  double volume_dir_p50_deg = 0, volume_dir_p95_deg = 0, volume_arm_rel_p50 = 0;
  int poses_truth_without_force = 0, poses_force_without_truth = 0;
  // The contact model's prediction: every PredictionStride()-th pose's model
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
  // A pressure-law setting's force and torque against that law's own truth (PoseTruth's
  // pressure_per_kp times k_p); NaN for the other settings.
  double pressure_force_rel_rms = std::numeric_limits<double>::quiet_NaN();
  double pressure_torque_rel_rms = std::numeric_limits<double>::quiet_NaN();
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
inline constexpr double kLocalSurfaceRadiusM = 2e-3;

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

// A file written under its name + ".partial" and renamed on Commit(), so that an interrupted run
// leaves no file that looks complete. Throws std::runtime_error when it cannot be written.
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

// frontier_setting_run.cc:
// Key of a ground-truth window: the pose, the tool's frame, and the window's geometry, bit for
// bit (windows of settings that differ only in grid or backend are one job).
std::string GtKey(int pose, const RigidTransform& X_TFt, const ContactWindow& w, double k);
// The displacements of the model-prediction measure: ±a about W's x and y and ±d along them
// (FrontierOptions::prediction_rotation_rad, prediction_translation_m: 1 mrad and 0.1 mm by
// default), about the tool's centre of mass (a tilt of a resting face either way, a slide), and
// ± FrontierOptions::prediction_yaw_rad about W's z where it is set.
std::vector<Twist> PredictionDisplacements(const FrontierOptions& options);
// Every how many poses the prediction measure samples (about 20 poses).
std::size_t PredictionStride(std::size_t poses);
// The displaced tool-mesh poses X_WFt of the prediction measure: each sampled pose's tool (frame
// T, X_TFt from the mesh frame) displaced by each of PredictionDisplacements().
std::vector<RigidTransform> PredictionPoses(const std::vector<RigidTransform>& poses_WFt,
                                            const RigidTransform& X_TFt,
                                            const FrontierOptions& options);
// Runs the timed steps of setting run.setting on `scene` at the tool-mesh poses `poses_WFt`
// (single thread; `consecutive`: one pose after the other as a trace's rows, with `switch_lag`
// rows of lag; FCL's setting on `fcl`), filling `run`'s records.
void RunSetting(const BenchmarkScene& scene, const std::vector<RigidTransform>& poses_WFt,
                const MeshContactBaseline& fcl, bool consecutive, int switch_lag,
                const FrontierOptions& frontier_options, SettingRun& run);

// frontier_metrics.cc:
// The metrics of `run` (run.m): timings, the texture-stage errors against the jobs' ground truth
// (the baselines against `reference_gt`, the default setting's per pose), poses missed or
// invented against FCL's `touching`, and the errors against the pipeline and volume truths.
void ComputeMetrics(SettingRun& run, const std::vector<GtJob>& jobs,
                    const std::vector<Wrench>& reference_gt, const std::vector<bool>& touching,
                    const std::vector<PoseTruth>& pipeline);
// The model-prediction measure of `run`: its contact models' wrenches at the displaced poses
// against the pipeline truth there (relative RMS), where both exist.
void ScorePrediction(const std::vector<PoseTruth>& displaced_truth, SettingRun& run);
// A pressure-law setting's Metrics::pressure_* against the pressure law's truth of each pose
// (`pipeline`'s pressure_per_kp) at k_p (N/m³); nothing for the other settings.
void ScorePressure(const std::vector<PoseTruth>& pipeline, double k_p, SettingRun& run);
// Marks the runs no other run beats in both step time (p50) and pipeline force error.
void MarkPareto(std::vector<SettingRun>& runs);

// v with `precision` significant digits ("nan" when not finite).
std::string Fmt(double v, int precision = 4);
// "px,py,pz,qw,qx,qy,qz" of a pose (m; the unit quaternion).
void WriteQuat(std::ostream& o, const RigidTransform& X);
// "fx,fy,fz,tx,ty,tz" of a wrench (N, N·m).
void WriteWrench(std::ostream& o, const Wrench& F);

// The header lines of contacts.csv (a row per contact of every setting at every pose) and
// patches.csv (a row per pipeline-truth patch).
void WriteContactsHeader(std::ostream& o);
void WritePatchesHeader(std::ostream& o);
// One row of patches.csv: patch q of pose k (tool mesh at X_WFt, its centre of mass at com_W; the
// object at X_WFe with its stiffness).
void WritePatchRow(std::ostream& o, const SceneReport& rep, std::size_t k, std::size_t q,
                   const TruthPatch& patch, const RigidTransform& X_WFt,
                   const RigidTransform& X_WFe, const glm::dvec3& com_W, double stiffness_n_per_m);
// One row of contacts.csv: contact c of `run` with its texture-stage ground truth `job`, the tool
// mesh at X_WFt.
void WriteContactRow(std::ostream& o, const SceneReport& rep, const SettingRun& run,
                     const ContactRecord& c, const GtJob& job, const RigidTransform& X_WFt);
// frontier.csv: a row per scene and setting.
void WriteFrontierCsv(const std::string& path, const std::vector<SceneReport>& reports);
// summary.md: the measures explained, then per scene its figures, table and verdicts.
// `plot_note` says why frontier.png is missing ("" when written); `total_s` the run's time.
void WriteSummary(const std::string& path, const FrontierOptions& options,
                  const std::vector<SceneReport>& reports, const std::string& plot_note,
                  double total_s);

}  // namespace ht::frontier
