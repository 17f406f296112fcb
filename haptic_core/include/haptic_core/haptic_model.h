#pragma once
// The haptic representation of one touchable object (DESIGN.md §2): a coarse triangle mesh plus a
// haptic texture (height field) that holds the detail the coarse mesh dropped, and the convex
// hull(s) used by the coarse contact query.

#include <cstdint>
#include <glm/gtc/quaternion.hpp>
#include <glm/vec2.hpp>
#include <glm/vec3.hpp>
#include <string>
#include <vector>

#include "haptic_core/height_field.h"
#include "haptic_core/hull_hierarchy.h"
#include "haptic_core/mesh.h"

namespace ht {

/// A textured coarse model in its own object frame O (metres). Built once at start-up and then
/// only read (MuJoCo-style constant model).
///
/// The full-resolution surface it stands for is p(u,v) = p_coarse(u,v) + h(u,v)·N(u,v), with N
/// the interpolated unit outward normal of the coarse surface and h the height field [S][L].
struct HapticModel {
  std::string name;
  /// Coarse vertices p_OV, #V.
  std::vector<glm::dvec3> vertices_O;
  /// Coarse triangles, #F, counter-clockwise seen from outside (outward face normals).
  std::vector<glm::ivec3> triangles;
  /// Interpolated unit outward normals per triangle corner, #F*3 (corner c of triangle f at 3f+c).
  std::vector<glm::dvec3> corner_normals_O;
  /// Texture coordinates per triangle corner, #F*3, into `texture`.
  std::vector<glm::vec2> corner_uvs;
  /// Per triangle: 1 when the texture applies, 0 when the face is smooth (h = 0), #F.
  std::vector<std::uint8_t> textured;
  /// Per triangle: metres on the surface covered by one level-0 texel, #F (for mip selection).
  std::vector<double> texel_size_m;
  /// The haptic texture shared by all textured triangles.
  HeightField texture;
  /// Vertices whose convex hull bounds the coarse surface (used by the convex coarse contact
  /// query, which widens its tolerance by OutwardReach() of both sides), #H.
  std::vector<glm::dvec3> hull_vertices_O;
  /// Bounding volume hierarchy of convex hulls over the coarse mesh (DESIGN.md §2); empty for
  /// the built-in procedural models, whose coarse meshes are convex (hull_vertices_O is their
  /// single hull). Built by BuildConvexHullHierarchy() for models loaded from files.
  ConvexHullHierarchy hull_hierarchy;
  /// Outward reach used by OutwardReach() (m); < 0 means "the texture's largest height". The model
  /// build sets it to the 99.9th percentile of the positive heights, so that a few texels whose
  /// rays hit another part of the object (the file's handle seen from its blade) do not widen
  /// every coarse query of the object by centimetres.
  double outward_reach_m = -1.0;
  /// Centre of mass, p_OOcm (m).
  glm::dvec3 center_of_mass_O{0.0};
  /// Mass (kg), and principal moments of inertia about the centre of mass along O's axes (kg·m²).
  double mass_kg = 0.0;
  glm::dvec3 inertia_diagonal_O{0.0};
  /// Triangle count of the full-resolution surface this model stands for (for reports).
  std::int64_t full_resolution_triangles = 0;

  /// Largest |h| of the texture (m): how far the true surface may lie outside the coarse one.
  double TextureReach() const noexcept;
  /// How far the true surface lies OUTSIDE the coarse one (m): outward_reach_m when set (≥ 0),
  /// else the texture's largest positive h (0 when there is none). Two objects' true surfaces can
  /// only touch where their coarse surfaces are within the sum of their outward reaches, so this
  /// (not TextureReach(), which also counts the inward deviations of concave regions the coarse
  /// mesh cuts across) widens the coarse query.
  double OutwardReach() const noexcept;

  /// Checks sizes, finiteness and normal lengths; throws std::invalid_argument naming the model
  /// and the first inconsistency found.
  void Validate() const;
};

/// Moves a model's frame origin to p_OC (m, expressed in O; e.g. its centre of mass, as the tool
/// frame T requires): every position of the model (coarse vertices, hull vertices and planes,
/// hierarchy nodes, centre of mass) becomes p − p_OC. Orientation, texture and normals are
/// unchanged.
void ShiftModelFrame(HapticModel& model, const glm::dvec3& p_OC);

/// Turns a model's frame about its origin: with R_NO the rotation from the old frame O to the new
/// frame N (a unit quaternion), every position and direction of the model (coarse vertices,
/// corner normals, hull vertices, plane normals and centres, hierarchy nodes, centre of mass)
/// becomes R_NO·p; the surface in W is unchanged when the model's pose becomes X_WN = X_WO·R_NO⁻¹.
/// The principal moments become the diagonal of R_NO·diag(I)·R_NO⁻¹ (exact for a rotation that
/// permutes O's axes, such as a quarter turn). Texture coordinates, the texture and texel sizes
/// are unchanged. Throws std::invalid_argument for a non-finite or non-unit R_NO.
void RotateModelFrame(HapticModel& model, const glm::dquat& R_NO);

}  // namespace ht
