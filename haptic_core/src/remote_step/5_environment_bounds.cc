// Stage 5's bounds on the environment's heights for the culled renders (penetration_depth.h):
// each triangle's texture bound (TriangleBoundCache), the rows' maxima (EnvironmentRowMax) and
// the max pyramid over the window (EnvironmentMaxPyramid).

#include <algorithm>
#include <cmath>
#include <limits>
#include <span>
#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "haptic_core/penetration_depth.h"

namespace ht {

void TriangleBoundCache::Reserve(std::size_t max_triangles) { entries_.reserve(max_triangles); }

void TriangleBoundCache::Reset(const HapticModel& model, double cell_size_m) noexcept {
  model_ = &model;
  cell_size_m_ = cell_size_m;
  usable_ = model.triangles.size() <= entries_.capacity();
  if (!usable_) return;
  if (entries_.size() < model.triangles.size()) entries_.resize(model.triangles.size());
  if (++stamp_ == 0) {  // the stamp wrapped: no entry may carry the new one by accident
    for (Entry& e : entries_) e.stamp = 0;
    stamp_ = 1;
  }
}

void EnvironmentRowMax::Reserve(int max_resolution) {
  const int blocks = (max_resolution + kBlock - 1) / kBlock;
  storage_.reserve(static_cast<std::size_t>(std::max(max_resolution, 0)) *
                   static_cast<std::size_t>(std::max(blocks, 0)));
}

void EnvironmentRowMax::Build(std::span<const float> env_heights, int n) noexcept {
  resolution_ = 0;
  if (n <= 0 || env_heights.size() < static_cast<std::size_t>(n) * n) return;
  const int blocks = (n + kBlock - 1) / kBlock;
  const std::size_t total = static_cast<std::size_t>(n) * static_cast<std::size_t>(blocks);
  if (storage_.capacity() < total) return;  // never allocates
  storage_.resize(total);
  const int full = n / kBlock;  // blocks of kBlock cells; the last may be shorter
  for (int j = 0; j < n; ++j) {
    const float* row = env_heights.data() + static_cast<std::size_t>(j) * n;
    float* dst = storage_.data() + static_cast<std::size_t>(j) * blocks;
    for (int b = 0; b < full; ++b) {
      const float* cell = row + b * kBlock;
#if defined(__SSE2__)
      // MAXPS(x, m) is x > m ? x : m: a NaN x is passed over (m starts at −∞, never NaN).
      const __m128 minus_inf = _mm_set1_ps(-std::numeric_limits<float>::infinity());
      __m128 m4 = _mm_max_ps(_mm_loadu_ps(cell), minus_inf);
      m4 = _mm_max_ps(_mm_loadu_ps(cell + 4), m4);
      m4 = _mm_max_ps(_mm_shuffle_ps(m4, m4, _MM_SHUFFLE(1, 0, 3, 2)), m4);
      m4 = _mm_max_ps(_mm_shuffle_ps(m4, m4, _MM_SHUFFLE(2, 3, 0, 1)), m4);
      dst[b] = _mm_cvtss_f32(m4);
#else
      float m = -std::numeric_limits<float>::infinity();
      for (int i = 0; i < kBlock; ++i) m = cell[i] > m ? cell[i] : m;
      dst[b] = m;
#endif
    }
    if (full < blocks) {
      float m = -std::numeric_limits<float>::infinity();
      for (int i = full * kBlock; i < n; ++i) m = row[i] > m ? row[i] : m;
      dst[full] = m;
    }
  }
  blocks_ = blocks;
  resolution_ = n;
}

void EnvironmentMaxPyramid::Reserve(int max_resolution) {
  std::size_t total = 0;
  for (int size = (max_resolution + 1) / 2; size >= 1; size = (size + 1) / 2) {
    total += static_cast<std::size_t>(size) * size;
    if (size == 1) break;
  }
  storage_.reserve(total);
  offset_.reserve(32);
  size_.reserve(32);
}

void EnvironmentMaxPyramid::Build(std::span<const float> env_heights, int n) noexcept {
  resolution_ = 0;
  env_ = nullptr;
  if (n <= 0 || env_heights.size() < static_cast<std::size_t>(n) * n) return;
  std::size_t total = 0;
  int levels = 0;
  for (int size = (n + 1) / 2;; size = (size + 1) / 2) {
    total += static_cast<std::size_t>(size) * size;
    ++levels;
    if (size == 1) break;
  }
  if (storage_.capacity() < total || offset_.capacity() < static_cast<std::size_t>(levels) + 1) {
    return;  // never allocates
  }
  storage_.resize(total);
  offset_.assign(1, 0);
  size_.assign(1, n);
  std::size_t at = 0;
  const float* src = env_heights.data();
  int src_size = n;
  for (int k = 1; k <= levels; ++k) {
    const int size = (src_size + 1) / 2;
    float* dst = storage_.data() + at;
    for (int y = 0; y < size; ++y) {
      const int y1 = std::min(2 * y + 1, src_size - 1);
      for (int x = 0; x < size; ++x) {
        const int x1 = std::min(2 * x + 1, src_size - 1);
        const float a = src[2 * y * src_size + 2 * x], b = src[2 * y * src_size + x1];
        const float c = src[y1 * src_size + 2 * x], d = src[y1 * src_size + x1];
        const float ab = a > b ? a : b, cd = c > d ? c : d;
        dst[y * size + x] = ab > cd ? ab : cd;
      }
    }
    offset_.push_back(static_cast<int>(at));
    size_.push_back(size);
    src = dst;
    src_size = size;
    at += static_cast<std::size_t>(size) * size;
  }
  env_ = env_heights.data();
  resolution_ = n;
}

float EnvironmentMaxPyramid::MaxOver(int i0, int i1, int j0, int j1) const noexcept {
  i0 = std::max(i0, 0);
  j0 = std::max(j0, 0);
  i1 = std::min(i1, resolution_ - 1);
  j1 = std::min(j1, resolution_ - 1);
  float m = -std::numeric_limits<float>::infinity();
  if (i0 > i1 || j0 > j1) return m;
  // Cell c of level 0 lies in block c >> k of level k.
  int k = 0;
  const int top = static_cast<int>(size_.size()) - 1;
  while (k < top && ((i1 >> k) - (i0 >> k) > 1 || (j1 >> k) - (j0 >> k) > 1)) ++k;
  const float* level = k == 0 ? env_ : storage_.data() + offset_[static_cast<std::size_t>(k)];
  const int size = size_[static_cast<std::size_t>(k)];
  for (int y = j0 >> k; y <= (j1 >> k); ++y) {
    for (int x = i0 >> k; x <= (i1 >> k); ++x) {
      const float v = level[y * size + x];
      m = v > m ? v : m;
    }
  }
  return m;
}

}  // namespace ht
