#pragma once
// Stage 5's raster kernels (internal to 5_patch_raster.cc): a triangle's cells on a window's
// grid (ProjectCells, the edge tolerance), their shading (ShadeCells: coarse height, texture
// coordinates, the normal's factor), and what a row cull (RowCull) and a culled tool render
// (DrawnCells) keep, in scalar code and SSE2. Their AVX2 / AVX-512 lanes, which write the scalar
// code's bits (compiled with -ffp-contract=off: no multiply-add may be fused), are in
// 5_raster_kernels_avx.h; the first largest b − a (FirstLargestDifference) in
// 5_raster_largest_difference.h.

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <limits>
#if defined(__SSE2__)
#include <emmintrin.h>
#endif
#include "../x86_simd.h"
#ifdef HT_X86_SIMD
#define HT_RASTER_AVX2 1
#endif

#include "haptic_core/penetration_depth.h"

namespace ht::raster_kernels {

// Inclusive edge test of the renders, with a small tolerance on the barycentrics: cells on shared
// edges may be covered twice, which the max/min envelope makes harmless, and no crack opens
// between triangles.
inline constexpr double kEdgeTolerance = -1e-9;

// A triangle projected on a render grid of `cells` × `cells` (corner pixel coordinates x, y;
// pixel i spans [i, i+1)): 1 / its signed area, and the range of cell centres its bounding box
// covers, clipped to the grid. False when it is edge-on or degenerate in projection, or covers
// no cell centre.
struct ProjectedCells {
  double inv_area;
  int i0, i1, j0, j1;
};
inline bool ProjectCells(const double x[3], const double y[3], int cells,
                         ProjectedCells& out) noexcept {
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
inline void ShadeCells(const TriangleShading& t, const double* b0, const double* b1, double* value,
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

// A row cull (CoverRowAvx2 with `cull`): a covered cell is also dropped where its coarse height
// cannot make it the deepest cell.
struct RowCull {
  const float* env;   // the environment's heights, indexed as the render buffer
  double d0, d1, d2;  // the triangle's corner heights along n
  double cut;         // keep a cell where env − (b·d) ≥ cut (ordered: NaN drops)
};

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

}  // namespace ht::raster_kernels
