#include "haptic_core/height_field.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace ht {

HeightField::HeightField(int width, int height, std::vector<float> texels, bool wrap_u, bool wrap_v)
    : wrap_u_(wrap_u), wrap_v_(wrap_v) {
  if (!(width > 0) || !(height > 0)) {
    throw std::invalid_argument("HeightField: size must be positive, got " + std::to_string(width) +
                                "x" + std::to_string(height));
  }
  if (texels.size() != static_cast<size_t>(width) * static_cast<size_t>(height)) {
    throw std::invalid_argument("HeightField: expected " +
                                std::to_string(static_cast<std::int64_t>(width) * height) +
                                " texels, got " + std::to_string(texels.size()));
  }
  min_height_ = texels.empty() ? 0.0f : texels[0];
  max_height_ = min_height_;
  for (float t : texels) {
    if (!std::isfinite(t)) throw std::invalid_argument("HeightField: non-finite texel");
    min_height_ = std::min(min_height_, t);
    max_height_ = std::max(max_height_, t);
  }
  levels_.push_back({width, height, std::move(texels)});
  while (levels_.back().width > 1 || levels_.back().height > 1) {
    const HeightFieldLevel& src = levels_.back();
    HeightFieldLevel dst;
    dst.width = std::max(1, src.width / 2);
    dst.height = std::max(1, src.height / 2);
    dst.texels.resize(static_cast<size_t>(dst.width) * dst.height);
    for (int y = 0; y < dst.height; ++y) {
      const int y0 = std::min(2 * y, src.height - 1), y1 = std::min(2 * y + 1, src.height - 1);
      for (int x = 0; x < dst.width; ++x) {
        const int x0 = std::min(2 * x, src.width - 1), x1 = std::min(2 * x + 1, src.width - 1);
        dst.texels[static_cast<size_t>(y) * dst.width + x] =
            0.25f * (src.texels[static_cast<size_t>(y0) * src.width + x0] +
                     src.texels[static_cast<size_t>(y0) * src.width + x1] +
                     src.texels[static_cast<size_t>(y1) * src.width + x0] +
                     src.texels[static_cast<size_t>(y1) * src.width + x1]);
      }
    }
    levels_.push_back(std::move(dst));
  }
  // The pyramids of the smallest and largest level-0 h (RangeOver; MaxAbsOver reads
  // max(|min|, |max|) from them), over the mip's footprints: with power-of-two sizes, texel c of
  // a level lies under texel c / 2 of the next.
  const auto power_of_two = [](int n) { return (n & (n - 1)) == 0; };
  if (power_of_two(width) && power_of_two(height)) {
    for (std::size_t k = 1; k < levels_.size(); ++k) {
      const HeightFieldLevel& src = levels_[k - 1];
      const HeightFieldLevel& dst = levels_[k];
      const std::vector<float>& below_lo = k == 1 ? src.texels : min_.back();
      const std::vector<float>& below_hi = k == 1 ? src.texels : max_.back();
      std::vector<float> lo(dst.texels.size()), hi(dst.texels.size());
      for (int y = 0; y < dst.height; ++y) {
        const int y0 = std::min(2 * y, src.height - 1), y1 = std::min(2 * y + 1, src.height - 1);
        for (int x = 0; x < dst.width; ++x) {
          const int x0 = std::min(2 * x, src.width - 1), x1 = std::min(2 * x + 1, src.width - 1);
          const auto i = [&](int xx, int yy) {
            return static_cast<std::size_t>(yy) * src.width + xx;
          };
          const auto o = static_cast<std::size_t>(y) * dst.width + x;
          lo[o] = std::min(
              {below_lo[i(x0, y0)], below_lo[i(x1, y0)], below_lo[i(x0, y1)], below_lo[i(x1, y1)]});
          hi[o] = std::max(
              {below_hi[i(x0, y0)], below_hi[i(x1, y0)], below_hi[i(x0, y1)], below_hi[i(x1, y1)]});
        }
      }
      min_.push_back(std::move(lo));
      max_.push_back(std::move(hi));
    }
  }
}

