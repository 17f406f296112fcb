#include "haptic_core/convex_contact.h"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

namespace ht {
namespace {

std::vector<glm::dvec3> Cube(double h) {
  std::vector<glm::dvec3> v;
  for (int i = 0; i < 8; ++i) v.push_back({i & 1 ? h : -h, i & 2 ? h : -h, i & 4 ? h : -h});
  return v;
}

RigidTransform At(double x, double y, double z) {
  RigidTransform X;
  X.translation = {x, y, z};
  return X;
}

TEST(ConvexContact, SignedDistanceOfStackedCubes) {
  const auto cube = Cube(0.01);
  for (double gap : {-2e-3, -1e-4, 0.0, 5e-4, 9e-4}) {
    const auto c = QueryConvexContact(cube, At(0.002, 0.001, 0.02 + gap), cube, At(0, 0, 0), 1e-3);
    ASSERT_TRUE(c.has_value()) << "gap " << gap;
    EXPECT_NEAR(c->signed_distance_m, gap, 1e-6) << "gap " << gap;
    EXPECT_NEAR(c->normal_W.z, 1.0, 1e-6);  // from B (below) towards A (above)
    // The point lies in the region where the faces meet: inside the common footprint, between
    // the two cube centres (its height along n is not used by the texture stage).
    EXPECT_LE(std::abs(c->point_W.x), 0.01);
    EXPECT_LE(std::abs(c->point_W.y), 0.01);
    EXPECT_GT(c->point_W.z, 0.0);
    EXPECT_LT(c->point_W.z, 0.02 + gap);
  }
}

TEST(ConvexContact, BeyondToleranceIsNoContact) {
  const auto cube = Cube(0.01);
  EXPECT_FALSE(QueryConvexContact(cube, At(0, 0, 0.025), cube, At(0, 0, 0), 1e-3).has_value());
}

TEST(ConvexContact, BadInputIsNoContact) {
  const auto cube = Cube(0.01);
  EXPECT_FALSE(QueryConvexContact({}, At(0, 0, 0), cube, At(0, 0, 0), 1e-3).has_value());
  EXPECT_FALSE(QueryConvexContact(cube, At(NAN, 0, 0), cube, At(0, 0, 0), 1e-3).has_value());
  EXPECT_FALSE(QueryConvexContact(cube, At(0, 0, 0.02), cube, At(0, 0, 0), NAN).has_value());
}

}  // namespace
}  // namespace ht
