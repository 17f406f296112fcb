#pragma once
// Stage 5's raster kernels in AVX2 and AVX-512 lanes (internal to 5_patch_raster.cc): each writes
// the bits of its scalar form in 5_raster_kernels.h (no multiply-add fused: built with
// -ffp-contract=off), and runs where the CPU has the instructions (CpuHasAvx2, CpuHasAvx512).
// Empty where the compiler does not target x86-64 (HT_RASTER_AVX2 undefined).

#include "5_raster_kernels.h"

namespace ht::raster_kernels {

#ifdef HT_RASTER_AVX2
// A compare's four 64-bit lane masks as four 32-bit ones, in order.
[[gnu::target("avx2")]] inline __m128i NarrowMaskAvx2(__m256d mask) noexcept {
  return _mm256_castsi256_si128(_mm256_permutevar8x32_epi32(
      _mm256_castpd_si256(mask), _mm256_setr_epi32(0, 2, 4, 6, 1, 3, 5, 7)));
}

// ShadeCells four cells a step (AVX2, the same operations in the same order and no FMA, so the
// bits of the scalar code); the last n mod 4 cells go to ShadeCells.
[[gnu::target("avx2")]] inline void ShadeCellsAvx2(const TriangleShading& t, const double* b0,
                                                   const double* b1, double* value, float* u,
                                                   float* v, double* ndotn, int n) noexcept {
  int k = 0;
  const __m256d uv0x = _mm256_set1_pd(t.uv0x), uv1x = _mm256_set1_pd(t.uv1x);
  const __m256d uv2x = _mm256_set1_pd(t.uv2x), uv0y = _mm256_set1_pd(t.uv0y);
  const __m256d uv1y = _mm256_set1_pd(t.uv1y), uv2y = _mm256_set1_pd(t.uv2y);
  const __m256d nn0 = _mm256_set1_pd(t.nn0), nn1 = _mm256_set1_pd(t.nn1);
  const __m256d nn2 = _mm256_set1_pd(t.nn2), c01 = _mm256_set1_pd(t.cos01);
  const __m256d c02 = _mm256_set1_pd(t.cos02), c12 = _mm256_set1_pd(t.cos12);
  const __m256d d0 = _mm256_set1_pd(t.d0), d1 = _mm256_set1_pd(t.d1), d2 = _mm256_set1_pd(t.d2);
  const __m256d one = _mm256_set1_pd(1.0), two = _mm256_set1_pd(2.0);
  const __m256d tiny = _mm256_set1_pd(1e-12);
  for (; k + 4 <= n; k += 4) {
    const __m256d a = _mm256_loadu_pd(b0 + k), b = _mm256_loadu_pd(b1 + k);
    const __m256d c = _mm256_sub_pd(_mm256_sub_pd(one, a), b);
    _mm256_storeu_pd(value + k,
                     _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(a, d0), _mm256_mul_pd(b, d1)),
                                   _mm256_mul_pd(c, d2)));
    const __m256d uu = _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(a, uv0x), _mm256_mul_pd(b, uv1x)),
                                     _mm256_mul_pd(c, uv2x));
    const __m256d vv = _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(a, uv0y), _mm256_mul_pd(b, uv1y)),
                                     _mm256_mul_pd(c, uv2y));
    _mm_storeu_ps(u + k, _mm256_cvtpd_ps(uu));
    _mm_storeu_ps(v + k, _mm256_cvtpd_ps(vv));
    if (t.flat) {
      _mm256_storeu_pd(ndotn + k, nn0);
      continue;
    }
    const __m256d squares =
        _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(a, a), _mm256_mul_pd(b, b)), _mm256_mul_pd(c, c));
    const __m256d cross = _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(_mm256_mul_pd(a, b), c01),
                                                      _mm256_mul_pd(_mm256_mul_pd(a, c), c02)),
                                        _mm256_mul_pd(_mm256_mul_pd(b, c), c12));
    const __m256d len2 = _mm256_add_pd(squares, _mm256_mul_pd(two, cross));
    const __m256d dot = _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(a, nn0), _mm256_mul_pd(b, nn1)),
                                      _mm256_mul_pd(c, nn2));
    const __m256d quotient = _mm256_div_pd(dot, _mm256_sqrt_pd(len2));
    _mm256_storeu_pd(ndotn + k, _mm256_and_pd(quotient, _mm256_cmp_pd(len2, tiny, _CMP_GT_OQ)));
  }
  if (k < n) ShadeCells(t, b0 + k, b1 + k, value + k, u + k, v + k, ndotn + k, n - k);
}

