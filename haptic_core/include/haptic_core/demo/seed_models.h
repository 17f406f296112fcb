#pragma once
// The six seed benchmark models (DESIGN.md §7, seed Table 6) at full resolution. The originals are
// not public; these are procedural analogues at the seed's triangle counts (within 1 %): the
// ridged block and gear of procedural_models.h, a textured hammer, a rough CAD part, a flat file
// with fine teeth, and a wrinkled helicoidal torus.
//
// Every mesh is closed, 2-manifold, consistently wound counter-clockwise seen from outside, free
// of degenerate triangles, in metres, with frame O at the centre of the model's (undisplaced)
// bounding box. The hammer, CAD part and file are smooth non-convex base shapes (a union of boxes
// and cylinders, rounded and filleted by the 0.5 level set of its Gaussian-blurred indicator)
// carrying fine detail as a displacement h along the base's outward normal, with |h| of
// 0.1–0.5 mm and periods of 1.2–6 mm: detail a coarse mesh of a few hundred triangles cannot hold,
// which the model build bakes into a height-field texture.

#include <cstdint>
#include <glm/vec2.hpp>
#include <glm/vec3.hpp>
#include <string>
#include <vector>

#include "haptic_core/haptic_model.h"

namespace ht {

/// The six seed benchmark models (seed Table 6, DESIGN.md §7).
enum class SeedModel { kBlock, kGear, kHammer, kCadPart, kFile, kTorus };

/// One row of seed Table 6.
struct SeedModelSpec {
  SeedModel model;
  /// "block", "gear", "hammer", "cad_part", "file" or "torus".
  const char* name;
  /// Triangles of the seed's full-resolution model.
  std::int64_t seed_full_triangles;
  /// Triangles of the seed's coarse (low-resolution) model.
  std::int64_t seed_coarse_triangles;
  /// Convex bounding volumes of the seed's coarse model.
  std::int64_t seed_bounding_volumes;
};

/// The table, in enum order: block 65,536/16/1, gear 25,600/1,600/1, hammer 433,152/518/210,
/// CAD part 658,432/720/390, file 285,824/632/113, torus 128,000/532/114.
const std::vector<SeedModelSpec>& SeedModelSpecs();

/// The row of `model`.
const SeedModelSpec& SeedModelSpecOf(SeedModel model);

/// Full-resolution mesh of a seed model with default parameters, frame O at the model's centre
/// (metres). Block and gear come from MakeRidgedBlockFullResolution / MakeRidgedGearFullResolution.
/// Takes up to ≈ 0.3 s (the CAD part, Release build).
TriangleMesh MakeSeedModelFullResolution(SeedModel model);

/// Parses "block", "gear", "hammer", "cad_part", "file", "torus"; throws std::invalid_argument
/// naming the bad value and listing the valid names.
SeedModel ParseSeedModelName(const std::string& name);

/// The name of `model` as ParseSeedModelName accepts it.
const char* SeedModelName(SeedModel model);

// ------------------------------------------------------------------------------------------------
// Individual generators. Every parameter struct has `detail_scale`: the displacement is multiplied
// by it (1 = the model, 0 = the smooth base shape with the same connectivity), and the generators
// throw std::invalid_argument naming the first non-positive size or inconsistent layout.

/// Textured hammer: a box head along O's x (rounded edges) on a cylindrical handle along O's z,
/// one closed genus-0 surface filleted where the handle meets the head. Head top at z = +length/2,
/// handle bottom at z = −length/2. Detail: diamond knurling on the handle's grip zone,
/// h = A_k·cos(N·θ)·cos(2π z/P_k) with θ the angle about z and N = round(2πR/P_k); and a peened
/// texture on the head, h = A_p·tanh(½·n(p)) with n a unit-RMS sum of 8 plane waves of periods
/// in [P_min, P_max].
struct TexturedHammerParams {
  glm::dvec3 head_half_extents_m{0.055, 0.019, 0.016};  ///< Head box half sizes along x, y, z (m).
  double length_m = 0.30;          ///< Overall length along z, handle bottom to head top (m).
  double handle_radius_m = 0.012;  ///< Handle radius R (m); ≤ head half size y − 3 mm − 2σ.
  double edge_blur_m = 1.5e-3;     ///< σ of the blur: convex edges round to ≈ 1.9σ radius (m).
  double grip_start_m = 0.008;     ///< Knurled zone starts this far above the handle bottom (m).
  double grip_length_m = 0.16;     ///< Length of the knurled zone along z (m).
  double knurl_amplitude_m = 0.35e-3;  ///< A_k (m).
  double knurl_period_m = 3.0e-3;      ///< P_k, axial period; ≈ circumferential period (m).
  double peen_amplitude_m = 0.3e-3;    ///< A_p, bound of |h| on the head (m).
  double peen_min_period_m = 2.0e-3;   ///< P_min (m).
  double peen_max_period_m = 5.0e-3;   ///< P_max (m).
  /// Target edge lengths along x, y, z of the grid cells the surface is built from (m): these
  /// give 433,164 triangles (seed: 433,152).
  glm::dvec3 cell_size_m{0.4487e-3, 0.4487e-3, 0.44601e-3};
  double detail_scale = 1.0;
};
/// Full-resolution hammer (m, frame O at the bounding-box centre): the boundary of the box-grid
/// union, projected onto the blurred solid, then displaced. Throws std::invalid_argument on bad
/// parameters; std::logic_error if a layout leaves the grid too far from the smoothed surface.
TriangleMesh MakeTexturedHammerFullResolution(const TexturedHammerParams& params = {});

/// Rough CAD part: a 100 × 70 × 8 mm plate (z from z_bottom to plate_top) with a raised step over
/// x ≥ step_start (up to step_top) that is cut by a slot |y| < slot_half_width for
/// x ≥ slot_start (floor at slot_floor, open at the +x end), two cylindrical bosses on the low
/// part at (boss_x, ±boss_y) and two pins on the step at (pin_x, ±pin_y), all edges rounded and
/// filleted. Detail: face-milling arcs on up/down-facing faces, h = A_m·cos(2π|p_xy − c_m|/P_m)
/// with the cutter centre c_m far off the part; horizontal feed marks on walls,
/// h = A_w·cos(2π z/P_w); plus everywhere a roughness h = A_r·tanh(½·n(p)) (8 plane waves).
struct RoughCadPartParams {
  glm::dvec2 plate_half_extents_m{0.05, 0.035};  ///< Plate half sizes along x, y (m).
  double bottom_z_m = -0.010;                    ///< Underside of the plate (m).
  double plate_top_z_m = -0.002;                 ///< Top of the low part of the plate (m).
  double step_start_x_m = 0.005;                 ///< The step covers x ≥ this (m).
  double step_top_z_m = 0.004;                   ///< Top of the step (m).
  double slot_half_width_m = 0.005;              ///< Slot half width along y (m).
  double slot_start_x_m = 0.02;                  ///< The slot covers x ≥ this (m).
  double slot_floor_z_m = 0.0;                   ///< Slot floor (m).
  glm::dvec2 boss_centre_m{-0.03, 0.017};        ///< Boss axes at (x, ±y) (m).
  double boss_radius_m = 0.008;
  double boss_top_z_m = 0.010;
  glm::dvec2 pin_centre_m{0.035, 0.022};  ///< Pin axes at (x, ±y), on the step (m).
  double pin_radius_m = 0.004;
  double pin_top_z_m = 0.010;
  double edge_blur_m = 0.6e-3;         ///< σ of the blur (m).
  double mill_amplitude_m = 0.2e-3;    ///< A_m (m).
  double mill_period_m = 1.5e-3;       ///< P_m (m).
  double wall_amplitude_m = 0.15e-3;   ///< A_w (m).
  double wall_period_m = 1.25e-3;      ///< P_w (m).
  double rough_amplitude_m = 0.08e-3;  ///< A_r, bound of the roughness (m).
  double rough_min_period_m = 1.2e-3;
  double rough_max_period_m = 3.0e-3;
  /// Target grid cell edges along x, y, z (m): 0.2467 mm gives 658,456 triangles (seed: 658,432).
  glm::dvec3 cell_size_m{0.2467e-3, 0.2467e-3, 0.2467e-3};
  double detail_scale = 1.0;
};
/// Full-resolution CAD part (m, frame O at the bounding-box centre with the defaults); throws as
/// MakeTexturedHammerFullResolution.
TriangleMesh MakeRoughCadPartFullResolution(const RoughCadPartParams& params = {});

/// Flat file along O's x: a round handle (−x end), a narrow neck, and a flat blade whose width and
/// thickness scale by 1 − (1 − tip_scale)·t² over the last taper_length (t from 0 to 1 at the
/// tip). Detail: double-cut teeth on both wide blade faces, h = A_t·min(T(u₁/P₁), T(u₂/P₂)) with
/// T an asymmetric saw tooth in [0, 1] (rise over 75 % of the period) and u₁, u₂ the coordinates
/// across cuts at +65° and −45° to the axis; single-cut teeth h = A_e·T(x/P_e) on the +y edge;
/// grip rings h = A_g·cos(2π x/P_g) on the handle.
struct ToothedFileParams {
  double handle_length_m = 0.055;
  double handle_radius_m = 0.011;
  double neck_length_m = 0.010;
  double neck_half_width_m = 0.004;        ///< Along y (m).
  double neck_half_thickness_m = 0.00175;  ///< Along z (m).
  double blade_length_m = 0.135;
  double blade_half_width_m = 0.009;        ///< Along y at the heel (m).
  double blade_half_thickness_m = 0.00225;  ///< Along z at the heel (m).
  double taper_length_m = 0.07;
  double tip_width_scale = 0.6;
  double tip_thickness_scale = 0.7;
  double edge_blur_m = 0.5e-3;             ///< σ of the blur, before the taper (m).
  double tooth_amplitude_m = 0.3e-3;       ///< A_t (m).
  double overcut_period_m = 1.6e-3;        ///< P₁ (m), cut at +65°.
  double upcut_period_m = 2.4e-3;          ///< P₂ (m), cut at −45°.
  double edge_tooth_amplitude_m = 0.2e-3;  ///< A_e (m).
  double edge_tooth_period_m = 1.5e-3;     ///< P_e (m).
  double grip_amplitude_m = 0.2e-3;        ///< A_g (m).
  double grip_period_m = 4.0e-3;           ///< P_g (m).
  /// Target grid cell edges along x, y, z (m): 0.2932 mm gives 285,944 triangles (seed: 285,824).
  glm::dvec3 cell_size_m{0.2932e-3, 0.2932e-3, 0.2932e-3};
  double detail_scale = 1.0;

