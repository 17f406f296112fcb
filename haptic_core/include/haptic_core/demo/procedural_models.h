#pragma once
// Procedural analogues of the seed's benchmark models (DESIGN.md §7, seed Table 6): a ridged block
// and a ridged gear whose coarse models are convex and whose ridges live in haptic textures.

#include <functional>
#include <string>

#include "haptic_core/haptic_model.h"

namespace ht {

/// Ridge cross-section used by the block and the gear: A·tanh(β·cos(2π s/P))/tanh(β), a rounded
/// trapezoid with flat crests and valleys (so the block can rest on ridge tops) and flanks of
/// maximum slope A·β·(2π/P)/tanh(β).
struct RidgeProfile {
  double amplitude_m = 0.4e-3;  ///< A: crest height above the mean surface (m).
  double period_m = 3.0e-3;     ///< P: ridge spacing (m).
  double sharpness = 1.5;       ///< β: 0 → sinusoid, large → square wave.

  /// Height (m) at arc-length coordinate s (m) across the ridges.
  double Height(double s_m) const noexcept;
  /// Largest slope |dh/ds| of the profile (dimensionless).
  double MaxSlope() const noexcept;
};

/// A box of half sizes `half_extents_m` (frame O at its centre, which is the centre of mass) whose
/// bottom face (outward normal −z) carries the texture h(x, y) = `bottom_height(x_m, y_m)` (m along
/// the outward normal, x and y in O), sampled on a `texture_size`² height field. 16 coarse
/// triangles: bottom and top faces as 4-triangle fans and 8 side triangles. Throws
/// std::invalid_argument for non-positive sizes or mass, or a non-finite height.
HapticModel MakeTexturedBox(const glm::dvec3& half_extents_m,
                            const std::function<double(double, double)>& bottom_height,
                            int texture_size, double mass_kg, std::string name);

/// Parameters of the ridged block (the tool of the seed's Fig. 72-b / Fig. 75).
struct RidgedBlockParams {
  glm::dvec3 half_extents_m{0.02, 0.02, 0.01};  ///< Box half sizes along O's x, y, z (m).
  RidgeProfile ridges;                          ///< Ridges on the bottom face, along x.
  int texture_size = 1024;                      ///< Texels per side of the height field.
  double mass_kg = 0.1;
  /// Grid cells per side of the full-resolution bottom face: 178 gives 65,504 triangles
  /// (seed: 65,536, within 0.05 %).
  int full_resolution_grid = 178;
};

/// Ridged block: 16 coarse triangles (bottom and top faces as 4-triangle fans, 8 side triangles),
/// convex; the bottom face (outward normal −z) carries ridges running along x. Frame O at the
/// centre of mass. Throws std::invalid_argument for non-positive sizes.
HapticModel MakeRidgedBlock(const RidgedBlockParams& params = {});
/// Full-resolution surface of the same block (for display, baking and counts).
TriangleMesh MakeRidgedBlockFullResolution(const RidgedBlockParams& params = {});

/// Parameters of the ridged gear (the fixed environment of Fig. 72-b / Fig. 75).
struct RidgedGearParams {
  double radius_m = 0.025;  ///< Coarse cylinder radius (m).
  double length_m = 0.06;   ///< Length along O's x axis (m).
  int teeth = 52;           ///< Ridges around the circumference (arc period 2πR/teeth).
  double amplitude_m = 0.4e-3;
  double sharpness = 1.5;
  int coarse_segments = 400;            ///< 400 → 1,600 coarse triangles (seed: 1,600).
  int texture_size = 1024;              ///< Texels per side of the height field.
  int full_resolution_segments = 3200;  ///< with 3 length rows → 25,600 triangles (seed: 25,600).
  int full_resolution_rows = 3;
  double mass_kg = 1.0;

  /// Ridge profile along the arc length (period 2πR/teeth).
  RidgeProfile Profile() const noexcept;
};

/// Ridged gear: a convex prism of `coarse_segments` sides around O's x axis, with smooth
/// (radial) interpolated normals on the side and ridges parallel to x in the texture.
/// Throws std::invalid_argument for non-positive sizes or fewer than 3 segments.
HapticModel MakeRidgedGear(const RidgedGearParams& params = {});
/// Full-resolution surface of the same gear.
TriangleMesh MakeRidgedGearFullResolution(const RidgedGearParams& params = {});

}  // namespace ht