// What the envelope takes from n textured cells, four a step: fv[k] = float(value[k] + h[k]·
// ndotn[k]) (double arithmetic without FMA, the scalar code's bits), or the envelope's neutral
// value (−∞ when keep_max, else +∞) where that height is outside the window's box (|·| > range,
// or NaN), so that it replaces no cell.
[[gnu::target("avx2")]] inline void FinishCellsAvx2(const double* value, const float* h,
                                                    const double* ndotn, double range,
                                                    bool keep_max, float* fv, int n) noexcept {
  const __m256d abs_mask = _mm256_castsi256_pd(_mm256_set1_epi64x(0x7fffffffffffffff));
  const __m256d vrange = _mm256_set1_pd(range);
  const float neutral_value =
      keep_max ? -std::numeric_limits<float>::infinity() : std::numeric_limits<float>::infinity();
  const __m128 neutral = _mm_set1_ps(neutral_value);
  int k = 0;
  for (; k + 4 <= n; k += 4) {
    const __m256d x = _mm256_add_pd(
        _mm256_loadu_pd(value + k),
        _mm256_mul_pd(_mm256_cvtps_pd(_mm_loadu_ps(h + k)), _mm256_loadu_pd(ndotn + k)));
    const __m256d inside = _mm256_cmp_pd(_mm256_and_pd(x, abs_mask), vrange, _CMP_LE_OQ);
    const __m128 keep = _mm_castsi128_ps(NarrowMaskAvx2(inside));
    _mm_storeu_ps(fv + k, _mm_blendv_ps(neutral, _mm256_cvtpd_ps(x), keep));
  }
  for (; k < n; ++k) {
    const double x = value[k] + static_cast<double>(h[k]) * ndotn[k];
    fv[k] = std::abs(x) <= range ? static_cast<float>(x) : neutral_value;
  }
}

// The covered cells of one row of a triangle, four cells a step: for each cell i in [ia, ib]
// with centre px = i + 0.5, b0 = r0 + gx0·px, b1 = r1 + gx1·px and b2 = 1 − b0 − b1, the cells
// where no b is below the edge tolerance (a NaN b passes, as the scalar test's `<` lets it) are
// appended to b0_out, b1_out and, as row_start + i (the cell's index in the render buffer),
// cell_out, in increasing i; returns how many. AVX2 without FMA: the compiler may not fuse the
// multiplies and adds, so each b has the scalar code's bits. The outputs need room for ib − ia + 4
// cells.
// With `cull` (a RowCull), a covered cell is also dropped where its coarse height cannot make it
// the deepest cell.

