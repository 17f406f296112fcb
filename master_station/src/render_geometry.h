// The operator display's geometry (scene_renderer.h): the camera's checks and matrices, and the
// unit shapes arrows and markers are made of. Internal to master_station/src.
#pragma once

#include <glm/mat4x4.hpp>
#include <glm/vec3.hpp>
#include <glm/vec4.hpp>
#include <string>

#include "master_station/scene_renderer.h"

namespace ht::render {

bool Finite(const glm::dvec3& v);
bool Finite(const glm::vec4& v);
bool Finite(const glm::dmat4& m);
// "(x, y, z)" for error messages.
std::string Str(const glm::dvec3& v);
// Throws std::invalid_argument saying what is wrong with a camera: non-finite vectors, eye on
// target, up parallel to the view, yfov outside (0, π), or not 0 < near < far < ∞.
void CheckCamera(const RenderCamera& c);
// X_CW: W → C (camera looks along −z_C, y_C up).
glm::dmat4 CameraFromWorld(const RenderCamera& c);
// C → clip coordinates (OpenGL, depth −1…1) for an image of width × height pixels.
glm::dmat4 Projection(const RenderCamera& c, int width, int height);
// The unit shapes arrows and markers are made of, in their node frame N: a closed cylinder of
// radius 1 over z ∈ [0, 1], a closed cone (base radius 1 at z = 0, apex at z = 1), and an
// octahedron with vertices at ±1 on each axis.
RenderMesh UnitCylinder();
RenderMesh UnitCone();
RenderMesh UnitOctahedron();
// An affine map that takes the unit z axis to `unit_axis_W`·length, x and y to `radius`·(two unit
// vectors perpendicular to it), and the origin to `origin_W`.
glm::dmat4 AlongAxis(const glm::dvec3& origin_W, const glm::dvec3& unit_axis_W, double length,
                     double radius);

}  // namespace ht::render
