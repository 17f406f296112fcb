// SampleLevelBatch (issue 15): every kernel writes HeightField::Sample's bits, on clamped and
// periodic textures (power-of-two and other sizes), at coordinates inside, on the edges of and
// far outside [0, 1]², and at non-finite ones; batch lengths that leave SIMD tails.
#include "haptic_core/height_field_batch.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <vector>

namespace ht {
namespace {

HeightField RandomField(int width, int height, bool wrap_u, bool wrap_v, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> h(-2e-4f, 3e-4f);
  std::vector<float> texels(static_cast<std::size_t>(width) * height);
  for (float& t : texels) t = h(rng);
  return HeightField(width, height, std::move(texels), wrap_u, wrap_v);
}

bool SameBits(float a, float b) { return std::memcmp(&a, &b, sizeof a) == 0; }

TEST(SampleLevelBatch, EveryKernelWritesTheBitsOfSample) {
  std::mt19937 rng(15);
  std::uniform_real_distribution<float> inside(0.0f, 1.0f), outside(-3.0f, 4.0f);
  const float specials[] = {0.0f,
                            1.0f,
                            -0.0f,
                            0.5f / 64.0f,
                            1.0f - 0.5f / 64.0f,
                            -1e7f,
                            1e7f,
                            std::numeric_limits<float>::infinity(),
                            -std::numeric_limits<float>::infinity(),
                            std::numeric_limits<float>::quiet_NaN(),
                            std::numeric_limits<float>::denorm_min()};
  struct Case {
    int width, height;
    bool wrap_u, wrap_v;
  };
  const Case cases[] = {{64, 64, false, false}, {64, 32, true, true},  {128, 64, true, false},
                        {48, 40, true, true},   {33, 17, false, true}, {1, 1, false, false}};
  int compared = 0;
  for (const Case& c : cases) {
    const HeightField field = RandomField(c.width, c.height, c.wrap_u, c.wrap_v, 7);
    for (int level = 0; level < field.num_levels(); ++level) {
      for (const std::size_t n :
           {std::size_t{1}, std::size_t{7}, std::size_t{8}, std::size_t{13}, std::size_t{16},
            std::size_t{29}, std::size_t{256}}) {
        std::vector<float> u(n), v(n), best(n, -1.0f), avx2(n, -3.0f), scalar(n, -2.0f);
        for (std::size_t k = 0; k < n; ++k) {
          const int pick = static_cast<int>(rng() % 8);
          u[k] = pick < 5 ? inside(rng) : pick < 7 ? outside(rng) : specials[rng() % 11];
          v[k] = pick < 4 ? inside(rng) : pick < 7 ? outside(rng) : specials[rng() % 11];
        }
        SampleLevelBatch(field, level, u, v, best, SampleKernel::kBest);
        SampleLevelBatch(field, level, u, v, avx2, SampleKernel::kAvx2);
        SampleLevelBatch(field, level, u, v, scalar, SampleKernel::kScalar);
        for (std::size_t k = 0; k < n; ++k) {
          const float want = field.Sample(level, u[k], v[k]);
          ASSERT_TRUE(SameBits(best[k], want))
              << SampleKernelName() << " " << c.width << "x" << c.height << " wrap " << c.wrap_u
              << c.wrap_v << " level " << level << " at (" << u[k] << ", " << v[k]
              << "): " << best[k] << " vs " << want;
          ASSERT_TRUE(SameBits(avx2[k], want)) << SampleKernelName(SampleKernel::kAvx2);
          ASSERT_TRUE(SameBits(scalar[k], want));
          ++compared;
        }
      }
    }
  }
  EXPECT_GT(compared, 5000);
}

TEST(SampleLevelBatch, BadArgumentsWriteNothing) {
  const HeightField field = RandomField(16, 16, false, false, 3);
  std::vector<float> u(9, 0.5f), v(9, 0.5f), h(9, 42.0f), short_v(8, 0.5f);
  SampleLevelBatch(field, -1, u, v, h);
  SampleLevelBatch(field, field.num_levels(), u, v, h);
  SampleLevelBatch(field, 0, u, short_v, h);
  for (const float x : h) EXPECT_EQ(x, 42.0f);
  const HeightField empty;
  SampleLevelBatch(empty, 0, u, v, h);
  for (const float x : h) EXPECT_EQ(x, 42.0f);
  SampleLevelBatch(field, 0, u, v, h);
  for (const float x : h) EXPECT_NE(x, 42.0f);
}

}  // namespace
}  // namespace ht