namespace {

// The texels [t0, t1] along one axis of n texels that Sample's bilinear taps (floor(u·n − 0.5)
// and the next) reach for coordinates in [a, b], the box widened by `widen` texels each way and
// the range by `pad` whole texels; clamped to the axis, false where a periodic axis's taps would
// cross its edge.
bool Taps(float a, float b, int n, bool wrap, double widen, int pad, int& t0, int& t1) {
  const double l = std::floor(std::min(a, b) * static_cast<double>(n) - 0.5 - widen) - pad;
  const double h = std::floor(std::max(a, b) * static_cast<double>(n) - 0.5 + widen) + 1.0 + pad;
  if (wrap && (l < 0.0 || h > n - 1.0)) return false;
  t0 = static_cast<int>(std::clamp(l, 0.0, n - 1.0));
  t1 = static_cast<int>(std::clamp(h, 0.0, n - 1.0));
  return true;
}

}  // namespace

void HeightField::RangeOver(float u0, float v0, float u1, float v1, float& lo,
                            float& hi) const noexcept {
  lo = hi = 0.0f;
  if (levels_.empty()) return;
  // Widen a bound away from zero by the rounding allowance (and by an absolute 1e-12 m).
  constexpr float kRounding = 1e-6f;
  const auto widen = [&](float& a, float& b) {
    a -= std::abs(a) * kRounding + 1e-12f;
    b += std::abs(b) * kRounding + 1e-12f;
  };
  lo = min_height_;
  hi = max_height_;
  if (min_.size() + 1 != levels_.size() ||
      !(std::isfinite(u0) && std::isfinite(u1) && std::isfinite(v0) && std::isfinite(v1)) ||
      std::max(std::abs(u0), std::abs(u1)) > 1e6f || std::max(std::abs(v0), std::abs(v1)) > 1e6f) {
    widen(lo, hi);
    return;
  }
  const HeightFieldLevel& L = levels_[0];
  // The taps of Sample at level 0 over the box widened by 1e-3 texel for Sample's float
  // arithmetic (a float u's rounding moves u·W by ~1e-4 texel at 2048 texels).
  int x0, x1, y0, y1;
  if (!Taps(u0, u1, L.width, wrap_u_, 1e-3, 0, x0, x1) ||
      !Taps(v0, v1, L.height, wrap_v_, 1e-3, 0, y0, y1)) {
    widen(lo, hi);
    return;
  }
  // The first level where the taps lie under at most 4×4 texels.
  int s = 0;
  while (((x1 >> s) - (x0 >> s) > 3 || (y1 >> s) - (y0 >> s) > 3) && s + 1 < num_levels()) ++s;
  const HeightFieldLevel& K = levels_[static_cast<std::size_t>(s)];
  const std::vector<float>& K_lo = s == 0 ? K.texels : min_[static_cast<std::size_t>(s - 1)];
  const std::vector<float>& K_hi = s == 0 ? K.texels : max_[static_cast<std::size_t>(s - 1)];
  lo = std::numeric_limits<float>::infinity();
  hi = -std::numeric_limits<float>::infinity();
  for (int y = y0 >> s; y <= std::min(y1 >> s, K.height - 1); ++y) {
    for (int x = x0 >> s; x <= std::min(x1 >> s, K.width - 1); ++x) {
      const auto i = static_cast<std::size_t>(y) * K.width + x;
      lo = std::min(lo, K_lo[i]);
      hi = std::max(hi, K_hi[i]);
    }
  }
  widen(lo, hi);
}