[[gnu::target("avx2")]] inline int CoverRowAvx2(double r0, double gx0, double r1, double gx1,
                                                int ia, int ib, int row_start, double* b0_out,
                                                double* b1_out, int* cell_out,
                                                const RowCull* cull = nullptr) noexcept {
  const __m256d vr0 = _mm256_set1_pd(r0), vgx0 = _mm256_set1_pd(gx0);
  const __m256d vr1 = _mm256_set1_pd(r1), vgx1 = _mm256_set1_pd(gx1);
  const __m256d one = _mm256_set1_pd(1.0), half = _mm256_set1_pd(0.5);
  const __m256d tol = _mm256_set1_pd(kEdgeTolerance);
  const __m128i steps = _mm_set_epi32(3, 2, 1, 0);
  const __m128i start = _mm_set1_epi32(row_start);
  int count = 0;
  for (int i = ia; i <= ib; i += 4) {
    const __m128i lanes = _mm_add_epi32(_mm_set1_epi32(i), steps);
    const __m256d px = _mm256_add_pd(_mm256_cvtepi32_pd(lanes), half);  // exact
    const __m256d b0 = _mm256_add_pd(vr0, _mm256_mul_pd(vgx0, px));
    const __m256d b1 = _mm256_add_pd(vr1, _mm256_mul_pd(vgx1, px));
    const __m256d b2 = _mm256_sub_pd(_mm256_sub_pd(one, b0), b1);
    const __m256d keep = _mm256_and_pd(
        _mm256_and_pd(_mm256_cmp_pd(b0, tol, _CMP_NLT_UQ), _mm256_cmp_pd(b1, tol, _CMP_NLT_UQ)),
        _mm256_cmp_pd(b2, tol, _CMP_NLT_UQ));
    int mask = _mm256_movemask_pd(keep);
    if (ib - i < 3) mask &= (1 << (ib - i + 1)) - 1;  // lanes past ib
    if (cull != nullptr && mask != 0) {
      const __m128i load = _mm_cmpgt_epi32(_mm_set1_epi32(ib - i + 1), steps);  // lanes ≤ ib
      const __m256d env = _mm256_cvtps_pd(_mm_maskload_ps(cull->env + row_start + i, load));
      const __m256d value =
          _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(b0, _mm256_set1_pd(cull->d0)),
                                      _mm256_mul_pd(b1, _mm256_set1_pd(cull->d1))),
                        _mm256_mul_pd(b2, _mm256_set1_pd(cull->d2)));
      mask &= _mm256_movemask_pd(
          _mm256_cmp_pd(_mm256_sub_pd(env, value), _mm256_set1_pd(cull->cut), _CMP_GE_OQ));
    }
    if (mask == 0xF) {
      _mm256_storeu_pd(b0_out + count, b0);
      _mm256_storeu_pd(b1_out + count, b1);
      _mm_storeu_si128(reinterpret_cast<__m128i*>(cell_out + count), _mm_add_epi32(lanes, start));
      count += 4;
      continue;
    }
    if (mask == 0) continue;
    alignas(32) double a0[4], a1[4];
    _mm256_store_pd(a0, b0);
    _mm256_store_pd(a1, b1);
    for (int l = 0; l < 4; ++l) {
      if ((mask >> l & 1) == 0) continue;
      b0_out[count] = a0[l];
      b1_out[count] = a1[l];
      cell_out[count] = row_start + i + l;
      ++count;
    }
  }
  return count;
}

