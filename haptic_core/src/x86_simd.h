#pragma once
// The x86 SIMD set-up the texture stage's two kernel files share (height_field_batch.cc,
// remote_step/5_raster_kernels*.h): the intrinsics where GCC or Clang targets x86-64 (HT_X86_SIMD),
// and the function attribute of their AVX-512 kernels. Both files are built with -ffp-contract=off
// (haptic_core/CMakeLists.txt): AVX-512 F has FMA instructions, and no multiply-add may be fused,
// so that every kernel writes the scalar code's bits. Which kernel runs is asked at run time
// (CpuHasAvx2, CpuHasAvx512 in height_field_batch.h).

// -DHT_NO_X86_SIMD leaves them out on x86-64 too: the scalar and SSE2 code alone, as a target
// without AVX (an arm64 build) compiles it.
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__)) && !defined(HT_NO_X86_SIMD)
// GCC 12 reports its own AVX-512 intrinsics (the _mm*_undefined_* operands of conversions and
// masked gathers) as (maybe) uninitialized where they are inlined.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#pragma GCC diagnostic ignored "-Wuninitialized"
#endif
#include <immintrin.h>
#define HT_X86_SIMD 1
#define HT_AVX512_TARGET gnu::target("avx512f,avx512vl,avx512dq,avx512cd")
#endif
