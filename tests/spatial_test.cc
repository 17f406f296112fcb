#include "haptic_core/spatial.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace ht {
namespace {

TEST(Spatial, RotationVectorRoundTripsThroughQuaternion) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int i = 0; i < 1000; ++i) {
    glm::dvec3 theta(u(rng), u(rng), u(rng));
    theta *= (3.0 * std::abs(u(rng))) / std::max(glm::length(theta), 1e-12);  // |θ| < π
    const glm::dvec3 back = RotationVectorFromQuaternion(QuaternionFromRotationVector(theta));
    EXPECT_NEAR(glm::length(back - theta), 0.0, 1e-9);
  }
  const glm::dvec3 tiny(1e-12, -2e-12, 3e-12);
  EXPECT_NEAR(glm::length(RotationVectorFromQuaternion(QuaternionFromRotationVector(tiny)) - tiny),
              0.0, 1e-20);
}

TEST(Spatial, PoseDifferenceInvertsDisplace) {
  RigidTransform X0;
  X0.translation = {0.1, -0.2, 0.3};
  X0.rotation = QuaternionFromRotationVector({0.3, 0.1, -0.4});
  const Twist d{{1e-3, -2e-3, 5e-4}, {0.01, -0.02, 0.03}};
  const Twist back = PoseDifference(Displace(X0, d), X0);
  EXPECT_NEAR(glm::length(back.linear - d.linear), 0.0, 1e-12);
  EXPECT_NEAR(glm::length(back.angular - d.angular), 0.0, 1e-12);
}

TEST(Spatial, CompositionCancelsInnerFrames) {
  RigidTransform X_AB, X_BC;
  X_AB.translation = {1, 2, 3};
  X_AB.rotation = QuaternionFromRotationVector({0, 0, 1.0});
  X_BC.translation = {-1, 0.5, 0};
  X_BC.rotation = QuaternionFromRotationVector({0.2, 0, 0});
  const glm::dvec3 p_C(0.3, -0.1, 0.2);
  const glm::dvec3 direct = (X_AB * X_BC) * p_C, nested = X_AB * (X_BC * p_C);
  EXPECT_NEAR(glm::length(direct - nested), 0.0, 1e-12);
  const glm::dvec3 p_A = X_AB * p_C;
  EXPECT_NEAR(glm::length(X_AB.Inverse() * p_A - p_C), 0.0, 1e-12);
}

TEST(Spatial, FinitenessChecksCatchNaNAndNonUnitQuaternions) {
  RigidTransform X;
  EXPECT_TRUE(IsFiniteRigidTransform(X));
  X.translation.x = NAN;
  EXPECT_FALSE(IsFiniteRigidTransform(X));
  X = {};
  X.rotation = glm::dquat(2.0, 0, 0, 0);
  EXPECT_FALSE(IsFiniteRigidTransform(X));
  EXPECT_FALSE(IsFinite(Wrench{{0, INFINITY, 0}, {}}));
}

}  // namespace
}  // namespace ht
