// The operator display's geometry (render_geometry.h, scene_renderer.h): the camera's checks and
// matrices, the follow camera and the projection to pixels, and the unit shapes.
#include "render_geometry.h"

#include <cmath>
#include <glm/ext/matrix_clip_space.hpp>
#include <glm/ext/matrix_transform.hpp>
#include <glm/geometric.hpp>
#include <numbers>
#include <stdexcept>
#include <string>

namespace ht {
namespace render {
namespace {

constexpr int kRoundSegments = 16;

}  // namespace

bool Finite(const glm::dvec3& v) {
  return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}
bool Finite(const glm::vec4& v) {
  return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z) && std::isfinite(v.w);
}
bool Finite(const glm::dmat4& m) {
  for (int c = 0; c < 4; ++c) {
    for (int r = 0; r < 4; ++r) {
      if (!std::isfinite(m[c][r])) return false;
    }
  }
  return true;
}

std::string Str(const glm::dvec3& v) {
  return "(" + std::to_string(v.x) + ", " + std::to_string(v.y) + ", " + std::to_string(v.z) + ")";
}

void CheckCamera(const RenderCamera& c) {
  if (!Finite(c.eye_W) || !Finite(c.target_W) || !Finite(c.up_W)) {
    throw std::invalid_argument("render camera: eye " + Str(c.eye_W) + ", target " +
                                Str(c.target_W) + " and up " + Str(c.up_W) + " must be finite");
  }
  const glm::dvec3 forward = c.target_W - c.eye_W;
  const double f = glm::length(forward), u = glm::length(c.up_W);
  if (!(f > 0.0)) {
    throw std::invalid_argument("render camera: eye and target are the same point " + Str(c.eye_W));
  }
  if (!(glm::length(glm::cross(forward, c.up_W)) > 1e-9 * f * u)) {
    throw std::invalid_argument("render camera: up " + Str(c.up_W) +
                                " is zero or parallel to the view direction " + Str(forward));
  }
  if (!(c.yfov_rad > 0.0 && c.yfov_rad < std::numbers::pi)) {
    throw std::invalid_argument("render camera: yfov_rad must be in (0, pi), got " +
                                std::to_string(c.yfov_rad));
  }
  if (!(c.near_m > 0.0 && c.far_m > c.near_m && std::isfinite(c.far_m))) {
    throw std::invalid_argument("render camera: need 0 < near_m < far_m < inf, got near " +
                                std::to_string(c.near_m) + ", far " + std::to_string(c.far_m));
  }
}

// X_CW: W → C (camera looks along −z_C, y_C up).
glm::dmat4 CameraFromWorld(const RenderCamera& c) {
  return glm::lookAtRH(c.eye_W, c.target_W, c.up_W);
}

// C → clip coordinates (OpenGL, depth −1…1).
glm::dmat4 Projection(const RenderCamera& c, int width, int height) {
  return glm::perspectiveRH_NO(c.yfov_rad, static_cast<double>(width) / height, c.near_m, c.far_m);
}

// The unit shapes arrows and markers are made of.
RenderMesh UnitCylinder() {  // radius 1, z ∈ [0, 1], closed
  RenderMesh m;
  m.positions_N = {{0, 0, 0}, {0, 0, 1}};
  for (int i = 0; i < kRoundSegments; ++i) {
    const double a = 2.0 * std::numbers::pi * i / kRoundSegments;
    const float x = static_cast<float>(std::cos(a)), y = static_cast<float>(std::sin(a));
    m.positions_N.push_back({x, y, 0.f});
    m.positions_N.push_back({x, y, 1.f});
  }
  for (unsigned i = 0; i < kRoundSegments; ++i) {
    const unsigned j = (i + 1) % kRoundSegments;
    const unsigned b0 = 2 + 2 * i, t0 = b0 + 1, b1 = 2 + 2 * j, t1 = b1 + 1;
    m.triangles.push_back({b0, b1, t1});
    m.triangles.push_back({b0, t1, t0});
    m.triangles.push_back({0, b1, b0});
    m.triangles.push_back({1, t0, t1});
  }
  return m;
}

RenderMesh UnitCone() {  // base radius 1 at z = 0, apex at z = 1, closed
  RenderMesh m;
  m.positions_N = {{0, 0, 0}, {0, 0, 1}};
  for (int i = 0; i < kRoundSegments; ++i) {
    const double a = 2.0 * std::numbers::pi * i / kRoundSegments;
    m.positions_N.push_back(
        {static_cast<float>(std::cos(a)), static_cast<float>(std::sin(a)), 0.f});
  }
  for (unsigned i = 0; i < kRoundSegments; ++i) {
    const unsigned b0 = 2 + i, b1 = 2 + (i + 1) % kRoundSegments;
    m.triangles.push_back({b0, b1, 1});
    m.triangles.push_back({0, b1, b0});
  }
  return m;
}

RenderMesh UnitOctahedron() {  // vertices at ±1 on each axis
  RenderMesh m;
  m.positions_N = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
  m.triangles = {{0, 2, 4}, {2, 1, 4}, {1, 3, 4}, {3, 0, 4},
                 {2, 0, 5}, {1, 2, 5}, {3, 1, 5}, {0, 3, 5}};
  return m;
}

// An affine map that takes the unit z axis to `axis_W` (any length), x and y to `radius`·(two
// unit vectors perpendicular to it), and the origin to `origin_W`.
glm::dmat4 AlongAxis(const glm::dvec3& origin_W, const glm::dvec3& unit_axis_W, double length,
                     double radius) {
  const glm::dvec3 helper =
      std::abs(unit_axis_W.x) < 0.9 ? glm::dvec3(1, 0, 0) : glm::dvec3(0, 1, 0);
  const glm::dvec3 e1 = glm::normalize(glm::cross(helper, unit_axis_W));
  const glm::dvec3 e2 = glm::cross(unit_axis_W, e1);
  glm::dmat4 X(1.0);
  X[0] = glm::dvec4(e1 * radius, 0.0);
  X[1] = glm::dvec4(e2 * radius, 0.0);
  X[2] = glm::dvec4(unit_axis_W * length, 0.0);
  X[3] = glm::dvec4(origin_W, 1.0);
  return X;
}

}  // namespace render

