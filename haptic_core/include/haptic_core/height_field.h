#pragma once
// Haptic texture storage: a scalar height field with a mip chain (DESIGN.md §2, seed §19.6.2).

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

namespace ht {

/// One mip level of a height field: `width` × `height` texels, row-major (`texels[y*width + x]`),
/// heights in metres along the coarse surface's outward normal.
struct HeightFieldLevel {
  int width = 0;
  int height = 0;
  std::vector<float> texels;
};

/// A haptic texture: the height h(u,v) (m) of the full-resolution surface above the coarse surface
/// along its interpolated outward normal, p_full = p_coarse + h·N [S][L]. Texture coordinates
/// (u,v) ∈ [0,1]² map texel centres at ((x+0.5)/width, (y+0.5)/height). Level 0 is the full
/// resolution (seed: 1024×1024 floats); each further level halves both sizes with a 2×2 box filter
/// so that samples taken at the level whose texel matches the penetration-depth grid cell do not
/// alias.
class HeightField {
 public:
  HeightField() = default;

  /// Builds a height field from `texels` (#width*height, row-major, metres) and its mip chain.
  /// `wrap_u`/`wrap_v` select periodic addressing (else clamp to edge) along each axis.
  /// Throws std::invalid_argument if a size is not positive, the texel count does not match,
  /// or any texel is not finite.
  HeightField(int width, int height, std::vector<float> texels, bool wrap_u, bool wrap_v);

  /// Number of mip levels (1 + floor(log2(max(width,height)))); 0 for an empty field.
  int num_levels() const noexcept { return static_cast<int>(levels_.size()); }
  /// Level `i` (0 = full resolution). Precondition: 0 <= i < num_levels().
  const HeightFieldLevel& level(int i) const noexcept { return levels_[i]; }
  bool empty() const noexcept { return levels_.empty(); }
  bool wrap_u() const noexcept { return wrap_u_; }
  bool wrap_v() const noexcept { return wrap_v_; }
  /// Smallest and largest level-0 height (m).
  float min_height() const noexcept { return min_height_; }
  float max_height() const noexcept { return max_height_; }

  /// Bilinear sample (m) of level `level` (clamped to the chain) at texture coordinates (u,v).
  /// Returns 0 for an empty field. Never allocates; non-finite u or v gives 0.
  inline float Sample(int level, float u, float v) const noexcept;
  /// The same value as Sample(level, u, v), bit for bit, with the address arithmetic (wrap or
  /// clamp) skipped when the 2×2 footprint lies inside the level: the texture stage's fast
  /// path. `L` must be level(level) of this field, 0 <= level < num_levels().
  inline float SampleAt(int level, const HeightFieldLevel& L, float u, float v) const noexcept;

  /// An upper bound (m) of |Sample(level, u, v)| over the box u ∈ [u0, u1], v ∈ [v0, v1]: the
  /// largest level-0 |h| under the texels the box's bilinear taps reach, max(|min|, |max|) of the
  /// level-0 minima and maxima pyramids (built with the mip chain, same footprints; RangeOver's)
  /// at the first level where the taps
  /// span at most two texels each way, enlarged by 1e-6 relative for the mip averages' and the
  /// bilinear sample's float rounding. Local where the whole texture's largest |h| is not: on the
  /// seed's hammer 16 mm for the whole texture, 1.6 mm at its 99th percentile (what the texture
  /// stage's culled renders use). Falls back to the whole texture's bound (max(|min|, |max|)
  /// of level 0, enlarged the same) when a periodic axis's taps cross its edge, a size is not a
  /// power of two, or the box is not finite. 0 for an empty field. Never allocates.
  float MaxAbsOver(int level, float u0, float v0, float u1, float v1) const noexcept;

  /// Bounds (m) of Sample(0, u, v) over the box u ∈ [u0, u1], v ∈ [v0, v1]: `lo` ≤ every level-0
  /// bilinear sample in the box ≤ `hi` (a bilinear sample lies between its four taps). Read from
  /// the pyramids of the level-0 minima and maxima under each texel at the
  /// first level where the taps span at most four texels each way, the box widened by 1e-3 texel
  /// and the bounds by 1e-6 relative for the float arithmetic: the conservative screen of the
  /// depth refinement (a maximum is bounded by maxima, not by the mip's means). Falls
  /// back to the whole level 0's [min_height, max_height] (widened the same) where MaxAbsOver
  /// falls back to its whole bound. {0, 0} for an empty field. Never allocates.
  void RangeOver(float u0, float v0, float u1, float v1, float& lo, float& hi) const noexcept;

