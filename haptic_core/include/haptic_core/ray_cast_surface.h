#pragma once
// Ray casting on a full-resolution triangle mesh (Embree 3): the first hit along a ray, the first
// hit on a surface facing it (the method's facing rule, penetration_depth.h), and inside/outside.
// Library haptic_raycast (links Embree); neither the remote step nor the operator links it.

#include <cstddef>
#include <glm/vec3.hpp>
#include <memory>

#include "haptic_core/mesh.h"

namespace ht {

/// A full-resolution triangle mesh ready for ray casting (Embree 3, float vertices). Queries are
/// in the surface's frame S: the mesh's frame F moved to `origin_F` (S = F − origin_F), so that a
/// caller working near a point far from F's origin keeps the floats' resolution there (the
/// texture bake puts S at its coarse mesh's centre); with the default origin S is F (about
/// 10 nm of rounding at 10 cm from F's origin). Immutable after construction and safe to query
/// from several threads. One ray caster for the ground truth (accuracy/) and the texture bake
/// (model_build/).
class RayCastSurface {
 public:
  /// Builds the ray-casting structure over `mesh_F` (#V vertices, #F triangles, counter-clockwise
  /// seen from outside, metres), each vertex stored as float(p_F − origin_F). Degenerate
  /// triangles are kept but never face a ray. Throws std::invalid_argument for an empty mesh, a
  /// non-finite vertex or origin or an index out of range, and std::runtime_error when Embree
  /// fails.
  explicit RayCastSurface(const TriangleMesh& mesh_F, const glm::dvec3& origin_F = glm::dvec3(0.0));
  ~RayCastSurface();
  RayCastSurface(const RayCastSurface&) = delete;
  RayCastSurface& operator=(const RayCastSurface&) = delete;

  /// Distance (m) along the unit direction `dir_S` from `org_S` (both in S) to the first surface
  /// point within [0, tfar_m], whichever way its triangle faces; −1 when there is none.
  /// Thread-safe.
  double FirstHit(const glm::dvec3& org_S, const glm::dvec3& dir_S, double tfar_m) const noexcept;

  /// Distance (m) along the unit direction `dir_S` from `org_S` (both in S) to the first surface
  /// point within [0, tfar_m] whose triangle faces the ray (unit face normal · dir_S <
  /// −kPatchFacingThreshold); −1 when there is none. Thread-safe.
  double FirstFacingHit(const glm::dvec3& org_S, const glm::dvec3& dir_S,
                        double tfar_m) const noexcept;

  /// True when `p_S` is inside the closed mesh: the first surface that a ray from `p_S` along the
  /// unit direction `dir_S` meets, whichever way it faces, faces away from the ray (unit face
  /// normal · dir_S > 0: the ray leaves the solid there). A point with nothing along the ray is
  /// outside. Exact for a closed, outward-oriented mesh up to float rounding (~10 nm at 10 cm);
  /// the direction only matters for rays through edges. Thread-safe.
  bool IsInside(const glm::dvec3& p_S, const glm::dvec3& dir_S) const noexcept;

  /// Triangles of the mesh.
  std::size_t triangle_count() const noexcept;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace ht
