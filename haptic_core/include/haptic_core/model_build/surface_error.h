#pragma once
// How well a built haptic model holds the full-resolution surface it stands for: the
// bake's own validation (TextureBakeReport::max_bake_error_m) samples the COARSE surface and asks
// whether the stored height matches a ray cast there, so it cannot see full-resolution surface
// that no ray of the coarse surface reaches (a fold, a part the coarse mesh cuts across, a ray
// that hit another sheet first). This measure goes the other way: it samples the FULL-resolution
// surface and asks how far each point lies from the textured coarse model p(u,v) =
// p_coarse(u,v) + h(u,v)·N(u,v) (haptic_model.h).

#include <cstdint>

#include "haptic_core/haptic_model.h"

namespace ht {

/// Settings of MeasureSurfaceError().
struct SurfaceErrorParams {
  /// Points sampled on the full-resolution surface (area-weighted); >= 1.
  int samples = 4096;
  /// Seed of the sample generator (the same seed gives the same samples).
  std::uint64_t seed = 1;
  /// A sample whose full-resolution point lies outside the model by more than this (m) counts in
  /// SurfaceErrorReport::share_outside; > 0.
  double outside_threshold_m = 25e-6;
  /// > 0: only full-resolution triangles whose centroid lies within this distance (m) of
  /// region_center_O are sampled (a contact's neighbourhood); 0 = the whole surface. Finite, >= 0.
  double region_radius_m = 0.0;
  /// Centre of that region, frame O (m).
  glm::dvec3 region_center_O{0.0};
};

/// Distances (m) from full-resolution surface points to the textured coarse model.
struct SurfaceErrorReport {
  int samples = 0;
  /// Percentiles of the distance |p − r| from a full-resolution point p to its model point r.
  double p50_m = 0.0, p95_m = 0.0, p99_m = 0.0, max_m = 0.0;
  /// The same signed along the model's normal N at r, positive where the full-resolution surface
  /// lies OUTSIDE the model (there the method reads the penetration depth low, or finds no contact
  /// where the meshes touch): the 99th percentile of max(0, signed), and the share of samples
  /// above SurfaceErrorParams::outside_threshold_m.
  double outside_p99_m = 0.0;
  double share_outside = 0.0;
  /// Wall time (s).
  double seconds = 0.0;
};

/// Samples `params.samples` points p on `full_O` (the full-resolution surface, frame O of `model`,
/// metres; area-weighted over its triangles with the generator seeded by params.seed) and for
/// each finds its model point r = q + h(q)·N(q): q on the coarse triangle, among the three whose
/// closest points are nearest p, where p − q runs along the interpolated normal N(q) (four
/// fixed-point steps from the closest point, kept inside the triangle), and h(q) the level-0
/// bilinear height (0 on an untextured triangle) — the point the bake's ray from q would have
/// stored. The distance is |p − r| for the triangle that gives the smallest one. Brute force over
/// the coarse triangles: O(samples·#F), about 0.1–0.5 s for the seed models at 4096 samples.
/// Throws std::invalid_argument for params out of range, an empty `full_O` or model, a triangle
/// index out of range, a model without corner normals and uvs per triangle, or a region that
/// holds no full-resolution area.
SurfaceErrorReport MeasureSurfaceError(const HapticModel& model, const TriangleMesh& full_O,
                                       const SurfaceErrorParams& params = {});

}  // namespace ht
