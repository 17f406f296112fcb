// The pressure law on a depth field (depth_field.h, ForceLaw::kPressure): closed forms (a box's
// edge pressed into a plane, a flat face's rotational stiffness, a sphere on a half-space, a flat
// tool slid over a sinusoid), its wrench against finite differences of its energy, the node sums
// done by hand, the two kernels against each other, and the contact model's wrench from it.

#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <cmath>
#include <glm/gtc/quaternion.hpp>
#include <random>

#include "haptic_core/contact_model.h"
#include "haptic_core/depth_field.h"

namespace ht {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kAreaRef = 1e-4;  // A_ref (m²) of the test fields
using Mat6 = Eigen::Matrix<double, 6, 6>;

/// A pressure-law field on an nx×ny grid of spacing h, F at X_WF, its maps from callbacks (x, y
/// in F, m; NaN: none), the tool at X_WT0, prepared.
template <typename Env, typename Tool>
DepthField MakeField(int nx, int ny, double h, const RigidTransform& X_WF,
                     const RigidTransform& X_WT0, const Env& env, const Tool& tool,
                     double margin_m = 1e-3) {
  DepthField f;
  f.id = 3;
  f.X_WF = X_WF;
  f.cell_m = h;
  f.nx = nx;
  f.ny = ny;
  f.X_WT0 = X_WT0;
  f.travel_margin_m = margin_m;
  f.force_law = ForceLaw::kPressure;
  f.pressure_area_m2 = kAreaRef;
  for (int j = 0; j < ny; ++j) {
    for (int i = 0; i < nx; ++i) {
      f.env_height_m.push_back(static_cast<float>(env(i * h, j * h)));
      f.tool_height_m.push_back(static_cast<float>(tool(i * h, j * h)));
    }
  }
  EXPECT_TRUE(f.Prepare());
  return f;
}

RigidTransform TurnedFrame() {
  RigidTransform X;
  X.translation = {0.1, -0.05, 0.02};
  X.rotation = glm::normalize(glm::dquat(0.9, 0.2, -0.3, 0.1));
  return X;
}

/// The pressure law's own quantities per unit k_p, in F's axes, from an evaluation (whose depth,
/// gradient and curvature are the law as the seed's penalty on δ_eq: DepthFieldEvaluation).
struct Pressure {
  glm::dvec3 force_F{0.0}, torque_F{0.0};  // −∇U / k_p (m³, m⁴)
  double energy = 0.0;                     // U / k_p (m⁵)
  Mat6 stiffness_F = Mat6::Zero();         // ∇²U / k_p, Gauss–Newton (F's axes)
  double volume = 0.0;                     // Σ A d (m³)
};
Pressure PressureOf(const DepthFieldEvaluation& e, const RigidTransform& X_WF) {
  Pressure p;
  if (!(e.depth_m > 0.0)) return p;
  const glm::dquat R_FW = glm::inverse(X_WF.rotation);
  const double s = kAreaRef * e.depth_m;
  p.force_F = -s * (R_FW * e.gradient.d_translation_W);
  p.torque_F = -s * (R_FW * e.gradient.d_rotation_W);
  p.energy = 0.5 * kAreaRef * e.depth_m * e.depth_m;
  Eigen::Matrix<double, 6, 1> J;
  J << e.gradient.d_translation_W.x, e.gradient.d_translation_W.y, e.gradient.d_translation_W.z,
      e.gradient.d_rotation_W.x, e.gradient.d_rotation_W.y, e.gradient.d_rotation_W.z;
  const Mat6 K_W = kAreaRef * (J * J.transpose() + e.depth_m * e.curvature);
  const glm::dmat3 R = glm::mat3_cast(R_FW);
  Mat6 B = Mat6::Zero();
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) B(r, c) = B(r + 3, c + 3) = R[c][r];
  }
  p.stiffness_F = B * K_W * B.transpose();
  p.volume = e.pressure_volume_m3;
  return p;
}

