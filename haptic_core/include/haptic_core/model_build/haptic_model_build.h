#pragma once
// The haptic model build (DESIGN.md §2, seed §19.4): full-resolution mesh → coarse mesh (quadric
// decimation) → haptic texture (height field baked by ray casting) → bounding volume hierarchy of
// convex hulls, plus mass properties; cached on disk by content.

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "haptic_core/haptic_model.h"
#include "haptic_core/model_build/hull_hierarchy_build.h"
#include "haptic_core/model_build/mesh_decimation.h"
#include "haptic_core/model_build/surface_error.h"
#include "haptic_core/model_build/texture_bake.h"

namespace ht {

/// The texture size from the surface's detail (model only what a scene needs): the
/// atlas side chosen per object from the error each size leaves between the full-resolution
/// surface and the textured coarse model (MeasureSurfaceError's p99 distance, surface_error.h),
/// instead of one size for every object. Our rule [R]: bake at min_size, then double while
///  - the surface error p99 is above surface_budget_m, and
///  - the last doubling lowered it by at least min_improvement (a fraction): past the size where
///    doubling stops helping, what error is left is the coarse mesh's (a fold or a surface no ray
///    of the coarse surface reaches), not the texture's, and a larger texture is memory and
///    bandwidth for nothing;
/// keeping the smallest size that met the budget, else the size before a doubling that did not
/// help, else max_size. Each trial is a full bake (the atlas layout depends on the size, so a
/// coarser mip level of one bake is not the smaller bake), about 4^k times a min_size bake.
struct TextureSizingParams {
  /// False: TextureBakeParams::texture_size as given. True: the rule above (texture_size is then
  /// ignored).
  bool from_detail = false;
  /// Surface error p99 (m) at which a size is enough; > 0. The default is the depth error the
  /// issue asks of the texture stage (δ p50 ≤ 10 µm).
  double surface_budget_m = 10e-6;
  /// Least fractional drop of the p99 that a doubling must give to be worth it; in [0, 1).
  double min_improvement = 0.15;
  /// Sizes tried: powers of two with 16 ≤ min_size ≤ max_size ≤ 8192.
  int min_size = 256;
  int max_size = 4096;

