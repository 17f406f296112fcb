#pragma once
// Many bilinear samples of one mip level at once: the texture stage's fast path
// gathers a triangle's covered cells and samples them together, with SIMD where the CPU has it.

#include <span>

#include "haptic_core/height_field.h"

namespace ht {

/// Which code samples a batch. Every kernel writes the same bits: the arithmetic is
/// HeightField::Sample's, in the same order, and no multiply-add is fused.
enum class SampleKernel {
  kBest,    ///< AVX-512 (16 samples a step, texel taps as gathers) where the CPU has AVX-512 F,
            ///< VL, DQ and CD, else AVX2 (8 a step), else SSE2 (4 a step) on x86-64, else kScalar
  kAvx2,    ///< as kBest without AVX-512: AVX2 where the CPU has it (what kBest runs on CPUs
            ///< without AVX-512; the tests compare both against kScalar)
  kScalar,  ///< HeightField::SampleAt one sample at a time
};

/// h[k] = field.Sample(level, u[k], v[k]) for k < u.size(), bit for bit (0 where u or v is not
/// finite). `level` must be in [0, num_levels()); u, v and h must have the same size (else
/// nothing is written). Texture coordinates as HeightField: texel centres at (x+0.5)/width.
/// Periodic levels whose size is not a power of two are sampled one at a time whatever the
/// kernel. Never allocates.
void SampleLevelBatch(const HeightField& field, int level, std::span<const float> u,
                      std::span<const float> v, std::span<float> h,
                      SampleKernel kernel = SampleKernel::kBest) noexcept;

/// Whether this CPU runs AVX2 (asked once; false off x86-64 or without GCC/Clang): what kAvx2
/// picks here, and the texture stage's raster rows (RenderPatchHeightsFast) too.
bool CpuHasAvx2() noexcept;

/// Whether this CPU runs AVX-512 F, VL, DQ and CD (asked once; false off x86-64 or without
/// GCC/Clang): what kBest picks here, for the samples and the texture stage's raster rows.
bool CpuHasAvx512() noexcept;

/// What `kernel` runs on this CPU: "avx512", "avx2", "sse2" or "scalar" (for benchmark
/// reports).
const char* SampleKernelName(SampleKernel kernel = SampleKernel::kBest) noexcept;

}  // namespace ht