/// X_WT0 turned by `angle` (rad) about F's axis `axis_F` through the tool's centre of mass.
RigidTransform TurnedAbout(const RigidTransform& X_WT0, const RigidTransform& X_WF,
                           const glm::dvec3& axis_F, double angle) {
  return Displace(X_WT0, Twist{glm::dvec3(0.0), angle * (X_WF.rotation * axis_F)});
}

double Flat(double, double) { return 0.0; }

TEST(PressureLaw, ABoxEdgePressedIntoAPlanePushesWithTheOverlapsVolumeThroughItsCentroid) {
  // A box b wide, tilted by θ about its lowest edge (along y), the edge d below a flat plate:
  // the overlap's cross-section is a triangle with legs along the bottom face (d cot θ) and the
  // side (d tan θ), V = b d² / sin 2θ, the pressures' resultant k_p V along n through the
  // triangle's centroid, (d cot θ − d tan θ) / 3 from the edge. Edges on a node, between nodes.
  const double h = 20e-6, d = 200e-6, tan_theta = 0.1;
  const double theta = std::atan(tan_theta);
  const int nx = 130, ny = 12, j0 = 4, j1 = 7;  // the box's width: nodes j0..j1
  const double width = (j1 - j0 + 1) * h;
  const RigidTransform X_WF = TurnedFrame();
  for (const double offset : {0.0, 0.3, 0.5}) {
    const double x_edge = (12 + offset) * h;
    const auto box = [&](double x, double y) {
      if (y < j0 * h - 1e-9 || y > j1 * h + 1e-9) return std::nan("");
      return -d + std::max((x - x_edge) * tan_theta, (x_edge - x) / tan_theta);
    };
    RigidTransform X_WT0;  // the centre of mass 3 mm above the edge's middle
    X_WT0.translation = X_WF * glm::dvec3(x_edge, 0.5 * (j0 + j1) * h, 3e-3);
    X_WT0.rotation = X_WF.rotation;
    const DepthField f = MakeField(nx, ny, h, X_WF, X_WT0, Flat, box);
    ASSERT_EQ(f.node_stride, 1);
    const DepthFieldEvaluation e = DepthFieldDepthAt(f, X_WT0);
    ASSERT_TRUE(e.valid);
    EXPECT_EQ(e.force_law, ForceLaw::kPressure);
    const Pressure p = PressureOf(e, X_WF);
    const double volume = width * d * d / std::sin(2.0 * theta);
    EXPECT_NEAR(p.volume / volume, 1.0, 0.01) << offset;
    EXPECT_NEAR(p.force_F.z / volume, 1.0, 0.01) << offset;
    EXPECT_NEAR(std::hypot(p.force_F.x, p.force_F.y), 0.0, 1e-9 * volume) << offset;
    // τ = r × F with F along +z: τ_y = −(x − c_x)·F_z.
    const double line_of_action = (d / tan_theta - d * tan_theta) / 3.0;
    const double x_line = -p.torque_F.y / p.force_F.z;  // from the centre of mass, above the edge
    EXPECT_NEAR(x_line / line_of_action, 1.0, 0.01) << offset;
    // The deepest node: the edge's depth, less the bottom face's rise to the next node.
    EXPECT_LE(e.max_node_depth_m, d + 1e-9);
    EXPECT_GE(e.max_node_depth_m, d - h * tan_theta - 1e-9);
  }
}