// A triangle's row spans, four rows a step: for rows j0 + k (k < count), the parts r0[k] and
// r1[k] of b0 and b1 and the columns [ia[k], ib[k]] (ib < ia: no cell) that the scalar loop of
// RenderPatchHeightsFast computes, with its bits: the same operations in the same order, no FMA,
// and std::max(lo, x) / std::min(hi, x) as max(x, lo) / min(x, hi), which keep lo and hi where x
// is NaN as they do. (k0, gy0) and (k1, gy1) give r0 and r1 = k + gy·(j + 0.5); gx0, gx1 and
// g2 = −gx0 − gx1 are the edges' x slopes and inv_* their reciprocals (0 for a zero slope).
// The outputs need room for count rounded up to a multiple of 4.
[[gnu::target("avx2")]] inline void RowSpansAvx2(double k0, double gy0, double k1, double gy1,
                                                 const double g[3], const double inv_g[3], int i0,
                                                 int i1, int j0, int count, double* r0_out,
                                                 double* r1_out, int* ia_out,
                                                 int* ib_out) noexcept {
  const __m256d vk0 = _mm256_set1_pd(k0), vgy0 = _mm256_set1_pd(gy0);
  const __m256d vk1 = _mm256_set1_pd(k1), vgy1 = _mm256_set1_pd(gy1);
  const __m256d one = _mm256_set1_pd(1.0), half = _mm256_set1_pd(0.5);
  const __m256d two = _mm256_set1_pd(2.0), tol = _mm256_set1_pd(kEdgeTolerance);
  const __m256d slack0 = _mm256_set1_pd(1e-7), slack1 = _mm256_set1_pd(1e-12);
  const __m256d abs_mask = _mm256_castsi256_pd(_mm256_set1_epi64x(0x7fffffffffffffff));
  const __m256d lo0 = _mm256_set1_pd(static_cast<double>(i0));
  const __m256d hi0 = _mm256_set1_pd(static_cast<double>(i1) + 1.0);
  const __m128i vi0 = _mm_set1_epi32(i0), vi1 = _mm_set1_epi32(i1);
  const __m128i steps = _mm_set_epi32(3, 2, 1, 0);
  for (int k = 0; k < count; k += 4) {
    const __m256d py = _mm256_add_pd(
        _mm256_cvtepi32_pd(_mm_add_epi32(_mm_set1_epi32(j0 + k), steps)), half);  // exact
    __m256d r[3];
    r[0] = _mm256_add_pd(vk0, _mm256_mul_pd(vgy0, py));
    r[1] = _mm256_add_pd(vk1, _mm256_mul_pd(vgy1, py));
    r[2] = _mm256_sub_pd(_mm256_sub_pd(one, r[0]), r[1]);
    __m256d lo = lo0, hi = hi0, empty = _mm256_setzero_pd();
    for (int e = 0; e < 3; ++e) {
      if (g[e] == 0.0) {
        empty = _mm256_or_pd(empty, _mm256_cmp_pd(r[e], tol, _CMP_LT_OQ));
        continue;
      }
      const __m256d ig = _mm256_set1_pd(inv_g[e]);
      const __m256d bound = _mm256_mul_pd(_mm256_sub_pd(tol, r[e]), ig);
      const __m256d slack = _mm256_add_pd(
          slack0, _mm256_mul_pd(slack1, _mm256_and_pd(_mm256_mul_pd(r[e], ig), abs_mask)));
      if (g[e] > 0.0) {
        lo = _mm256_max_pd(_mm256_sub_pd(bound, slack), lo);
      } else {
        hi = _mm256_min_pd(_mm256_add_pd(bound, slack), hi);
      }
    }
    // Rows to skip: empty, or !(lo <= hi + 2).
    const __m256d skip =
        _mm256_or_pd(empty, _mm256_cmp_pd(lo, _mm256_add_pd(hi, two), _CMP_NLE_UQ));
    const __m256d lo_c = _mm256_sub_pd(lo, half), hi_c = _mm256_sub_pd(hi, half);
    const __m128i lo_t = _mm256_cvttpd_epi32(lo_c), hi_t = _mm256_cvttpd_epi32(hi_c);
    // + (lo_c > lo_t) and − (hi_c < hi_t): a true compare is −1 as an integer.
    const __m128i lo_up = NarrowMaskAvx2(_mm256_cmp_pd(lo_c, _mm256_cvtepi32_pd(lo_t), _CMP_GT_OQ));
    const __m128i hi_down =
        NarrowMaskAvx2(_mm256_cmp_pd(hi_c, _mm256_cvtepi32_pd(hi_t), _CMP_LT_OQ));
    __m128i ia = _mm_max_epi32(vi0, _mm_sub_epi32(lo_t, lo_up));
    __m128i ib = _mm_min_epi32(vi1, _mm_add_epi32(hi_t, hi_down));
    const __m128i skip_i = NarrowMaskAvx2(skip);
    // A skipped row: ia = 1, ib = 0 (no cell).
    ia = _mm_blendv_epi8(ia, _mm_set1_epi32(1), skip_i);
    ib = _mm_blendv_epi8(ib, _mm_setzero_si128(), skip_i);
    _mm256_storeu_pd(r0_out + k, r[0]);
    _mm256_storeu_pd(r1_out + k, r[1]);
    _mm_storeu_si128(reinterpret_cast<__m128i*>(ia_out + k), ia);
    _mm_storeu_si128(reinterpret_cast<__m128i*>(ib_out + k), ib);
  }
}

// The AVX-512 kernels (F, VL, DQ, CD): the AVX2 kernels' operations on eight cells a step,
// lane for lane, so the same bits (x86_simd.h: no multiply-add is fused).