  /// Overall length along x (m).
  double TotalLength() const noexcept { return handle_length_m + neck_length_m + blade_length_m; }
};
/// Full-resolution file (m, frame O at the bounding-box centre, x from −TotalLength()/2 at the
/// handle end to +TotalLength()/2 at the tip); throws as MakeTexturedHammerFullResolution.
TriangleMesh MakeToothedFileFullResolution(const ToothedFileParams& params = {});

/// Wrinkled helicoidal torus about O's z axis: the tube point at major angle θ (about z) and tube
/// angle φ, displaced along the tube's outward normal by h = A·sin(m·θ + n·φ), so the wrinkle
/// crests are helices winding around the tube. A (major_segments × tube_segments) grid:
/// 2·major·tube triangles (500 × 128 → 128,000, as the seed).
struct WrinkledTorusParams {
  double major_radius_m = 0.05;         ///< R (m).
  double minor_radius_m = 0.015;        ///< r (m).
  double wrinkle_amplitude_m = 0.5e-3;  ///< A (m).
  int major_waves = 64;                 ///< m: ≈ 4.9 mm period along the centre circle.
  int tube_waves = 16;                  ///< n: ≈ 5.9 mm period around the tube.
  int major_segments = 500;
  int tube_segments = 128;
  double detail_scale = 1.0;
};
/// Full-resolution torus (m, frame O at its centre). Throws std::invalid_argument for
/// non-positive radii, fewer than 3 segments, r + |A| ≥ R or |A| ≥ r/2.
TriangleMesh MakeWrinkledTorusFullResolution(const WrinkledTorusParams& params = {});

}  // namespace ht