TEST(PressureLaw, AFlatFacePressedInWholeHasTheRotationalStiffnessOfItsSecondMomentOfArea) {
  // A flat face a × b, wholly 50 µm into a flat plate: U(φ) = ½ k_p b ∫ (d + φ x)² dx, so that
  // ∂²U/∂φ² = k_p b a³ / 12 about the face's middle (the nodes' sum: (a³/12)(1 − 1/n²)). The
  // law's stiffness, and the second difference of its energy, against it.
  const double h = 100e-6, d = 50e-6;
  const int n_a = 30, n_b = 12, i0 = 4, j0 = 6;
  const double a = n_a * h, b = n_b * h;
  const RigidTransform X_WF = TurnedFrame();
  const auto face = [&](double x, double y) {
    const bool on = x > (i0 - 0.5) * h && x < (i0 + n_a - 0.5) * h && y > (j0 - 0.5) * h &&
                    y < (j0 + n_b - 0.5) * h;
    return on ? -d : std::nan("");
  };
  RigidTransform X_WT0;
  // The centre of mass on the face's middle, so that a turn about it moves the face's nodes
  // along n by φ·x alone (a centre above the face would add its height times φ²/2).
  X_WT0.translation = X_WF * glm::dvec3((i0 + 0.5 * (n_a - 1)) * h, (j0 + 0.5 * (n_b - 1)) * h, -d);
  X_WT0.rotation = X_WF.rotation;
  const DepthField f = MakeField(n_a + 2 * i0, n_b + 2 * j0, h, X_WF, X_WT0, Flat, face);
  ASSERT_EQ(f.node_stride, 1);
  const Pressure p0 = PressureOf(DepthFieldDepthAt(f, X_WT0), X_WF);
  const double closed_form = b * a * a * a / 12.0;
  EXPECT_NEAR(p0.stiffness_F(4, 4) / closed_form, 1.0, 0.01);             // about y
  EXPECT_NEAR(p0.stiffness_F(3, 3) / (a * b * b * b / 12.0), 1.0, 0.01);  // about x
  EXPECT_NEAR(p0.stiffness_F(2, 2) / (a * b), 1.0, 1e-9);                 // along n: the area
  EXPECT_NEAR(p0.force_F.z / (a * b * d), 1.0, 1e-6);
  EXPECT_NEAR(p0.torque_F.y, 0.0, 1e-9 * a * a * b * d);
  // The second route: the energy's second difference under a turn of ±φ about F's y.
  const double phi = 2e-3;  // the face's ends move 4 µm: it stays wholly in
  const double up =
      PressureOf(DepthFieldDepthAt(f, TurnedAbout(X_WT0, X_WF, {0, 1, 0}, phi)), X_WF).energy;
  const double down =
      PressureOf(DepthFieldDepthAt(f, TurnedAbout(X_WT0, X_WF, {0, 1, 0}, -phi)), X_WF).energy;
  const double second_difference = (up - 2.0 * p0.energy + down) / (phi * phi);
  EXPECT_NEAR(second_difference / closed_form, 1.0, 0.01);
}

TEST(PressureLaw, ASpherePressedIntoAHalfSpacePushesWithItsCapsVolume) {
  // A sphere of radius R, d into a flat plate: the overlap is a spherical cap, V = π d² (3R − d)/3,
  // pushed straight back along n through the sphere's centre (no torque about it). At 200 µm
  // the field keeps every other node (kDepthFieldDensePressureNodes): a quadrature step of 2h.
  const double R = 5e-3, h = 70e-6;
  const int n = 50;
  const RigidTransform X_WF = TurnedFrame();
  const glm::dvec3 c_F(25 * h + 13e-6, 25 * h - 21e-6, 0.0);  // the centre, off the nodes
  for (const double d : {50e-6, 200e-6}) {
    const auto sphere = [&](double x, double y) {
      const double r2 = (x - c_F.x) * (x - c_F.x) + (y - c_F.y) * (y - c_F.y);
      if (r2 > 0.25 * R * R) return std::nan("");
      return -d + R - std::sqrt(R * R - r2);
    };
    RigidTransform X_WT0;
    X_WT0.translation = X_WF * glm::dvec3(c_F.x, c_F.y, R - d);  // the sphere's centre
    X_WT0.rotation = X_WF.rotation;
    const DepthField f = MakeField(n, n, h, X_WF, X_WT0, Flat, sphere);
    EXPECT_EQ(f.node_stride, d > 100e-6 ? 2 : 1);
    const DepthFieldEvaluation e = DepthFieldDepthAt(f, X_WT0);
    const Pressure p = PressureOf(e, X_WF);
    const double volume = kPi * d * d * (3.0 * R - d) / 3.0;
    EXPECT_NEAR(p.force_F.z / volume, 1.0, 0.01)
        << d << " nodes " << e.overlapping_nodes << " stride " << f.node_stride;
    EXPECT_NEAR(p.volume / volume, 1.0, 0.01) << d;
    EXPECT_LT(std::hypot(p.force_F.x, p.force_F.y), 1e-9 * volume) << d;
    EXPECT_LT(glm::length(p.torque_F), 1e-3 * volume * std::sqrt(2.0 * R * d)) << d;
    EXPECT_NEAR(e.max_node_depth_m, d, 2e-6) << d;
  }
}