// CoverRowAvx2 eight cells a step, the covered lanes compressed into the outputs (which need
// room for ib − ia + 8 cells).
[[HT_AVX512_TARGET]] inline int CoverRowAvx512(double r0, double gx0, double r1, double gx1, int ia,
                                               int ib, int row_start, double* b0_out,
                                               double* b1_out, int* cell_out,
                                               const RowCull* cull = nullptr) noexcept {
  const __m512d vr0 = _mm512_set1_pd(r0), vgx0 = _mm512_set1_pd(gx0);
  const __m512d vr1 = _mm512_set1_pd(r1), vgx1 = _mm512_set1_pd(gx1);
  const __m512d one = _mm512_set1_pd(1.0), half = _mm512_set1_pd(0.5);
  const __m512d tol = _mm512_set1_pd(kEdgeTolerance);
  const __m256i steps = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
  const __m256i start = _mm256_set1_epi32(row_start);
  int count = 0;
  for (int i = ia; i <= ib; i += 8) {
    const __m256i lanes = _mm256_add_epi32(_mm256_set1_epi32(i), steps);
    const __m512d px = _mm512_add_pd(_mm512_cvtepi32_pd(lanes), half);  // exact
    const __m512d b0 = _mm512_add_pd(vr0, _mm512_mul_pd(vgx0, px));
    const __m512d b1 = _mm512_add_pd(vr1, _mm512_mul_pd(vgx1, px));
    const __m512d b2 = _mm512_sub_pd(_mm512_sub_pd(one, b0), b1);
    unsigned keep = _mm512_cmp_pd_mask(b0, tol, _CMP_NLT_UQ) &
                    _mm512_cmp_pd_mask(b1, tol, _CMP_NLT_UQ) &
                    _mm512_cmp_pd_mask(b2, tol, _CMP_NLT_UQ);
    if (ib - i < 7) keep &= (1u << (ib - i + 1)) - 1;  // lanes past ib
    if (cull != nullptr && keep != 0) {
      const __m512d env = _mm512_cvtps_pd(
          _mm256_maskz_loadu_ps(static_cast<__mmask8>(keep), cull->env + row_start + i));
      const __m512d value =
          _mm512_add_pd(_mm512_add_pd(_mm512_mul_pd(b0, _mm512_set1_pd(cull->d0)),
                                      _mm512_mul_pd(b1, _mm512_set1_pd(cull->d1))),
                        _mm512_mul_pd(b2, _mm512_set1_pd(cull->d2)));
      keep &= _mm512_cmp_pd_mask(_mm512_sub_pd(env, value), _mm512_set1_pd(cull->cut), _CMP_GE_OQ);
    }
    if (keep == 0) continue;
    if (keep == 0xFF) {  // a full run: no compress
      _mm512_storeu_pd(b0_out + count, b0);
      _mm512_storeu_pd(b1_out + count, b1);
      _mm256_storeu_si256(reinterpret_cast<__m256i*>(cell_out + count),
                          _mm256_add_epi32(lanes, start));
      count += 8;
      continue;
    }
    const auto k = static_cast<__mmask8>(keep);
    _mm512_storeu_pd(b0_out + count, _mm512_maskz_compress_pd(k, b0));
    _mm512_storeu_pd(b1_out + count, _mm512_maskz_compress_pd(k, b1));
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(cell_out + count),
                        _mm256_maskz_compress_epi32(k, _mm256_add_epi32(lanes, start)));
    count += __builtin_popcount(keep);
  }
  return count;
}

