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
#include "frontier_records.h"
#include "haptic_core/accuracy/contact_patch_truth.h"
#include "haptic_core/accuracy/mesh_contact_baseline.h"
#include "haptic_core/gpu_penetration_depth.h"
#include "haptic_core/haptic_scene.h"
#include "haptic_core/model_build/surface_error.h"
#include "haptic_core/remote_step.h"
#include "slave_sim/benchmark_scenes.h"

namespace ht::frontier {
namespace {

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

// The relative change of the pressure law's truth at which its grid stops doubling
// (ContactPatchTruthOptions::pressure_tolerance).
constexpr double kPressureTruthTolerance = 0.01;

// The pipeline truth of every pose (ContactPatchTruth, one per thread), with progress.
// With `pressure`, each patch's pressure-law truth too (step 4b, refined to
// kPressureTruthTolerance).
void RunPipelineTruth(const BenchmarkScene& scene, const RayCastSurface& tool,
                      const RayCastSurface& object, const std::vector<RigidTransform>& poses_WFt,
                      const FrontierOptions& options, bool pressure, std::vector<PoseTruth>& out) {
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
  if (pressure) truth_options.pressure_tolerance = kPressureTruthTolerance;
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
// A progress line on stderr ("[frontier] ..."), when options.progress.
template <typename... Args>
void Say(const FrontierOptions& options, const char* fmt, Args... args) {
  if (!options.progress) return;
  std::fprintf(stderr, "[frontier] ");
  std::fprintf(stderr, fmt, args...);
  std::fprintf(stderr, "\n");
}

// The scenes to run: options.scenes, else the defaults. Throws std::invalid_argument naming an
// unknown scene, or a trace for a scene not run or a file that does not exist.
std::vector<std::string> ChosenScenes(const FrontierOptions& options) {
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
  return scenes;
}

// The settings to run: FrontierSettings(), kept to options.settings where given. Throws
// std::invalid_argument naming an unknown setting.
std::vector<FrontierSetting> ChosenSettings(const FrontierOptions& options) {
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
  return settings;
}

// One scene's models, built once per (texture size, coarse scale, textured) through the cache.
class SceneBuilds {
 public:
  SceneBuilds(std::string name, const HapticModelCache& cache)
      : name_(std::move(name)), cache_(cache) {}

  // Builds on first use; throws std::runtime_error naming the scene and the setting.
  const BuiltBenchmark& For(const BenchmarkModelSettings& b) {
    auto& slot = built_[{b.texture_size, b.coarse_scale, b.textured}];
    if (!slot) {
      try {
        slot = std::make_unique<BuiltBenchmark>(
            MakeBuiltBenchmark(MakeBenchmarkScene(name_, b, cache_)));
      } catch (const std::exception& e) {
        throw std::runtime_error("scene " + name_ + " (texture " + std::to_string(b.texture_size) +
                                 ", coarse x" + Fmt(b.coarse_scale) + "): " + e.what());
      }
    }
    return *slot;
  }
  // The textured build of a setting, or null when none was made.
  const BuiltBenchmark* Find(int texture_size, double coarse_scale) const {
    const auto found = built_.find({texture_size, coarse_scale, true});
    return found != built_.end() ? found->second.get() : nullptr;
  }

 private:
  std::string name_;
  const HapticModelCache& cache_;
  std::map<std::tuple<int, double, bool>, std::unique_ptr<BuiltBenchmark>> built_;
};

// The scene's full-resolution meshes into out_dir/meshes (once), and what the report says of
// them.
void WriteSceneMeshes(const FrontierOptions& options, const BenchmarkScene& ref, SceneReport& rep) {
  rep.tool_file = ref.tool_name + ".glb";
  rep.object_file = ref.object_name + ".glb";
  rep.tool_full = static_cast<std::int64_t>(ref.tool_mesh_Ft->triangles.size());
  rep.object_full = static_cast<std::int64_t>(ref.object_mesh_Fe->triangles.size());
  for (const auto& [file, mesh] : {std::pair{rep.tool_file, ref.tool_mesh_Ft},
                                   std::pair{rep.object_file, ref.object_mesh_Fe}}) {
    const std::string path = options.out_dir + "/meshes/" + file;
    if (!std::filesystem::exists(path)) {
      WriteGlb(path + ".partial", {{file.substr(0, file.size() - 4), *mesh, glm::dmat4(1.0), ""}});
      std::filesystem::rename(path + ".partial", path);
    }
  }
  rep.mesh_note =
      (rep.name == "fig75" || rep.name == "fig76")
          ? "procedural (haptic_core/demo/procedural_models.h), the same code that makes "
            "the haptic models; also written by `slave_sim seed-models`"
          : "procedural seed analogues (haptic_core/demo/seed_models.h), as written by "
            "`slave_sim seed-models`; the haptic models are decimated and baked "
            "from them through the model cache";
}

// The tool mesh's poses X_WFt: rows in contact of the scene's trace, or the scripted motion.
// Throws std::runtime_error when none is in contact.
std::vector<RigidTransform> ScenePoses(const FrontierOptions& options, const BenchmarkScene& ref,
                                       int pose_count, SceneReport& rep) {
  std::vector<RigidTransform> poses;
  const auto trace = options.traces.find(rep.name);
  if (trace != options.traces.end()) {
    poses = PosesFromTrace(trace->second, ref, pose_count, options.trace_from_s);
    rep.pose_source = "rows in contact of the run trace " + trace->second;
  } else {
    Say(options, "%s: finding %d in-contact poses on the full-resolution meshes", rep.name.c_str(),
        pose_count);
    poses = ScriptedContactPoses(ref, pose_count);
    rep.pose_source =
        "scripted motion (ScriptedContactPoses): lowered until the full-resolution meshes touch, "
        "then pressed 0.02-0.4 mm further";
  }
  if (poses.empty()) throw std::runtime_error("scene " + rep.name + ": no in-contact pose found");
  rep.poses = static_cast<int>(poses.size());
  return poses;
}

// Progress over all scenes' settings.
struct Units {
  int done = 0;
  int total = 0;
};

// The timed steps of every setting, one after the other, on this thread alone (rep.runs); each
// contact's window joins the texture-stage ground truth's jobs (windows equal bit for bit are one
// job).
void RunTimedSettings(const FrontierOptions& options, const std::vector<FrontierSetting>& settings,
                      SceneBuilds& builds, const std::vector<RigidTransform>& poses,
                      const MeshContactBaseline& fcl, bool consecutive, Units& units,
                      SceneReport& rep, std::vector<GtJob>& jobs) {
  const std::string& name = rep.name;
  std::map<std::string, int> job_index;
  for (const FrontierSetting& st : settings) {
    SettingRun run;
    run.setting = st;
    ++units.done;
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
      const BuiltBenchmark& models = builds.For(b);
      const BenchmarkScene& scene = models.scene;
      if (!scene.texture_note.empty()) run.note = "texture sizes " + scene.texture_note;
      run.tool_surface = models.tool_surface;
      run.object_surface = models.object_surface;
      const auto t0 = Clock::now();
      RunSetting(scene, poses, fcl, consecutive, consecutive ? options.switch_lag_rows : 0, options,
                 run);
      for (ContactRecord& c : run.contacts) {
        const std::string key = GtKey(c.pose, run.X_TFt, c.query.window, c.query.stiffness_n_per_m);
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
      Say(options, "%s: setting %d/%d done (%s, %.1f s)%s%s", name.c_str(), units.done, units.total,
          st.name.c_str(), Seconds(t0),
          run.skipped.empty() ? "" : ": skipped: ", run.skipped.c_str());
    }
    rep.runs.push_back(std::move(run));
  }
}

// The pipeline truth's figures of the scene (rep.truth_*), and its patches' rows of patches.csv.
void RecordPipelineTruth(const BenchmarkScene& ref, const std::vector<RigidTransform>& poses,
                         const std::vector<PoseTruth>& pipeline, SceneReport& rep,
                         std::ostream& pc) {
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
      const glm::dvec3 com_W = poses[k] * ref.X_TFt.Inverse().translation;
      WritePatchRow(pc, rep, k, q, patch, poses[k], ref.haptic.touchables.at(0).X_WO, com_W,
                    ref.haptic.touchables.at(0).stiffness_n_per_m);
    }
  }
}

// The texture-stage ground truth's figures of the scene (rep.gt_*).
void RecordGroundTruth(const std::vector<GtJob>& jobs, SceneReport& rep) {
  rep.gt_windows = jobs.size();
  for (const GtJob& j : jobs) {
    rep.gt_converged += j.result.base.converged;
    if (std::isfinite(j.result.base.change_m)) {
      rep.gt_change_max_m = std::max(rep.gt_change_max_m, j.result.base.change_m);
    }
    rep.gt_rays += j.result.rays;
    rep.gt_m.push_back(j.result.base.samples_per_side);
  }
}

// One scene: its models, poses, every setting's timed steps, the truths, every setting's
// metrics, and its rows of contacts.csv (cc) and patches.csv (pc).
SceneReport RunScene(const FrontierOptions& options, const std::string& name,
                     const std::vector<FrontierSetting>& settings, const HapticModelCache& cache,
                     int pose_count, Units& units, Clock::time_point t_start, std::ostream& cc,
                     std::ostream& pc) {
  SceneReport rep;
  rep.name = name;
  Say(options, "%s: building the models (cache: %s)", name.c_str(),
      options.cache_dir.empty() ? "none" : options.cache_dir.c_str());
  SceneBuilds builds(name, cache);
  const BenchmarkScene& ref = builds.For({}).scene;
  WriteSceneMeshes(options, ref, rep);
  const std::vector<RigidTransform> poses = ScenePoses(options, ref, pose_count, rep);
  const bool consecutive =
      options.traces.find(name) != options.traces.end() && options.trace_from_s >= 0.0;
  const RigidTransform X_WFe = ref.haptic.touchables.at(0).X_WO;
  const MeshContactBaseline fcl(*ref.tool_mesh_Ft, *ref.object_mesh_Fe);
  std::vector<bool> touching;
  for (const RigidTransform& X : poses) touching.push_back(fcl.Intersects(X, X_WFe));
  rep.touching = static_cast<int>(std::count(touching.begin(), touching.end(), true));

  std::vector<GtJob> jobs;
  RunTimedSettings(options, settings, builds, poses, fcl, consecutive, units, rep, jobs);

  // The ground truth of every distinct window, on all threads.
  Say(options, "%s: ground truth of %zu windows on %d thread(s)", name.c_str(), jobs.size(),
      options.threads);
  const auto t_gt = Clock::now();
  const RayCastSurface tool_rays(*ref.tool_mesh_Ft);
  const RayCastSurface object_rays(*ref.object_mesh_Fe);
  RunGroundTruth(ref, tool_rays, object_rays, jobs, options);
  rep.gt_seconds = Seconds(t_gt);
  // The pipeline truth of every pose: from the full-resolution meshes alone.
  Say(options, "%s: pipeline truth of %zu poses on %d thread(s)", name.c_str(), poses.size(),
      options.threads);
  const auto t_truth = Clock::now();
  std::vector<PoseTruth> pipeline;
  const bool pressure =
      std::any_of(settings.begin(), settings.end(),
                  [](const FrontierSetting& st) { return st.force_law == ForceLaw::kPressure; });
  RunPipelineTruth(ref, tool_rays, object_rays, poses, options, pressure, pipeline);
  // The truth at the prediction measure's displaced poses.
  std::vector<PoseTruth> displaced_truth;
  if (options.model_prediction) {
    const std::vector<RigidTransform> displaced = PredictionPoses(poses, ref.X_TFt, options);
    Say(options, "%s: pipeline truth of %zu displaced poses (model prediction)", name.c_str(),
        displaced.size());
    RunPipelineTruth(ref, tool_rays, object_rays, displaced, options, false, displaced_truth);
  }
  rep.truth_seconds = Seconds(t_truth);
  RecordPipelineTruth(ref, poses, pipeline, rep, pc);
  RecordGroundTruth(jobs, rep);

  // The pressure law's k_p as the method's fields take it by default (PipelineOptions).
  const double pressure_stiffness = ref.haptic.touchables.at(0).stiffness_n_per_m /
                                    std::max(ToolContactArea(*ref.haptic.tool), 1e-12);
  // The default setting's ground truth per pose: the truth for the baselines.
  std::vector<Wrench> reference_gt(poses.size());
  for (const ContactRecord& c : rep.runs.front().contacts) {
    reference_gt[c.pose] += jobs[c.gt].result.F_T_W;
  }
  for (SettingRun& run : rep.runs) {
    if (!run.skipped.empty()) continue;
    ComputeMetrics(run, jobs, reference_gt, touching, pipeline);
    if (run.setting.method != FrontierMethod::kCoarseOnly) {
      if (const BuiltBenchmark* built =
              builds.Find(run.setting.texture_size, run.setting.coarse_scale)) {
        AddLocalSurfaceErrors(*built, poses, pipeline, run);
      }
    }
    ScorePrediction(displaced_truth, run);
    ScorePressure(pipeline, pressure_stiffness, run);
    for (const ContactRecord& c : run.contacts) {
      WriteContactRow(cc, rep, run, c, jobs[c.gt], poses[c.pose]);
    }
  }
  MarkPareto(rep.runs);
  Say(options, "%s: done (%.0f s so far)", name.c_str(), Seconds(t_start));
  return rep;
}

// frontier.png from frontier.csv by the plot script; "" when written, else why not.
std::string PlotFrontier(const FrontierOptions& options) {
  if (options.plot_script.empty()) return "frontier.png was not written (no plot script given)";
  const std::string cmd = "/usr/bin/python3 '" + options.plot_script + "' '" + options.out_dir +
                          "/frontier.csv' '" + options.out_dir + "/frontier.png'";
  const int rc = std::system(cmd.c_str());
  if (rc == 0) return "";
  std::string note = "frontier.png was not written (`" + cmd + "` exited with " +
                     std::to_string(rc) +
                     "; it needs /usr/bin/python3 with matplotlib: apt-get install "
                     "python3-matplotlib)";
  Say(options, "%s", note.c_str());
  return note;
}

}  // namespace
}  // namespace ht::frontier

