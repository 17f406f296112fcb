#include "haptic_core/demo/procedural_models.h"

#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <utility>

#include "haptic_core/demo/demo_scenes.h"
#include "haptic_core/haptic_scene.h"

namespace ht {
namespace {

// Every undirected edge used exactly twice, in opposite directions: closed and consistently
// oriented.
void ExpectClosedAndOriented(const std::vector<glm::ivec3>& triangles) {
  std::map<std::pair<int, int>, int> directed;
  for (const auto& t : triangles) {
    for (int c = 0; c < 3; ++c) ++directed[{t[c], t[(c + 1) % 3]}];
  }
  for (const auto& [edge, count] : directed) {
    ASSERT_EQ(count, 1) << "edge " << edge.first << "-" << edge.second
                        << " used twice the same way";
    ASSERT_EQ(directed.count({edge.second, edge.first}), 1u)
        << "edge " << edge.first << "-" << edge.second << " is on a boundary";
  }
}

double SignedVolume(const std::vector<glm::dvec3>& v, const std::vector<glm::ivec3>& t) {
  double vol = 0.0;
  for (const auto& f : t) vol += glm::dot(v[f[0]], glm::cross(v[f[1]], v[f[2]])) / 6.0;
  return vol;
}

TEST(ProceduralModels, BlockHasTheSeedsTriangleCounts) {
  const HapticModel block = MakeRidgedBlock();
  EXPECT_EQ(block.triangles.size(), 16u);
  const TriangleMesh full = MakeRidgedBlockFullResolution();
  EXPECT_EQ(static_cast<std::int64_t>(full.triangles.size()), block.full_resolution_triangles);
  EXPECT_NEAR(static_cast<double>(full.triangles.size()), 65536.0, 0.01 * 65536.0);
  ExpectClosedAndOriented(block.triangles);
  ExpectClosedAndOriented(full.triangles);
  EXPECT_NEAR(SignedVolume(block.vertices_O, block.triangles), 0.04 * 0.04 * 0.02, 1e-12);
  EXPECT_GT(SignedVolume(full.vertices, full.triangles), 0.0);
}

TEST(ProceduralModels, GearHasTheSeedsTriangleCounts) {
  const HapticModel gear = MakeRidgedGear();
  EXPECT_EQ(gear.triangles.size(), 1600u);
  const TriangleMesh full = MakeRidgedGearFullResolution();
  EXPECT_EQ(full.triangles.size(), 25600u);
  ExpectClosedAndOriented(gear.triangles);
  ExpectClosedAndOriented(full.triangles);
  EXPECT_GT(SignedVolume(gear.vertices_O, gear.triangles), 0.0);
}

TEST(ProceduralModels, TextureMatchesTheFullResolutionSurface) {
  // Two routes to the bottom surface height of the block: the full-resolution mesh vertex, and
  // the coarse face plus the texture sampled at the vertex's (u, v).
  const RidgedBlockParams p;
  const HapticModel block = MakeRidgedBlock(p);
  const TriangleMesh full = MakeRidgedBlockFullResolution(p);
  const double texel = 2 * p.half_extents_m.y / p.texture_size;
  double worst = 0.0;
  for (const auto& v : full.vertices) {
    if (v.z > 0.0) continue;  // top ring
    const float u = static_cast<float>((v.x + p.half_extents_m.x) / (2 * p.half_extents_m.x));
    const float w = static_cast<float>((v.y + p.half_extents_m.y) / (2 * p.half_extents_m.y));
    const double from_texture = -p.half_extents_m.z - block.texture.Sample(0, u, w);
    worst = std::max(worst, std::abs(from_texture - v.z));
  }
  // Bilinear reconstruction error: at most slope × texel.
  EXPECT_LT(worst, p.ridges.MaxSlope() * texel);
}

TEST(ProceduralModels, BadParametersThrow) {
  RidgedBlockParams p;
  p.half_extents_m.x = 0.0;
  EXPECT_THROW(MakeRidgedBlock(p), std::invalid_argument);
  RidgedGearParams g;
  g.coarse_segments = 2;
  EXPECT_THROW(MakeRidgedGear(g), std::invalid_argument);
  EXPECT_THROW(MakeTexturedBox(
                   {0.01, 0.01, 0.01}, [](double, double) { return NAN; }, 8, 1.0, "nan"),
               std::invalid_argument);
}

TEST(ProceduralModels, SceneHomePoseRestsTheBlockJustAboveTheGear) {
  const HapticScene scene = MakeBlockOnGearScene();
  EXPECT_NEAR(scene.X_WT_home.translation.z, 0.025 + 0.01 + 0.5e-3, 1e-12);
  EXPECT_EQ(scene.touchables.size(), 1u);
}

}  // namespace
}  // namespace ht
