#include "haptic_core/penetration_depth.h"

#include <algorithm>
#include <cmath>
#include <glm/geometric.hpp>
#if defined(__SSE2__)
#include <emmintrin.h>
#endif
#include "x86_simd.h"
#ifdef HT_X86_SIMD
#define HT_RASTER_AVX2 1
#endif
#include <glm/gtc/quaternion.hpp>
#include <limits>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>

namespace ht {

namespace {

// What is wrong with a window's arguments (nullptr when nothing): the one rule TryMake and Make
// share.
const char* WindowProblem(const glm::dvec3& center_W, const glm::dvec3& normal_W, double extent_m,
                          int resolution) noexcept {
  const double len = glm::length(normal_W);
  if (!std::isfinite(len) || !(len > 1e-12)) return "normal must be finite and non-zero";
  if (!std::isfinite(center_W.x) || !std::isfinite(center_W.y) || !std::isfinite(center_W.z)) {
    return "centre must be finite";
  }
  if (!(extent_m > 0.0) || !std::isfinite(extent_m)) return "extent must be positive";
  if (resolution < 2 || resolution > 1024) return "resolution must be in [2, 1024]";
  return nullptr;
}

// Inclusive edge test of the renders, with a small tolerance on the barycentrics: cells on shared
// edges may be covered twice, which the max/min envelope makes harmless, and no crack opens
// between triangles.
constexpr double kEdgeTolerance = -1e-9;

// A triangle projected on a render grid of `cells` × `cells` (corner pixel coordinates x, y;
// pixel i spans [i, i+1)): 1 / its signed area, and the range of cell centres its bounding box
// covers, clipped to the grid. False when it is edge-on or degenerate in projection, or covers
// no cell centre.
struct ProjectedCells {
  double inv_area;
  int i0, i1, j0, j1;
};
bool ProjectCells(const double x[3], const double y[3], int cells, ProjectedCells& out) noexcept {
  const double area = (x[1] - x[0]) * (y[2] - y[0]) - (x[2] - x[0]) * (y[1] - y[0]);
  if (!(std::abs(area) > 1e-12)) return false;
  out.inv_area = 1.0 / area;
  out.i0 = std::max(0, static_cast<int>(std::ceil(std::min({x[0], x[1], x[2]}) - 0.5)));
  out.i1 = std::min(cells - 1, static_cast<int>(std::floor(std::max({x[0], x[1], x[2]}) - 0.5)));
  out.j0 = std::max(0, static_cast<int>(std::ceil(std::min({y[0], y[1], y[2]}) - 0.5)));
  out.j1 = std::min(cells - 1, static_cast<int>(std::floor(std::max({y[0], y[1], y[2]}) - 0.5)));
  return out.i0 <= out.i1 && out.j0 <= out.j1;
}

// What the fast render's textured cells need besides their barycentrics: one triangle's corner
// texture coordinates (the floats, exactly, as doubles), its corner normals' components along n
// and their cosines, and whether it is flat-shaded.
struct TriangleShading {
  double uv0x, uv1x, uv2x, uv0y, uv1y, uv2y;
  double nn0, nn1, nn2, cos01, cos02, cos12;
  bool flat;
  double d0, d1, d2;  // corner heights along n (m)
};

// Per cell k < n with barycentrics (b0, b1)[k] (b2 = 1 − b0 − b1): the coarse height along n
// (value = b·d), the texture coordinates, and the unit interpolated normal's component along n,
// (b·nn)/|Σ b_k n_k| (0 where that length vanishes; nn0 for a flat triangle). The arithmetic of
// RenderPatchHeights in its order, so that the SSE2 lanes (two cells a step: the square roots and
// divisions, the slowest part of a smooth triangle's cell, no longer wait one after the other)
// write the bits of the scalar code.
void ShadeCells(const TriangleShading& t, const double* b0, const double* b1, double* value,
                float* u, float* v, double* ndotn, int n) noexcept {
  int k = 0;
#if defined(__SSE2__)
  const __m128d uv0x = _mm_set1_pd(t.uv0x), uv1x = _mm_set1_pd(t.uv1x), uv2x = _mm_set1_pd(t.uv2x);
  const __m128d uv0y = _mm_set1_pd(t.uv0y), uv1y = _mm_set1_pd(t.uv1y), uv2y = _mm_set1_pd(t.uv2y);
  const __m128d nn0 = _mm_set1_pd(t.nn0), nn1 = _mm_set1_pd(t.nn1), nn2 = _mm_set1_pd(t.nn2);
  const __m128d c01 = _mm_set1_pd(t.cos01), c02 = _mm_set1_pd(t.cos02), c12 = _mm_set1_pd(t.cos12);
  const __m128d d0 = _mm_set1_pd(t.d0), d1 = _mm_set1_pd(t.d1), d2 = _mm_set1_pd(t.d2);
  const __m128d one = _mm_set1_pd(1.0), two = _mm_set1_pd(2.0), tiny = _mm_set1_pd(1e-12);
  for (; k + 2 <= n; k += 2) {
    const __m128d a = _mm_loadu_pd(b0 + k), b = _mm_loadu_pd(b1 + k);
    const __m128d c = _mm_sub_pd(_mm_sub_pd(one, a), b);
    _mm_storeu_pd(value + k,
                  _mm_add_pd(_mm_add_pd(_mm_mul_pd(a, d0), _mm_mul_pd(b, d1)), _mm_mul_pd(c, d2)));
    const __m128d uu =
        _mm_add_pd(_mm_add_pd(_mm_mul_pd(a, uv0x), _mm_mul_pd(b, uv1x)), _mm_mul_pd(c, uv2x));
    const __m128d vv =
        _mm_add_pd(_mm_add_pd(_mm_mul_pd(a, uv0y), _mm_mul_pd(b, uv1y)), _mm_mul_pd(c, uv2y));
    _mm_storel_pi(reinterpret_cast<__m64*>(u + k), _mm_cvtpd_ps(uu));
    _mm_storel_pi(reinterpret_cast<__m64*>(v + k), _mm_cvtpd_ps(vv));
    if (t.flat) {
      _mm_storeu_pd(ndotn + k, nn0);
      continue;
    }
    const __m128d squares =
        _mm_add_pd(_mm_add_pd(_mm_mul_pd(a, a), _mm_mul_pd(b, b)), _mm_mul_pd(c, c));
    const __m128d cross =
        _mm_add_pd(_mm_add_pd(_mm_mul_pd(_mm_mul_pd(a, b), c01), _mm_mul_pd(_mm_mul_pd(a, c), c02)),
                   _mm_mul_pd(_mm_mul_pd(b, c), c12));
    const __m128d len2 = _mm_add_pd(squares, _mm_mul_pd(two, cross));
    const __m128d dot =
        _mm_add_pd(_mm_add_pd(_mm_mul_pd(a, nn0), _mm_mul_pd(b, nn1)), _mm_mul_pd(c, nn2));
    const __m128d quotient = _mm_div_pd(dot, _mm_sqrt_pd(len2));
    _mm_storeu_pd(ndotn + k, _mm_and_pd(quotient, _mm_cmpgt_pd(len2, tiny)));
  }
#endif
  for (; k < n; ++k) {
    const double a = b0[k], b = b1[k], c = 1.0 - a - b;
    value[k] = a * t.d0 + b * t.d1 + c * t.d2;
    u[k] = static_cast<float>(a * t.uv0x + b * t.uv1x + c * t.uv2x);
    v[k] = static_cast<float>(a * t.uv0y + b * t.uv1y + c * t.uv2y);
    if (t.flat) {
      ndotn[k] = t.nn0;
      continue;
    }
    const double len2 =
        a * a + b * b + c * c + 2.0 * (a * b * t.cos01 + a * c * t.cos02 + b * c * t.cos12);
    ndotn[k] = len2 > 1e-12 ? (a * t.nn0 + b * t.nn1 + c * t.nn2) / std::sqrt(len2) : 0.0;
  }
}

#ifdef HT_RASTER_AVX2
// A compare's four 64-bit lane masks as four 32-bit ones, in order.
[[gnu::target("avx2")]] inline __m128i NarrowMaskAvx2(__m256d mask) noexcept {
  return _mm256_castsi256_si128(_mm256_permutevar8x32_epi32(
      _mm256_castpd_si256(mask), _mm256_setr_epi32(0, 2, 4, 6, 1, 3, 5, 7)));
}

// ShadeCells four cells a step (AVX2, the same operations in the same order and no FMA, so the
// bits of the scalar code); the last n mod 4 cells go to ShadeCells.
[[gnu::target("avx2")]] void ShadeCellsAvx2(const TriangleShading& t, const double* b0,
                                            const double* b1, double* value, float* u, float* v,
                                            double* ndotn, int n) noexcept {
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
[[gnu::target("avx2")]] void FinishCellsAvx2(const double* value, const float* h,
                                             const double* ndotn, double range, bool keep_max,
                                             float* fv, int n) noexcept {
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
// With `cull` (a RowCull, below), a covered cell is also dropped where its coarse height cannot
// make it the deepest cell.
struct RowCull {
  const float* env;   // the environment's heights, indexed as the render buffer
  double d0, d1, d2;  // the triangle's corner heights along n
  double cut;         // keep a cell where env − (b·d) ≥ cut (ordered: NaN drops)
};

[[gnu::target("avx2")]] int CoverRowAvx2(double r0, double gx0, double r1, double gx1, int ia,
                                         int ib, int row_start, double* b0_out, double* b1_out,
                                         int* cell_out, const RowCull* cull = nullptr) noexcept {
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
[[gnu::target("avx2")]] void RowSpansAvx2(double k0, double gy0, double k1, double gy1,
                                          const double g[3], const double inv_g[3], int i0, int i1,
                                          int j0, int count, double* r0_out, double* r1_out,
                                          int* ia_out, int* ib_out) noexcept {
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
[[HT_AVX512_TARGET]] int CoverRowAvx512(double r0, double gx0, double r1, double gx1, int ia,
                                        int ib, int row_start, double* b0_out, double* b1_out,
                                        int* cell_out, const RowCull* cull = nullptr) noexcept {
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
[[HT_AVX512_TARGET]] void ShadeCellsAvx512(const TriangleShading& t, const double* b0,
                                           const double* b1, double* value, float* u, float* v,
                                           double* ndotn, int n) noexcept {
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

// What a culled tool render (RenderToolDepth) keeps of its drawn cells: the environment's
// heights (indexed as the render), the largest b − a (float, as the depth scan takes it) of the
// cells drawn, and the lowest and highest cell drawn.
struct DrawnCells {
  const float* env;
  float lower;
  int min_cell, max_cell;
  int count;  // cells drawn (a cell drawn twice counts twice)
  // A cell drawn at tool height fv: its env − fv (float, as the depth scan takes it; −∞ where
  // the environment has no cell or fv is +∞, outside the box) raises the lower bound.
  void Draw(int cell, float fv) noexcept {
    const float diff = env[cell] - fv;
    lower = diff > lower ? diff : lower;
    min_cell = std::min(min_cell, cell);
    max_cell = std::max(max_cell, cell);
  }
};

// FinishCellsAvx2 and the envelope, eight cells a step: the heights fv (float(value + h·ndotn),
// or the neutral value outside the box), then heights[cell] = fv where fv > it (keep_max) or
// fv < it. Eight cells that are one run of a row (the common case) are loaded and stored as one
// vector; others go one at a time in the order drawn (gathers and scatters of distinct cells
// measured slower). Each cell sees the same comparisons in the same order as the scalar loop.
// With `drawn` (the tool's side), the cells also raise its lower bound and widen its cell range.
[[HT_AVX512_TARGET]] void FinishEnvelopeAvx512(const double* value, const float* h,
                                               const double* ndotn, const int* cell, double range,
                                               bool keep_max, float* heights, int n,
                                               DrawnCells* drawn) noexcept {
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
[[gnu::target("avx2")]] std::size_t LargestDifferenceLanesAvx2(const float* b, const float* a,
                                                               std::size_t n, int first_cell,
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
[[HT_AVX512_TARGET]] std::size_t LargestDifferenceLanesAvx512(const float* b, const float* a,
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

}  // namespace

std::optional<ContactWindow> ContactWindow::TryMake(const glm::dvec3& center_W,
                                                    const glm::dvec3& normal_W, double extent_m,
                                                    int resolution) noexcept {
  if (WindowProblem(center_W, normal_W, extent_m, resolution) != nullptr) return std::nullopt;
  ContactWindow w;
  w.center_W = center_W;
  w.normal_W = normal_W / glm::length(normal_W);
  const glm::dvec3 ref = std::abs(w.normal_W.x) < 0.9 ? glm::dvec3(1, 0, 0) : glm::dvec3(0, 1, 0);
  w.axis_u_W = glm::normalize(ref - glm::dot(ref, w.normal_W) * w.normal_W);
  w.axis_v_W = glm::cross(w.normal_W, w.axis_u_W);
  w.extent_m = extent_m;
  w.resolution = resolution;
  return w;
}

ContactWindow ContactWindow::Make(const glm::dvec3& center_W, const glm::dvec3& normal_W,
                                  double extent_m, int resolution) {
  if (const char* problem = WindowProblem(center_W, normal_W, extent_m, resolution)) {
    throw std::invalid_argument(std::string("ContactWindow: ") + problem + " (extent " +
                                std::to_string(extent_m) + ", resolution " +
                                std::to_string(resolution) + ")");
  }
  return *TryMake(center_W, normal_W, extent_m, resolution);
}

glm::dvec3 ContactWindow::CellCenter(int index) const noexcept {
  const int i = index % resolution, j = index / resolution;
  const double s = ((i + 0.5) / resolution - 0.5) * extent_m;
  const double t = ((j + 0.5) / resolution - 0.5) * extent_m;
  return center_W + s * axis_u_W + t * axis_v_W;
}

namespace {

// True when the corners' coordinates a, b, c along an axis all lie below −limit or all above
// +limit: the triangle misses the slab |x| ≤ limit.
[[gnu::always_inline]] inline bool MissesSlab(double a, double b, double c, double limit) noexcept {
  return std::max({a, b, c}) < -limit || std::min({a, b, c}) > limit;
}

// SelectPatchTriangles' tests of triangle f, cheapest and most selective first: the extent along
// u (from `along_u`, each vertex's p·u + ou, when given), then v, then n, then the facing test.
[[gnu::always_inline]] inline bool PatchTriangleTest(
    const HapticModel& model, int f, const glm::dvec3& u_O, const glm::dvec3& v_O,
    const glm::dvec3& n_O, double ou, double ov, double on, double half, double depth_limit,
    PatchSide side, double threshold, const double* along_u, double margin_per_radius) noexcept {
  const glm::dvec3* vertices = model.vertices_O.data();
  const glm::ivec3 t = model.triangles[static_cast<std::size_t>(f)];
  if (margin_per_radius > 0.0) {
    // The triangle's own margin: its farthest corner from the model's origin (every point of
    // the triangle is at most that far).
    const double r = std::sqrt(std::max({glm::dot(vertices[t[0]], vertices[t[0]]),
                                         glm::dot(vertices[t[1]], vertices[t[1]]),
                                         glm::dot(vertices[t[2]], vertices[t[2]])}));
    half += margin_per_radius * r;
    depth_limit += margin_per_radius * r;
  }
  double s0, s1, s2;
  if (along_u != nullptr) {
    s0 = along_u[t[0]];
    s1 = along_u[t[1]];
    s2 = along_u[t[2]];
  } else {
    s0 = glm::dot(vertices[t[0]], u_O) + ou;
    s1 = glm::dot(vertices[t[1]], u_O) + ou;
    s2 = glm::dot(vertices[t[2]], u_O) + ou;
  }
  if (MissesSlab(s0, s1, s2, half)) return false;
  const glm::dvec3& p0 = vertices[t[0]];
  const glm::dvec3& p1 = vertices[t[1]];
  const glm::dvec3& p2 = vertices[t[2]];
  const double t0 = glm::dot(p0, v_O) + ov, t1 = glm::dot(p1, v_O) + ov,
               t2 = glm::dot(p2, v_O) + ov;
  if (MissesSlab(t0, t1, t2, half)) return false;
  const double d0 = glm::dot(p0, n_O) + on, d1 = glm::dot(p1, n_O) + on,
               d2 = glm::dot(p2, n_O) + on;
  if (MissesSlab(d0, d1, d2, depth_limit)) return false;
  const glm::dvec3 cr = glm::cross(p1 - p0, p2 - p0);
  const double area2 = glm::length(cr);
  if (!(area2 > 0.0)) return false;
  const double facing = glm::dot(cr, n_O) / area2;
  return !(side == PatchSide::kEnvironment ? facing <= threshold : facing >= -threshold);
}

// PatchTriangleTest on a tree's record of the triangle: the same tests on the same doubles (the
// record's corners, cross product, its length and the radius are the scan's own expressions), the
// facing test first, as it needs no corner projection. The tests are pure, so their order does
// not change which triangles pass.
[[gnu::always_inline]] inline bool PatchRecordTest(const TriangleBoxTree::Triangle& t,
                                                   const glm::dvec3& u_O, const glm::dvec3& v_O,
                                                   const glm::dvec3& n_O, double ou, double ov,
                                                   double on, double half, double depth_limit,
                                                   PatchSide side, double threshold,
                                                   double margin_per_radius) noexcept {
  const double area2 = t.cross_length;
  if (!(area2 > 0.0)) return false;
  const double facing = glm::dot(t.cross_O, n_O) / area2;
  if (side == PatchSide::kEnvironment ? facing <= threshold : facing >= -threshold) return false;
  if (margin_per_radius > 0.0) {
    half += margin_per_radius * t.radius_m;
    depth_limit += margin_per_radius * t.radius_m;
  }
  const double s0 = glm::dot(t.p0_O, u_O) + ou, s1 = glm::dot(t.p1_O, u_O) + ou,
               s2 = glm::dot(t.p2_O, u_O) + ou;
  if (MissesSlab(s0, s1, s2, half)) return false;
  const double t0 = glm::dot(t.p0_O, v_O) + ov, t1 = glm::dot(t.p1_O, v_O) + ov,
               t2 = glm::dot(t.p2_O, v_O) + ov;
  if (MissesSlab(t0, t1, t2, half)) return false;
  const double d0 = glm::dot(t.p0_O, n_O) + on, d1 = glm::dot(t.p1_O, n_O) + on,
               d2 = glm::dot(t.p2_O, n_O) + on;
  return !MissesSlab(d0, d1, d2, depth_limit);
}

// SelectPatchTriangles, and with `subset` (not all) the same tests on its listed triangles only
// (SelectPatchTrianglesIn).
void SelectPatchTrianglesImpl(const HapticModel& model, const RigidTransform& X_WO,
                              const ContactWindow& w, PatchSide side, double margin_m,
                              std::vector<int>& out, double facing_slack,
                              std::vector<double>* vertex_scratch, const TriangleBoxTree* tree,
                              double margin_per_radius, TriangleSubset subset) noexcept {
  out.clear();
  const double half = 0.5 * w.extent_m + margin_m;
  const double depth_limit = w.depth_range_m() + margin_m;
  const double threshold = kPatchFacingThreshold - facing_slack;
  // The window's axes in O, once (as RenderPatchHeightsFast): a vertex's window coordinates are
  // p_O·a_O + (t − c)·a. The tests run cheapest and most selective first (the extent along u, then
  // v, then n), so that the many triangles far from the window cost nine multiply-adds each; the
  // facing test (a square root) only runs for those near it. A pre-filter: a rounding difference
  // from the world-frame arithmetic can only move triangles at the margin's edge, which draw
  // nothing inside the window.
  const glm::dquat q_inv = glm::conjugate(X_WO.rotation);
  const glm::dvec3 u_O = q_inv * w.axis_u_W, v_O = q_inv * w.axis_v_W, n_O = q_inv * w.normal_W;
  const glm::dvec3 offset = X_WO.translation - w.center_W;
  const double ou = glm::dot(offset, w.axis_u_W), ov = glm::dot(offset, w.axis_v_W),
               on = glm::dot(offset, w.normal_W);
  const int nf = static_cast<int>(model.triangles.size());
  if (!subset.all) {
    for (const int f : subset.indices) {
      if (f >= 0 && f < nf &&
          PatchTriangleTest(model, f, u_O, v_O, n_O, ou, ov, on, half, depth_limit, side, threshold,
                            nullptr, margin_per_radius)) {
        out.push_back(f);
      }
    }
    std::sort(out.begin(), out.end());
    return;
  }
  const glm::dvec3* vertices = model.vertices_O.data();
  if (tree != nullptr && tree->BuiltFrom(model)) {
    // The leaves whose boxes reach the window, then the same tests on their triangles, in
    // increasing order. A box's extent along an axis a is c·a ± |a|·half; the slack (10⁻¹² of
    // the magnitudes) far exceeds the rounding of that and of a corner's p·a + offset, so a box
    // is passed over only where each of its triangles fails the same test below.
    const std::span<const TriangleBoxTree::Node> nodes = tree->nodes();
    const std::span<const TriangleBoxTree::Triangle> records = tree->triangles();
    const glm::dvec3 abs_u = glm::abs(u_O), abs_v = glm::abs(v_O), abs_n = glm::abs(n_O);
    const auto misses = [margin_per_radius](const TriangleBoxTree::Node& node,
                                            const glm::dvec3& axis, const glm::dvec3& abs_axis,
                                            double plane_offset, double limit) {
      if (margin_per_radius > 0.0) {  // the largest of the node's triangles' own margins
        limit += margin_per_radius * (glm::length(node.center_O) + glm::length(node.half_O)) *
                 (1.0 + 1e-12);
      }
      const double c = glm::dot(node.center_O, axis) + plane_offset;
      const double r = glm::dot(node.half_O, abs_axis);
      const glm::dvec3 ac = glm::abs(node.center_O);
      const double slack = 1e-12 * (ac.x + ac.y + ac.z + node.half_O.x + node.half_O.y +
                                    node.half_O.z + std::abs(plane_offset) + limit) +
                           1e-300;
      return c + r + slack < -limit || c - r - slack > limit;
    };
    constexpr int kStack = 64;  // the tree's depth is at most log2(#F / 8) + 2
    int stack[kStack];
    int top = 0;
    if (!nodes.empty()) stack[top++] = 0;
    while (top > 0) {
      const int index = stack[--top];
      const TriangleBoxTree::Node& node = nodes[static_cast<std::size_t>(index)];
      if (misses(node, u_O, abs_u, ou, half) || misses(node, v_O, abs_v, ov, half) ||
          misses(node, n_O, abs_n, on, depth_limit)) {
        continue;
      }
      if (node.second < 0) {
        for (int k = node.begin; k < node.end; ++k) {
          const TriangleBoxTree::Triangle& record = records[static_cast<std::size_t>(k)];
          if (PatchRecordTest(record, u_O, v_O, n_O, ou, ov, on, half, depth_limit, side, threshold,
                              margin_per_radius)) {
            out.push_back(record.index);
          }
        }
      } else if (top + 2 <= kStack) {
        stack[top++] = node.second;
        stack[top++] = index + 1;
      }
    }
    std::sort(out.begin(), out.end());
    return;
  }
  // With room in the scratch, each vertex's coordinate along u once (the same double as per
  // triangle below, so the same triangles): a vertex is shared by about six triangles.
  const std::size_t nv = model.vertices_O.size();
  double* along_u = nullptr;
  if (vertex_scratch != nullptr && vertex_scratch->capacity() >= nv) {
    vertex_scratch->resize(nv);
    along_u = vertex_scratch->data();
    for (std::size_t k = 0; k < nv; ++k) along_u[k] = glm::dot(vertices[k], u_O) + ou;
  }
  for (int f = 0; f < nf; ++f) {
    if (PatchTriangleTest(model, f, u_O, v_O, n_O, ou, ov, on, half, depth_limit, side, threshold,
                          along_u, margin_per_radius)) {
      out.push_back(f);
    }
  }
}

}  // namespace

void SelectPatchTriangles(const HapticModel& model, const RigidTransform& X_WO,
                          const ContactWindow& w, PatchSide side, double margin_m,
                          std::vector<int>& out, double facing_slack,
                          std::vector<double>* vertex_scratch, const TriangleBoxTree* tree,
                          double margin_per_radius) noexcept {
  SelectPatchTrianglesImpl(model, X_WO, w, side, margin_m, out, facing_slack, vertex_scratch, tree,
                           margin_per_radius, TriangleSubset::All());
}

void SelectPatchTrianglesIn(TriangleSubset subset, const HapticModel& model,
                            const RigidTransform& X_WO, const ContactWindow& w, PatchSide side,
                            double margin_m, std::vector<int>& out, double facing_slack,
                            std::vector<double>* vertex_scratch, const TriangleBoxTree* tree,
                            double margin_per_radius) noexcept {
  SelectPatchTrianglesImpl(model, X_WO, w, side, margin_m, out, facing_slack, vertex_scratch, tree,
                           margin_per_radius, subset);
}

namespace {

int TreeDepth(std::span<const TriangleBoxTree::Node> nodes, int index) noexcept {
  const TriangleBoxTree::Node& node = nodes[static_cast<std::size_t>(index)];
  if (node.second < 0) return 1;
  return 1 + std::max(TreeDepth(nodes, index + 1), TreeDepth(nodes, node.second));
}

}  // namespace

void TriangleBoxTree::Clear() noexcept {
  nodes_.clear();
  triangles_data_.clear();
  model_ = nullptr;
  vertices_ = triangles_ = nullptr;
  vertex_count_ = triangle_count_ = 0;
}

void TriangleBoxTree::Build(const HapticModel& model) {
  Clear();
  const std::size_t nf = model.triangles.size();
  std::vector<int> order(nf);  // the triangles, permuted into leaf order by BuildNode
  std::vector<glm::dvec3> centroids(nf);
  for (std::size_t f = 0; f < nf; ++f) {
    order[f] = static_cast<int>(f);
    const glm::ivec3 t = model.triangles[f];
    centroids[f] = (model.vertices_O[static_cast<std::size_t>(t[0])] +
                    model.vertices_O[static_cast<std::size_t>(t[1])] +
                    model.vertices_O[static_cast<std::size_t>(t[2])]) /
                   3.0;
  }
  nodes_.reserve(nf / (kLeafTriangles / 2) + 1);
  if (nf > 0) BuildNode(model, centroids, order, 0, static_cast<int>(nf));
  triangles_data_.resize(nf);
  for (std::size_t k = 0; k < nf; ++k) {
    const glm::ivec3 t = model.triangles[static_cast<std::size_t>(order[k])];
    Triangle& r = triangles_data_[k];
    r.index = order[k];
    r.p0_O = model.vertices_O[static_cast<std::size_t>(t[0])];
    r.p1_O = model.vertices_O[static_cast<std::size_t>(t[1])];
    r.p2_O = model.vertices_O[static_cast<std::size_t>(t[2])];
    r.cross_O = glm::cross(r.p1_O - r.p0_O, r.p2_O - r.p0_O);
    r.cross_length = glm::length(r.cross_O);
    r.radius_m = std::sqrt(
        std::max({glm::dot(r.p0_O, r.p0_O), glm::dot(r.p1_O, r.p1_O), glm::dot(r.p2_O, r.p2_O)}));
  }
  // Median splits keep the depth near log2(#F / 8); SelectPatchTriangles walks with a stack of
  // 64, which a depth of 60 cannot overflow.
  if (!nodes_.empty() && TreeDepth(nodes_, 0) > 60) {
    Clear();
    return;
  }
  model_ = &model;
  vertices_ = model.vertices_O.data();
  triangles_ = model.triangles.data();
  vertex_count_ = model.vertices_O.size();
  triangle_count_ = nf;
  if (vertex_count_ > 0) {
    first_vertex_ = model.vertices_O.front();
    last_vertex_ = model.vertices_O.back();
  }
  if (nf > 0) {
    first_triangle_ = model.triangles.front();
    last_triangle_ = model.triangles.back();
  }
}

int TriangleBoxTree::BuildNode(const HapticModel& model, const std::vector<glm::dvec3>& centroids,
                               std::vector<int>& order, int begin, int end) {
  glm::dvec3 lo(std::numeric_limits<double>::infinity());
  glm::dvec3 hi(-std::numeric_limits<double>::infinity());
  for (int k = begin; k < end; ++k) {
    const glm::ivec3 t =
        model.triangles[static_cast<std::size_t>(order[static_cast<std::size_t>(k)])];
    for (int c = 0; c < 3; ++c) {
      const glm::dvec3& p = model.vertices_O[static_cast<std::size_t>(t[c])];
      lo = glm::min(lo, p);
      hi = glm::max(hi, p);
    }
  }
  const int index = static_cast<int>(nodes_.size());
  Node node;
  node.center_O = 0.5 * (lo + hi);
  node.half_O = 0.5 * (hi - lo);
  node.half_O += 1e-12 * (glm::abs(node.center_O) + node.half_O);
  node.begin = begin;
  node.end = end;
  nodes_.push_back(node);
  if (end - begin <= kLeafTriangles) return index;
  const glm::dvec3 size = hi - lo;
  const int axis = size.x >= size.y && size.x >= size.z ? 0 : (size.y >= size.z ? 1 : 2);
  const int mid = begin + (end - begin) / 2;
  std::nth_element(order.begin() + begin, order.begin() + mid, order.begin() + end,
                   [&](int a, int b) {
                     const double ca = centroids[static_cast<std::size_t>(a)][axis];
                     const double cb = centroids[static_cast<std::size_t>(b)][axis];
                     return ca < cb || (ca == cb && a < b);
                   });
  BuildNode(model, centroids, order, begin, mid);
  const int second = BuildNode(model, centroids, order, mid, end);
  nodes_[static_cast<std::size_t>(index)].second = second;
  return index;
}

const TriangleBoxTree* TriangleBoxTreeCache::For(const HapticModel& model) noexcept {
  if (model.triangles.size() < kMinTriangles) return nullptr;
  ++clock_;
  Slot* replace = nullptr;
  for (Slot& slot : slots_) {
    if (slot.last_use != 0 && slot.tree.BuiltFrom(model)) {
      slot.last_use = clock_;
      return &slot.tree;
    }
    // A never-built slot first, else the least recently used one if it is stale.
    if (replace == nullptr || slot.last_use < replace->last_use) replace = &slot;
  }
  if (replace->last_use != 0 && clock_ - replace->last_use <= kStaleCalls) {
    return nullptr;  // every slot in use: the whole scan, without building (or allocating)
  }
  try {
    replace->tree.Build(model);
  } catch (...) {  // std::bad_alloc
    replace->tree.Clear();
    replace->last_use = 0;
    return nullptr;
  }
  replace->last_use = clock_;
  return &replace->tree;
}

bool TriangleBoxTree::BuiltFrom(const HapticModel& model) const noexcept {
  if (model_ != &model || vertices_ != model.vertices_O.data() ||
      triangles_ != model.triangles.data() || vertex_count_ != model.vertices_O.size() ||
      triangle_count_ != model.triangles.size()) {
    return false;
  }
  if (vertex_count_ > 0 &&
      (model.vertices_O.front() != first_vertex_ || model.vertices_O.back() != last_vertex_)) {
    return false;
  }
  if (triangle_count_ > 0 &&
      (model.triangles.front() != first_triangle_ || model.triangles.back() != last_triangle_)) {
    return false;
  }
  return true;
}

void RenderPatchHeights(const HapticModel& model, const RigidTransform& X_WO,
                        std::span<const int> triangles, const ContactWindow& w, PatchSide side,
                        std::span<float> heights, double depth_range_m) noexcept {
  const int n = w.resolution;
  if (heights.size() < static_cast<size_t>(n) * n) return;
  const double inv_cell = 1.0 / w.cell_size_m();
  const double half_cells = 0.5 * n;
  const bool keep_max = side == PatchSide::kEnvironment;
  const double range = depth_range_m > 0.0 ? depth_range_m : w.depth_range_m();
  for (const int f : triangles) {
    const glm::ivec3 tri = model.triangles[f];
    double x[3], y[3], d[3], nn[3];
    glm::dvec3 p[3];
    for (int c = 0; c < 3; ++c) {
      p[c] = X_WO * model.vertices_O[tri[c]] - w.center_W;
      x[c] = glm::dot(p[c], w.axis_u_W) * inv_cell + half_cells;  // pixel i spans [i, i+1)
      y[c] = glm::dot(p[c], w.axis_v_W) * inv_cell + half_cells;
      d[c] = glm::dot(p[c], w.normal_W);
      nn[c] = glm::dot(X_WO.rotation * model.corner_normals_O[3 * f + c], w.normal_W);
    }
    // Facing test at this pose (the selection may have been made at another one).
    const glm::dvec3 cr = glm::cross(p[1] - p[0], p[2] - p[0]);
    const double cr_len = glm::length(cr);
    if (!(cr_len > 0.0)) continue;
    const double facing = glm::dot(cr, w.normal_W) / cr_len;
    if (keep_max ? facing <= kPatchFacingThreshold : facing >= -kPatchFacingThreshold) continue;
    ProjectedCells pc;
    if (!ProjectCells(x, y, n, pc)) continue;
    const double inv_area = pc.inv_area;
    const bool textured = model.textured[f] != 0 && !model.texture.empty();
    const int level =
        textured ? model.texture.LevelForFootprint(model.texel_size_m[f], w.cell_size_m()) : 0;
    const glm::dvec3& n0 = model.corner_normals_O[3 * f];
    const glm::dvec3& n1 = model.corner_normals_O[3 * f + 1];
    const glm::dvec3& n2 = model.corner_normals_O[3 * f + 2];
    const double cos01 = glm::dot(n0, n1), cos02 = glm::dot(n0, n2), cos12 = glm::dot(n1, n2);
    const glm::vec2 uv0 = model.corner_uvs[3 * f], uv1 = model.corner_uvs[3 * f + 1],
                    uv2 = model.corner_uvs[3 * f + 2];
    for (int j = pc.j0; j <= pc.j1; ++j) {
      const double py = j + 0.5;
      for (int i = pc.i0; i <= pc.i1; ++i) {
        const double px = i + 0.5;
        const double b0 = ((x[1] - px) * (y[2] - py) - (x[2] - px) * (y[1] - py)) * inv_area;
        const double b1 = ((x[2] - px) * (y[0] - py) - (x[0] - px) * (y[2] - py)) * inv_area;
        const double b2 = 1.0 - b0 - b1;
        if (b0 < kEdgeTolerance || b1 < kEdgeTolerance || b2 < kEdgeTolerance) continue;
        double value = b0 * d[0] + b1 * d[1] + b2 * d[2];
        if (textured) {
          const float u = static_cast<float>(b0 * uv0.x + b1 * uv1.x + b2 * uv2.x);
          const float v = static_cast<float>(b0 * uv0.y + b1 * uv1.y + b2 * uv2.y);
          // h is along the unit interpolated normal N = Ñ/|Ñ|, Ñ = Σ b_i n_i (unit n_i):
          // |Ñ|² = Σ b_i² + 2 Σ_{i<j} b_i b_j (n_i·n_j), from the per-triangle corner cosines.
          const double len2 = b0 * b0 + b1 * b1 + b2 * b2 +
                              2.0 * (b0 * b1 * cos01 + b0 * b2 * cos02 + b1 * b2 * cos12);
          const double ndotn =
              len2 > 1e-12 ? (b0 * nn[0] + b1 * nn[1] + b2 * nn[2]) / std::sqrt(len2) : 0.0;
          value += static_cast<double>(model.texture.Sample(level, u, v)) * ndotn;
        }
        if (!(std::abs(value) <= range)) continue;  // outside the window's box along n
        float& cell = heights[static_cast<size_t>(j) * n + i];
        const auto fv = static_cast<float>(value);
        if (keep_max ? fv > cell : fv < cell) cell = fv;
      }
    }
  }
}

DepthSample DirectionalPenetrationDepth(std::span<const float> b,
                                        std::span<const float> a) noexcept {
  const size_t count = std::min(a.size(), b.size());
  FirstLargestDifference scan;
  scan.Add(b.data(), a.data(), count, 0);
  return scan.Result();
}

namespace {

// What RenderToolDepth adds to RenderPatchHeightsFast (margin 0, the tool's side): the cell
// around which the first pass draws, the cells drawn (with the environment's heights and
// drawn.lower, the largest b − a of the cells drawn so far: a lower bound of the render's depth,
// as a cell's tool height only falls as more triangles are drawn), and the hints of
// ToolDepthCull. Each triangle's texture bound is HeightField::MaxAbsOver's; texture_bound_m,
// the whole texture's (m), only sizes the rounding margin.
struct DepthCull {
  double texture_bound_m;
  int first_i, first_j;
  DrawnCells drawn;  // the environment, the lower bound, the cells drawn (the rest stay +∞)
  std::span<const int> first_triangles;   // the first pass's triangles (empty: all)
  std::vector<int>* first_triangles_out;  // gets the triangles the first pass drew, or nullptr
  const EnvironmentMaxPyramid* env_max;   // whole triangles skipped by it, or nullptr
  TriangleBoundCache* bounds;             // levels and texture bounds, or nullptr
  const EnvironmentRowMax* env_row_max;   // whole rows of a triangle skipped by it, or nullptr
  int rows_skipped = 0;                   // out: the rows env_row_max skipped
};

void RenderHeightsFastImpl(const HapticModel& model, const RigidTransform& X_WO,
                           std::span<const int> triangles, const ContactWindow& w, PatchSide side,
                           int margin_cells, std::span<float> heights, SampleKernel kernel,
                           DepthCull* cull) noexcept {
  const int n = w.resolution;
  const int m = std::max(margin_cells, 0);
  const int nt = n + 2 * m;
  if (heights.size() < static_cast<size_t>(nt) * nt) return;
  const double inv_cell = 1.0 / w.cell_size_m();
  const double half_cells = 0.5 * n + m;  // extended pixel i spans [i, i+1)
  const bool keep_max = side == PatchSide::kEnvironment;
  const double range = w.depth_range_m();
  // The window's frame in O: p_W·a − c·a = p_O·(R⁻¹a) + (t − c)·a for each axis a.
  const glm::dquat q_inv = glm::conjugate(X_WO.rotation);
  const glm::dvec3 u_O = q_inv * w.axis_u_W, v_O = q_inv * w.axis_v_W, n_O = q_inv * w.normal_W;
  const glm::dvec3 offset = X_WO.translation - w.center_W;
  const double ou = glm::dot(offset, w.axis_u_W), ov = glm::dot(offset, w.axis_v_W),
               on = glm::dot(offset, w.normal_W);
  const bool have_texture = !model.texture.empty();
  // A textured triangle's covered cells wait here with their barycentrics. At the end of the
  // triangle they get their texture coordinates and normal factors (ShadeCells, with the
  // triangle's shading); when the batch is full, the mip level changes or an untextured triangle
  // comes, every waiting cell gets its texture sample (SampleLevelBatch, one call for many
  // triangles) and finishes as the reference does: value + h·(N·n), the box test, the envelope,
  // in the order the cells were drawn.
  constexpr int kBatch = 256;
  alignas(32) float batch_u[kBatch], batch_v[kBatch], batch_h[kBatch];
  alignas(32) double batch_b0[kBatch], batch_b1[kBatch];
  double batch_value[kBatch], batch_ndotn[kBatch];
  alignas(16) int batch_cell[kBatch];  // index into heights (row · nt + column)
#ifdef HT_RASTER_AVX2
  alignas(32) float batch_fv[kBatch];  // the cells' heights, as the envelope takes them
#endif
  int batch_count = 0, batch_shaded = 0, batch_level = 0;
#ifdef HT_RASTER_AVX2
  // Rows eight cells a step where the CPU has AVX-512 (and the caller asked for the best
  // kernel), else four where it has AVX2 (and the caller did not ask for scalar code).
  const bool avx512_rows = kernel == SampleKernel::kBest && CpuHasAvx512();
  const bool avx2_rows = kernel != SampleKernel::kScalar && CpuHasAvx2();
#endif
  TriangleShading shading{};
  const auto shade = [&] {  // the current triangle's waiting cells
    const int s = batch_shaded;
    if (batch_count > s) {
#ifdef HT_RASTER_AVX2
      if (avx512_rows) {
        ShadeCellsAvx512(shading, batch_b0 + s, batch_b1 + s, batch_value + s, batch_u + s,
                         batch_v + s, batch_ndotn + s, batch_count - s);
        batch_shaded = batch_count;
        return;
      }
      if (avx2_rows) {
        ShadeCellsAvx2(shading, batch_b0 + s, batch_b1 + s, batch_value + s, batch_u + s,
                       batch_v + s, batch_ndotn + s, batch_count - s);
        batch_shaded = batch_count;
        return;
      }
#endif
      ShadeCells(shading, batch_b0 + s, batch_b1 + s, batch_value + s, batch_u + s, batch_v + s,
                 batch_ndotn + s, batch_count - s);
    }
    batch_shaded = batch_count;
  };
  const auto flush = [&] {
    shade();
    if (batch_count == 0) return;
    const auto count = static_cast<std::size_t>(batch_count);
    SampleLevelBatch(model.texture, batch_level, std::span<const float>(batch_u, count),
                     std::span<const float>(batch_v, count), std::span<float>(batch_h, count),
                     kernel);
#ifdef HT_RASTER_AVX2
    if (avx512_rows) {
      FinishEnvelopeAvx512(batch_value, batch_h, batch_ndotn, batch_cell, range, keep_max,
                           heights.data(), batch_count, cull != nullptr ? &cull->drawn : nullptr);
      batch_count = batch_shaded = 0;
      return;
    }
#endif
    if (cull != nullptr) {
      // The finish, and each cell's b − a (float, as the depth scan takes it) raises the lower
      // bound: the cell's final tool height is at most this one.
      DrawnCells& drawn = cull->drawn;
#ifdef HT_RASTER_AVX2
      if (avx2_rows) {
        FinishCellsAvx2(batch_value, batch_h, batch_ndotn, range, false, batch_fv, batch_count);
        float* const cells = heights.data();
        for (std::size_t k = 0; k < count; ++k) {
          const int c = batch_cell[k];
          const float fv = batch_fv[k];  // +∞ outside the box: no cell, and e − fv = −∞
          if (fv < cells[c]) cells[c] = fv;
          drawn.Draw(c, fv);
        }
        drawn.count += batch_count;
        batch_count = batch_shaded = 0;
        return;
      }
#endif
      for (std::size_t k = 0; k < count; ++k) {
        const double value = batch_value[k] + static_cast<double>(batch_h[k]) * batch_ndotn[k];
        if (!(std::abs(value) <= range)) continue;  // outside the window's box along n
        float& cell = heights[static_cast<std::size_t>(batch_cell[k])];
        const auto fv = static_cast<float>(value);
        if (fv < cell) cell = fv;
        drawn.Draw(batch_cell[k], fv);
      }
      drawn.count += batch_count;
      batch_count = batch_shaded = 0;
      return;
    }
#ifdef HT_RASTER_AVX2
    if (avx2_rows) {
      // The heights four cells a step, a cell outside the box made the envelope's neutral value
      // (which never replaces a cell); then the envelope, cell by cell in the order drawn.
      FinishCellsAvx2(batch_value, batch_h, batch_ndotn, range, keep_max, batch_fv, batch_count);
      float* const cells = heights.data();
      if (keep_max) {
        for (std::size_t k = 0; k < count; ++k) {
          float& cell = cells[batch_cell[k]];
          if (batch_fv[k] > cell) cell = batch_fv[k];
        }
      } else {
        for (std::size_t k = 0; k < count; ++k) {
          float& cell = cells[batch_cell[k]];
          if (batch_fv[k] < cell) cell = batch_fv[k];
        }
      }
      batch_count = batch_shaded = 0;
      return;
    }
#endif
    for (std::size_t k = 0; k < count; ++k) {
      const double value = batch_value[k] + static_cast<double>(batch_h[k]) * batch_ndotn[k];
      if (!(std::abs(value) <= range)) continue;  // outside the window's box along n
      float& cell = heights[static_cast<std::size_t>(batch_cell[k])];
      const auto fv = static_cast<float>(value);
      if (keep_max ? fv > cell : fv < cell) cell = fv;
    }
    batch_count = batch_shaded = 0;
  };
  // With culling, two passes: the cells within kFirstCellReach of the first cell, then (after a
  // flush, which sets the lower bound from them) every cell, dropped where its coarse height
  // cannot reach the lower bound (the first pass's cells are drawn again: the envelope keeps
  // them). Without, one pass.
  constexpr int kFirstCellReach = 2;
  const int passes = cull != nullptr && cull->first_i >= 0 ? 2 : 1;
  // Culling margin: the float roundings of a cell's height and of b − a (relative 2⁻²⁴ each, of
  // values within the window's box) and of the double arithmetic, far exceeded.
  const double cull_margin =
      cull != nullptr ? 1e-6 * (3.0 * range + cull->texture_bound_m) + 1e-15 : 0.0;
  TriangleBoundCache* const bounds =
      cull != nullptr && cull->bounds != nullptr && cull->bounds->Matches(model, w.cell_size_m())
          ? cull->bounds
          : nullptr;
  for (int pass = 0; pass < passes; ++pass) {
    if (pass == 1) flush();
    const std::span<const int> list = pass == 0 && passes == 2 && !cull->first_triangles.empty()
                                          ? cull->first_triangles
                                          : triangles;
    for (const int f : list) {
      shade();  // the previous triangle's cells, before its shading is replaced
      const glm::ivec3 tri = model.triangles[f];
      const glm::dvec3& a0 = model.vertices_O[tri[0]];
      const glm::dvec3& a1 = model.vertices_O[tri[1]];
      const glm::dvec3& a2 = model.vertices_O[tri[2]];
      // Facing test at this pose (the selection may have been made at another one).
      const glm::dvec3 cr = glm::cross(a1 - a0, a2 - a0);
      const double cr_len = glm::length(cr);
      if (!(cr_len > 0.0)) continue;
      const double facing = glm::dot(cr, n_O) / cr_len;
      if (keep_max ? facing <= kPatchFacingThreshold : facing >= -kPatchFacingThreshold) continue;
      double x[3], y[3], d[3], nn[3];
      const glm::dvec3* corners[3] = {&a0, &a1, &a2};
      for (int c = 0; c < 3; ++c) {
        const glm::dvec3& p = *corners[c];
        x[c] = (glm::dot(p, u_O) + ou) * inv_cell + half_cells;
        y[c] = (glm::dot(p, v_O) + ov) * inv_cell + half_cells;
        d[c] = glm::dot(p, n_O) + on;
        nn[c] = glm::dot(model.corner_normals_O[3 * f + c], n_O);
      }
      ProjectedCells pc;
      if (!ProjectCells(x, y, nt, pc)) continue;
      if (pass == 0 && passes == 2) {
        // The first pass draws the cells around the first cell only.
        pc.i0 = std::max(pc.i0, cull->first_i - kFirstCellReach);
        pc.i1 = std::min(pc.i1, cull->first_i + kFirstCellReach);
        pc.j0 = std::max(pc.j0, cull->first_j - kFirstCellReach);
        pc.j1 = std::min(pc.j1, cull->first_j + kFirstCellReach);
        if (pc.i0 > pc.i1 || pc.j0 > pc.j1) continue;
        std::vector<int>* out = cull->first_triangles_out;
        if (out != nullptr && out->size() < out->capacity()) out->push_back(f);
      }
      const double inv_area = pc.inv_area;
      const int i0 = pc.i0, i1 = pc.i1;
      const bool textured = have_texture && model.textured[f] != 0;
      // The level and (with culling) the texture bound below, from the window's cache when it
      // has them: the same values.
      double texture_bound = 0.0;
      int level = 0;
      const bool cached = bounds != nullptr && bounds->Find(f, level, texture_bound);
      if (!cached && textured) {
        level = model.texture.LevelForFootprint(model.texel_size_m[f], w.cell_size_m());
      }
      // The cull of this triangle's cells: a cell's b − a is at most env − (b·d) + |h·(N·n)|
      // (|N·n| ≤ 1, and |h| at most the largest |h| under the triangle's texture coordinates, whose
      // box holds every cell's: b ≥ −1e-9 sum to 1), so cells where that, with the margin, is below
      // the lower bound cannot be the deepest (nor tie with it).
      RowCull row_cull{};
      const RowCull* row_cull_ptr = nullptr;
      if (cull != nullptr && std::isfinite(cull->drawn.lower)) {
        if (!cached && textured) {
          const glm::vec2 uv0 = model.corner_uvs[3 * f], uv1 = model.corner_uvs[3 * f + 1],
                          uv2 = model.corner_uvs[3 * f + 2];
          texture_bound = model.texture.MaxAbsOver(
              level, std::min({uv0.x, uv1.x, uv2.x}), std::min({uv0.y, uv1.y, uv2.y}),
              std::max({uv0.x, uv1.x, uv2.x}), std::max({uv0.y, uv1.y, uv2.y}));
        }
        if (!cached && bounds != nullptr) bounds->Store(f, level, texture_bound);
        row_cull = {cull->drawn.env, d[0], d[1], d[2],
                    static_cast<double>(cull->drawn.lower) - texture_bound - cull_margin};
        row_cull_ptr = &row_cull;
        // The whole triangle: its cells' coarse heights are at least its smallest corner's (to
        // rounding far below the margin), and their environment heights at most the box's largest.
        if (cull->env_max != nullptr &&
            static_cast<double>(cull->env_max->MaxOver(pc.i0, pc.i1, pc.j0, pc.j1)) -
                    std::min({d[0], d[1], d[2]}) <
                row_cull.cut) {
          continue;
        }
      }
      if (!textured || level != batch_level) flush();
      batch_level = level;
      const glm::dvec3& n0 = model.corner_normals_O[3 * f];
      const glm::dvec3& n1 = model.corner_normals_O[3 * f + 1];
      const glm::dvec3& n2 = model.corner_normals_O[3 * f + 2];
      if (textured) {
        const glm::vec2 uv0 = model.corner_uvs[3 * f], uv1 = model.corner_uvs[3 * f + 1],
                        uv2 = model.corner_uvs[3 * f + 2];
        // A flat-shaded triangle (the three corner normals equal): the interpolated normal is the
        // corner normal, (b·nn)/|Σ b_k n_k| = nn0 up to rounding (1e-16 relative), without the
        // per-cell square root and division.
        shading = {uv0.x,
                   uv1.x,
                   uv2.x,
                   uv0.y,
                   uv1.y,
                   uv2.y,
                   nn[0],
                   nn[1],
                   nn[2],
                   glm::dot(n0, n1),
                   glm::dot(n0, n2),
                   glm::dot(n1, n2),
                   n0 == n1 && n0 == n2,
                   d[0],
                   d[1],
                   d[2]};
      }
      // Barycentrics, affine in the cell centre (px, py): b0 = k0 + gx0·px + gy0·py, likewise b1,
      // and b2 = 1 − b0 − b1.
      const double k0 = (x[1] * y[2] - x[2] * y[1]) * inv_area;
      const double gx0 = (y[1] - y[2]) * inv_area, gy0 = (x[2] - x[1]) * inv_area;
      const double k1 = (x[2] * y[0] - x[0] * y[2]) * inv_area;
      const double gx1 = (y[2] - y[0]) * inv_area, gy1 = (x[0] - x[2]) * inv_area;
      // Each row's span: the cell centres px where each b = r + g·px ≥ the tolerance (r the row's
      // part, the same double the per-cell test uses), by reciprocals. A computed bound differs
      // from the exact one by a few ulps of px plus a few of r/g; each is widened by 1e-7 cell plus
      // 1e-12·|r/g|, far more than that, so every cell the exact per-cell test below accepts lies
      // in the span (the cells drawn are those of the test alone) while the span no longer carries
      // the whole extra cell at each end that it did (a third of the cells tested on the CAD part).
      // lo stays in [i0, i1 + 3] and hi in [i0 − 2, i1 + 1] wherever the span is used, so the
      // floors and ceilings by truncation are exact.
      const double g2 = -gx0 - gx1;
      const double inv_gx0 = gx0 != 0.0 ? 1.0 / gx0 : 0.0, inv_gx1 = gx1 != 0.0 ? 1.0 / gx1 : 0.0,
                   inv_g2 = g2 != 0.0 ? 1.0 / g2 : 0.0;
      // A row of this triangle whose cells [ia, ib] none can pass the per-cell cull (RowCull):
      // the environment's largest height over the span (whole blocks, so at least the cells'),
      // less the lower of the coarse heights b·d at the span's two ends, below the cut. b·d is
      // affine along the row and the ends are computed as the per-cell test computes them; the
      // cells between differ from that line by the rounding of b (about 1e-13 at N ≤ 128, |b| ≤ 1
      // over a span) times |d| (≤ 0.1 m in a window's box), far below the 1e-12 m slack. Every
      // cell such a row would cover is dropped by the per-cell test, so it is skipped (its
      // chunks' flushes kept: the render draws the cells it draws without the row cull).
      const EnvironmentRowMax* const row_max =
          row_cull_ptr != nullptr ? cull->env_row_max : nullptr;  // its resolution checked
      const auto row_cannot_reach = [&](int j, int ia, int ib, double r0, double r1) {
        const auto coarse = [&](int i) {
          const double px = i + 0.5;
          const double b0 = r0 + gx0 * px, b1 = r1 + gx1 * px, b2 = 1.0 - b0 - b1;
          return b0 * d[0] + b1 * d[1] + b2 * d[2];
        };
        const double lowest = std::min(coarse(ia), coarse(ib)) - 1e-12;
        return !(static_cast<double>(row_max->MaxOver(j, ia, ib)) - lowest >= row_cull.cut);
      };
#ifdef HT_RASTER_AVX2
      if (textured && avx2_rows) {
        // The spans of up to kRows rows at a time (RowSpansAvx2, the bits of the loop below), then
        // each row's covered cells straight into the batch, a chunk at a time (flushed early when a
        // chunk might not fit: cells are independent, so where a batch ends changes nothing).
        constexpr int kRows = 64;
        alignas(32) double span_r0[kRows], span_r1[kRows];
        alignas(16) int span_ia[kRows], span_ib[kRows];
        const double g[3] = {gx0, gx1, g2}, inv_g[3] = {inv_gx0, inv_gx1, inv_g2};
        for (int jb = pc.j0; jb <= pc.j1; jb += kRows) {
          const int rows = std::min(kRows, pc.j1 - jb + 1);
          RowSpansAvx2(k0, gy0, k1, gy1, g, inv_g, i0, i1, jb, rows, span_r0, span_r1, span_ia,
                       span_ib);
          for (int k = 0; k < rows; ++k) {
            const int ia = span_ia[k], ib = span_ib[k], row_start = (jb + k) * nt;
            constexpr int kChunk = kBatch / 2;
            const bool skip = row_max != nullptr && ia <= ib &&
                              row_cannot_reach(jb + k, ia, ib, span_r0[k], span_r1[k]);
            if (skip) ++cull->rows_skipped;
            for (int start = ia; start <= ib; start += kChunk) {
              const int end = std::min(ib, start + kChunk - 1);
              // A skipped row still makes its chunks' flushes (they raise the lower bound the next
              // triangles' cuts start from), so the render draws the cells it draws without it.
              if (batch_count + (end - start + 8) > kBatch) flush();
              if (skip) continue;
              batch_count +=
                  avx512_rows
                      ? CoverRowAvx512(span_r0[k], gx0, span_r1[k], gx1, start, end, row_start,
                                       batch_b0 + batch_count, batch_b1 + batch_count,
                                       batch_cell + batch_count, row_cull_ptr)
                      : CoverRowAvx2(span_r0[k], gx0, span_r1[k], gx1, start, end, row_start,
                                     batch_b0 + batch_count, batch_b1 + batch_count,
                                     batch_cell + batch_count, row_cull_ptr);
            }
          }
        }
        continue;
      }
#endif
      for (int j = pc.j0; j <= pc.j1; ++j) {
        const double py = j + 0.5;
        const double r0 = k0 + gy0 * py, r1 = k1 + gy1 * py, r2 = 1.0 - r0 - r1;
        double lo = static_cast<double>(i0), hi = static_cast<double>(i1) + 1.0;
        bool empty = false;
        const auto clip = [&](double r, double g, double inv_g) {
          if (g == 0.0) {
            empty = empty || r < kEdgeTolerance;
            return;
          }
          const double bound = (kEdgeTolerance - r) * inv_g;
          const double slack = 1e-7 + 1e-12 * std::abs(r * inv_g);
          if (g > 0.0) {
            lo = std::max(lo, bound - slack);
          } else {
            hi = std::min(hi, bound + slack);
          }
        };
        clip(r0, gx0, inv_gx0);
        clip(r1, gx1, inv_gx1);
        clip(r2, g2, inv_g2);
        if (empty || !(lo <= hi + 2.0)) continue;
        // Cell i (centre i + 0.5) with lo ≤ i + 0.5 ≤ hi.
        const double lo_c = lo - 0.5, hi_c = hi - 0.5;
        const int lo_t = static_cast<int>(lo_c), hi_t = static_cast<int>(hi_c);
        const int ia = std::max(i0, lo_t + static_cast<int>(lo_c > lo_t));
        const int ib = std::min(i1, hi_t - static_cast<int>(hi_c < hi_t));
        if (row_max != nullptr && ia <= ib && row_cannot_reach(j, ia, ib, r0, r1)) {
          ++cull->rows_skipped;
          continue;
        }
        float* row = &heights[static_cast<size_t>(j) * nt];
        for (int i = ia; i <= ib; ++i) {
          const double px = i + 0.5;
          const double b0 = r0 + gx0 * px;
          const double b1 = r1 + gx1 * px;
          const double b2 = 1.0 - b0 - b1;
          if (b0 < kEdgeTolerance || b1 < kEdgeTolerance || b2 < kEdgeTolerance) continue;
          if (row_cull_ptr != nullptr && !(static_cast<double>(row_cull.env[j * nt + i]) -
                                               (b0 * d[0] + b1 * d[1] + b2 * d[2]) >=
                                           row_cull.cut)) {
            continue;
          }
          if (textured) {  // b·d and h along the unit interpolated normal, in flush()
            batch_b0[batch_count] = b0;
            batch_b1[batch_count] = b1;
            batch_cell[batch_count] = j * nt + i;
            if (++batch_count == kBatch) flush();
            continue;
          }
          const double value = b0 * d[0] + b1 * d[1] + b2 * d[2];
          if (!(std::abs(value) <= range)) continue;  // outside the window's box along n
          float& cell = row[i];
          const auto fv = static_cast<float>(value);
          if (keep_max ? fv > cell : fv < cell) cell = fv;
          if (cull != nullptr) {
            cull->drawn.Draw(j * nt + i, fv);
            ++cull->drawn.count;
          }
        }
      }
    }
  }
  flush();
}

}  // namespace

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

void RenderPatchHeightsFast(const HapticModel& model, const RigidTransform& X_WO,
                            std::span<const int> triangles, const ContactWindow& w, PatchSide side,
                            int margin_cells, std::span<float> heights,
                            SampleKernel kernel) noexcept {
  RenderHeightsFastImpl(model, X_WO, triangles, w, side, margin_cells, heights, kernel, nullptr);
}

DepthSample RenderToolDepth(const HapticModel& tool, const RigidTransform& X_WT,
                            std::span<const int> triangles, const ContactWindow& w,
                            std::span<const float> env_heights, std::span<float> heights,
                            ToolDepthCull& hints, SampleKernel kernel) noexcept {
  const int n = w.resolution;
  const auto cells = static_cast<std::size_t>(n) * n;
  hints.cells_drawn = 0;
  hints.rows_skipped = 0;
  if (hints.first_triangles_out != nullptr) hints.first_triangles_out->clear();
  const int first_cell = hints.first_cell;
  if (n <= 0 || env_heights.size() < cells || heights.size() < cells) {
    return {-std::numeric_limits<double>::infinity(), -1};
  }
  std::fill_n(heights.begin(), cells, std::numeric_limits<float>::infinity());
  const bool has_first = first_cell >= 0 && first_cell < static_cast<int>(cells);
  DepthCull cull{
      tool.TextureReach(),
      has_first ? first_cell % n : -1,
      has_first ? first_cell / n : -1,
      {env_heights.data(), -std::numeric_limits<float>::infinity(), static_cast<int>(cells), -1, 0},
      hints.first_triangles,
      hints.first_triangles_out,
      hints.env_max != nullptr && hints.env_max->resolution() == n ? hints.env_max : nullptr,
      hints.bounds,
      hints.env_row_max != nullptr && hints.env_row_max->resolution() == n ? hints.env_row_max
                                                                           : nullptr};
  RenderHeightsFastImpl(tool, X_WT, triangles, w, PatchSide::kTool, 0, heights, kernel, &cull);
  hints.cells_drawn = cull.drawn.count;
  hints.rows_skipped = cull.rows_skipped;
  // The scan over the rows drawn (every other cell is +∞, which no scan takes), row by row in
  // increasing cell order: the whole scan's cell and bits.
  FirstLargestDifference scan;
  if (cull.drawn.max_cell >= 0) {
    const int j0 = cull.drawn.min_cell / n, j1 = cull.drawn.max_cell / n;
    const auto first = static_cast<std::size_t>(j0) * n;
    scan.Add(env_heights.data() + first, heights.data() + first,
             static_cast<std::size_t>(j1 - j0 + 1) * n, j0 * n);
  }
  return scan.Result();
}

DepthSample DirectionalPenetrationDepthShifted(std::span<const float> b, int resolution,
                                               std::span<const float> a_ext, int margin_cells,
                                               int di, int dj) noexcept {
  DepthSample best{-std::numeric_limits<double>::infinity(), -1};
  const int n = resolution, m = margin_cells, nt = n + 2 * m;
  if (n <= 0 || m < 0 || std::abs(di) > m || std::abs(dj) > m ||
      b.size() < static_cast<size_t>(n) * n || a_ext.size() < static_cast<size_t>(nt) * nt) {
    return best;
  }
  FirstLargestDifference scan;  // row by row: the tool's rows are offset
  for (int j = 0; j < n; ++j) {
    scan.Add(&b[static_cast<size_t>(j) * n],
             &a_ext[static_cast<size_t>(j + m + dj) * nt + (m + di)], static_cast<size_t>(n),
             j * n);
  }
  return scan.Result();
}

}  // namespace ht
