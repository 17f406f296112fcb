#include "haptic_core/height_field.h"

#include <algorithm>
#include <cmath>
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

}  // namespace ht
