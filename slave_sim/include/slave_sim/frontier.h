#pragma once
// The speed-vs-error frontier: every setting of the remote step (grid N, texture size,
// coarse triangle count, threads, depth fields, CPU or GPU backend) and two baselines a user might
// pick instead (coarse meshes without textures; full-resolution meshes through FCL), run on
// in-contact poses of the seed's benchmark scenes and measured, in one run on one machine, for time
// per step and for error against the full-resolution ground truth (haptic_core/accuracy).

#include <map>
#include <string>
#include <vector>

#include "haptic_core/accuracy/contact_patch_truth.h"
#include "haptic_core/accuracy/ground_truth_depth.h"
#include "haptic_core/contact_linearization.h"
#include "haptic_core/contact_model.h"
#include "haptic_core/remote_step.h"

namespace ht {

/// How a setting computes the contact wrench.
enum class FrontierMethod {
  kTexture,            ///< The method: coarse query, clustering, texture penetration depth.
  kCoarseOnly,         ///< The same pipeline on the coarse meshes with the textures dropped.
  kFullResolutionFcl,  ///< FCL contacts between the full-resolution meshes, Σ k·d·n.
};

/// "texture", "coarse_only", "fcl_full_resolution".
const char* FrontierMethodName(FrontierMethod method) noexcept;

/// One point of the sweep.
struct FrontierSetting {
  std::string name;  ///< Row name in the outputs: "default", "grid16", "texture256", "gpu16", …
  FrontierMethod method = FrontierMethod::kTexture;  ///< What computes the wrench.
  int grid = 50;                                     ///< N of the penetration-depth grid.
  int texture_size = 1024;    ///< Haptic texture side (texels); 0: each model's from its detail.
  double coarse_scale = 1.0;  ///< Coarse triangle target × the seed's count.
  /// True: the texture size and coarse scale are the product's for each scene
  /// (ProductModelSettings), not the two fields above ("product").
  bool product_models = false;
  std::string backend = "cpu";  ///< "cpu" or "gpu".
  int depth_bits = 32;          ///< GPU depth precision (16 or 32); the CPU works in float.
  /// CPU texture stage: the fast path (the product's) or the reference it replaced,
  /// and its threads, which the coarse query's traversal uses too (timings are single-thread
  /// unless a setting says otherwise).
  TextureStagePath texture_path = TextureStagePath::kFast;
  int texture_threads = 1;
  /// PipelineOptions::refine_depth (on; "grid_only" and the grid-alone settings "gridN" turn it
  /// off, "grid16_refined" keeps it).
  bool refine_depth = true;
  /// PipelineOptions::depth_fields ("depth_fields"): each pose's force at q0 and the model's
  /// prediction are its depth fields' (evaluated as the operator's loop does); the per-contact
  /// columns stay the linearization's.
  bool depth_fields = false;
  /// PipelineOptions::force_law ("pressure": the depth fields under the pressure law, scored
  /// against that law's own truth, Metrics' pressure_*).
  ForceLaw force_law = ForceLaw::kSeed;
};

/// The sweep: the default setting (grid 50, 1024² textures, the seed's coarse counts, CPU) first,
/// then the grid alone at N ∈ {50, 16, 100} ("grid_only", "grid16", "grid100"), stage 5b on the
/// 16 grid ("grid16_refined"), texture size 256 and 2048, coarse ×2, the product's models
/// ("product"), the reference texture path ("reference", the path the fast one replaced: the same
/// error, its time), the fast path on two threads ("threads2"), the contact model as depth fields
/// ("depth_fields") and the same under the pressure law ("pressure"), the GPU at 16 depth bits
/// (when `with_gpu`), and the two baselines. `quick` leaves out texture 2048, "product",
/// "threads2", "depth_fields" and "pressure".
std::vector<FrontierSetting> FrontierSettings(bool quick, bool with_gpu);

/// The remote step's options of a texture-method setting (`st.method` kTexture): every
/// PipelineOptions field the setting names, the rest PipelineOptions' defaults. The backend's own
/// choices (texture path, rotation gradient, GPU depth bits) are the caller's to make from `st`.
PipelineOptions PipelineOptionsFor(const FrontierSetting& st);

/// The setting of FrontierSettings(false, with_gpu) named `name`; throws std::invalid_argument
/// naming it when there is none, or when it is not a texture-method setting.
FrontierSetting FrontierSettingNamed(const std::string& name, bool with_gpu = false);

/// Options of a run.
struct FrontierOptions {
  /// Output folder (created). Written there: frontier.csv, contacts.csv, patches.csv (the
  /// pipeline truth's patches, contact_patch_truth.h), meshes/*.glb, summary.md and (when
  /// matplotlib is there) frontier.png.
  std::string out_dir;
  /// Fewer poses and settings, and only the procedural scenes (fig75, fig76): minutes, for ctest.
  bool quick = false;
  /// Scenes to run (BenchmarkSceneNames() when empty).
  std::vector<std::string> scenes;
  /// Settings to run, by name (all of FrontierSettings() when empty); an unknown name throws.
  std::vector<std::string> settings;
  /// In-contact poses per scene (0 = 200, or 12 with quick).
  int poses = 0;
  /// Every setting on the product's models (ProductModelSettings per scene) instead of the
  /// texture size and coarse scale it names: to take the product's own errors apart with the
  /// other settings (e.g. "reference", "grid_only") on the models slave_sim builds.
  bool on_product_models = false;
  /// Scene name → a run's trace.csv to take the poses from (else ScriptedContactPoses).
  std::map<std::string, std::string> traces;
  /// With traces: ≥ 0 takes `poses` consecutive rows in contact from this time (s) on instead of
  /// spreading them over the run (PosesFromTrace), and adds the model-switch measure: along
  /// those rows, the model made switch_lag_rows rows earlier evaluated at each row's pose against
  /// that row's own model (frontier.csv switch_jump_*: the force steps a delayed linear model
  /// leaves the operator's loop, on one trajectory for every setting). −1: spread, no measure.
  double trace_from_s = -1.0;
  /// Rows between the held model and the next one (the loop's model age in ticks). ≥ 1.
  int switch_lag_rows = 2;
  /// Model cache folder ("" = none).
  std::string cache_dir;
  /// Include the GPU settings (through EGL; llvmpipe without a GPU).
  bool gpu = true;
  /// Threads for the ground truth (the timed steps always run on one).
  int threads = 2;
  /// The ground truth's resolution and convergence.
  GroundTruthOptions ground_truth;
  /// The pipeline truth merges patches that measure one interpenetration twice and slivers at a
  /// patch's edge (ContactPatchTruthOptions::overlap_merge_angle_deg, minor_patch_fraction);
  /// false: the single-linkage patches as they are.
  bool truth_merge_patches = true;
  /// The pipeline truth's share fade (ContactPatchTruthOptions::share_fade_m, m; 0: separate
  /// patches always sum).
  double truth_share_fade_m = ContactPatchTruthOptions{}.share_fade_m;
  /// The pipeline truth's tilt step as a lift at half the window (ContactPatchTruthOptions::
  /// tilt_lift_m, m; 0: a texel step's lift, the default measure).
  double truth_tilt_lift_m = ContactPatchTruthOptions{}.tilt_lift_m;
  /// The model-prediction measure (the operator's linearized model at displaced poses against the
  /// pipeline truth there): a second pipeline truth, on deeper poses, which costs about as much as
  /// the first; false leaves its columns NaN.
  bool model_prediction = true;
  /// The model-prediction measure's displacements: ±this along W's x and y (m, > 0) …
  double prediction_translation_m = 1e-4;
  /// … and ±this about them (rad, > 0), each about the tool's centre of mass.
  double prediction_rotation_rad = 1e-3;
  /// … and, when > 0, ±this about W's z too (rad; 0: none).
  double prediction_yaw_rad = 0.0;
  /// The plotting script (python3 + matplotlib), "" = no plot.
  std::string plot_script;
  /// The command line, for summary.md.
  std::string command_line;
  /// Progress lines on stderr.
  bool progress = true;
};

/// Runs the study and writes its files. Each file is written under a temporary name and renamed
/// when complete, summary.md last, so a run that fails leaves nothing that looks finished.
/// Throws std::invalid_argument for bad options or an unknown scene, std::runtime_error when a
/// scene cannot be built or a file cannot be written.
void RunSpeedErrorFrontier(const FrontierOptions& options);

}  // namespace ht
