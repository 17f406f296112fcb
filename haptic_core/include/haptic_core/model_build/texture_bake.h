#pragma once
// Haptic texture bake (DESIGN.md §2): the height field h over a coarse mesh such that the
// full-resolution surface is p_full = p_coarse + h·N, found by casting rays from the coarse surface
// along its interpolated unit normal N to the full-resolution mesh (Embree 3), stored in a
// per-triangle texture atlas with gutters.

#include <cstdint>
#include <glm/vec2.hpp>
#include <glm/vec3.hpp>
#include <vector>

#include "haptic_core/haptic_model.h"
#include "haptic_core/height_field.h"

namespace ht {

/// Settings of BakeHapticTexture().
struct TextureBakeParams {
  /// Atlas texels per side at level 0; a power of two in [16, 16384].
  int texture_size = 1024;
  /// Gutter (texels) kept around each chart, in [1, 16]: bilinear samples anywhere in a chart only
  /// read that chart's texels, and mip level k stays inside a chart's gutter when 2^k <= gutter.
  int gutter_texels = 2;
  /// Corner normals are angle-weighted vertex normals, split at edges whose dihedral angle (the
  /// angle between the two face normals, degrees) exceeds this: a box gets face normals, a smooth
  /// surface smooth ones. In [0, 180].
  double crease_angle_deg = 60.0;
  /// How far (m) from the coarse surface a ray searches along +N and along -N, and the largest
  /// |h| stored. 0 = automatic: kAutoRayDistanceFraction of the coarse mesh's bounding-box
  /// diagonal. Must be finite and >= 0.
  double max_ray_distance_m = 0.0;
  /// Random surface points (area-weighted over textured triangles) at which the baked texture is
  /// compared with a ray cast; >= 0.
  int validation_samples = 20000;
  /// Seed of the validation sample generator.
  std::uint64_t seed = 1;
  /// Worker threads for the ray casts; 0 = std::thread::hardware_concurrency().
  int threads = 0;
};

/// Automatic ray range as a fraction of the coarse mesh's bounding-box diagonal.
inline constexpr double kAutoRayDistanceFraction = 0.05;

/// What happened during a bake.
struct TextureBakeReport {
  /// Texels for which rays were cast (chart interiors and their gutters, textured or not).
  std::int64_t texels_baked = 0;
  /// Rays cast (two per surface point: one per interior texel, three per gutter texel, one per
  /// validation sample).
  std::int64_t rays = 0;
  /// Baked texels whose two rays found no full-resolution surface within range; their value is
  /// filled from neighbouring texels of the same chart, or 0 when the chart has none.
  std::int64_t misses = 0;
  /// Texel heights whose magnitude was limited to the ray range (rays search only within it, so
  /// only gutter texels, whose heights are extrapolated, can need it).
  std::int64_t clamped = 0;
  /// Largest |h| of level 0 (m).
  double max_abs_height_m = 0.0;
  /// Over the validation samples: |h sampled bilinearly from level 0 at a random point of a random
  /// textured triangle (area-weighted) - h found by a ray cast at that very point| (m); samples
  /// whose ray missed are left out and counted in validation_misses. 0 when there is no sample.
  double max_bake_error_m = 0.0;
  double rms_bake_error_m = 0.0;
  std::int64_t validation_misses = 0;
  /// The ray range used (m): params.max_ray_distance_m or the automatic value.
  double max_ray_distance_m = 0.0;
  /// Atlas layout: cell side (texels) and cells per atlas side; two charts per cell.
  int cell_texels = 0;
  int cells_per_side = 0;
  /// Wall time of the bake (s).
  double seconds = 0.0;
};

/// A baked haptic texture for one coarse mesh, in that mesh's frame O.
struct BakedTexture {
  /// Unit interpolation normals per triangle corner, frame O, #F*3 (corner c of f at 3f+c).
  std::vector<glm::dvec3> corner_normals_O;
  /// Texture coordinates in [0,1]² per triangle corner, #F*3, into `texture`.
  std::vector<glm::vec2> corner_uvs;
  /// Per triangle, #F: 1 when its chart holds heights (at least one ray hit), 0 when the triangle
  /// is degenerate or no ray of its chart found the full-resolution surface (its texels are 0).
  std::vector<std::uint8_t> textured;
  /// Per triangle, #F: metres on the surface per level-0 texel in the chart's coarsest direction
  /// (largest singular value of the affine map from atlas texels to the triangle, m/texel); 0 for
  /// a degenerate triangle.
  std::vector<double> texel_size_m;
  /// Heights h (m) along the corner normals interpolated barycentrically and normalized;
  /// texture_size² texels, clamp addressing, with mips (2×2 box filter; levels whose texel exceeds
  /// the gutter blend neighbouring charts at chart borders).
  HeightField texture;
  TextureBakeReport report;
};

/// Bakes the haptic texture of `coarse_O` (#V vertices, #F triangles) against `full_O` (the
/// full-resolution surface, same frame O, metres) [S][L] (DESIGN.md §2).
///
/// Atlas: the texture is cut into square cells of `report.cell_texels` texels, the largest that
/// fit ceil(#F/2) cells; cell k holds triangle 2k in its lower-left half and 2k+1 in its
/// upper-right half, each mapped affinely to an isosceles right triangle (the corner opposite the
/// longest edge at the right angle) inset by the gutter from the cell's border and from the
/// diagonal. Every texel of a half-cell is baked: texel centres inside the triangle directly;
/// those outside it (the gutter) get the linear function through the heights at the corners of a
/// copy of the triangle shrunk about the texel's nearest triangle point to legs of max(1, distance)
/// texels, extrapolated to the texel (by at most 1.5 texels, constant beyond). Bilinear samples
/// near an edge thus see a smooth continuation of the chart's own heights (error O(h''·texel²)),
/// whether or not the full surface has a feature along that coarse edge (measuring against the
/// triangle's plane extended across the edge would err by distance·tan(dihedral angle) there).
/// Texels whose rays miss are filled from neighbours of the same chart.
///
/// Rays: at a point of barycentric b the coarse point p and N = normalize(Σ b_i n_i) are computed;
/// one ray goes from p along +N and one from p along -N, each up to the ray range d (both start
/// 1e-6·d behind p so that a surface through p is found), and the hit nearer to p gives h (+t or
/// -t): the full surface is p + h·N.
///
/// Throws std::invalid_argument for bad params (size not a power of two in [16, 16384], gutter
/// outside [1, 16], crease angle outside [0, 180], negative or non-finite ray distance, negative
/// validation samples, negative threads), for an empty mesh, a non-finite vertex, a triangle index
/// out of range, more triangles than the atlas can give charts of at least 4 texels per side, or
/// an automatic ray range on a coarse mesh of zero extent; std::runtime_error when Embree fails.
BakedTexture BakeHapticTexture(const TriangleMesh& coarse_O, const TriangleMesh& full_O,
                               const TextureBakeParams& params = {});

/// The smallest atlas side (a power of two in [16, 16384]) whose charts fit `triangles` coarse
/// triangles with `gutter_texels` (BakeHapticTexture's layout, chart legs of at least 4 texels);
/// 0 when none does.
int SmallestAtlasSize(int triangles, int gutter_texels) noexcept;

/// Moves corner_normals_O, corner_uvs, textured, texel_size_m and texture of `baked` into
/// `model`, whose vertices_O and triangles must be the coarse mesh that was baked. Throws
/// std::invalid_argument when the sizes do not match model.triangles.
void ApplyBakedTexture(BakedTexture baked, HapticModel& model);

}  // namespace ht