TEST(PressureLaw, AFlatToolSlidOverASinusoidFeelsItsEndsLateralForceAndItsCapsPressure) {
  // b = A sin(2πx/λ); a flat face at height z0 over x ∈ [x_L, x_R] (whole cells), L wide, slid
  // by s along x. U(s) = ½ k_p L ∫ q(x)² dx over the face with q = (b − z0)⁺: the lateral force
  // −∂U/∂s = −½ k_p L (q(x_R + s)² − q(x_L + s)²) comes from the face's ends alone (the slopes
  // under the face cancel), the normal force is k_p L ∫ q, and the torque about the centre of
  // mass c, τ_y = −k_p L ∫ q(x)·((x − c_x) + (z0 − c_z) b'(x)) dx (1-D quadrature).
  const double A = 100e-6, z0 = 50e-6, wavelength = 4e-3, h = 50e-6;
  const int i0 = 10, n_face = 83, j0 = 4, n_width = 10;
  const double x_L = (i0 - 0.5) * h, x_R = x_L + n_face * h, L = n_width * h;
  const double k = 2.0 * kPi / wavelength;
  const auto env = [&](double x, double) { return A * std::sin(k * x); };
  const auto face = [&](double x, double y) {
    const bool on = x > x_L && x < x_R && y > (j0 - 0.5) * h && y < (j0 + n_width - 0.5) * h;
    return on ? z0 : std::nan("");
  };
  const RigidTransform X_WF = TurnedFrame();
  const glm::dvec3 c0_F(0.5 * (x_L + x_R), (j0 + 0.5 * (n_width - 1)) * h, 1e-3);
  RigidTransform X_WT0;
  X_WT0.translation = X_WF * c0_F;
  X_WT0.rotation = X_WF.rotation;
  const DepthField f =
      MakeField(i0 + n_face + 90, n_width + 2 * j0, h, X_WF, X_WT0, env, face, 3e-3);
  ASSERT_EQ(f.node_stride, 1);
  const auto q = [&](double x) { return std::max(0.0, A * std::sin(k * x) - z0); };
  double largest_normal = 0.0, largest_lateral = 0.0, largest_torque = 0.0;
  struct Row {
    Pressure field;
    double lateral, normal, torque;
  };
  std::vector<Row> rows;
  for (int step = 0; step < 37; ++step) {  // 108 µm steps: the nodes cross the crests anew
    const double s = step * wavelength / 37.0 + 7e-6;
    const RigidTransform X_WT =
        Displace(X_WT0, Twist{s * (X_WF.rotation * glm::dvec3(1, 0, 0)), glm::dvec3(0.0)});
    Row r;
    r.field = PressureOf(DepthFieldDepthAt(f, X_WT), X_WF);
    r.lateral = -0.5 * L * (q(x_R + s) * q(x_R + s) - q(x_L + s) * q(x_L + s));
    r.normal = 0.0;
    r.torque = 0.0;
    constexpr int kSteps = 200000;
    const double dx = (x_R - x_L) / kSteps;
    for (int m = 0; m < kSteps; ++m) {
      const double x = x_L + s + (m + 0.5) * dx;
      const double qx = q(x);
      if (qx == 0.0) continue;
      r.normal += L * qx * dx;
      r.torque -= L * qx * ((x - (c0_F.x + s)) + (z0 - c0_F.z) * A * k * std::cos(k * x)) * dx;
    }
    largest_normal = std::max(largest_normal, r.normal);
    largest_lateral = std::max(largest_lateral, std::abs(r.lateral));
    largest_torque = std::max(largest_torque, std::abs(r.torque));
    rows.push_back(r);
  }
  ASSERT_GT(largest_lateral, 0.002 * largest_normal);  // the case has a lateral force to read
  for (std::size_t m = 0; m < rows.size(); ++m) {
    const Row& r = rows[m];
    EXPECT_NEAR(r.field.force_F.z, r.normal, 0.01 * largest_normal) << m;
    EXPECT_NEAR(r.field.force_F.x, r.lateral, 0.02 * largest_lateral) << m;
    EXPECT_NEAR(r.field.force_F.y, 0.0, 1e-6 * largest_normal) << m;
    EXPECT_NEAR(r.field.torque_F.y, r.torque, 0.01 * largest_torque) << m;
  }
}