  /// What a texture of level `level`'s size would lose (to model only what a scene needs): over
  /// every level-0 texel centre, |level-0 height − Sample(level, ·)| (m), its largest value and its
  /// RMS. A surface with nothing finer than level k's texels loses little at k. Level 0 gives
  /// zeros; an empty field or a level outside the chain gives zeros too. O(texels); never
  /// allocates.
  struct LevelLoss {
    double max_m = 0.0;
    double rms_m = 0.0;
  };
  LevelLoss LossAtLevel(int level) const noexcept;

  /// Mip level whose texel size best matches `cell_size_m` for a surface whose level-0 texel
  /// measures `texel_size_m` on the coarse surface: floor(log2(cell/texel)), clamped to the chain.
  int LevelForFootprint(double texel_size_m, double cell_size_m) const noexcept;

 private:
  std::vector<HeightFieldLevel> levels_;
  /// Level k ≥ 1's smallest and largest level-0 h under each texel (min_[k − 1], max_[k − 1],
  /// the mip's sizes; RangeOver, and MaxAbsOver as max(|min|, |max|)); empty unless both sizes
  /// are powers of two.
  std::vector<std::vector<float>> min_, max_;
  bool wrap_u_ = false;
  bool wrap_v_ = false;
  float min_height_ = 0.0f;
  float max_height_ = 0.0f;
};

inline float HeightField::Sample(int level, float u, float v) const noexcept {
  if (levels_.empty() || !std::isfinite(u) || !std::isfinite(v)) return 0.0f;
  const HeightFieldLevel& L = levels_[std::clamp(level, 0, num_levels() - 1)];
  // Keep coordinates in a range where float→int conversion is defined.
  const float fx = std::clamp(u * static_cast<float>(L.width) - 0.5f, -1e6f, 1e6f);
  const float fy = std::clamp(v * static_cast<float>(L.height) - 0.5f, -1e6f, 1e6f);
  const float x0f = std::floor(fx), y0f = std::floor(fy);
  const float tx = fx - x0f, ty = fy - y0f;
  const int x0 = static_cast<int>(x0f), y0 = static_cast<int>(y0f);
  const auto address = [](int i, int n, bool wrap) {
    if (wrap) {
      i %= n;
      return i < 0 ? i + n : i;
    }
    return std::clamp(i, 0, n - 1);
  };
  const int xa = address(x0, L.width, wrap_u_), xb = address(x0 + 1, L.width, wrap_u_);
  const int ya = address(y0, L.height, wrap_v_), yb = address(y0 + 1, L.height, wrap_v_);
  const float* row_a = &L.texels[static_cast<size_t>(ya) * L.width];
  const float* row_b = &L.texels[static_cast<size_t>(yb) * L.width];
  const float top = row_a[xa] + tx * (row_a[xb] - row_a[xa]);
  const float bottom = row_b[xa] + tx * (row_b[xb] - row_b[xa]);
  return top + ty * (bottom - top);
}

inline float HeightField::SampleAt(int level, const HeightFieldLevel& L, float u,
                                   float v) const noexcept {
  if (!std::isfinite(u) || !std::isfinite(v)) return 0.0f;
  // The same arithmetic as Sample() up to the texel addresses (so the same value). floor() by
  // truncation and a correction: the same integer for the clamped, finite fx and fy, without a
  // libm call on targets without SSE4.1's round instruction.
  const float fx = std::clamp(u * static_cast<float>(L.width) - 0.5f, -1e6f, 1e6f);
  const float fy = std::clamp(v * static_cast<float>(L.height) - 0.5f, -1e6f, 1e6f);
  int x0 = static_cast<int>(fx), y0 = static_cast<int>(fy);
  x0 -= static_cast<int>(fx < static_cast<float>(x0));
  y0 -= static_cast<int>(fy < static_cast<float>(y0));
  const float x0f = static_cast<float>(x0), y0f = static_cast<float>(y0);
  if (x0 < 0 || y0 < 0 || x0 + 1 >= L.width || y0 + 1 >= L.height) return Sample(level, u, v);
  const float tx = fx - x0f, ty = fy - y0f;
  const float* row_a = &L.texels[static_cast<size_t>(y0) * L.width];
  const float* row_b = row_a + L.width;
  const float top = row_a[x0] + tx * (row_a[x0 + 1] - row_a[x0]);
  const float bottom = row_b[x0] + tx * (row_b[x0 + 1] - row_b[x0]);
  return top + ty * (bottom - top);
}

}  // namespace ht
