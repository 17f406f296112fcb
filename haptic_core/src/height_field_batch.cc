#include "haptic_core/height_field_batch.h"

#include <cmath>
#include <cstddef>
#include <limits>

#include "x86_simd.h"
#ifdef HT_X86_SIMD
#define HT_SAMPLE_X86 1
#endif

namespace ht {

namespace {

[[maybe_unused]] bool IsPowerOfTwo(int n) noexcept { return n > 0 && (n & (n - 1)) == 0; }

void SampleScalar(const HeightField& field, int level, const HeightFieldLevel& L, const float* u,
                  const float* v, float* h, std::size_t n) noexcept {
  for (std::size_t k = 0; k < n; ++k) h[k] = field.SampleAt(level, L, u[k], v[k]);
}

#ifdef HT_SAMPLE_X86
// The address of HeightField::Sample, four lanes: periodic (power-of-two size: the mask is the
// modulo of negative indices too) or clamped to the edge. SSE2 has no 32-bit integer min/max.
inline __m128i AddressSse2(__m128i i, __m128i size_minus_1, bool wrap) noexcept {
  if (wrap) return _mm_and_si128(i, size_minus_1);
  const __m128i zero = _mm_setzero_si128();
  const __m128i neg = _mm_cmplt_epi32(i, zero);
  i = _mm_andnot_si128(neg, i);
  const __m128i over = _mm_cmpgt_epi32(i, size_minus_1);
  return _mm_or_si128(_mm_and_si128(over, size_minus_1), _mm_andnot_si128(over, i));
}

// Non-finite u or v: 0, as HeightField::Sample. |x| <= FLT_MAX is false for ±inf and NaN.
inline __m128 FiniteMaskSse2(__m128 u, __m128 v) noexcept {
  const __m128 abs_mask = _mm_castsi128_ps(_mm_set1_epi32(0x7fffffff));
  const __m128 big = _mm_set1_ps(std::numeric_limits<float>::max());
  return _mm_and_ps(_mm_cmple_ps(_mm_and_ps(u, abs_mask), big),
                    _mm_cmple_ps(_mm_and_ps(v, abs_mask), big));
}

std::size_t SampleSse2(const HeightFieldLevel& L, bool wrap_u, bool wrap_v, const float* u,
                       const float* v, float* h, std::size_t n) noexcept {
  const __m128 tw = _mm_set1_ps(static_cast<float>(L.width));
  const __m128 th = _mm_set1_ps(static_cast<float>(L.height));
  const __m128 half = _mm_set1_ps(0.5f), lo = _mm_set1_ps(-1e6f), hi = _mm_set1_ps(1e6f);
  const __m128i wm1 = _mm_set1_epi32(L.width - 1), hm1 = _mm_set1_epi32(L.height - 1);
  const __m128i one = _mm_set1_epi32(1);
  const float* texels = L.texels.data();
  const std::ptrdiff_t width = L.width;
  std::size_t k = 0;
  for (; k + 4 <= n; k += 4) {
    const __m128 uu = _mm_loadu_ps(u + k), vv = _mm_loadu_ps(v + k);
    // std::clamp(u·W − 0.5, −1e6, 1e6): max then min, as the scalar code's comparisons.
    const __m128 fx = _mm_min_ps(_mm_max_ps(_mm_sub_ps(_mm_mul_ps(uu, tw), half), lo), hi);
    const __m128 fy = _mm_min_ps(_mm_max_ps(_mm_sub_ps(_mm_mul_ps(vv, th), half), lo), hi);
    __m128i x0 = _mm_cvttps_epi32(fx), y0 = _mm_cvttps_epi32(fy);
    // floor: truncation, minus one where that rounded up (the comparison's mask is −1).
    x0 = _mm_add_epi32(x0, _mm_castps_si128(_mm_cmplt_ps(fx, _mm_cvtepi32_ps(x0))));
    y0 = _mm_add_epi32(y0, _mm_castps_si128(_mm_cmplt_ps(fy, _mm_cvtepi32_ps(y0))));
    const __m128 tx = _mm_sub_ps(fx, _mm_cvtepi32_ps(x0));
    const __m128 ty = _mm_sub_ps(fy, _mm_cvtepi32_ps(y0));
    alignas(16) int xa[4], xb[4], ya[4], yb[4];
    _mm_store_si128(reinterpret_cast<__m128i*>(xa), AddressSse2(x0, wm1, wrap_u));
    _mm_store_si128(reinterpret_cast<__m128i*>(xb),
                    AddressSse2(_mm_add_epi32(x0, one), wm1, wrap_u));
    _mm_store_si128(reinterpret_cast<__m128i*>(ya), AddressSse2(y0, hm1, wrap_v));
    _mm_store_si128(reinterpret_cast<__m128i*>(yb),
                    AddressSse2(_mm_add_epi32(y0, one), hm1, wrap_v));
    alignas(16) float aa[4], ab[4], ba[4], bb[4];
    for (int l = 0; l < 4; ++l) {
      const float* row_a = texels + ya[l] * width;
      const float* row_b = texels + yb[l] * width;
      aa[l] = row_a[xa[l]];
      ab[l] = row_a[xb[l]];
      ba[l] = row_b[xa[l]];
      bb[l] = row_b[xb[l]];
    }
    const __m128 a0 = _mm_load_ps(aa), a1 = _mm_load_ps(ab);
    const __m128 b0 = _mm_load_ps(ba), b1 = _mm_load_ps(bb);
    const __m128 top = _mm_add_ps(a0, _mm_mul_ps(tx, _mm_sub_ps(a1, a0)));
    const __m128 bottom = _mm_add_ps(b0, _mm_mul_ps(tx, _mm_sub_ps(b1, b0)));
    const __m128 value = _mm_add_ps(top, _mm_mul_ps(ty, _mm_sub_ps(bottom, top)));
    _mm_storeu_ps(h + k, _mm_and_ps(value, FiniteMaskSse2(uu, vv)));
  }
  return k;
}

// AVX2 without FMA: the compiler may not fuse the multiplies and adds, so the bits are those of
// the scalar code.
[[gnu::target("avx2")]] inline __m256i AddressAvx2(__m256i i, __m256i size_minus_1,
                                                   bool wrap) noexcept {
  if (wrap) return _mm256_and_si256(i, size_minus_1);
  return _mm256_min_epi32(_mm256_max_epi32(i, _mm256_setzero_si256()), size_minus_1);
}

[[gnu::target("avx2")]] std::size_t SampleAvx2(const HeightFieldLevel& L, bool wrap_u, bool wrap_v,
                                               const float* u, const float* v, float* h,
                                               std::size_t n) noexcept {
  const __m256 tw = _mm256_set1_ps(static_cast<float>(L.width));
  const __m256 th = _mm256_set1_ps(static_cast<float>(L.height));
  const __m256 half = _mm256_set1_ps(0.5f), lo = _mm256_set1_ps(-1e6f), hi = _mm256_set1_ps(1e6f);
  const __m256i wm1 = _mm256_set1_epi32(L.width - 1), hm1 = _mm256_set1_epi32(L.height - 1);
  const __m256i one = _mm256_set1_epi32(1), width = _mm256_set1_epi32(L.width);
  const __m256 abs_mask = _mm256_castsi256_ps(_mm256_set1_epi32(0x7fffffff));
  const __m256 big = _mm256_set1_ps(std::numeric_limits<float>::max());
  const float* texels = L.texels.data();
  std::size_t k = 0;
  for (; k + 8 <= n; k += 8) {
    const __m256 uu = _mm256_loadu_ps(u + k), vv = _mm256_loadu_ps(v + k);
    const __m256 fx =
        _mm256_min_ps(_mm256_max_ps(_mm256_sub_ps(_mm256_mul_ps(uu, tw), half), lo), hi);
    const __m256 fy =
        _mm256_min_ps(_mm256_max_ps(_mm256_sub_ps(_mm256_mul_ps(vv, th), half), lo), hi);
    __m256i x0 = _mm256_cvttps_epi32(fx), y0 = _mm256_cvttps_epi32(fy);
    x0 = _mm256_add_epi32(
        x0, _mm256_castps_si256(_mm256_cmp_ps(fx, _mm256_cvtepi32_ps(x0), _CMP_LT_OQ)));
    y0 = _mm256_add_epi32(
        y0, _mm256_castps_si256(_mm256_cmp_ps(fy, _mm256_cvtepi32_ps(y0), _CMP_LT_OQ)));
    const __m256 tx = _mm256_sub_ps(fx, _mm256_cvtepi32_ps(x0));
    const __m256 ty = _mm256_sub_ps(fy, _mm256_cvtepi32_ps(y0));
    const __m256i xa = AddressAvx2(x0, wm1, wrap_u);
    const __m256i xb = AddressAvx2(_mm256_add_epi32(x0, one), wm1, wrap_u);
    const __m256i ya = _mm256_mullo_epi32(AddressAvx2(y0, hm1, wrap_v), width);
    const __m256i yb =
        _mm256_mullo_epi32(AddressAvx2(_mm256_add_epi32(y0, one), hm1, wrap_v), width);
    const __m256 a0 = _mm256_i32gather_ps(texels, _mm256_add_epi32(ya, xa), 4);
    const __m256 a1 = _mm256_i32gather_ps(texels, _mm256_add_epi32(ya, xb), 4);
    const __m256 b0 = _mm256_i32gather_ps(texels, _mm256_add_epi32(yb, xa), 4);
    const __m256 b1 = _mm256_i32gather_ps(texels, _mm256_add_epi32(yb, xb), 4);
    const __m256 top = _mm256_add_ps(a0, _mm256_mul_ps(tx, _mm256_sub_ps(a1, a0)));
    const __m256 bottom = _mm256_add_ps(b0, _mm256_mul_ps(tx, _mm256_sub_ps(b1, b0)));
    const __m256 value = _mm256_add_ps(top, _mm256_mul_ps(ty, _mm256_sub_ps(bottom, top)));
    const __m256 finite =
        _mm256_and_ps(_mm256_cmp_ps(_mm256_and_ps(uu, abs_mask), big, _CMP_LE_OQ),
                      _mm256_cmp_ps(_mm256_and_ps(vv, abs_mask), big, _CMP_LE_OQ));
    _mm256_storeu_ps(h + k, _mm256_and_ps(value, finite));
  }
  return k;
}

// AVX-512, sixteen samples a step: SampleAvx2's operations, lane for lane (x86_simd.h: the
// multiplies and adds are not fused, so the bits are the scalar code's).

[[HT_AVX512_TARGET]] inline __m512i AddressAvx512(__m512i i, __m512i size_minus_1,
                                                  bool wrap) noexcept {
  if (wrap) return _mm512_and_si512(i, size_minus_1);
  return _mm512_min_epi32(_mm512_max_epi32(i, _mm512_setzero_si512()), size_minus_1);
}

// Texels index[l] and index[l] + 1 of each lane l in `pair` as `left` and `right` (one 64-bit
// load per lane, eight lanes a gather); lanes outside `pair` are 0 (no load: index + 1 may lie
// past the level there).
[[HT_AVX512_TARGET]] inline void PairGatherAvx512(const float* texels, __m512i index,
                                                  __mmask16 pair, __m512& left,
                                                  __m512& right) noexcept {
  const __m512i zero = _mm512_setzero_si512();
  const __m512i lo = _mm512_mask_i32gather_epi64(zero, static_cast<__mmask8>(pair),
                                                 _mm512_castsi512_si256(index), texels, 4);
  const __m512i hi = _mm512_mask_i32gather_epi64(zero, static_cast<__mmask8>(pair >> 8),
                                                 _mm512_extracti64x4_epi64(index, 1), texels, 4);
  const __m512i l = _mm512_inserti64x4(_mm512_castsi256_si512(_mm512_cvtepi64_epi32(lo)),
                                       _mm512_cvtepi64_epi32(hi), 1);
  const __m512i r =
      _mm512_inserti64x4(_mm512_castsi256_si512(_mm512_cvtepi64_epi32(_mm512_srli_epi64(lo, 32))),
                         _mm512_cvtepi64_epi32(_mm512_srli_epi64(hi, 32)), 1);
  left = _mm512_castsi512_ps(l);
  right = _mm512_castsi512_ps(r);
}

[[HT_AVX512_TARGET]] std::size_t SampleAvx512(const HeightFieldLevel& L, bool wrap_u, bool wrap_v,
                                              const float* u, const float* v, float* h,
                                              std::size_t n) noexcept {
  const __m512 tw = _mm512_set1_ps(static_cast<float>(L.width));
  const __m512 th = _mm512_set1_ps(static_cast<float>(L.height));
  const __m512 half = _mm512_set1_ps(0.5f), lo = _mm512_set1_ps(-1e6f), hi = _mm512_set1_ps(1e6f);
  const __m512i wm1 = _mm512_set1_epi32(L.width - 1), hm1 = _mm512_set1_epi32(L.height - 1);
  const __m512i one = _mm512_set1_epi32(1), width = _mm512_set1_epi32(L.width);
  const __m512 big = _mm512_set1_ps(std::numeric_limits<float>::max());
  const float* texels = L.texels.data();
  std::size_t k = 0;
  for (; k + 16 <= n; k += 16) {
    const __m512 uu = _mm512_loadu_ps(u + k), vv = _mm512_loadu_ps(v + k);
    const __m512 fx =
        _mm512_min_ps(_mm512_max_ps(_mm512_sub_ps(_mm512_mul_ps(uu, tw), half), lo), hi);
    const __m512 fy =
        _mm512_min_ps(_mm512_max_ps(_mm512_sub_ps(_mm512_mul_ps(vv, th), half), lo), hi);
    __m512i x0 = _mm512_cvttps_epi32(fx), y0 = _mm512_cvttps_epi32(fy);
    // floor: truncation, minus one where that rounded up.
    x0 = _mm512_mask_sub_epi32(x0, _mm512_cmp_ps_mask(fx, _mm512_cvtepi32_ps(x0), _CMP_LT_OQ), x0,
                               one);
    y0 = _mm512_mask_sub_epi32(y0, _mm512_cmp_ps_mask(fy, _mm512_cvtepi32_ps(y0), _CMP_LT_OQ), y0,
                               one);
    const __m512 tx = _mm512_sub_ps(fx, _mm512_cvtepi32_ps(x0));
    const __m512 ty = _mm512_sub_ps(fy, _mm512_cvtepi32_ps(y0));
    const __m512i xa = AddressAvx512(x0, wm1, wrap_u);
    const __m512i xb = AddressAvx512(_mm512_add_epi32(x0, one), wm1, wrap_u);
    const __m512i ya = _mm512_mullo_epi32(AddressAvx512(y0, hm1, wrap_v), width);
    const __m512i yb =
        _mm512_mullo_epi32(AddressAvx512(_mm512_add_epi32(y0, one), hm1, wrap_v), width);
    // Where xb = xa + 1 (every lane but those at a clamped or wrapped edge) the two taps of a row
    // are adjacent texels: one 64-bit gather brings both (half the loads), the low half the
    // left tap. The other lanes gather each tap alone. The same texels either way.
    const __mmask16 pair = _mm512_cmpeq_epi32_mask(xb, _mm512_add_epi32(xa, one));
    __m512 a0, a1, b0, b1;
    PairGatherAvx512(texels, _mm512_add_epi32(ya, xa), pair, a0, a1);
    PairGatherAvx512(texels, _mm512_add_epi32(yb, xa), pair, b0, b1);
    if (pair != 0xFFFF) {
      const __mmask16 alone = static_cast<__mmask16>(~pair);
      a0 = _mm512_mask_i32gather_ps(a0, alone, _mm512_add_epi32(ya, xa), texels, 4);
      a1 = _mm512_mask_i32gather_ps(a1, alone, _mm512_add_epi32(ya, xb), texels, 4);
      b0 = _mm512_mask_i32gather_ps(b0, alone, _mm512_add_epi32(yb, xa), texels, 4);
      b1 = _mm512_mask_i32gather_ps(b1, alone, _mm512_add_epi32(yb, xb), texels, 4);
    }
    const __m512 top = _mm512_add_ps(a0, _mm512_mul_ps(tx, _mm512_sub_ps(a1, a0)));
    const __m512 bottom = _mm512_add_ps(b0, _mm512_mul_ps(tx, _mm512_sub_ps(b1, b0)));
    const __m512 value = _mm512_add_ps(top, _mm512_mul_ps(ty, _mm512_sub_ps(bottom, top)));
    // Non-finite u or v: +0, as HeightField::Sample (|x| <= FLT_MAX is false for ±inf and NaN).
    const __mmask16 finite = _mm512_cmp_ps_mask(_mm512_abs_ps(uu), big, _CMP_LE_OQ) &
                             _mm512_cmp_ps_mask(_mm512_abs_ps(vv), big, _CMP_LE_OQ);
    _mm512_storeu_ps(h + k, _mm512_maskz_mov_ps(finite, value));
  }
  return k;
}

#endif

}  // namespace

bool CpuHasAvx2() noexcept {
#ifdef HT_SAMPLE_X86
  static const bool have = __builtin_cpu_supports("avx2");
  return have;
#else
  return false;
#endif
}

void SampleLevelBatch(const HeightField& field, int level, std::span<const float> u,
                      std::span<const float> v, std::span<float> h, SampleKernel kernel) noexcept {
  const std::size_t n = u.size();
  if (v.size() != n || h.size() != n || level < 0 || level >= field.num_levels()) return;
  const HeightFieldLevel& L = field.level(level);
  std::size_t done = 0;
#ifdef HT_SAMPLE_X86
  const bool wrap_u = field.wrap_u(), wrap_v = field.wrap_v();
  // The texel index y·width + x must fit 32-bit lanes; periodic sizes must be powers of two.
  const bool simd = kernel != SampleKernel::kScalar &&
                    static_cast<long long>(L.width) * L.height <= (1LL << 31) - 1 &&
                    (!wrap_u || IsPowerOfTwo(L.width)) && (!wrap_v || IsPowerOfTwo(L.height));
  if (simd) {
    if (kernel == SampleKernel::kBest && CpuHasAvx512()) {
      done = SampleAvx512(L, wrap_u, wrap_v, u.data(), v.data(), h.data(), n);
    }
    done += CpuHasAvx2() ? SampleAvx2(L, wrap_u, wrap_v, u.data() + done, v.data() + done,
                                      h.data() + done, n - done)
                         : SampleSse2(L, wrap_u, wrap_v, u.data() + done, v.data() + done,
                                      h.data() + done, n - done);
  }
#else
  (void)kernel;
#endif
  SampleScalar(field, level, L, u.data() + done, v.data() + done, h.data() + done, n - done);
}

bool CpuHasAvx512() noexcept {
#ifdef HT_SAMPLE_X86
  static const bool have = __builtin_cpu_supports("avx512f") &&
                           __builtin_cpu_supports("avx512vl") &&
                           __builtin_cpu_supports("avx512dq") && __builtin_cpu_supports("avx512cd");
  return have;
#else
  return false;
#endif
}

const char* SampleKernelName(SampleKernel kernel) noexcept {
#ifdef HT_SAMPLE_X86
  if (kernel == SampleKernel::kBest && CpuHasAvx512()) return "avx512";
  if (kernel != SampleKernel::kScalar) return CpuHasAvx2() ? "avx2" : "sse2";
#else
  (void)kernel;
#endif
  return "scalar";
}

}  // namespace ht