// A rough plate, and a rough face over part of the grid.
constexpr double kH = 0.5e-3;
double Rough(double x, double y) {
  return 40e-6 * std::sin(1700.0 * x + 0.3) * std::cos(2300.0 * y) + 15e-6 * std::sin(5100.0 * y);
}
double RoughFace(double x, double y) {
  const double lo = 8 * kH - 1e-9, hi = 31 * kH + 1e-9;
  if (!(x >= lo && x <= hi && y >= lo && y <= hi)) return std::nan("");
  return -30e-6 + 20e-6 * std::cos(2900.0 * x) * std::sin(1100.0 * y + 1.0);
}
RigidTransform ToolAboveRoughFace(const RigidTransform& X_WF) {
  RigidTransform X_WT;
  X_WT.translation = X_WF * glm::dvec3(19.5 * kH, 19.5 * kH, 5e-3);
  X_WT.rotation = X_WF.rotation;
  return X_WT;
}

TEST(PressureLaw, TheWrenchIsMinusTheGradientOfTheEnergyAlongEachOfTheSixAxes) {
  const RigidTransform X_WF = TurnedFrame();
  const RigidTransform X_WT0 = ToolAboveRoughFace(X_WF);
  const DepthField f = MakeField(40, 40, kH, X_WF, X_WT0, Rough, RoughFace, 3e-3);
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const auto energy = [&](const RigidTransform& X) {
    const DepthFieldEvaluation e = DepthFieldDepthAt(f, X);
    return e.depth_m > 0.0 ? 0.5 * kAreaRef * e.depth_m * e.depth_m : 0.0;
  };
  int with_overlap = 0;
  for (int trial = 0; trial < 20; ++trial) {
    const Twist dq{glm::dvec3(u(rng) * 0.6e-3, u(rng) * 0.6e-3, u(rng) * 20e-6),
                   glm::dvec3(u(rng), u(rng), u(rng)) * 4e-3};
    const RigidTransform X_WT = Displace(X_WT0, dq);
    const DepthFieldEvaluation e = DepthFieldDepthAt(f, X_WT);
    ASSERT_TRUE(e.valid);
    if (!(e.depth_m > 0.0)) continue;
    ++with_overlap;
    const double s = kAreaRef * e.depth_m;  // −∇U = −s·∇δ_eq per unit k_p
    const double g[6] = {s * e.gradient.d_translation_W.x, s * e.gradient.d_translation_W.y,
                         s * e.gradient.d_translation_W.z, s * e.gradient.d_rotation_W.x,
                         s * e.gradient.d_rotation_W.y,    s * e.gradient.d_rotation_W.z};
    for (int axis = 0; axis < 6; ++axis) {
      const double step = axis < 3 ? 1e-8 : 1e-7;
      Twist plus{}, minus{};
      if (axis < 3) {
        plus.linear[axis] = step;
        minus.linear[axis] = -step;
      } else {
        plus.angular[axis - 3] = step;
        minus.angular[axis - 3] = -step;
      }
      const double fd =
          (energy(Displace(X_WT, plus)) - energy(Displace(X_WT, minus))) / (2.0 * step);
      const double scale = (axis < 3 ? 1.0 : 0.01) * e.pressure_volume_m3;
      EXPECT_NEAR(g[axis], fd, 1e-4 * scale + 1e-18) << "trial " << trial << " axis " << axis;
    }
  }
  EXPECT_GE(with_overlap, 10);
}

