#pragma once
// Novint Falcon, kinematics: encoder counts -> motor angles -> handle position (forward solution
// of the Falcon's delta mechanism), inverse kinematics, the Jacobian, and Jacobian transpose
// force -> joint torques -> motor commands. Part of the Falcon backend (falcon.h).
//
// The mechanism model is R. E. Stamper's, "A Three Degree of Freedom Parallel Manipulator with
// Only Translational Degrees of Freedom", PhD thesis, Univ. of Maryland, 1997 (ISR PhD 97-4), as
// parameterised in libnifalcon (github.com/libnifalcon/libnifalcon, BSD; read, not copied).
//
// Frames. K is libnifalcon's kinematic frame of the Falcon (z out of the device towards the
// user, +y up, the legs at 105°, -15° and -135° about z). D, the frame every function here works
// in, has K's axes and its origin at the centre of the workspace, 0.11 m out along z (libnifalcon
// examples/falcon_test_cli/FalconSphereTest.cpp centres its sphere there). H is the handle (the
// grip centre). Orientation is not sensed: R_DH is the identity. The device base M that the rest
// of the product sees (+z up, +y away from the user, +x right: the SpaceMouse's and the replay's
// axes) is D turned about x: kR_MD below; FalconDevice converts at its ReadState/WriteWrench.

#include <array>
#include <cstdint>
#include <glm/mat3x3.hpp>
#include <glm/matrix.hpp>
#include <glm/vec3.hpp>

namespace ht::falcon {

// ---------------------------------------------------------------------------------------------
// Kinematics
// ---------------------------------------------------------------------------------------------

/// Actuated angles θ1 of legs 1..3 (rad), Stamper's convention as in libnifalcon.
using MotorAngles = std::array<double, 3>;
/// Joint torques about the three actuated axes (N·m), positive in the direction of growing θ1.
using MotorTorques = glm::dvec3;

/// Position of the workspace centre in K (m): D's (and M's) origin.
inline constexpr double kWorkspaceCentreZ_m = 0.11;

/// R_MD, D's axes in M (columns): D's +x (right) is M's +x, D's +y (up) is M's +z, and D's +z
/// (towards the user) is M's −y. A proper rotation (det +1); p_M = kR_MD · p_D,
/// F_D = transpose(kR_MD) · F_M.
inline constexpr glm::dmat3 kR_MD{1.0, 0.0,  0.0,   // column 0: D's x in M
                                  0.0, 0.0,  1.0,   // column 1: D's y in M
                                  0.0, -1.0, 0.0};  // column 2: D's z in M

/// Motor angle θ1 (rad) for an encoder count: 320-slot wheel read in quadrature (1280 counts
/// per motor turn) on a 14.25 mm shaft driving a 110 mm arm capstan, 35° at count 0
/// (libnifalcon core/FalconGeometry.h WHEEL_SLOTS_NUMBER, SHAFT_DIAMETER, SMALL_ARM_DIAMETER,
/// THETA_OFFSET_ANGLE; core/FalconKinematic.h getTheta).
double EncoderToMotorAngle(double counts) noexcept;
/// Inverse of EncoderToMotorAngle (counts, not rounded).
double MotorAngleToEncoder(double angle_rad) noexcept;

/// Closed-form inverse kinematics: the motor angles that put the handle at p_DH (m, in D).
/// False when the point is outside the mechanism's reach. Per leg: the point in the leg's
/// (u,v,w) frame fixes the parallelogram's out-of-plane angle θ3 from v, and θ1 from the circle
/// the knee must lie on (Stamper 1997, ch. 3; libnifalcon FalconKinematicStamper::IK chooses
/// the same branch).
bool InverseKinematics(const glm::dvec3& p_DH, MotorAngles& theta) noexcept;

/// Forward kinematics: the handle position p_DH (m, in D) for motor angles `theta` (rad), by
/// Newton's method on the three leg-closure equations starting from the value `p_DH` holds
/// (pass the previous solution; the workspace centre, zero, when there is none). The result is
/// checked against InverseKinematics. False, `p_DH` untouched, when it does not converge within
/// 30 iterations or lands on the other knee branch.
bool ForwardKinematics(const MotorAngles& theta, glm::dvec3& p_DH) noexcept;

/// The Jacobian J = ∂p_DH/∂θ (m/rad; column j is the handle velocity per unit rate of motor j)
/// at handle position p_DH, from the implicit-function theorem on the leg-closure equations.
/// False near a singularity (|det| of ∂θ/∂p below 1e-9) or outside the reach.
bool HandleJacobian(const glm::dvec3& p_DH, glm::dmat3& J) noexcept;

/// Joint torques that render the force F_H_D (N, on the handle, in D) at the pose whose
/// Jacobian is J: τ = Jᵀ F (virtual work).
inline MotorTorques TorquesForForce(const glm::dmat3& J, const glm::dvec3& F_H_D) noexcept {
  return glm::transpose(J) * F_H_D;
}

/// Motor command units per N·m of joint torque, with the sign flip the firmware wants:
/// command = -kMotorCommandPerNm · τ (libnifalcon FalconKinematicStamper::getForces, "convert
/// torque to motor voltages": torque *= 10000; enc_force = -torque). An empirical scale, not a
/// calibrated one.
inline constexpr double kMotorCommandPerNm = 10000.0;
/// Default per-motor command limit: 10000 units = 1 N·m. libnifalcon documents no limit (it
/// clamps at a self-described "rather random" 30 N·m); 8.9 N at the workspace centre needs
/// about 0.54 N·m on the most loaded motor, so this leaves ~1.9x headroom inside the int16 field.
inline constexpr int kDefaultMaxMotorCommand = 10000;

/// Motor commands for joint torques τ (N·m): -kMotorCommandPerNm·τ, and when any motor would
/// exceed `max_command` (1..32767) the whole vector is scaled down so that the largest is at the
/// limit, which keeps the force direction. Non-finite torques give zero commands.
struct MotorCommands {
  std::array<std::int16_t, 3> command{};
  bool saturated = false;
};
MotorCommands TorquesToMotorCommands(const MotorTorques& tau_nm, int max_command) noexcept;

}  // namespace ht::falcon
