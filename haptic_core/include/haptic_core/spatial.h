#pragma once
// Spatial algebra on GLM: rigid transforms, twists, wrenches, rotation vectors.
//
// Frames follow Drake's monogram notation (see docs/STYLE.md): `X_WT` is the pose of
// tool frame T in world W, `p_WT` the position of T's origin in W, `V_WT_W` the twist of T in W
// expressed in W, `F_T_W` a wrench on T (at T's origin) expressed in W. SI units throughout.

#include <glm/geometric.hpp>
#include <glm/gtc/quaternion.hpp>
#include <glm/mat4x4.hpp>
#include <glm/vec3.hpp>

namespace ht {

/// Rigid transform X_AB: pose of frame B in frame A. `rotation` is R_AB (unit quaternion) and
/// `translation` is p_AB (metres, position of B's origin expressed in A).
struct RigidTransform {
  glm::dvec3 translation{0.0};
  glm::dquat rotation{1.0, 0.0, 0.0, 0.0};

  /// Identity transform.
  static RigidTransform Identity() noexcept { return {}; }

  /// Composition X_AC = X_AB * X_BC (inner frame letters cancel).
  RigidTransform operator*(const RigidTransform& X_BC) const noexcept {
    return {translation + rotation * X_BC.translation, rotation * X_BC.rotation};
  }
  /// p_AQ = X_AB * p_BQ: maps a point expressed in B to A.
  glm::dvec3 operator*(const glm::dvec3& p_BQ) const noexcept {
    return translation + rotation * p_BQ;
  }
  /// X_BA, the inverse of X_AB.
  RigidTransform Inverse() const noexcept {
    const glm::dquat R_BA = glm::conjugate(rotation);
    return {-(R_BA * translation), R_BA};
  }
  /// X_AB as a 4×4 homogeneous matrix (glm, column-major; metres): (p_AQ, 1) = M·(p_BQ, 1). For
  /// composing with scene-graph matrices that carry scale.
  glm::dmat4 Matrix() const noexcept {
    glm::dmat4 M = glm::mat4_cast(rotation);
    M[3] = glm::dvec4(translation, 1.0);
    return M;
  }
};

/// Spatial velocity of a body: `linear` (m/s) of the body's reference point and `angular`
/// (rad/s), both expressed in the frame named at the use site (e.g. V_WT_W).
struct Twist {
  glm::dvec3 linear{0.0};
  glm::dvec3 angular{0.0};
};

/// Wrench on a body: `force` (N) applied at the body's reference point and `torque` (N·m) about
/// that point, both expressed in the frame named at the use site (e.g. F_T_W).
struct Wrench {
  glm::dvec3 force{0.0};
  glm::dvec3 torque{0.0};

  Wrench operator+(const Wrench& o) const noexcept { return {force + o.force, torque + o.torque}; }
  Wrench operator-() const noexcept { return {-force, -torque}; }
  Wrench& operator+=(const Wrench& o) noexcept {
    force += o.force;
    torque += o.torque;
    return *this;
  }
};

/// Unit quaternion for the rotation vector `theta` (axis times angle, rad). Exact for any angle;
/// uses a Taylor expansion below 1e-8 rad so that tiny rotations keep full precision.
glm::dquat QuaternionFromRotationVector(const glm::dvec3& theta) noexcept;

/// Rotation vector (axis times angle, rad, angle in [0, pi]) of the unit quaternion `q`.
/// The quaternion need not be normalized; returns zero for the identity. q and -q give the same
/// result (shortest rotation).
glm::dvec3 RotationVectorFromQuaternion(const glm::dquat& q) noexcept;

/// The 6-DoF difference q ⊖ q0 used by the contact linearization (DESIGN.md §5): translation
/// difference p - p0 (m) and the world-frame rotation vector of R * R0ᵀ (rad). Both in the frame
/// that X and X0 are expressed in.
Twist PoseDifference(const RigidTransform& X, const RigidTransform& X0) noexcept;

/// Applies a small world-frame displacement: translation by `delta.linear` (m) and rotation by
/// the rotation vector `delta.angular` (rad) about the body's own origin, axes of the outer frame.
/// Inverse of PoseDifference: PoseDifference(Displace(X0, d), X0) == d for |d.angular| < pi.
RigidTransform Displace(const RigidTransform& X0, const Twist& delta) noexcept;

/// True when every component is finite and the quaternion has a norm within 1e-3 of one.
bool IsFiniteRigidTransform(const RigidTransform& X) noexcept;
/// True when every component (translation, m; quaternion w, x, y, z) is finite, whatever the
/// quaternion's norm.
bool IsFinite(const RigidTransform& X) noexcept;

/// True when every component is finite.
bool IsFinite(const Twist& V) noexcept;
/// True when every component is finite.
bool IsFinite(const Wrench& F) noexcept;

}  // namespace ht