// ShadeCellsAvx2 eight cells a step; the last n mod 8 in masked lanes.
[[HT_AVX512_TARGET]] inline void ShadeCellsAvx512(const TriangleShading& t, const double* b0,
                                                  const double* b1, double* value, float* u,
                                                  float* v, double* ndotn, int n) noexcept {
  const __m512d uv0x = _mm512_set1_pd(t.uv0x), uv1x = _mm512_set1_pd(t.uv1x);
  const __m512d uv2x = _mm512_set1_pd(t.uv2x), uv0y = _mm512_set1_pd(t.uv0y);
  const __m512d uv1y = _mm512_set1_pd(t.uv1y), uv2y = _mm512_set1_pd(t.uv2y);
  const __m512d nn0 = _mm512_set1_pd(t.nn0), nn1 = _mm512_set1_pd(t.nn1);
  const __m512d nn2 = _mm512_set1_pd(t.nn2), c01 = _mm512_set1_pd(t.cos01);
  const __m512d c02 = _mm512_set1_pd(t.cos02), c12 = _mm512_set1_pd(t.cos12);
  const __m512d d0 = _mm512_set1_pd(t.d0), d1 = _mm512_set1_pd(t.d1), d2 = _mm512_set1_pd(t.d2);
  const __m512d one = _mm512_set1_pd(1.0), two = _mm512_set1_pd(2.0);
  const __m512d tiny = _mm512_set1_pd(1e-12);
  for (int k = 0; k < n; k += 8) {
    const auto m = static_cast<__mmask8>(n - k >= 8 ? 0xFF : (1u << (n - k)) - 1);
    const __m512d a = _mm512_maskz_loadu_pd(m, b0 + k), b = _mm512_maskz_loadu_pd(m, b1 + k);
    const __m512d c = _mm512_sub_pd(_mm512_sub_pd(one, a), b);
    _mm512_mask_storeu_pd(value + k, m,
                          _mm512_add_pd(_mm512_add_pd(_mm512_mul_pd(a, d0), _mm512_mul_pd(b, d1)),
                                        _mm512_mul_pd(c, d2)));
    const __m512d uu = _mm512_add_pd(_mm512_add_pd(_mm512_mul_pd(a, uv0x), _mm512_mul_pd(b, uv1x)),
                                     _mm512_mul_pd(c, uv2x));
    const __m512d vv = _mm512_add_pd(_mm512_add_pd(_mm512_mul_pd(a, uv0y), _mm512_mul_pd(b, uv1y)),
                                     _mm512_mul_pd(c, uv2y));
    _mm256_mask_storeu_ps(u + k, m, _mm512_cvtpd_ps(uu));
    _mm256_mask_storeu_ps(v + k, m, _mm512_cvtpd_ps(vv));
    if (t.flat) {
      _mm512_mask_storeu_pd(ndotn + k, m, nn0);
      continue;
    }
    const __m512d squares =
        _mm512_add_pd(_mm512_add_pd(_mm512_mul_pd(a, a), _mm512_mul_pd(b, b)), _mm512_mul_pd(c, c));
    const __m512d cross = _mm512_add_pd(_mm512_add_pd(_mm512_mul_pd(_mm512_mul_pd(a, b), c01),
                                                      _mm512_mul_pd(_mm512_mul_pd(a, c), c02)),
                                        _mm512_mul_pd(_mm512_mul_pd(b, c), c12));
    const __m512d len2 = _mm512_add_pd(squares, _mm512_mul_pd(two, cross));
    const __m512d dot = _mm512_add_pd(_mm512_add_pd(_mm512_mul_pd(a, nn0), _mm512_mul_pd(b, nn1)),
                                      _mm512_mul_pd(c, nn2));
    const __m512d quotient = _mm512_div_pd(dot, _mm512_sqrt_pd(len2));
    // +0 where len2 ≤ 1e-12 (or NaN), as the scalar code's conditional.
    _mm512_mask_storeu_pd(
        ndotn + k, m, _mm512_maskz_mov_pd(_mm512_cmp_pd_mask(len2, tiny, _CMP_GT_OQ), quotient));
  }
}