TEST(PressureLaw, TheFieldsSumsAreTheNodesSumsDoneByHandAndBothKernelsAgree) {
  // A plate b = c0 + c1·x + c2·y (the bicubic reads a plane exactly; powers of two, so that the
  // float map holds it exactly) and a curved tool at a turned and slid pose: every tool node
  // moved by hand, its overlap d = b(s) − s.z and ∇d = (g, (s − c) × g) with g = (c1, c2, −1),
  // summed as the law says.
  const double h = 1.0 / 4096.0, c0 = 1.0 / 32768.0, c1 = 1.0 / 32.0, c2 = -1.0 / 64.0;
  const int n = 40;
  const auto plate = [&](double x, double y) { return c0 + c1 * x + c2 * y; };
  const auto dome = [&](double x, double y) {
    const double r2 = (x - 20 * h) * (x - 20 * h) + (y - 20 * h) * (y - 20 * h);
    if (r2 > 12.0 * 12.0 * h * h) return std::nan("");
    return 50e-6 + r2 / (2.0 * 0.02);  // a 20 mm radius, lowest 50 µm above the plate's level
  };
  const RigidTransform X_WF = TurnedFrame();
  RigidTransform X_WT0;
  X_WT0.translation = X_WF * glm::dvec3(20 * h, 20 * h, 4e-3);
  X_WT0.rotation = X_WF.rotation;
  DepthField f = MakeField(n, n, h, X_WF, X_WT0, plate, dome, 2e-3);
  std::mt19937 rng(17);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  int compared = 0;
  for (int trial = 0; trial < 30; ++trial) {
    const RigidTransform X_WT = Displace(
        X_WT0,
        Twist{X_WF.rotation * glm::dvec3(u(rng) * 0.5e-3, u(rng) * 0.5e-3, -60e-6 + u(rng) * 30e-6),
              glm::dvec3(u(rng), u(rng), u(rng)) * 5e-3});
    const RigidTransform D = X_WF.Inverse() * X_WT * X_WT0.Inverse() * X_WF;
    const glm::dvec3 c_F = X_WF.Inverse() * X_WT.translation;
    double squared = 0.0, volume = 0.0;
    Eigen::Matrix<double, 6, 1> first = Eigen::Matrix<double, 6, 1>::Zero();
    Mat6 second = Mat6::Zero();
    for (int j = 0; j < n; ++j) {
      for (int i = 0; i < n; ++i) {
        const double a = f.tool_height_m[static_cast<std::size_t>(j * n + i)];
        if (!std::isfinite(a)) continue;
        const glm::dvec3 s = D * glm::dvec3(i * h, j * h, a);
        const double d = plate(s.x, s.y) - s.z;
        if (!(d > 0.0)) continue;
        const glm::dvec3 g(c1, c2, -1.0), lever = glm::cross(s - c_F, g);
        Eigen::Matrix<double, 6, 1> J;
        J << g.x, g.y, g.z, lever.x, lever.y, lever.z;
        squared += h * h * d * d;
        volume += h * h * d;
        first += h * h * d * J;
        second += h * h * J * J.transpose();
      }
    }
    for (const DepthFieldKernel kernel : {DepthFieldKernel::kScalar, DepthFieldKernel::kAvx2}) {
      if (!DepthFieldKernelAvailable(kernel)) continue;
      const DepthFieldEvaluation e = DepthFieldDepthAt(f, X_WT, kernel);
      ASSERT_TRUE(e.valid);
      if (volume == 0.0) {
        EXPECT_LE(e.depth_m, 0.0);
        continue;
      }
      ++compared;
      const Pressure p = PressureOf(e, X_WF);
      EXPECT_NEAR(p.volume, volume, 1e-6 * volume) << trial;
      EXPECT_NEAR(p.energy, 0.5 * squared, 1e-6 * squared) << trial;
      const double scale = first.head<3>().norm();
      EXPECT_NEAR(p.force_F.x, -first[0], 1e-6 * scale) << trial;
      EXPECT_NEAR(p.force_F.y, -first[1], 1e-6 * scale) << trial;
      EXPECT_NEAR(p.force_F.z, -first[2], 1e-6 * scale) << trial;
      EXPECT_NEAR(p.torque_F.x, -first[3], 1e-6 * scale * 0.01) << trial;
      EXPECT_NEAR(p.torque_F.y, -first[4], 1e-6 * scale * 0.01) << trial;
      EXPECT_NEAR(p.torque_F.z, -first[5], 1e-6 * scale * 0.01) << trial;
      EXPECT_LE((p.stiffness_F - second).norm(), 1e-6 * second.norm()) << trial;
      // The curvature the implicit step takes is positive semi-definite.
      const Eigen::SelfAdjointEigenSolver<Mat6> eig(e.curvature);
      EXPECT_GE(eig.eigenvalues().minCoeff(), -1e-9 * e.curvature.norm()) << trial;
    }
  }
  EXPECT_GE(compared, 30);
}