using render::CameraFromWorld;
using render::CheckCamera;
using render::Finite;
using render::Projection;
using render::Str;

RenderCamera FollowCamera(const glm::dvec3& target_W, const glm::dvec3& up_W, double distance_m) {
  if (!Finite(target_W)) {
    throw std::invalid_argument("FollowCamera: target " + Str(target_W) + " is not finite");
  }
  if (!Finite(up_W) || !(glm::length(up_W) > 0.0)) {
    throw std::invalid_argument("FollowCamera: up " + Str(up_W) + " must be finite and non-zero");
  }
  if (!(distance_m > 0.0 && std::isfinite(distance_m))) {
    throw std::invalid_argument("FollowCamera: distance_m must be finite and > 0, got " +
                                std::to_string(distance_m));
  }
  const glm::dvec3 u = glm::normalize(up_W);
  // "Behind": W's +z made perpendicular to up (glTF's viewer side), or −y where up is near ±z.
  glm::dvec3 back = glm::dvec3(0, 0, 1) - u.z * u;
  if (glm::length(back) < 0.15) back = glm::dvec3(0, -1, 0) + u.y * u;
  back = glm::normalize(back);
  constexpr double kElevation = 35.0 * std::numbers::pi / 180.0;
  RenderCamera c;
  c.target_W = target_W;
  c.eye_W = target_W + distance_m * (std::cos(kElevation) * back + std::sin(kElevation) * u);
  c.up_W = u;
  c.yfov_rad = 0.8;
  c.near_m = 0.01 * distance_m;
  c.far_m = 100.0 * distance_m;
  return c;
}

bool ProjectToPixel(const RenderCamera& c, int width, int height, const glm::dvec3& p_W,
                    glm::dvec2* pixel) {
  CheckCamera(c);
  if (width < 1 || height < 1) {
    throw std::invalid_argument("ProjectToPixel: image size must be >= 1, got " +
                                std::to_string(width) + " x " + std::to_string(height));
  }
  const glm::dvec4 p_C = CameraFromWorld(c) * glm::dvec4(p_W, 1.0);
  if (!(p_C.z < 0.0)) return false;  // at or behind the eye's plane
  const glm::dvec4 clip = Projection(c, width, height) * p_C;
  const double x_ndc = clip.x / clip.w, y_ndc = clip.y / clip.w;
  if (pixel != nullptr) {
    *pixel = glm::dvec2(0.5 * (x_ndc + 1.0) * width, 0.5 * (1.0 - y_ndc) * height);
  }
  return true;
}

}  // namespace ht