// FinishCellsAvx2 and the envelope, eight cells a step: the heights fv (float(value + h·ndotn),
// or the neutral value outside the box), then heights[cell] = fv where fv > it (keep_max) or
// fv < it. Eight cells that are one run of a row (the common case) are loaded and stored as one
// vector; others go one at a time in the order drawn (gathers and scatters of distinct cells
// measured slower). Each cell sees the same comparisons in the same order as the scalar loop.
// With `drawn` (the tool's side), the cells also raise its lower bound and widen its cell range.
[[HT_AVX512_TARGET]] inline void FinishEnvelopeAvx512(const double* value, const float* h,
                                                      const double* ndotn, const int* cell,
                                                      double range, bool keep_max, float* heights,
                                                      int n, DrawnCells* drawn) noexcept {
  const __m512d abs_mask = _mm512_castsi512_pd(_mm512_set1_epi64(0x7fffffffffffffff));
  const __m512d vrange = _mm512_set1_pd(range);
  const float neutral_value =
      keep_max ? -std::numeric_limits<float>::infinity() : std::numeric_limits<float>::infinity();
  const __m256 neutral = _mm256_set1_ps(neutral_value);
  const __m256 minus_inf = _mm256_set1_ps(-std::numeric_limits<float>::infinity());
  const __m256i steps = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
  __m256 lower = minus_inf;  // b − a of the runs drawn, lane by lane
  for (int k = 0; k < n; k += 8) {
    const unsigned valid = n - k >= 8 ? 0xFFu : (1u << (n - k)) - 1;
    const auto m = static_cast<__mmask8>(valid);
    const __m512d x = _mm512_add_pd(_mm512_maskz_loadu_pd(m, value + k),
                                    _mm512_mul_pd(_mm512_cvtps_pd(_mm256_maskz_loadu_ps(m, h + k)),
                                                  _mm512_maskz_loadu_pd(m, ndotn + k)));
    const __mmask8 inside = _mm512_cmp_pd_mask(_mm512_and_pd(x, abs_mask), vrange, _CMP_LE_OQ);
    const __m256 fv = _mm256_mask_mov_ps(neutral, inside, _mm512_cvtpd_ps(x));
    const __m256i idx = _mm256_maskz_loadu_epi32(m, cell + k);
    const int first = cell[k];
    const __m256i run = _mm256_add_epi32(_mm256_set1_epi32(first), steps);
    const int lanes = std::min(8, n - k);
    // The lanes that continue the first lane's run, and (a row's end in the middle of the eight)
    // those that continue the first other lane's: each run is one masked load and store, in
    // memory order of its cells (distinct cells, so either run may go first).
    const unsigned first_run = _mm256_cmpeq_epi32_mask(idx, run) & valid;
    const unsigned rest = valid & ~first_run;
    unsigned second_run = 0;
    int second = 0;
    if (rest != 0) {
      const int p = __builtin_ctz(rest);
      second = cell[k + p] - p;  // the run's cell at lane 0
      second_run =
          _mm256_cmpeq_epi32_mask(idx, _mm256_add_epi32(_mm256_set1_epi32(second), steps)) & rest;
    }
    if ((first_run | second_run) == valid) {
      const int bases[2] = {first, second};
      const unsigned masks[2] = {first_run, second_run};
      for (int r = 0; r < 2; ++r) {
        const int base = bases[r];
        const unsigned lanes_mask = masks[r];
        if (lanes_mask == 0) continue;
        const auto mm = static_cast<__mmask8>(lanes_mask);
        // Lane l writes cell base + l (a lane outside the mask is neither read nor written).
        const __m256 old = _mm256_maskz_loadu_ps(mm, heights + base);
        const __mmask8 take = mm & (keep_max ? _mm256_cmp_ps_mask(fv, old, _CMP_GT_OQ)
                                             : _mm256_cmp_ps_mask(fv, old, _CMP_LT_OQ));
        _mm256_mask_storeu_ps(heights + base, take, fv);
        if (drawn != nullptr) {
          // env − fv: −∞ where the environment has no cell or the height is outside the box.
          const __m256 diff = _mm256_sub_ps(_mm256_maskz_loadu_ps(mm, drawn->env + base), fv);
          lower = _mm256_max_ps(lower, _mm256_mask_mov_ps(minus_inf, mm & inside, diff));
          const int lo = __builtin_ctz(lanes_mask), hi = 31 - __builtin_clz(lanes_mask);
          drawn->min_cell = std::min(drawn->min_cell, base + lo);
          drawn->max_cell = std::max(drawn->max_cell, base + hi);
        }
      }
      continue;
    }
    alignas(32) float f[8];
    _mm256_store_ps(f, fv);
    for (int l = 0; l < lanes; ++l) {
      float& c = heights[cell[k + l]];
      if (keep_max ? f[l] > c : f[l] < c) c = f[l];
      if (drawn != nullptr) drawn->Draw(cell[k + l], f[l]);
    }
  }
  if (drawn != nullptr) {
    drawn->count += n;
    alignas(32) float l[8];
    _mm256_store_ps(l, lower);
    for (const float x : l) drawn->lower = x > drawn->lower ? x : drawn->lower;
  }
}