  /// Throws std::invalid_argument naming a value out of range.
  void Validate() const;
};

/// One size tried by ChooseTextureSize.
struct TextureSizeTrial {
  int size = 0;                        ///< Atlas side (texels).
  double surface_p99_m = 0.0;          ///< SurfaceErrorReport::p99_m of the model at that size.
  double surface_outside_p99_m = 0.0;  ///< SurfaceErrorReport::outside_p99_m.
  double seconds = 0.0;                ///< Bake and measure (s).
};

/// What ChooseTextureSize chose and why.
struct TextureSizeChoice {
  int size = 0;  ///< Atlas side chosen (texels): the last size tried or the one before.
  std::vector<TextureSizeTrial> trials;
  /// One sentence with the figures that decided it.
  std::string reason;
};

/// Applies TextureSizingParams' rule (from_detail is not read): `measure(size)` builds the model
/// at that atlas side and returns its surface error (samples = 0 when it cannot be measured: the
/// size tried is then kept, and the reason says so). Throws std::invalid_argument for bad params,
/// and what `measure` throws.
TextureSizeChoice ChooseTextureSize(const TextureSizingParams& params,
                                    const std::function<SurfaceErrorReport(int size)>& measure);

/// What to build for one object. Every field enters the cache key (texture_sizing's only when
/// from_detail, so that fixed-size keys are those of older builds).
struct HapticModelBuildParams {
  /// Coarse triangle target (seed: a few hundred to a few thousand).
  int coarse_triangles = 500;
  /// Haptic texture bake (texture_size is the atlas side in texels).
  TextureBakeParams texture;
  /// The atlas side per object from its detail (off by default: texture.texture_size).
  TextureSizingParams texture_sizing;
  /// Convex-hull hierarchy.
  HullHierarchyParams hulls;
  /// Density (kg/m³) for the mass properties of a closed coarse mesh.
  double density_kg_per_m3 = 1000.0;
};

/// Figures of one build, for `slave_sim inspect` and the notes.
struct HapticModelBuildReport {
  std::string name;
  std::int64_t full_triangles = 0;
  std::int64_t coarse_triangles = 0;
  /// Decimation details (welded vertices, dropped non-manifold triangles, boundary edges).
  std::int64_t welded_vertices = 0;
  std::int64_t dropped_non_manifold_triangles = 0;
  std::int64_t input_boundary_edges = 0;
  std::int64_t coarse_boundary_edges = 0;
  /// Hierarchy size: all nodes, and leaves (convex surface patches).
  int hull_nodes = 0;
  int hull_leaves = 0;
  int hull_depth = 0;
  int texture_size = 0;
  /// With TextureSizingParams::from_detail: each size tried and why texture_size was chosen
  /// (stored in the cache with the model); empty trials and reason otherwise.
  std::vector<TextureSizeTrial> texture_trials;
  std::string texture_size_reason;
  /// HapticModel::OutwardReach() of the built model (m).
  double outward_reach_m = 0.0;
  TextureBakeReport bake;
  /// How far the full-resolution surface lies from the built model (MeasureSurfaceError at its
  /// default 4096 samples): the bake's validation samples the coarse surface, this the full one.
  /// Measured on every build and on every cache hit (not stored; about 0.05-0.5 s); samples = 0
  /// when the measure failed.
  SurfaceErrorReport surface;
  /// Wall time per stage (s); zeros for stages skipped because the cache had the model.
  double decimate_s = 0.0;
  double bake_s = 0.0;
  double hulls_s = 0.0;
  double cache_load_s = 0.0;
  double total_s = 0.0;
  /// True when the model came from the cache instead of being built.
  bool from_cache = false;
  /// Hex digest naming the cache entry ("" when no cache was used).
  std::string cache_key;
  /// Why a cache entry present on disk was not used ("" when none or used).
  std::string cache_note;
};

/// A built model and its report.
struct HapticModelBuild {
  std::shared_ptr<const HapticModel> model;
  HapticModelBuildReport report;
};

/// Builds the haptic model of the closed (or open) surface `full_O` (#V vertices, #F triangles,
/// counter-clockwise seen from outside, frame O, metres): DecimateQuadric() to
/// params.coarse_triangles, BakeHapticTexture() of the detail, BuildConvexHullHierarchy() over
/// the coarse mesh (its root hull's vertices become HapticModel::hull_vertices_O), and mass,
/// centre of mass and inertia of the coarse solid at params.density (from its bounding box when the
/// coarse mesh is open or has no positive volume). Throws what the stages throw
/// (std::invalid_argument for bad meshes or parameters, naming `name`).
HapticModelBuild BuildHapticModel(const std::string& name, const TriangleMesh& full_O,
                                  const HapticModelBuildParams& params);

/// Hex BLAKE2b-256 of everything a build depends on: the build format version, `full_O`'s
/// vertices and triangles (bit exact), and every field of `params`. Equal keys mean equal builds.
std::string HapticModelCacheKey(const TriangleMesh& full_O, const HapticModelBuildParams& params);

/// The on-disk cache of built models: one file per key, `<dir>/<key>.htmodel`, written to a
/// temporary name and renamed (a crash never leaves a half file under the final name).
class HapticModelCache {
 public:
  /// `dir` is created on first Store(). An empty `dir` disables the cache.
  explicit HapticModelCache(std::string dir) : dir_(std::move(dir)) {}

  /// The default folder: $HT_CACHE_DIR, else $XDG_CACHE_HOME/haptic_teleop, else
  /// $HOME/.cache/haptic_teleop, else "" (no cache).
  static std::string DefaultDir();

  const std::string& dir() const noexcept { return dir_; }

  /// Reads the entry `key`. Returns nullopt when there is none; when the file is unreadable,
  /// truncated, of another format version, for another key, or holds invalid numbers, returns
  /// nullopt and puts the reason in `*why` (the caller rebuilds and overwrites it).
  std::optional<HapticModelBuild> Load(const std::string& key, std::string* why) const;

  /// Writes `build` under `key`. Throws std::runtime_error naming the path when it cannot.
  void Store(const std::string& key, const HapticModelBuild& build) const;

 private:
  std::string dir_;
};

/// BuildHapticModel() through `cache`: a hit returns the stored model (report.from_cache, with the
/// stored stage times kept and cache_load_s set); a miss builds, stores (a failed store is noted in
/// report.cache_note, not thrown) and returns. Builds of different models may run on several
/// threads at once (each entry is written to a file of its own and renamed into place).
HapticModelBuild BuildHapticModelCached(const std::string& name, const TriangleMesh& full_O,
                                        const HapticModelBuildParams& params,
                                        const HapticModelCache& cache);

}  // namespace ht
