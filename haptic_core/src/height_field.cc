#include "haptic_core/height_field.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace ht {

HeightField::HeightField(int width, int height, std::vector<float> texels, bool wrap_u,
                         bool wrap_v)
    : wrap_u_(wrap_u), wrap_v_(wrap_v) {
  if (!(width > 0) || !(height > 0)) {
    throw std::invalid_argument("HeightField: size must be positive, got " +
                                std::to_string(width) + "x" + std::to_string(height));
  }
  if (texels.size() != static_cast<size_t>(width) * static_cast<size_t>(height)) {
    throw std::invalid_argument("HeightField: expected " + std::to_string(width * height) +
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

namespace {
inline int Address(int i, int n, bool wrap) noexcept {
  if (wrap) {
    i %= n;
    return i < 0 ? i + n : i;
  }
  return std::clamp(i, 0, n - 1);
}
}  // namespace

float HeightField::Sample(int level, float u, float v) const noexcept {
  if (levels_.empty() || !std::isfinite(u) || !std::isfinite(v)) return 0.0f;
  const HeightFieldLevel& L = levels_[std::clamp(level, 0, num_levels() - 1)];
  // Keep coordinates in a range where float→int conversion is defined.
  const float fx = std::clamp(u * static_cast<float>(L.width) - 0.5f, -1e6f, 1e6f);
  const float fy = std::clamp(v * static_cast<float>(L.height) - 0.5f, -1e6f, 1e6f);
  const float x0f = std::floor(fx), y0f = std::floor(fy);
  const float tx = fx - x0f, ty = fy - y0f;
  const int x0 = static_cast<int>(x0f), y0 = static_cast<int>(y0f);
  const int xa = Address(x0, L.width, wrap_u_), xb = Address(x0 + 1, L.width, wrap_u_);
  const int ya = Address(y0, L.height, wrap_v_), yb = Address(y0 + 1, L.height, wrap_v_);
  const float* row_a = &L.texels[static_cast<size_t>(ya) * L.width];
  const float* row_b = &L.texels[static_cast<size_t>(yb) * L.width];
  const float top = row_a[xa] + tx * (row_a[xb] - row_a[xa]);
  const float bottom = row_b[xa] + tx * (row_b[xb] - row_b[xa]);
  return top + ty * (bottom - top);
}

int HeightField::LevelForFootprint(double texel_size_m, double cell_size_m) const noexcept {
  if (levels_.empty() || !(texel_size_m > 0.0) || !(cell_size_m > texel_size_m)) return 0;
  const int level = static_cast<int>(std::floor(std::log2(cell_size_m / texel_size_m)));
  return std::clamp(level, 0, num_levels() - 1);
}

}  // namespace ht