// FirstLargestDifference's lanes, eight cells a step (AVX2): lane l keeps the first cell of the
// largest finite b − a among cells ≡ l (mod 8) of this call; returns how many cells it took (a
// multiple of 8), the rest being the caller's.
[[gnu::target("avx2")]] inline std::size_t LargestDifferenceLanesAvx2(const float* b,
                                                                      const float* a, std::size_t n,
                                                                      int first_cell,
                                                                      float* lane_values,
                                                                      int* lane_cells) noexcept {
  if (n < 8) return 0;
  const __m256 abs_mask = _mm256_castsi256_ps(_mm256_set1_epi32(0x7fffffff));
  const __m256 big = _mm256_set1_ps(std::numeric_limits<float>::max());
  __m256 values = _mm256_loadu_ps(lane_values);
  __m256i cells = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(lane_cells));
  __m256i cell =
      _mm256_add_epi32(_mm256_set1_epi32(first_cell), _mm256_set_epi32(7, 6, 5, 4, 3, 2, 1, 0));
  const __m256i eight = _mm256_set1_epi32(8);
  std::size_t k = 0;
  for (; k + 8 <= n; k += 8) {
    const __m256 bv = _mm256_loadu_ps(b + k), av = _mm256_loadu_ps(a + k);
    const __m256 finite =
        _mm256_and_ps(_mm256_cmp_ps(_mm256_and_ps(bv, abs_mask), big, _CMP_LE_OQ),
                      _mm256_cmp_ps(_mm256_and_ps(av, abs_mask), big, _CMP_LE_OQ));
    const __m256 diff = _mm256_sub_ps(bv, av);
    const __m256 take = _mm256_and_ps(finite, _mm256_cmp_ps(diff, values, _CMP_GT_OQ));
    values = _mm256_blendv_ps(values, diff, take);
    cells = _mm256_castps_si256(
        _mm256_blendv_ps(_mm256_castsi256_ps(cells), _mm256_castsi256_ps(cell), take));
    cell = _mm256_add_epi32(cell, eight);
  }
  _mm256_storeu_ps(lane_values, values);
  _mm256_storeu_si256(reinterpret_cast<__m256i*>(lane_cells), cells);
  return k;
}

// LargestDifferenceLanesAvx2 sixteen cells a step (AVX-512): lane l of 16.
[[HT_AVX512_TARGET]] inline std::size_t LargestDifferenceLanesAvx512(const float* b, const float* a,
                                                                     std::size_t n, int first_cell,
                                                                     float* lane_values,
                                                                     int* lane_cells) noexcept {
  if (n < 16) return 0;
  const __m512 big = _mm512_set1_ps(std::numeric_limits<float>::max());
  __m512 values = _mm512_loadu_ps(lane_values);
  __m512i cells = _mm512_loadu_si512(lane_cells);
  __m512i cell =
      _mm512_add_epi32(_mm512_set1_epi32(first_cell),
                       _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15));
  const __m512i sixteen = _mm512_set1_epi32(16);
  std::size_t k = 0;
  for (; k + 16 <= n; k += 16) {
    const __m512 bv = _mm512_loadu_ps(b + k), av = _mm512_loadu_ps(a + k);
    const __mmask16 finite = _mm512_cmp_ps_mask(_mm512_abs_ps(bv), big, _CMP_LE_OQ) &
                             _mm512_cmp_ps_mask(_mm512_abs_ps(av), big, _CMP_LE_OQ);
    const __m512 diff = _mm512_sub_ps(bv, av);
    const __mmask16 take = finite & _mm512_cmp_ps_mask(diff, values, _CMP_GT_OQ);
    values = _mm512_mask_mov_ps(values, take, diff);
    cells = _mm512_mask_mov_epi32(cells, take, cell);
    cell = _mm512_add_epi32(cell, sixteen);
  }
  _mm512_storeu_ps(lane_values, values);
  _mm512_storeu_si512(lane_cells, cells);
  return k;
}
#endif

}  // namespace ht::raster_kernels
