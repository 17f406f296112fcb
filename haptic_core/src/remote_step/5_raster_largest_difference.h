#pragma once
// Stage 5's largest-difference scan (internal to 5_patch_raster.cc): FirstLargestDifference, in
// scalar code and SSE2, AVX2 and AVX-512 lanes.

#include "5_raster_kernels_avx.h"

namespace ht::raster_kernels {

// The first cell of the largest b − a over cells where both are finite: one strictly-greater
// scan, sixteen cells a step with AVX-512 (then eight), eight with AVX2 or four with SSE2. Each
// lane (and the scalar tail) keeps the first cell of its own largest difference; Result() takes
// the largest of them and, among equal ones (a −0 equals a +0), the lowest cell, which is the one
// scan's cell, with its difference's bits. Rows may be added in any number (Add), in increasing
// cell order.
class FirstLargestDifference {
 public:
  FirstLargestDifference() noexcept {
    for (int l = 0; l < kLanes; ++l) {
      lane_values_[l] = -std::numeric_limits<float>::infinity();
      lane_cells_[l] = -1;
    }
  }

  void Add(const float* b, const float* a, std::size_t n, int first_cell) noexcept {
    std::size_t k = 0;
#ifdef HT_RASTER_AVX2
    if (avx2_) {
      // AVX-512 sixteen cells a step where the CPU has it, then AVX2 eight: lanes 0–7 serve
      // both, which is sound as every lane still sees its cells in increasing order.
      if (avx512_) {
        k = LargestDifferenceLanesAvx512(b, a, n, first_cell, lane_values_, lane_cells_);
      }
      k += LargestDifferenceLanesAvx2(b + k, a + k, n - k, first_cell + static_cast<int>(k),
                                      lane_values_, lane_cells_);
    } else
#endif
    {
#if defined(__SSE2__)
      const __m128 abs_mask = _mm_castsi128_ps(_mm_set1_epi32(0x7fffffff));
      const __m128 big = _mm_set1_ps(std::numeric_limits<float>::max());
      __m128 values = _mm_loadu_ps(lane_values_);
      __m128i cells = _mm_loadu_si128(reinterpret_cast<const __m128i*>(lane_cells_));
      __m128i cell = _mm_add_epi32(_mm_set1_epi32(first_cell), _mm_set_epi32(3, 2, 1, 0));
      const __m128i four = _mm_set1_epi32(4);
      for (; k + 4 <= n; k += 4) {
        const __m128 bv = _mm_loadu_ps(b + k), av = _mm_loadu_ps(a + k);
        const __m128 finite = _mm_and_ps(_mm_cmple_ps(_mm_and_ps(bv, abs_mask), big),
                                         _mm_cmple_ps(_mm_and_ps(av, abs_mask), big));
        const __m128 diff = _mm_sub_ps(bv, av);
        const __m128 take = _mm_and_ps(finite, _mm_cmpgt_ps(diff, values));
        values = _mm_or_ps(_mm_and_ps(take, diff), _mm_andnot_ps(take, values));
        const __m128i take_i = _mm_castps_si128(take);
        cells = _mm_or_si128(_mm_and_si128(take_i, cell), _mm_andnot_si128(take_i, cells));
        cell = _mm_add_epi32(cell, four);
      }
      _mm_storeu_ps(lane_values_, values);
      _mm_storeu_si128(reinterpret_cast<__m128i*>(lane_cells_), cells);
#endif
    }
    for (; k < n; ++k) {
      if (!(std::isfinite(b[k]) && std::isfinite(a[k]))) continue;
      const float diff = b[k] - a[k];
      if (diff > tail_value_) {
        tail_value_ = diff;
        tail_cell_ = first_cell + static_cast<int>(k);
      }
    }
  }

  DepthSample Result() const noexcept {
    float value = tail_value_;
    int cell = tail_cell_;
    for (int l = 0; l < kLanes; ++l) {
      const float v = lane_values_[l];
      const int c = lane_cells_[l];
      if (c < 0) continue;
      if (cell < 0 || v > value || (v == value && c < cell)) {
        value = v;
        cell = c;
      }
    }
    if (cell < 0) return {-std::numeric_limits<double>::infinity(), -1};
    return {static_cast<double>(value), cell};
  }

 private:
  // Lanes 0–3 for SSE2, 0–7 for AVX2, 0–15 for AVX-512.
  static constexpr int kLanes = 16;
  alignas(64) float lane_values_[kLanes];
  alignas(64) int lane_cells_[kLanes];
  float tail_value_ = -std::numeric_limits<float>::infinity();
  int tail_cell_ = -1;
#ifdef HT_RASTER_AVX2
  bool avx2_ = CpuHasAvx2();
  bool avx512_ = CpuHasAvx512();
#endif
};

}  // namespace ht::raster_kernels
