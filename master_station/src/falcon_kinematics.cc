// Novint Falcon, kinematics: encoder scale, closed-form inverse and Newton forward kinematics of
// the delta mechanism (Stamper 1997, as parameterised in libnifalcon), the Jacobian, and torques
// to motor commands.

#include "master_station/falcon_kinematics.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <glm/geometric.hpp>
#include <numbers>

namespace ht::falcon {
namespace {

// ---- Mechanism (libnifalcon core/FalconGeometry.h, after Stamper 1997, fig. p. 30) ----
constexpr double kA = 0.060;         // leg base to knee (m)
constexpr double kB = 0.1025;        // parallelogram (shin) side (m)
constexpr double kC = 0.014;         // shin joint to effector centre, u component (m)
constexpr double kD = 0.01125;       // shin to effector joint (m)
constexpr double kE = kD;            // knee to shin joint (m)
constexpr double kF = -0.025;        // shin joint to effector centre, v component (m)
constexpr double kR = 0.037233758;   // frame origin to leg base, u component (m)
constexpr double kS = -0.027330909;  // frame origin to leg base, v component (m)
// Leg directions about z: 90°, -30°, -150°, each turned by the 15° tilt of the device.
constexpr std::array<double, 3> kPhi = {std::numbers::pi / 2 + std::numbers::pi / 12,
                                        -std::numbers::pi / 6 + std::numbers::pi / 12,
                                        -5 * std::numbers::pi / 6 + std::numbers::pi / 12};
// Encoder: 320 slots in quadrature on a 14.25 mm shaft, 110 mm arm capstan, 35° at 0 counts.
constexpr double kCountsPerMotorTurn = 4.0 * 320.0;
constexpr double kShaftDiameter_m = 0.01425;
constexpr double kArmDiameter_m = 0.110;
constexpr double kRadPerCount =
    2.0 * std::numbers::pi * kShaftDiameter_m / (kCountsPerMotorTurn * kArmDiameter_m);
constexpr double kAngleAtZero_rad = 35.0 * std::numbers::pi / 180.0;

struct LegTrig {
  double c, s;
};
const std::array<LegTrig, 3>& LegTrigs() noexcept {
  static const std::array<LegTrig, 3> trig = {LegTrig{std::cos(kPhi[0]), std::sin(kPhi[0])},
                                              LegTrig{std::cos(kPhi[1]), std::sin(kPhi[1])},
                                              LegTrig{std::cos(kPhi[2]), std::sin(kPhi[2])}};
  return trig;
}

glm::dvec3 ToK(const glm::dvec3& p_DH) noexcept {
  return {p_DH.x, p_DH.y, p_DH.z + kWorkspaceCentreZ_m};
}

// One leg's closure equation and its derivatives at handle point p_K for motor angle theta:
//   C(p, θ) = (u + c - a cos θ)² + (w - a sin θ)² - (d + e + sqrt(b² - (v + f)²))² = 0,
// with (u, v, w) the point in the leg's frame: the knee (end of the arm a) lies on the circle of
// radius d + e + b sin θ3 around the effector-side joint, b cos θ3 = v + f.
struct LegClosure {
  double value = 0.0;
  glm::dvec3 grad_p{0.0};  // ∂C/∂p_K
  double d_theta = 0.0;    // ∂C/∂θ
  bool ok = false;
};

LegClosure EvaluateLeg(int i, const glm::dvec3& p_K, double theta) noexcept {
  LegClosure out;
  const LegTrig& t = LegTrigs()[i];
  const double u = t.c * p_K.x + t.s * p_K.y - kR;
  const double v = -t.s * p_K.x + t.c * p_K.y - kS;
  const double w = p_K.z;
  const double q = v + kF;
  const double s2 = kB * kB - q * q;
  if (!(s2 > 1e-12)) return out;
  const double root = std::sqrt(s2);
  const double L = kD + kE + root;
  const double U = u + kC - kA * std::cos(theta);
  const double W = w - kA * std::sin(theta);
  out.value = U * U + W * W - L * L;
  const double dC_du = 2.0 * U;
  const double dC_dv = 2.0 * L * q / root;
  const double dC_dw = 2.0 * W;
  out.grad_p = {dC_du * t.c - dC_dv * t.s, dC_du * t.s + dC_dv * t.c, dC_dw};
  out.d_theta = 2.0 * kA * (U * std::sin(theta) - W * std::cos(theta));
  out.ok = std::isfinite(out.value);
  return out;
}

glm::dmat3 FromRows(const glm::dvec3& r0, const glm::dvec3& r1, const glm::dvec3& r2) noexcept {
  return glm::transpose(glm::dmat3(r0, r1, r2));
}

}  // namespace

double EncoderToMotorAngle(double counts) noexcept {
  return counts * kRadPerCount + kAngleAtZero_rad;
}

double MotorAngleToEncoder(double angle_rad) noexcept {
  return (angle_rad - kAngleAtZero_rad) / kRadPerCount;
}

bool InverseKinematics(const glm::dvec3& p_DH, MotorAngles& theta) noexcept {
  const glm::dvec3 p_K = ToK(p_DH);
  MotorAngles out{};
  for (int i = 0; i < 3; ++i) {
    const LegTrig& t = LegTrigs()[i];
    const double u = t.c * p_K.x + t.s * p_K.y - kR;
    const double v = -t.s * p_K.x + t.c * p_K.y - kS;
    const double w = p_K.z;
    const double q = v + kF;  // b cos θ3
    if (!(std::abs(q) < kB)) return false;
    const double L = kD + kE + std::sqrt(kB * kB - q * q);  // d + e + b sin θ3
    // Knee circle: (X - a cos θ)² + (w - a sin θ)² = L², X = u + c, i.e.
    // X cos θ + w sin θ = (X² + w² + a² - L²) / (2a) = ρ cos(θ - atan2(w, X)).
    const double X = u + kC;
    const double rho = std::hypot(X, w);
    if (!(rho > 1e-9)) return false;
    const double k = (X * X + w * w + kA * kA - L * L) / (2.0 * kA * rho);
    if (!(std::abs(k) <= 1.0)) return false;
    out[i] = std::atan2(w, X) - std::acos(k);
  }
  theta = out;
  return true;
}

bool ForwardKinematics(const MotorAngles& theta, glm::dvec3& p_DH) noexcept {
  for (double th : theta) {
    if (!std::isfinite(th)) return false;
  }
  glm::dvec3 p_K = ToK(p_DH);
  if (!(std::isfinite(p_K.x) && std::isfinite(p_K.y) && std::isfinite(p_K.z))) {
    p_K = ToK(glm::dvec3(0.0));
  }
  constexpr int kMaxIterations = 30;
  constexpr double kMaxStep_m = 0.02;
  bool converged = false;
  for (int it = 0; it < kMaxIterations && !converged; ++it) {
    std::array<LegClosure, 3> leg;
    for (int i = 0; i < 3; ++i) {
      leg[i] = EvaluateLeg(i, p_K, theta[i]);
      if (!leg[i].ok) return false;
    }
    const glm::dmat3 G = FromRows(leg[0].grad_p, leg[1].grad_p, leg[2].grad_p);
    const double det = glm::determinant(G);
    if (!(std::abs(det) > 1e-18)) return false;
    glm::dvec3 step = glm::inverse(G) * -glm::dvec3(leg[0].value, leg[1].value, leg[2].value);
    const double len = glm::length(step);
    if (!std::isfinite(len)) return false;
    if (len > kMaxStep_m) step *= kMaxStep_m / len;
    p_K += step;
    converged = len < 1e-13;
  }
  // The closure equations hold on both knee branches; keep only the one IK returns.
  const glm::dvec3 p = {p_K.x, p_K.y, p_K.z - kWorkspaceCentreZ_m};
  MotorAngles check{};
  if (!InverseKinematics(p, check)) return false;
  for (int i = 0; i < 3; ++i) {
    if (!(std::abs(check[i] - theta[i]) < 1e-7)) return false;
  }
  p_DH = p;
  return true;
}

bool HandleJacobian(const glm::dvec3& p_DH, glm::dmat3& J) noexcept {
  MotorAngles theta{};
  if (!InverseKinematics(p_DH, theta)) return false;
  const glm::dvec3 p_K = ToK(p_DH);
  // C_i(p, θ_i) = 0 along any motion: ∇C_i · ṗ + ∂C_i/∂θ_i θ̇_i = 0, so row i of ∂θ/∂p is
  // -∇C_i / (∂C_i/∂θ_i), and J = ∂p/∂θ is its inverse.
  std::array<glm::dvec3, 3> rows;
  for (int i = 0; i < 3; ++i) {
    const LegClosure leg = EvaluateLeg(i, p_K, theta[i]);
    if (!leg.ok || !(std::abs(leg.d_theta) > 1e-12)) return false;
    rows[i] = -leg.grad_p / leg.d_theta;
  }
  const glm::dmat3 dtheta_dp = FromRows(rows[0], rows[1], rows[2]);
  if (!(std::abs(glm::determinant(dtheta_dp)) > 1e-9)) return false;
  J = glm::inverse(dtheta_dp);
  return true;
}

MotorCommands TorquesToMotorCommands(const MotorTorques& tau_nm, int max_command) noexcept {
  MotorCommands out;
  const double limit = std::clamp(max_command, 1, 32767);
  glm::dvec3 c = -kMotorCommandPerNm * tau_nm;
  if (!(std::isfinite(c.x) && std::isfinite(c.y) && std::isfinite(c.z))) return out;
  const double largest = std::max({std::abs(c.x), std::abs(c.y), std::abs(c.z)});
  if (largest > limit) {
    c *= limit / largest;
    out.saturated = true;
  }
  for (int i = 0; i < 3; ++i) {
    out.command[i] = static_cast<std::int16_t>(std::clamp(std::round(c[i]), -limit, limit));
  }
  return out;
}

}  // namespace ht::falcon
