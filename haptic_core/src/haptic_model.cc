#include "haptic_core/haptic_model.h"

#include <algorithm>
#include <cmath>
#include <glm/geometric.hpp>
#include <glm/gtc/quaternion.hpp>
#include <stdexcept>
#include <string>

namespace ht {

double HapticModel::TextureReach() const noexcept {
  if (texture.empty()) return 0.0;
  return std::max(std::abs(static_cast<double>(texture.min_height())),
                  std::abs(static_cast<double>(texture.max_height())));
}

double HapticModel::OutwardReach() const noexcept {
  if (outward_reach_m >= 0.0) return outward_reach_m;
  if (texture.empty()) return 0.0;
  return std::max(0.0, static_cast<double>(texture.max_height()));
}

void HapticModel::Validate() const {
  const auto fail = [&](const std::string& what) {
    throw std::invalid_argument("haptic model '" + name + "': " + what);
  };
  const size_t nf = triangles.size();
  if (vertices_O.empty() || nf == 0) fail("no coarse geometry");
  if (corner_normals_O.size() != 3 * nf) fail("corner_normals_O must have 3 entries per triangle");
  if (corner_uvs.size() != 3 * nf) fail("corner_uvs must have 3 entries per triangle");
  if (textured.size() != nf) fail("textured must have one entry per triangle");
  if (texel_size_m.size() != nf) fail("texel_size_m must have one entry per triangle");
  if (hull_vertices_O.size() < 4) fail("hull needs at least 4 vertices");
  for (size_t f = 0; f < nf; ++f) {
    for (int c = 0; c < 3; ++c) {
      const int vi = triangles[f][c];
      if (vi < 0 || static_cast<size_t>(vi) >= vertices_O.size()) {
        fail("triangle " + std::to_string(f) + " indexes vertex " + std::to_string(vi) +
             " out of range");
      }
      const double len = glm::length(corner_normals_O[3 * f + c]);
      if (!(std::abs(len - 1.0) < 1e-6))
        fail("corner normal of triangle " + std::to_string(f) + " is not unit length");
    }
  }
  for (const auto& v : vertices_O) {
    if (!std::isfinite(v.x) || !std::isfinite(v.y) || !std::isfinite(v.z)) {
      fail("non-finite vertex");
    }
  }
  if (!(mass_kg > 0.0)) fail("mass must be positive");
  if (!(inertia_diagonal_O.x > 0.0 && inertia_diagonal_O.y > 0.0 && inertia_diagonal_O.z > 0.0)) {
    fail("inertia must be positive");
  }
}

void ShiftModelFrame(HapticModel& m, const glm::dvec3& p_OC) {
  for (glm::dvec3& p : m.vertices_O) p -= p_OC;
  for (glm::dvec3& p : m.hull_vertices_O) p -= p_OC;
  for (HullNode& node : m.hull_hierarchy.nodes) {
    for (glm::dvec3& p : node.hull.vertices_O) p -= p_OC;
    for (glm::dvec4& plane : node.hull.planes_O) plane.w -= glm::dot(glm::dvec3(plane), p_OC);
    node.hull.center_O -= p_OC;
  }
  m.center_of_mass_O -= p_OC;
}

void RotateModelFrame(HapticModel& m, const glm::dquat& R_NO) {
  const double norm = glm::length(R_NO);
  if (!std::isfinite(norm) || std::abs(norm - 1.0) > 1e-9) {
    throw std::invalid_argument("RotateModelFrame: the rotation of model '" + m.name +
                                "' must be a finite unit quaternion");
  }
  for (glm::dvec3& p : m.vertices_O) p = R_NO * p;
  for (glm::dvec3& n : m.corner_normals_O) n = R_NO * n;
  for (glm::dvec3& p : m.hull_vertices_O) p = R_NO * p;
  for (HullNode& node : m.hull_hierarchy.nodes) {
    for (glm::dvec3& p : node.hull.vertices_O) p = R_NO * p;
    for (glm::dvec4& plane : node.hull.planes_O) {
      plane = glm::dvec4(R_NO * glm::dvec3(plane), plane.w);  // n·p − d: d is frame-free
    }
    node.hull.center_O = R_NO * node.hull.center_O;
  }
  m.center_of_mass_O = R_NO * m.center_of_mass_O;
  const glm::dmat3 R = glm::mat3_cast(R_NO);
  const glm::dvec3 I = m.inertia_diagonal_O;
  glm::dvec3 turned(0.0);
  for (int a = 0; a < 3; ++a) {
    for (int k = 0; k < 3; ++k) turned[a] += R[k][a] * R[k][a] * I[k];  // (R·diag(I)·Rᵀ)_aa
  }
  m.inertia_diagonal_O = turned;
}

}  // namespace ht