namespace ht {

void RunSpeedErrorFrontier(const FrontierOptions& options) {
  using namespace frontier;
  if (options.out_dir.empty()) throw std::invalid_argument("--out DIR is required");
  options.ground_truth.Validate();
  const std::vector<std::string> scenes = ChosenScenes(options);
  const int pose_count = options.poses > 0 ? options.poses : (options.quick ? 12 : 200);
  const std::vector<FrontierSetting> settings = ChosenSettings(options);
  std::filesystem::create_directories(options.out_dir + "/meshes");
  // Nothing of an earlier run may be taken for this one's.
  for (const char* f :
       {"summary.md", "frontier.csv", "contacts.csv", "patches.csv", "frontier.png"}) {
    std::filesystem::remove(options.out_dir + "/" + f);
  }
  const HapticModelCache cache(options.cache_dir);
  const auto t_start = Clock::now();

  PartialFile contacts_csv(options.out_dir + "/contacts.csv");
  std::ostream& cc = contacts_csv.out();
  cc.precision(10);
  WriteContactsHeader(cc);
  PartialFile patches_csv(options.out_dir + "/patches.csv");
  std::ostream& pc = patches_csv.out();
  pc.precision(10);
  WritePatchesHeader(pc);
  std::vector<SceneReport> reports;
  Units units{0, static_cast<int>(scenes.size() * settings.size())};
  for (const std::string& name : scenes) {
    reports.push_back(RunScene(options, name, settings, cache, pose_count, units, t_start, cc, pc));
  }
  contacts_csv.Commit();
  patches_csv.Commit();

  WriteFrontierCsv(options.out_dir + "/frontier.csv", reports);
  const std::string plot_note = PlotFrontier(options);
  WriteSummary(options.out_dir + "/summary.md", options, reports, plot_note, Seconds(t_start));
  Say(options, "wrote %s/{frontier.csv,contacts.csv,patches.csv,summary.md%s,meshes/} in %.0f s",
      options.out_dir.c_str(), plot_note.empty() ? ",frontier.png" : "", Seconds(t_start));
}

}  // namespace ht
