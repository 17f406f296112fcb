#pragma once
// The seed's benchmark scenes (DESIGN.md §7) as the speed-vs-error study needs them:
// each with its haptic models built at a chosen texture size and coarse triangle count, the
// full-resolution meshes the ground truth is computed on, and in-contact tool poses.
//
// clang-format off
//   fig75         ridged block (tool) on the ridged gear (seed Figs. 72-b, 75)
//   fig76         two identical striped blocks, interlocked; the upper one is the tool
//                 (Fig. 72-a, 76)
//   fig77         the file (tool) scraping the rough CAD part (Figs. 74, 77)
//   hammer_torus  the textured hammer (tool) touching the wrinkled helicoidal torus (Fig. 73);
//                 the hammer mesh is turned head down (a half turn about x) so that the tool's
//                 home orientation, which the operator's workspace is aligned with, is the
//                 identity
// clang-format on

#include <memory>
#include <string>
#include <vector>

#include "haptic_core/haptic_scene.h"
#include "haptic_core/model_build/haptic_model_build.h"

namespace ht {

/// What the models of a benchmark scene are built with.
struct BenchmarkModelSettings {
  /// Haptic texture side (texels; seed: 1024); 0: each model's from its surface's detail
  /// (TextureSizingParams' defaults, haptic_model_build.h; the ridged blocks and gear, which are
  /// not baked, by the same rule over their procedural textures).
  int texture_size = 1024;
  /// Coarse triangle target as a multiple of the seed's count (Table 6). The ridged blocks keep
  /// their 16 triangles (a box); the gear's prism has 400·scale sides.
  double coarse_scale = 1.0;
  /// False: the coarse meshes alone, textures dropped (a baseline).
  bool textured = true;
};

/// One benchmark scene with one environment object, ready for the remote step and for the ground
/// truth.
struct BenchmarkScene {
  /// "fig75", "fig76", "fig77" or "hammer_torus".
  std::string name;
  /// The haptic scene: tool (frame T at its centre of mass) and one touchable object. Its
  /// X_WT_home is where the seed's experiment starts: fig75 and fig76 0.5 mm above touching (the
  /// fig76 blocks interlocked), fig77 and hammer_torus 1 mm above the first full-resolution touch
  /// at x = −3 cm, identity orientation (the scene's up is +z).
  HapticScene haptic;
  /// Full-resolution meshes (frames Ft and Fe of the files written for them, metres) and names.
  std::shared_ptr<const TriangleMesh> tool_mesh_Ft, object_mesh_Fe;
  std::string tool_name, object_name;
  /// Pose of the tool mesh's frame in T (T sits at the coarse model's centre of mass). The object
  /// mesh's frame is the object's model frame: X_WFe = haptic.touchables[0].X_WO.
  RigidTransform X_TFt;
  /// Coarse triangles actually built (tool, object), and a note when a setting does not apply.
  std::int64_t tool_coarse_triangles = 0, object_coarse_triangles = 0;
  std::string note;
  /// With texture_size 0: each model's chosen size and why ("" otherwise).
  std::string texture_note;
};

/// What `slave_sim --scene` builds the benchmark scene `name` with: the seed's Table 6 coarse
/// counts at 1024² (the default BenchmarkModelSettings), except
///  - fig77 (the file on the CAD part): twice the seed's coarse triangles at 2048²;
///  - hammer_torus: four times the seed's coarse triangles, each texture sized from its model's
///    detail (texture_size 0: 4096² for both).
/// Measured: docs/measurements.md. The frontier's "product" setting; its "default" keeps the
/// seed's counts for the comparison.
BenchmarkModelSettings ProductModelSettings(const std::string& name);

/// The scene names, in the order above.
const std::vector<std::string>& BenchmarkSceneNames();

/// The benchmark scene that `slave_sim --scene NAME` builds for its built-in scene NAME, with
/// ProductModelSettings: "striped-blocks" → "fig76", "file-on-cad-part" → "fig77",
/// "hammer-on-torus" → "hammer_torus". Empty for any other name (block-on-gear and stiff-wall
/// are made by demo_scenes.h, anything else is a file).
std::string BenchmarkSceneOfBuiltin(const std::string& scene);

/// Builds scene `name` with `settings`; models from files go through `cache` (the seed models are
/// generated procedurally, then decimated, baked and cached; about a minute each when cold).
/// Throws std::invalid_argument for an unknown name (listing the known ones) or bad settings, and
/// what the model build throws.
BenchmarkScene MakeBenchmarkScene(const std::string& name, const BenchmarkModelSettings& settings,
                                  const HapticModelCache& cache);

/// `count` in-contact poses X_WFt of the tool MESH's frame for a scene, from a scripted motion
/// of the seed's kind (fig75: sliding along and across the ridges; fig76: small oscillating
/// rotations about n, interlocked; fig77: scraping along the part with sway and yaw; hammer:
/// along the torus's tube with wobble). At each, the tool is first lowered along W's −z (the
/// scene's up is +z) until its full-resolution mesh touches the object's (bisection on FCL's
/// intersection test, to 10 nm), then pushed down a further depth that cycles through 0.05–0.4
/// mm (0.02–0.2 mm for the interlocked blocks): true penetrations of the size the 1.5 N presses of
/// the runs give. Poses where no touching height is found are skipped, so fewer may come back.
std::vector<RigidTransform> ScriptedContactPoses(const BenchmarkScene& scene, int count);

/// Poses X_WFt from a run's trace.csv (master_station: tool_x..tool_rz is X_WT), keeping rows
/// with at least one contact, `count` of them evenly spread, or with `from_s` ≥ 0 the first
/// `count` of them at or after t_s = from_s (s), consecutive. Throws std::runtime_error naming the
/// file when it cannot be read or lacks the columns.
std::vector<RigidTransform> PosesFromTrace(const std::string& trace_csv,
                                           const BenchmarkScene& scene, int count,
                                           double from_s = -1.0);

}  // namespace ht
