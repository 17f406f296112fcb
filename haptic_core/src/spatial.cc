#include "haptic_core/spatial.h"

#include <cmath>

namespace ht {
namespace {
bool Finite3(const glm::dvec3& v) noexcept {
  return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}
}  // namespace

glm::dquat QuaternionFromRotationVector(const glm::dvec3& theta) noexcept {
  const double angle = glm::length(theta);
  if (angle < 1e-8) {
    // sin(a/2)/a ≈ 1/2 - a²/48.
    const double s = 0.5 - angle * angle / 48.0;
    return glm::normalize(
        glm::dquat(1.0 - angle * angle / 8.0, s * theta.x, s * theta.y, s * theta.z));
  }
  const double s = std::sin(0.5 * angle) / angle;
  return glm::dquat(std::cos(0.5 * angle), s * theta.x, s * theta.y, s * theta.z);
}

glm::dvec3 RotationVectorFromQuaternion(const glm::dquat& q_in) noexcept {
  const double n = glm::length(q_in);
  if (!(n > 0.0)) return glm::dvec3(0.0);
  glm::dquat q = q_in / n;
  if (q.w < 0.0) q = -q;  // shortest rotation
  const glm::dvec3 v(q.x, q.y, q.z);
  const double s = glm::length(v);
  if (s < 1e-12) return 2.0 * v;  // angle ≈ 2 s
  const double angle = 2.0 * std::atan2(s, q.w);
  return v * (angle / s);
}

Twist PoseDifference(const RigidTransform& X, const RigidTransform& X0) noexcept {
  return {X.translation - X0.translation,
          RotationVectorFromQuaternion(X.rotation * glm::conjugate(X0.rotation))};
}

RigidTransform Displace(const RigidTransform& X0, const Twist& delta) noexcept {
  return {X0.translation + delta.linear,
          glm::normalize(QuaternionFromRotationVector(delta.angular) * X0.rotation)};
}

bool IsFinite(const RigidTransform& X) noexcept {
  const glm::dquat& q = X.rotation;
  return Finite3(X.translation) && std::isfinite(q.w) && std::isfinite(q.x) && std::isfinite(q.y) &&
         std::isfinite(q.z);
}

bool IsFiniteRigidTransform(const RigidTransform& X) noexcept {
  return IsFinite(X) && std::abs(glm::length(X.rotation) - 1.0) < 1e-3;
}

bool IsFinite(const Twist& V) noexcept { return Finite3(V.linear) && Finite3(V.angular); }
bool IsFinite(const Wrench& F) noexcept { return Finite3(F.force) && Finite3(F.torque); }

}  // namespace ht