float HeightField::MaxAbsOver(int level, float u0, float v0, float u1, float v1) const noexcept {
  if (levels_.empty()) return 0.0f;
  constexpr float kRounding = 1.0f + 1e-6f;
  const float whole = std::max(std::abs(min_height_), std::abs(max_height_)) * kRounding;
  if (max_.size() + 1 != levels_.size() ||
      !(std::isfinite(u0) && std::isfinite(u1) && std::isfinite(v0) && std::isfinite(v1))) {
    return whole;
  }
  level = std::clamp(level, 0, num_levels() - 1);
  const HeightFieldLevel& L = levels_[static_cast<std::size_t>(level)];
  // The taps of Sample widened by a texel each way for the float arithmetic.
  int x0, x1, y0, y1;
  if (std::max(std::abs(u0), std::abs(u1)) > 1e6f || std::max(std::abs(v0), std::abs(v1)) > 1e6f ||
      !Taps(u0, u1, L.width, wrap_u_, 0.0, 1, x0, x1) ||
      !Taps(v0, v1, L.height, wrap_v_, 0.0, 1, y0, y1)) {
    return whole;
  }
  // The first level up from `level` where the taps lie under at most 2×2 texels.
  int s = 0;
  while (((x1 >> s) - (x0 >> s) > 1 || (y1 >> s) - (y0 >> s) > 1) && level + s + 1 < num_levels()) {
    ++s;
  }
  const int k = level + s;
  const HeightFieldLevel& K = levels_[static_cast<std::size_t>(k)];
  float m = 0.0f;
  for (int y = y0 >> s; y <= std::min(y1 >> s, K.height - 1); ++y) {
    for (int x = x0 >> s; x <= std::min(x1 >> s, K.width - 1); ++x) {
      const auto i = static_cast<std::size_t>(y) * K.width + x;
      const float a = k == 0 ? std::abs(K.texels[i])
                             : std::max(std::abs(min_[static_cast<std::size_t>(k - 1)][i]),
                                        std::abs(max_[static_cast<std::size_t>(k - 1)][i]));
      m = std::max(m, a);
    }
  }
  return m * kRounding;
}

int HeightField::LevelForFootprint(double texel_size_m, double cell_size_m) const noexcept {
  if (levels_.empty() || !(texel_size_m > 0.0) || !(cell_size_m > texel_size_m)) return 0;
  const double ratio = cell_size_m / texel_size_m;
  // floor(log2(ratio)) from the exponent (ratio = m·2^e, m in [0.5, 1): e − 1), without a log2
  // call per triangle and render. Where m is within 1e-13 of 1, a log2 correct to within an ulp
  // may round up to e, so those take log2 itself: the level is floor(std::log2(ratio)) always.
  if (!std::isfinite(ratio)) return num_levels() - 1;  // a texel too small to be a number
  int e = 0;
  const double m = std::frexp(ratio, &e);
  const int level = m > 1.0 - 1e-13 ? static_cast<int>(std::floor(std::log2(ratio))) : e - 1;
  return std::clamp(level, 0, num_levels() - 1);
}

HeightField::LevelLoss HeightField::LossAtLevel(int level) const noexcept {
  LevelLoss loss;
  if (levels_.empty() || level <= 0 || level >= num_levels()) return loss;
  const HeightFieldLevel& L0 = levels_[0];
  double sum2 = 0.0;
  for (int y = 0; y < L0.height; ++y) {
    const float v = (static_cast<float>(y) + 0.5f) / static_cast<float>(L0.height);
    for (int x = 0; x < L0.width; ++x) {
      const float u = (static_cast<float>(x) + 0.5f) / static_cast<float>(L0.width);
      const double e =
          std::abs(static_cast<double>(L0.texels[static_cast<std::size_t>(y) * L0.width + x]) -
                   static_cast<double>(Sample(level, u, v)));
      loss.max_m = std::max(loss.max_m, e);
      sum2 += e * e;
    }
  }
  loss.rms_m = std::sqrt(sum2 / (static_cast<double>(L0.width) * L0.height));
  return loss;
}

}  // namespace ht