TEST(PressureLaw, ASeparatedToolReadsTheSeedsNegativeDepthAndFeelsNothing) {
  const RigidTransform X_WF = TurnedFrame();
  const RigidTransform X_WT0 = ToolAboveRoughFace(X_WF);
  const DepthField f = MakeField(40, 40, kH, X_WF, X_WT0, Rough, RoughFace, 3e-3);
  const glm::dvec3 n_W = X_WF.rotation * glm::dvec3(0, 0, 1);
  RigidTransform lifted = X_WT0;
  lifted.translation += 300e-6 * n_W;  // the surfaces overlap by 105 µm at most: ≥ 195 µm apart
  const DepthFieldEvaluation e = DepthFieldDepthAt(f, lifted);
  ASSERT_TRUE(e.valid);
  EXPECT_EQ(e.overlapping_nodes, 0);
  EXPECT_LT(e.depth_m, -150e-6);
  EXPECT_NEAR(glm::dot(e.gradient.d_translation_W, n_W), -1.0, 1e-6);
  ContactModel model;
  model.X_WT0 = X_WT0;
  model.num_contacts = 1;
  model.contacts[0].stiffness_n_per_m = 5000.0;
  model.contacts[0].depth_field_id = f.id;
  const DepthField* fields[] = {&f};
  const ContactModelEvaluation m = EvaluateContactModel(model, lifted, fields);
  EXPECT_EQ(m.active_contacts, 0);
  EXPECT_EQ(m.field_contacts, 1);
  EXPECT_EQ(glm::length(m.F_T_W.force), 0.0);
}

TEST(PressureLaw, TheContactModelPushesWithKOverTheReferenceAreaTimesTheNodesSums) {
  // The contact's k and the field's A_ref give k_p = k / A_ref: the model's force, energy,
  // stiffness and Hunt–Crossley weight are k_p times the field's sums.
  const RigidTransform X_WF = TurnedFrame();
  const RigidTransform X_WT0 = ToolAboveRoughFace(X_WF);
  const DepthField f = MakeField(40, 40, kH, X_WF, X_WT0, Rough, RoughFace, 3e-3);
  const double k = 6000.0;
  ContactModel model;
  model.X_WT0 = X_WT0;
  model.num_contacts = 1;
  model.contacts[0].stiffness_n_per_m = k;
  model.contacts[0].depth_field_id = f.id;
  const glm::dvec3 n_W = X_WF.rotation * glm::dvec3(0, 0, 1);
  RigidTransform pressed = X_WT0;
  pressed.translation -= 20e-6 * n_W;
  const DepthField* fields[] = {&f};
  const ContactModelEvaluation m = EvaluateContactModel(model, pressed, fields);
  const DepthFieldEvaluation e = DepthFieldDepthAt(f, pressed);
  ASSERT_GT(e.overlapping_nodes, 10);
  ASSERT_EQ(m.active_contacts, 1);
  const double k_p = k / kAreaRef;
  const Pressure p = PressureOf(e, X_WF);
  const glm::dvec3 force_W = X_WF.rotation * (k_p * p.force_F);
  EXPECT_LT(glm::length(m.F_T_W.force - force_W), 1e-9 * glm::length(force_W));
  EXPECT_NEAR(m.potential_energy_j, k_p * p.energy, 1e-9 * k_p * p.energy);
  // Along n the force is k_p times the overlap's volume (each node's ∇d has −1 along n).
  EXPECT_NEAR(glm::dot(m.F_T_W.force, n_W), k_p * e.pressure_volume_m3,
              1e-9 * k_p * e.pressure_volume_m3);
  EXPECT_LE((m.G - k * e.pressure_damping).norm(), 1e-9 * m.G.norm());
  EXPECT_GT(m.G.norm(), 0.0);
}

