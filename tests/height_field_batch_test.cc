// SampleLevelBatch (issue 15): every kernel writes HeightField::Sample's bits, on clamped and
// periodic textures (power-of-two and other sizes), at coordinates inside, on the edges of and
// far outside [0, 1]², and at non-finite ones; batch lengths that leave SIMD tails.
#include "haptic_core/height_field_batch.h"

#include <gtest/gtest.h>

#include <algorithm>
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
      for (const std::size_t n : {std::size_t{1}, std::size_t{7}, std::size_t{8}, std::size_t{13},
                                  std::size_t{16}, std::size_t{29}, std::size_t{256}}) {
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

// LevelForFootprint takes floor(log2(cell/texel)) from the ratio's exponent (issue 15: no log2
// per triangle and render): the level std::log2 gives, clamped, on random ratios, on exact
// powers of two and on ratios a few ulps either side of them.
TEST(HeightFieldLevels, LevelForFootprintIsTheFloorOfLog2) {
  const HeightField field = RandomField(1024, 512, true, true, 5);  // 11 levels
  const auto want = [&](double texel, double cell) {
    if (!(texel > 0.0) || !(cell > texel)) return 0;
    const double level = std::floor(std::log2(cell / texel));
    return static_cast<int>(std::clamp(level, 0.0, field.num_levels() - 1.0));
  };
  std::mt19937 rng(9);
  std::uniform_real_distribution<double> exponent(-2.0, 14.0);
  int compared = 0;
  for (int k = 0; k < 20000; ++k) {
    const double texel = 1e-5 * std::exp2(exponent(rng)), cell = 4e-4;
    ASSERT_EQ(field.LevelForFootprint(texel, cell), want(texel, cell)) << texel;
    ++compared;
  }
  for (int p = 0; p <= 13; ++p) {
    const double cell = 4e-4, exact = cell / std::exp2(p);
    double texel = exact;
    for (int step = 0; step < 4; ++step) texel = std::nextafter(texel, 0.0);
    for (int step = 0; step < 8; ++step) {
      ASSERT_EQ(field.LevelForFootprint(texel, cell), want(texel, cell)) << p << " " << step;
      texel = std::nextafter(texel, 1.0);
      ++compared;
    }
  }
  EXPECT_EQ(field.LevelForFootprint(0.0, 4e-4), 0);
  EXPECT_EQ(field.LevelForFootprint(4e-4, 1e-4), 0);
  EXPECT_EQ(field.LevelForFootprint(1e-320, 4e-4), field.num_levels() - 1);
  EXPECT_GT(compared, 20000);
}

// MaxAbsOver bounds every sample of its box (dense samples of random boxes, all levels, clamped
// and periodic textures, boxes that cross a periodic edge), and is local: far from a single tall
// spike it is the low texture's bound, not the spike's.
TEST(HeightFieldLevels, MaxAbsOverBoundsEverySampleOfItsBoxAndIsLocal) {
  std::mt19937 rng(21);
  std::uniform_real_distribution<float> U(-0.2f, 1.2f), size(0.0f, 0.05f);
  int checked = 0;
  for (const bool wrap : {false, true}) {
    std::vector<float> texels(256 * 128);
    std::uniform_real_distribution<float> h(-1e-4f, 1e-4f);
    for (float& t : texels) t = h(rng);
    texels[37 * 256 + 200] = 5e-3f;  // one spike, at texel (200, 37)
    const HeightField field(256, 128, std::move(texels), wrap, wrap);
    const float whole = 5e-3f;
    for (int trial = 0; trial < 400; ++trial) {
      const int level = static_cast<int>(rng() % static_cast<unsigned>(field.num_levels()));
      const float u0 = U(rng), v0 = U(rng), u1 = u0 + size(rng), v1 = v0 + size(rng);
      const float bound = field.MaxAbsOver(level, u0, v0, u1, v1);
      ASSERT_LE(bound, whole * 1.0001f);
      for (int a = 0; a <= 16; ++a) {
        for (int b = 0; b <= 16; ++b) {
          const float u = u0 + (u1 - u0) * static_cast<float>(a) / 16.0f;
          const float v = v0 + (v1 - v0) * static_cast<float>(b) / 16.0f;
          ASSERT_LE(std::abs(field.Sample(level, u, v)), bound)
              << "level " << level << " at (" << u << ", " << v << ") wrap " << wrap;
          ++checked;
        }
      }
    }
    // Far from the spike (u ≈ 0.78, v ≈ 0.29), at level 0 and 2: the low texture's bound.
    EXPECT_LE(field.MaxAbsOver(0, 0.1f, 0.6f, 0.12f, 0.62f), 1.001e-4f);
    EXPECT_LE(field.MaxAbsOver(2, 0.1f, 0.6f, 0.15f, 0.65f), 1.001e-4f);
    // Over the spike: at least the spike's sample there.
    EXPECT_GE(field.MaxAbsOver(0, 0.78f, 0.28f, 0.79f, 0.30f), 4.9e-3f);
  }
  EXPECT_GT(checked, 200000);
  const HeightField empty;
  EXPECT_EQ(empty.MaxAbsOver(0, 0.0f, 0.0f, 1.0f, 1.0f), 0.0f);
}

// RangeOver bounds every level-0 sample of its box from both sides (dense samples of random
// boxes, clamped and periodic textures, boxes crossing a periodic edge, a non-power-of-two size
// that falls back to the whole range), and is local and tight: far from a spike and a pit its
// bounds are the low texture's, over the spike its upper bound is the spike and its lower bound
// is not dragged down by the pit elsewhere.
TEST(HeightFieldLevels, RangeOverBoundsEveryLevelZeroSampleOfItsBoxFromBothSides) {
  std::mt19937 rng(2132);
  std::uniform_real_distribution<float> U(-0.2f, 1.2f), size(0.0f, 0.05f);
  int checked = 0;
  for (const int width : {256, 200}) {
    for (const bool wrap : {false, true}) {
      std::vector<float> texels(static_cast<std::size_t>(width) * 128);
      std::uniform_real_distribution<float> h(-1e-4f, 1e-4f);
      for (float& t : texels) t = h(rng);
      texels[37 * static_cast<std::size_t>(width) + 150] = 5e-3f;  // a spike at (150, 37)
      texels[90 * static_cast<std::size_t>(width) + 20] = -4e-3f;  // a pit at (20, 90)
      const HeightField field(width, 128, std::move(texels), wrap, wrap);
      for (int trial = 0; trial < 400; ++trial) {
        const float u0 = U(rng), v0 = U(rng), u1 = u0 + size(rng), v1 = v0 + size(rng);
        float lo = 0.0f, hi = 0.0f;
        field.RangeOver(u0, v0, u1, v1, lo, hi);
        ASSERT_LE(hi, 5e-3f * 1.0001f);
        ASSERT_GE(lo, -4e-3f * 1.0001f);
        for (int a = 0; a <= 16; ++a) {
          for (int b = 0; b <= 16; ++b) {
            const float u = u0 + (u1 - u0) * static_cast<float>(a) / 16.0f;
            const float v = v0 + (v1 - v0) * static_cast<float>(b) / 16.0f;
            const float sample = field.Sample(0, u, v);
            ASSERT_LE(sample, hi) << "at (" << u << ", " << v << ") wrap " << wrap;
            ASSERT_GE(sample, lo) << "at (" << u << ", " << v << ") wrap " << wrap;
            ++checked;
          }
        }
      }
      float lo = 0.0f, hi = 0.0f;
      if (width == 256) {
        // Far from both (u ≈ 0.4, v ≈ 0.6): the low texture's range.
        field.RangeOver(0.4f, 0.6f, 0.42f, 0.62f, lo, hi);
        EXPECT_LE(hi, 1.001e-4f);
        EXPECT_GE(lo, -1.001e-4f);
        // Over the spike (u ≈ 0.59, v ≈ 0.29): its height above, the low texture's below.
        field.RangeOver(0.585f, 0.285f, 0.595f, 0.295f, lo, hi);
        EXPECT_GE(hi, 4.99e-3f);
        EXPECT_GE(lo, -1.001e-4f);
      } else {
        // Not a power of two: the whole texture's range.
        field.RangeOver(0.4f, 0.6f, 0.42f, 0.62f, lo, hi);
        EXPECT_GE(hi, 5e-3f);
        EXPECT_LE(lo, -4e-3f);
      }
    }
  }
  EXPECT_GT(checked, 400000);
  const HeightField empty;
  float lo = 1.0f, hi = 1.0f;
  empty.RangeOver(0.0f, 0.0f, 1.0f, 1.0f, lo, hi);
  EXPECT_EQ(lo, 0.0f);
  EXPECT_EQ(hi, 0.0f);
}

}  // namespace
}  // namespace ht