TEST(PressureLaw, AStrideHintIsKeptWhileTheFieldsNodeCountAllowsIt) {
  // The sphere of ASpherePressedIntoAHalfSpace at 200 µm: 1,259 overlapping nodes, so that
  // without a hint Prepare keeps every 2nd node (315). A hint of 4 (~80 nodes, within
  // [512/8, 512]) is kept; a hint of 8 (~20 nodes, below the band) is refined to 4; a hint of 1
  // (1,259, above it) is coarsened to 2.
  const double R = 5e-3, h = 70e-6, d = 200e-6;
  const RigidTransform X_WF = TurnedFrame();
  const glm::dvec3 c_F(25 * h, 25 * h, 0.0);
  const auto sphere = [&](double x, double y) {
    const double r2 = (x - c_F.x) * (x - c_F.x) + (y - c_F.y) * (y - c_F.y);
    return r2 > 0.25 * R * R ? std::nan("") : -d + R - std::sqrt(R * R - r2);
  };
  RigidTransform X_WT0;
  X_WT0.translation = X_WF * glm::dvec3(c_F.x, c_F.y, R - d);
  X_WT0.rotation = X_WF.rotation;
  DepthField f = MakeField(50, 50, h, X_WF, X_WT0, Flat, sphere);
  EXPECT_EQ(f.node_stride, 2);
  const double volume = kPi * d * d * (3.0 * R - d) / 3.0;
  for (const auto& [hint, kept] : {std::pair{4, 4}, std::pair{8, 4}, std::pair{1, 2}}) {
    f.stride_hint = static_cast<std::uint8_t>(hint);
    ASSERT_TRUE(f.Prepare());
    EXPECT_EQ(f.node_stride, kept) << hint;
    // Every stride is a quadrature of the same integral.
    EXPECT_NEAR(DepthFieldDepthAt(f, X_WT0).pressure_volume_m3 / volume, 1.0, 0.02) << hint;
  }
  for (const int bad : {3, 16}) {
    f.stride_hint = static_cast<std::uint8_t>(bad);
    EXPECT_FALSE(f.Prepare()) << bad;
  }
}

TEST(PressureLaw, PrepareRefusesAnUnknownLawOrAReferenceAreaThatIsNotPositive) {
  const RigidTransform X_WF = TurnedFrame();
  DepthField f = MakeField(40, 40, kH, X_WF, ToolAboveRoughFace(X_WF), Rough, RoughFace);
  for (const double area : {0.0, -1e-4, std::nan(""), HUGE_VAL, 1e-300, 1e3}) {
    f.pressure_area_m2 = area;
    EXPECT_FALSE(f.Prepare()) << area;
  }
  f.pressure_area_m2 = kAreaRef;
  f.force_law = static_cast<ForceLaw>(2);
  EXPECT_FALSE(f.Prepare());
  f.force_law = ForceLaw::kSeed;
  f.pressure_area_m2 = 0.0;  // the seed's law needs none
  EXPECT_TRUE(f.Prepare());
}

}  // namespace
}  // namespace ht
