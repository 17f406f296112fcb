// The contact model's depth field (depth_field.h): its preparation, its evaluation at a tool
// pose, and the operator's cache of fields.

#include "haptic_core/depth_field.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <glm/geometric.hpp>
#include <glm/gtc/quaternion.hpp>
#include <stdexcept>

#include "x86_simd.h"
#ifdef HT_X86_SIMD
#define HT_DEPTH_FIELD_AVX2 1
#endif

namespace ht {
namespace {

/// Catmull–Rom weights w[0..3] of nodes −1, 0, 1, 2 at t ∈ [0, 1), and their derivatives d/dt.
inline void CatmullRom(double t, double w[4], double d[4]) noexcept {
  const double t2 = t * t, t3 = t2 * t;
  w[0] = 0.5 * (-t3 + 2.0 * t2 - t);
  w[1] = 0.5 * (3.0 * t3 - 5.0 * t2 + 2.0);
  w[2] = 0.5 * (-3.0 * t3 + 4.0 * t2 + t);
  w[3] = 0.5 * (t3 - t2);
  d[0] = 0.5 * (-3.0 * t2 + 4.0 * t - 1.0);
  d[1] = 0.5 * (9.0 * t2 - 10.0 * t);
  d[2] = 0.5 * (-9.0 * t2 + 8.0 * t + 1.0);
  d[3] = 0.5 * (3.0 * t2 - 2.0 * t);
}

/// One row of cells' column pass of DepthField::Prepare's bound: the Bézier coefficients along
/// v of one row-coefficient map (rows j−1, j, j+1, j+2), into the cells' largest and sum.
void AccumulateBezierColumn(const float* __restrict rm1, const float* __restrict rc0,
                            const float* __restrict rp1, const float* __restrict rp2, int nx,
                            float* __restrict hi_row, float* __restrict sum_row) noexcept {
  const float sixth = 1.0f / 6.0f;
  for (int i = 1; i < nx - 2; ++i) {
    const float q0 = rc0[i];
    const float q1 = rc0[i] + sixth * (rp1[i] - rm1[i]);
    const float q2 = rp1[i] - sixth * (rp2[i] - rc0[i]);
    const float q3 = rp1[i];
    const float m01 = q0 > q1 ? q0 : q1, m23 = q2 > q3 ? q2 : q3;
    const float m = m01 > m23 ? m01 : m23;
    hi_row[i] = hi_row[i] > m ? hi_row[i] : m;
    sum_row[i] += (q0 + q1) + (q2 + q3);
  }
}

/// Depths more than this many ε below the running maximum weigh less than e^−10 ≈ 4.5e−5 of the
/// deepest node: skipped. M nodes skipped lower δ by at most ε·ln(1 + M·e^−10) and take at most
/// M·e^−10 / (M·e^−10 + 1) of the weights from ∇δ. On the gear's crests (seed Fig. 75) a cutoff of
/// 20 ε computed ~4,400 nodes at the slowest evaluations, this one ~3,300.
constexpr double kCutoffWidths = 10.0;
/// Nodes lighter than this (relative to the deepest) add nothing to the curvature's sums: the
/// curvature only conditions the implicit step.
constexpr double kCurvatureWeight = 1e-6;

/// ⌊x⌋ for a grid coordinate, clamped to ±2²⁰ (far outside any grid; NaN gives −2²⁰): a cast
/// and a compare instead of std::floor, a library call on x86-64's baseline (no SSE4.1).
inline int CellFloor(double x) noexcept {
  constexpr double kReach = 1 << 20;
  const double c = x > kReach ? kReach : x > -kReach ? x : -kReach;
  const int i = static_cast<int>(c);
  return i - (c < static_cast<double>(i) ? 1 : 0);
}

using Vec6 = Eigen::Matrix<double, 6, 1>;
using Mat6 = Eigen::Matrix<double, 6, 6>;

}  // namespace

constexpr int kMaxBlocksPerSide = (kMaxDepthFieldSide + kDepthFieldBlock - 1) / kDepthFieldBlock;
constexpr int kMaxSubBlocksPerSide =
    (kMaxDepthFieldSide + kDepthFieldSubBlock - 1) / kDepthFieldSubBlock;
constexpr int kMaxSuperBlocksPerSide =
    (kMaxDepthFieldSide + kDepthFieldSuperBlock - 1) / kDepthFieldSuperBlock;
static_assert(kDepthFieldBlock % kDepthFieldSubBlock == 0);
static_assert(kDepthFieldSuperBlock % kDepthFieldBlock == 0);

namespace {

/// Per block of `side`² cells of the environment's nx × ny grid (row-major blocks): the largest
/// env bound (−∞ where none).
void EnvBlockBounds(const DepthField& f, int side, std::vector<float>& env) {
  const int bx = (f.nx + side - 1) / side, by = (f.ny + side - 1) / side;
  env.assign(static_cast<std::size_t>(bx) * by, -std::numeric_limits<float>::infinity());
  for (int j = 0; j < f.ny; ++j) {
    const std::size_t row = static_cast<std::size_t>(j) * f.nx;
    const std::size_t brow = static_cast<std::size_t>(j / side) * bx;
    for (int ti = 0; ti < bx; ++ti) {
      const int i0 = ti * side, i1 = std::min(f.nx, i0 + side);
      float eb = env[brow + ti];
      for (int i = i0; i < i1; ++i) eb = std::max(eb, f.env_bound_m[row + i]);
      env[brow + ti] = eb;
    }
  }
}

/// Per block of `side`² nodes of the tool's kept grid (DepthField::tool_grid_m, row-major
/// blocks): the heights' smallest and largest (+∞ and −∞ where none).
void ToolBlockBounds(const DepthField& f, int side, std::vector<float>& lo,
                     std::vector<float>& hi) {
  const int nx = f.tool_nx, ny = f.tool_ny;
  const int bx = (nx + side - 1) / side, by = (ny + side - 1) / side;
  const float inf = std::numeric_limits<float>::infinity();
  lo.assign(static_cast<std::size_t>(bx) * by, inf);
  hi.assign(static_cast<std::size_t>(bx) * by, -inf);
  for (int j = 0; j < ny; ++j) {
    const std::size_t row = static_cast<std::size_t>(j) * nx;
    const std::size_t brow = static_cast<std::size_t>(j / side) * bx;
    for (int ti = 0; ti < bx; ++ti) {
      const int i0 = ti * side, i1 = std::min(nx, i0 + side);
      float l = lo[brow + ti], h = hi[brow + ti];
      for (int i = i0; i < i1; ++i) {
        const float a = f.tool_grid_m[row + i];
        if (a == a) {  // not NaN
          l = std::min(l, a);
          h = std::max(h, a);
        }
      }
      lo[brow + ti] = l;
      hi[brow + ti] = h;
    }
  }
}

}  // namespace

void DepthField::Reserve() {
  const std::size_t n = static_cast<std::size_t>(kMaxDepthFieldSide) * kMaxDepthFieldSide;
  env_height_m.reserve(n);
  tool_height_m.reserve(n);
  tool_grid_m.reserve(n);
  env_bound_m.reserve(n);
  const std::size_t blocks = static_cast<std::size_t>(kMaxBlocksPerSide) * kMaxBlocksPerSide;
  env_block_bound_m.reserve(blocks);
  tool_block_min_m.reserve(blocks);
  tool_block_max_m.reserve(blocks);
  const std::size_t subs = static_cast<std::size_t>(kMaxSubBlocksPerSide) * kMaxSubBlocksPerSide;
  env_sub_bound_m.reserve(subs);
  tool_sub_min_m.reserve(subs);
  tool_sub_max_m.reserve(subs);
  const std::size_t supers =
      static_cast<std::size_t>(kMaxSuperBlocksPerSide) * kMaxSuperBlocksPerSide;
  env_super_bound_m.reserve(supers);
  tool_super_min_m.reserve(supers);
  tool_super_max_m.reserve(supers);
}

bool DepthField::Prepare() {
  prepared = false;
  const std::size_t n = static_cast<std::size_t>(nx) * static_cast<std::size_t>(ny);
  if (id == 0 || !IsFiniteRigidTransform(X_WF) || !IsFiniteRigidTransform(X_WT0) ||
      !(cell_m > 0.0) || !std::isfinite(cell_m) || nx < 4 || ny < 4 || nx > kMaxDepthFieldSide ||
      ny > kMaxDepthFieldSide || env_height_m.size() != n || tool_height_m.size() != n ||
      !(travel_margin_m >= 0.0) || !std::isfinite(travel_margin_m) || !(smooth_max_m > 0.0) ||
      !std::isfinite(smooth_max_m) || !(std::abs(tool_offset_u_m) <= cell_m) ||
      !(std::abs(tool_offset_v_m) <= cell_m) ||
      (force_law != ForceLaw::kSeed && force_law != ForceLaw::kPressure) ||
      (force_law == ForceLaw::kPressure &&
       !(pressure_area_m2 >= kMinPressureAreaM2 && pressure_area_m2 <= kMaxPressureAreaM2)) ||
      (stride_hint & (stride_hint - 1)) != 0 || stride_hint > kMaxDepthFieldNodeStride) {
    return false;
  }
  env_bound_m.assign(n, -std::numeric_limits<float>::infinity());
  // The Catmull–Rom segment between nodes 1 and 2 of four is the cubic Bézier with control
  // points P1, P1 + (P2 − P0)/6, P2 − (P3 − P1)/6, P2; over a cell the bicubic is the tensor
  // Bézier patch whose 16 coefficients are those of the rows' Bézier coefficients taken along
  // the columns, and it lies within their convex hull: their largest bounds it. Rows first
  // (four coefficient maps), then columns, each a loop over i that the compiler vectorizes; a
  // missing node makes its cells' sums NaN, and those cells get no bound.
  row_coefficients_m.resize(4 * n);
  float* R0 = row_coefficients_m.data();
  float* R1 = R0 + n;
  float* R2 = R1 + n;
  float* R3 = R2 + n;
  const float sixth = 1.0f / 6.0f;
  for (int j = 0; j < ny; ++j) {
    const float* y = env_height_m.data() + static_cast<std::size_t>(j) * nx;
    const std::size_t row = static_cast<std::size_t>(j) * nx;
    for (int i = 1; i + 2 < nx; ++i) {
      R0[row + i] = y[i];
      R1[row + i] = y[i] + sixth * (y[i + 1] - y[i - 1]);
      R2[row + i] = y[i + 1] - sixth * (y[i + 2] - y[i]);
      R3[row + i] = y[i + 1];
    }
  }
  float hi_row[kMaxDepthFieldSide], sum_row[kMaxDepthFieldSide];
  for (int j = 1; j + 2 < ny; ++j) {
    const std::size_t m1 = static_cast<std::size_t>(j - 1) * nx, c0 = m1 + nx, p1 = c0 + nx,
                      p2 = p1 + nx;
    for (int i = 0; i < nx; ++i) {
      hi_row[i] = -std::numeric_limits<float>::infinity();
      sum_row[i] = 0.0f;
    }
    for (const float* R : {R0, R1, R2, R3}) {
      AccumulateBezierColumn(R + m1, R + c0, R + p1, R + p2, nx, hi_row, sum_row);
    }
    float* out_row = env_bound_m.data() + c0;
    for (int i = 1; i + 2 < nx; ++i) {
      // Rounded up (float arithmetic, and the interpolant's own rounding) so that it holds.
      const float hi = hi_row[i];
      out_row[i] = std::isnan(sum_row[i]) ? -std::numeric_limits<float>::infinity()
                                          : hi + 1e-6f * std::abs(hi) + 1e-9f;
    }
  }
  EnvBlockBounds(*this, kDepthFieldBlock, env_block_bound_m);
  EnvBlockBounds(*this, kDepthFieldSubBlock, env_sub_bound_m);
  EnvBlockBounds(*this, kDepthFieldSuperBlock, env_super_bound_m);
  // Every tool node, then, for a dense field (kDepthFieldDenseNodes, kDepthFieldDenseTestedNodes;
  // kDepthFieldDensePressureNodes under the pressure law), every 2nd, 4th, … node of the tool's
  // lattice along each axis, until the evaluation at X_WT0 fits.
  const bool pressure = force_law == ForceLaw::kPressure;
  const int dense = pressure ? kDepthFieldDensePressureNodes : kDepthFieldDenseNodes;
  const auto fits = [&](int* computed, int* overlapping) {
    const DepthFieldEvaluation at_q0 =
        DepthFieldDepthAt(*this, X_WT0, DepthFieldKernel::kAvx2, dense + 1);
    if (computed != nullptr) *computed = at_q0.nodes_evaluated;
    if (overlapping != nullptr) *overlapping = at_q0.overlapping_nodes;
    return !at_q0.over_budget && at_q0.nodes_tested <= kDepthFieldDenseTestedNodes;
  };
  prepared = true;
  // The pressure law's hinted stride, kept while it computes more than dense/8 and at most
  // dense nodes, or while nothing overlaps (no count to go by); one step finer below that band
  // (four times the nodes, still within it).
  if (pressure && stride_hint > 0) {
    KeepToolNodes(stride_hint);
    int computed = 0, overlapping = 0;
    if (fits(&computed, &overlapping)) {
      if (node_stride == 1 || overlapping == 0 || 8 * computed > dense) return true;
      KeepToolNodes(node_stride / 2);
      if (fits(nullptr, nullptr)) return true;
      KeepToolNodes(2 * node_stride);
      return true;
    }
  } else {
    KeepToolNodes(1);
    if (fits(nullptr, nullptr)) return true;
  }
  while (node_stride < kMaxDepthFieldNodeStride) {
    KeepToolNodes(2 * node_stride);
    if (fits(nullptr, nullptr)) break;
  }
  return true;
}

void DepthField::KeepToolNodes(int stride) {
  node_stride = stride;
  // The first kept node along each axis: lattice coordinate a multiple of the stride (64-bit:
  // the coordinates come off the wire, and −INT32_MIN overflows).
  const auto first_kept = [stride](std::int32_t lattice0) {
    const std::int64_t s = stride, r = ((static_cast<std::int64_t>(lattice0) % s) + s) % s;
    return static_cast<int>((s - r) % s);
  };
  tool_i0 = first_kept(tool_lattice_i0);
  tool_j0 = first_kept(tool_lattice_j0);
  tool_nx = std::max(0, (nx - tool_i0 + stride - 1) / stride);
  tool_ny = std::max(0, (ny - tool_j0 + stride - 1) / stride);
  tool_grid_m.resize(static_cast<std::size_t>(tool_nx) * tool_ny);
  for (int q = 0; q < tool_ny; ++q) {
    const float* row = tool_height_m.data() + static_cast<std::size_t>(tool_j0 + q * stride) * nx;
    float* out = tool_grid_m.data() + static_cast<std::size_t>(q) * tool_nx;
    for (int p = 0; p < tool_nx; ++p) out[p] = row[tool_i0 + p * stride];
  }
  ToolBlockBounds(*this, kDepthFieldBlock, tool_block_min_m, tool_block_max_m);
  ToolBlockBounds(*this, kDepthFieldSubBlock, tool_sub_min_m, tool_sub_max_m);
  ToolBlockBounds(*this, kDepthFieldSuperBlock, tool_super_min_m, tool_super_max_m);
  // The tool's reach: the farthest corner of each block's box of nodes from the centre of mass
  // (an upper bound on the farthest node's distance).
  const int bx = (tool_nx + kDepthFieldBlock - 1) / kDepthFieldBlock;
  const int by = (tool_ny + kDepthFieldBlock - 1) / kDepthFieldBlock;
  const glm::dvec3 c_F = X_WF.Inverse() * X_WT0.translation;
  const double step = stride * cell_m;
  const double u0 = tool_i0 * cell_m + tool_offset_u_m, v0 = tool_j0 * cell_m + tool_offset_v_m;
  double r2 = 0.0;
  for (int tj = 0; tj < by; ++tj) {
    for (int ti = 0; ti < bx; ++ti) {
      const std::size_t b = static_cast<std::size_t>(tj) * bx + ti;
      if (!(tool_block_min_m[b] <= tool_block_max_m[b])) continue;
      const int i0 = ti * kDepthFieldBlock, i1 = std::min(tool_nx, i0 + kDepthFieldBlock) - 1;
      const int j0 = tj * kDepthFieldBlock, j1 = std::min(tool_ny, j0 + kDepthFieldBlock) - 1;
      const double x0 = u0 + i0 * step, x1 = u0 + i1 * step;
      const double y0 = v0 + j0 * step, y1 = v0 + j1 * step;
      const double dx = std::max(std::abs(x0 - c_F.x), std::abs(x1 - c_F.x));
      const double dy = std::max(std::abs(y0 - c_F.y), std::abs(y1 - c_F.y));
      const double dz =
          std::max(std::abs(tool_block_min_m[b] - c_F.z), std::abs(tool_block_max_m[b] - c_F.z));
      r2 = std::max(r2, dx * dx + dy * dy + dz * dz);
    }
  }
  tool_radius_m = std::sqrt(r2);
}

namespace {

/// Up to kBatch candidate nodes of one evaluation (their cell's bound passed), evaluated together.
constexpr int kBatch = 4;
struct NodeBatch {
  int n = 0;
  std::array<int, kBatch> cell{};
  std::array<double, kBatch> tu{}, tv{}, sx{}, sy{}, sz{}, bound{};
};

/// The evaluation's sums in four lanes (AVX2): S0, S1 (6) and S2's lower triangle (21), each
/// lane a share of the nodes, all relative to the running maximum m_ref.
struct LaneSums {
  alignas(32) std::array<double, 4 * 28> v{};
};

/// The pressure law's sums in four lanes (AVX2), each lane a share of the overlapping nodes:
/// Σ A d, Σ A d², Σ A d J (6), and the lower triangles of Σ A J Jᵀ and Σ A d J Jᵀ (21 each).
constexpr int kPressureSums = 1 + 1 + 6 + 21 + 21;
struct PressureLaneSums {
  alignas(32) std::array<double, 4 * kPressureSums> v{};
};

#ifdef HT_DEPTH_FIELD_AVX2
bool HasAvx2() noexcept {
  static const bool has = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
  return has;
}

/// Catmull–Rom weights (CatmullRom) in four double lanes.
__attribute__((target("avx2,fma"))) inline void CatmullRomAvx2(__m256d t, __m256d w[4],
                                                               __m256d dw[4]) noexcept {
  const __m256d half = _mm256_set1_pd(0.5);
  const __m256d t2 = _mm256_mul_pd(t, t), t3 = _mm256_mul_pd(t2, t);
  const __m256d two = _mm256_set1_pd(2.0), three = _mm256_set1_pd(3.0);
  const __m256d four = _mm256_set1_pd(4.0), five = _mm256_set1_pd(5.0);
  const __m256d eight = _mm256_set1_pd(8.0), nine = _mm256_set1_pd(9.0);
  const __m256d ten = _mm256_set1_pd(10.0), one = _mm256_set1_pd(1.0);
  // w0 = ½(−t³ + 2t² − t), w1 = ½(3t³ − 5t² + 2), w2 = ½(−3t³ + 4t² + t), w3 = ½(t³ − t²).
  w[0] = _mm256_mul_pd(half, _mm256_sub_pd(_mm256_fmsub_pd(two, t2, t3), t));
  w[1] =
      _mm256_mul_pd(half, _mm256_add_pd(_mm256_fnmadd_pd(five, t2, _mm256_mul_pd(three, t3)), two));
  w[2] =
      _mm256_mul_pd(half, _mm256_add_pd(_mm256_fnmadd_pd(three, t3, _mm256_mul_pd(four, t2)), t));
  w[3] = _mm256_mul_pd(half, _mm256_sub_pd(t3, t2));
  // d/dt: ½(−3t² + 4t − 1), ½(9t² − 10t), ½(−9t² + 8t + 1), ½(3t² − 2t).
  dw[0] =
      _mm256_mul_pd(half, _mm256_sub_pd(_mm256_fnmadd_pd(three, t2, _mm256_mul_pd(four, t)), one));
  dw[1] = _mm256_mul_pd(half, _mm256_fmsub_pd(nine, t2, _mm256_mul_pd(ten, t)));
  dw[2] =
      _mm256_mul_pd(half, _mm256_add_pd(_mm256_fnmadd_pd(nine, t2, _mm256_mul_pd(eight, t)), one));
  dw[3] = _mm256_mul_pd(half, _mm256_fmsub_pd(three, t2, _mm256_mul_pd(two, t)));
}

/// The batch's exact depths and gradients in four double lanes: the Catmull–Rom bicubic of the
/// environment under each node (as `exact` in DepthFieldDepthAt), its depth b − s.z and its
/// gradient J = (g, (s − c) × g), g = (∂b/∂x, ∂b/∂y, −1) in F. Lanes ≥ batch.n are copies of
/// lane 0 (the caller ignores them).
__attribute__((target("avx2,fma"))) void BatchDepthsAvx2(const NodeBatch& batch, const float* env,
                                                         int nx, double inv_h,
                                                         const glm::dvec3& c_F, double d[kBatch],
                                                         double J[6][kBatch]) noexcept {
  alignas(32) double tu[kBatch], tv[kBatch], sx[kBatch], sy[kBatch], sz[kBatch];
  alignas(16) int base[kBatch];
  for (int k = 0; k < kBatch; ++k) {
    const int l = k < batch.n ? k : 0;
    tu[k] = batch.tu[l];
    tv[k] = batch.tv[l];
    sx[k] = batch.sx[l];
    sy[k] = batch.sy[l];
    sz[k] = batch.sz[l];
    base[k] = batch.cell[l] - nx - 1;  // stencil node (−1, −1)
  }
  __m256d wu[4], du[4], wv[4], dv[4];
  CatmullRomAvx2(_mm256_load_pd(tu), wu, du);
  CatmullRomAvx2(_mm256_load_pd(tv), wv, dv);
  const __m128i b0 = _mm_load_si128(reinterpret_cast<const __m128i*>(base));
  __m256d b = _mm256_setzero_pd(), bu = _mm256_setzero_pd(), bv = _mm256_setzero_pd();
  for (int r = 0; r < 4; ++r) {
    const __m128i row = _mm_add_epi32(b0, _mm_set1_epi32(r * nx));
    __m256d x = _mm256_setzero_pd(), dx = _mm256_setzero_pd();
    for (int c = 0; c < 4; ++c) {
      const __m128i idx = _mm_add_epi32(row, _mm_set1_epi32(c));
      const __m256d v = _mm256_cvtps_pd(_mm_i32gather_ps(env, idx, 4));
      x = _mm256_fmadd_pd(wu[c], v, x);
      dx = _mm256_fmadd_pd(du[c], v, dx);
    }
    b = _mm256_fmadd_pd(wv[r], x, b);
    bu = _mm256_fmadd_pd(wv[r], dx, bu);
    bv = _mm256_fmadd_pd(dv[r], x, bv);
  }
  _mm256_storeu_pd(d, _mm256_sub_pd(b, _mm256_load_pd(sz)));
  const __m256d ih = _mm256_set1_pd(inv_h);
  const __m256d gx = _mm256_mul_pd(bu, ih), gy = _mm256_mul_pd(bv, ih);
  const __m256d rx = _mm256_sub_pd(_mm256_load_pd(sx), _mm256_set1_pd(c_F.x));
  const __m256d ry = _mm256_sub_pd(_mm256_load_pd(sy), _mm256_set1_pd(c_F.y));
  const __m256d rz = _mm256_sub_pd(_mm256_load_pd(sz), _mm256_set1_pd(c_F.z));
  // (r × g) with g = (gx, gy, −1).
  _mm256_storeu_pd(J[0], gx);
  _mm256_storeu_pd(J[1], gy);
  _mm256_storeu_pd(J[2], _mm256_set1_pd(-1.0));
  _mm256_storeu_pd(J[3], _mm256_fnmadd_pd(rz, gy, _mm256_sub_pd(_mm256_setzero_pd(), ry)));
  _mm256_storeu_pd(J[4], _mm256_fmadd_pd(rz, gx, rx));
  _mm256_storeu_pd(J[5], _mm256_fnmadd_pd(ry, gx, _mm256_mul_pd(rx, gy)));
}

/// Up to four tool nodes of one row (`count` ≤ 4, heights `a` from node i0 on), moved: s = first
/// + k·step_i + a_k·along_a for lane k. Which of them have a height (`tested` lanes), lie where the
/// environment has an interpolant, and whose cell's bound reaches `threshold` (bound − s.z ≥
/// threshold): their lanes' bits in the result, with their cell, cell fractions, s and the cell's
/// bound. As the scalar kernel's per-node test in DepthFieldDepthAt.
__attribute__((target("avx2,fma"))) int RowCandidatesAvx2(
    const float* a, int count, const glm::dvec3& first, const glm::dvec3& step_i,
    const glm::dvec3& along_a, double inv_h, int nx, int ny, const float* bound, double threshold,
    int& tested, int cell[4], double tu[4], double tv[4], double sx[4], double sy[4], double sz[4],
    double cell_bound[4]) noexcept {
  const __m128i lane = _mm_setr_epi32(0, 1, 2, 3);
  const __m128i in_row = _mm_cmpgt_epi32(_mm_set1_epi32(count), lane);
  const __m128 heights = _mm_maskload_ps(a, in_row);
  // A height: in the row and not NaN (a NaN compares unordered).
  const __m128 has = _mm_and_ps(_mm_castsi128_ps(in_row), _mm_cmp_ps(heights, heights, _CMP_ORD_Q));
  tested = __builtin_popcount(static_cast<unsigned>(_mm_movemask_ps(has)));
  const __m256d av = _mm256_cvtps_pd(heights);
  const __m256d k = _mm256_cvtepi32_pd(lane);
  const __m256d x =
      _mm256_fmadd_pd(av, _mm256_set1_pd(along_a.x),
                      _mm256_fmadd_pd(k, _mm256_set1_pd(step_i.x), _mm256_set1_pd(first.x)));
  const __m256d y =
      _mm256_fmadd_pd(av, _mm256_set1_pd(along_a.y),
                      _mm256_fmadd_pd(k, _mm256_set1_pd(step_i.y), _mm256_set1_pd(first.y)));
  const __m256d z =
      _mm256_fmadd_pd(av, _mm256_set1_pd(along_a.z),
                      _mm256_fmadd_pd(k, _mm256_set1_pd(step_i.z), _mm256_set1_pd(first.z)));
  const __m256d u = _mm256_mul_pd(x, _mm256_set1_pd(inv_h));
  const __m256d v = _mm256_mul_pd(y, _mm256_set1_pd(inv_h));
  const __m256d one = _mm256_set1_pd(1.0);
  // 1 ≤ u < nx − 2 and 1 ≤ v < ny − 2 (false for NaN).
  const __m256d inside =
      _mm256_and_pd(_mm256_and_pd(_mm256_cmp_pd(u, one, _CMP_GE_OQ),
                                  _mm256_cmp_pd(u, _mm256_set1_pd(nx - 2), _CMP_LT_OQ)),
                    _mm256_and_pd(_mm256_cmp_pd(v, one, _CMP_GE_OQ),
                                  _mm256_cmp_pd(v, _mm256_set1_pd(ny - 2), _CMP_LT_OQ)));
  // The lanes' masks as 32-bit lanes: a height and inside.
  const __m128 inside32 = _mm256_cvtpd_ps(_mm256_and_pd(inside, _mm256_set1_pd(1.0)));
  const __m128 ok = _mm_and_ps(has, _mm_cmp_ps(inside32, _mm_set1_ps(0.5f), _CMP_GT_OQ));
  // Where not ok, u and v may be anything: the cell computed there is never read (masked gather).
  const __m256d us = _mm256_blendv_pd(one, u, inside);
  const __m256d vs = _mm256_blendv_pd(one, v, inside);
  const __m128i iu = _mm256_cvttpd_epi32(us), iv = _mm256_cvttpd_epi32(vs);
  const __m128i c = _mm_add_epi32(_mm_mullo_epi32(iv, _mm_set1_epi32(nx)), iu);
  const __m128 b =
      _mm_mask_i32gather_ps(_mm_set1_ps(-std::numeric_limits<float>::infinity()), bound, c, ok, 4);
  // A finite bound (−∞ < b < +∞, false for a NaN) reaching the threshold (b − z ≥ threshold).
  const __m256d bd = _mm256_cvtps_pd(b);
  const __m256d inf = _mm256_set1_pd(std::numeric_limits<double>::infinity());
  const __m256d finite =
      _mm256_and_pd(_mm256_cmp_pd(bd, inf, _CMP_LT_OQ),
                    _mm256_cmp_pd(bd, _mm256_sub_pd(_mm256_setzero_pd(), inf), _CMP_GT_OQ));
  const __m256d pass = _mm256_and_pd(
      finite, _mm256_cmp_pd(_mm256_sub_pd(bd, z), _mm256_set1_pd(threshold), _CMP_GE_OQ));
  const int bits = _mm256_movemask_pd(pass) & _mm_movemask_ps(ok);
  if (bits == 0) return 0;  // most rows tested: nothing to hand back
  _mm_storeu_si128(reinterpret_cast<__m128i*>(cell), c);
  _mm256_storeu_pd(tu, _mm256_sub_pd(us, _mm256_cvtepi32_pd(iu)));
  _mm256_storeu_pd(tv, _mm256_sub_pd(vs, _mm256_cvtepi32_pd(iv)));
  _mm256_storeu_pd(sx, x);
  _mm256_storeu_pd(sy, y);
  _mm256_storeu_pd(sz, z);
  _mm256_storeu_pd(cell_bound, bd);
  return bits;
}

/// e^x in four double lanes for x ≤ 0 (0 below −700): Cody–Waite reduction by ln 2 and the
/// Taylor polynomial of degree 11 on |r| ≤ ln 2 / 2, relative error below 1e-14 (tested against
/// std::exp through the kernels' agreement).
__attribute__((target("avx2,fma"))) __m256d ExpAvx2(__m256d x) noexcept {
  const __m256d lo = _mm256_set1_pd(-700.0);
  const __m256d under = _mm256_cmp_pd(x, lo, _CMP_LT_OQ);
  x = _mm256_max_pd(x, lo);
  const __m256d n = _mm256_round_pd(_mm256_mul_pd(x, _mm256_set1_pd(1.4426950408889634)),
                                    _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC);
  __m256d r = _mm256_fnmadd_pd(n, _mm256_set1_pd(0.6931471803691238), x);
  r = _mm256_fnmadd_pd(n, _mm256_set1_pd(1.9082149292705877e-10), r);
  // Horner, 1/11! … 1.
  constexpr double kC[12] = {
      1.0 / 39916800.0, 1.0 / 3628800.0, 1.0 / 362880.0, 1.0 / 40320.0, 1.0 / 5040.0, 1.0 / 720.0,
      1.0 / 120.0,      1.0 / 24.0,      1.0 / 6.0,      0.5,           1.0,          1.0};
  __m256d p = _mm256_set1_pd(kC[0]);
  for (int k = 1; k < 12; ++k) p = _mm256_fmadd_pd(p, r, _mm256_set1_pd(kC[k]));
  // 2^n into the exponent (n ≥ −1010 here).
  const __m128i ni = _mm256_cvtpd_epi32(n);
  const __m256i bits =
      _mm256_slli_epi64(_mm256_add_epi64(_mm256_cvtepi32_epi64(ni), _mm256_set1_epi64x(1023)), 52);
  const __m256d scaled = _mm256_mul_pd(p, _mm256_castsi256_pd(bits));
  return _mm256_andnot_pd(under, scaled);
}

/// The batch's weights relative to m_final, exp((d − m_final)/ε), into w (lanes with use 0: 0).
__attribute__((target("avx2,fma"))) void BatchWeightsAvx2(const double d[kBatch],
                                                          const bool use[kBatch], double m_final,
                                                          double eps, double w[kBatch]) noexcept {
  alignas(32) double x[kBatch];
  for (int k = 0; k < kBatch; ++k) x[k] = use[k] ? (d[k] - m_final) / eps : -1000.0;
  _mm256_storeu_pd(w, ExpAvx2(_mm256_load_pd(x)));
}

/// Adds the batch's weighted gradients to the lane sums: S0 += w, S1 += w·J, and S2's lower
/// triangle += w2·J·Jᵀ (w2 = w where w ≥ kCurvatureWeight, else 0), lane by lane.
__attribute__((target("avx2,fma"))) void AccumulateAvx2(const double w[kBatch],
                                                        const double w2[kBatch],
                                                        const double J[6][kBatch],
                                                        LaneSums& sums) noexcept {
  double* v = sums.v.data();
  const __m256d W = _mm256_loadu_pd(w), W2 = _mm256_loadu_pd(w2);
  _mm256_store_pd(v, _mm256_add_pd(_mm256_load_pd(v), W));
  __m256d j[6], wj2[6];
  for (int a = 0; a < 6; ++a) {
    j[a] = _mm256_loadu_pd(J[a]);
    _mm256_store_pd(v + 4 * (1 + a), _mm256_fmadd_pd(W, j[a], _mm256_load_pd(v + 4 * (1 + a))));
    wj2[a] = _mm256_mul_pd(W2, j[a]);
  }
  int k = 7;
  for (int a = 0; a < 6; ++a) {
    for (int c = 0; c <= a; ++c, ++k) {
      _mm256_store_pd(v + 4 * k, _mm256_fmadd_pd(wj2[a], j[c], _mm256_load_pd(v + 4 * k)));
    }
  }
}

/// Adds the batch's overlapping nodes to the pressure law's lane sums (PressureLaneSums): w1 =
/// A·d and w0 = A on lanes that overlap, 0 on the others.
__attribute__((target("avx2,fma"))) void AccumulatePressureAvx2(const double w0[kBatch],
                                                                const double w1[kBatch],
                                                                const double d[kBatch],
                                                                const double J[6][kBatch],
                                                                PressureLaneSums& sums) noexcept {
  double* v = sums.v.data();
  const __m256d W0 = _mm256_loadu_pd(w0), W1 = _mm256_loadu_pd(w1);
  _mm256_store_pd(v, _mm256_add_pd(_mm256_load_pd(v), W1));
  _mm256_store_pd(v + 4, _mm256_fmadd_pd(W1, _mm256_loadu_pd(d), _mm256_load_pd(v + 4)));
  __m256d j[6], w0j[6], w1j[6];
  for (int a = 0; a < 6; ++a) {
    j[a] = _mm256_loadu_pd(J[a]);
    w0j[a] = _mm256_mul_pd(W0, j[a]);
    w1j[a] = _mm256_mul_pd(W1, j[a]);
    _mm256_store_pd(v + 4 * (2 + a), _mm256_add_pd(w1j[a], _mm256_load_pd(v + 4 * (2 + a))));
  }
  int k = 8;
  for (int a = 0; a < 6; ++a) {
    for (int c = 0; c <= a; ++c, ++k) {
      _mm256_store_pd(v + 4 * k, _mm256_fmadd_pd(w0j[a], j[c], _mm256_load_pd(v + 4 * k)));
      _mm256_store_pd(v + 4 * (k + 21),
                      _mm256_fmadd_pd(w1j[a], j[c], _mm256_load_pd(v + 4 * (k + 21))));
    }
  }
}
#endif

/// The pressure law's sums (PressureLaneSums' order), in F's axes.
struct PressureSums {
  double volume = 0.0, squared = 0.0;
  Vec6 first = Vec6::Zero();
  Mat6 second = Mat6::Zero(), weighted = Mat6::Zero();
};

/// DepthFieldDepthAt's traversal under one law: kPressure false, the seed's smooth maximum over
/// the nodes within the cutoff of the running maximum; true, the pressure law's sums over the
/// nodes that overlap (DepthFieldEvaluation).
template <bool kPressure>
DepthFieldEvaluation EvaluateField(const DepthField& f, const RigidTransform& X_WT, bool batched,
                                   int max_nodes) noexcept {
#ifndef HT_DEPTH_FIELD_AVX2
  batched = false;
#endif
  DepthFieldEvaluation out;
  if constexpr (kPressure) out.force_law = ForceLaw::kPressure;
  if (!f.prepared || !IsFiniteRigidTransform(X_WT)) return out;
  // The nodes' travel in F's plane (along n the field is exact): the centre of mass's in-plane
  // displacement plus the turn's reach.
  const Twist dq = PoseDifference(X_WT, f.X_WT0);
  const glm::dvec3 n_W = f.X_WF.rotation * glm::dvec3(0.0, 0.0, 1.0);
  const glm::dvec3 slide_W = dq.linear - glm::dot(dq.linear, n_W) * n_W;
  out.within_margin =
      glm::length(slide_W) + glm::length(dq.angular) * f.tool_radius_m <= f.travel_margin_m;
  out.valid = true;
  // The tool's motion since X_WT0 in F: s = D·p for a tool node p (F at X_WT0).
  const RigidTransform X_FW = f.X_WF.Inverse();
  const RigidTransform D = X_FW * X_WT * f.X_WT0.Inverse() * f.X_WF;
  const glm::dmat3 R = glm::mat3_cast(D.rotation);
  const glm::dvec3 c_F = X_FW * X_WT.translation;  // the centre of mass in F
  const double h = f.cell_m, inv_h = 1.0 / h, eps = f.smooth_max_m;
  const int nx = f.nx, ny = f.ny;              // the environment's grid
  const int tnx = f.tool_nx, tny = f.tool_ny;  // the tool's kept nodes
  const float* env = f.env_height_m.data();
  const float* tool = f.tool_grid_m.data();
  const float* bound = f.env_bound_m.data();
  const double tool_step = f.node_stride * h;
  const glm::dvec3 step_i = tool_step * R[0], step_j = tool_step * R[1], along_a = R[2];
  // Kept tool node (0, 0) at height 0, moved.
  const glm::dvec3 origin =
      D * glm::dvec3(f.tool_i0 * h + f.tool_offset_u_m, f.tool_j0 * h + f.tool_offset_v_m, 0.0);

  // The node's moved position and its cell's bound (−∞: no interpolant under it).
  const auto locate = [&](const glm::dvec3& s, int& cell, double& tu, double& tv) noexcept {
    const double u = s.x * inv_h, v = s.y * inv_h;
    if (!(u >= 1.0) || !(v >= 1.0) || !(u < nx - 2) || !(v < ny - 2)) return false;
    const int i0 = static_cast<int>(u), j0 = static_cast<int>(v);
    tu = u - i0;
    tv = v - j0;
    cell = j0 * nx + i0;
    return true;
  };
  // The exact depth of node (i, j): δ = b(s) − s.z and the node's gradient in F.
  const auto exact = [&](int i, int j, const glm::dvec3& s, int cell, double tu, double tv,
                         Vec6* J) noexcept {
    double wu[4], du[4], wv[4], dv[4];
    CatmullRom(tu, wu, du);
    CatmullRom(tv, wv, dv);
    const int i0 = cell % nx, j0 = cell / nx;
    double b = 0.0, bu = 0.0, bv = 0.0;
    for (int r = 0; r < 4; ++r) {
      const float* row = env + (j0 - 1 + r) * nx + (i0 - 1);
      const double x = wu[0] * row[0] + wu[1] * row[1] + wu[2] * row[2] + wu[3] * row[3];
      const double dx = du[0] * row[0] + du[1] * row[1] + du[2] * row[2] + du[3] * row[3];
      b += wv[r] * x;
      bu += wv[r] * dx;
      bv += dv[r] * x;
    }
    (void)i;
    (void)j;
    if (J != nullptr) {
      const glm::dvec3 g(bu * inv_h, bv * inv_h, -1.0);
      const glm::dvec3 lever = glm::cross(s - c_F, g);
      *J << g.x, g.y, g.z, lever.x, lever.y, lever.z;
    }
    return b - s.z;
  };
  // A bound on the depth of the tool nodes [i0, i1] × [j0, j1] whose heights lie in [a_lo,
  // a_hi]: the largest environment bound (per `side`² cells, `env_bounds`, gbx a row) under the
  // moved box's footprint, less the box's lowest point (−∞ when the footprint leaves the
  // environment's interpolant).
  // The moved box, from the nodes' affine map s = origin + i·step_i + j·step_j + a·along_a.
  const glm::dvec3 abs_step_i = glm::abs(step_i), abs_step_j = glm::abs(step_j);
  const glm::dvec3 abs_along_a = glm::abs(along_a);
  const auto box_bound = [&](int i0, int i1, int j0, int j1, float a_lo, float a_hi,
                             const float* env_bounds, int side, int gbx) noexcept {
    const glm::dvec3 s = origin + (0.5 * (i0 + i1)) * step_i + (0.5 * (j0 + j1)) * step_j +
                         (0.5 * (static_cast<double>(a_lo) + a_hi)) * along_a;
    const glm::dvec3 e = (0.5 * (i1 - i0)) * abs_step_i + (0.5 * (j1 - j0)) * abs_step_j +
                         (0.5 * (static_cast<double>(a_hi) - a_lo)) * abs_along_a;
    const int cu0 = std::max(1, CellFloor((s.x - e.x) * inv_h));
    const int cu1 = std::min(nx - 3, CellFloor((s.x + e.x) * inv_h));
    const int cv0 = std::max(1, CellFloor((s.y - e.y) * inv_h));
    const int cv1 = std::min(ny - 3, CellFloor((s.y + e.y) * inv_h));
    if (cu0 > cu1 || cv0 > cv1) return -std::numeric_limits<double>::infinity();
    float env_max = -std::numeric_limits<float>::infinity();
    for (int ej = cv0 / side; ej <= cv1 / side; ++ej) {
      for (int ei = cu0 / side; ei <= cu1 / side; ++ei) {
        env_max = std::max(env_max, env_bounds[ej * gbx + ei]);
      }
    }
    return static_cast<double>(env_max) - (s.z - e.z);
  };
  // Pass 1, per super-block of tool nodes: its bound; the blocks' bounds are taken only in the
  // super-blocks pass 2 visits.
  // The tool's blocks on its kept grid; the environment's bounds on its own (box_bound's gbx).
  const int bx = (tnx + kDepthFieldBlock - 1) / kDepthFieldBlock;
  const int by = (tny + kDepthFieldBlock - 1) / kDepthFieldBlock;
  const int sbx = (tnx + kDepthFieldSubBlock - 1) / kDepthFieldSubBlock;
  const int gx = (tnx + kDepthFieldSuperBlock - 1) / kDepthFieldSuperBlock;
  const int gy = (tny + kDepthFieldSuperBlock - 1) / kDepthFieldSuperBlock;
  const int env_bx = (nx + kDepthFieldBlock - 1) / kDepthFieldBlock;
  const int env_sbx = (nx + kDepthFieldSubBlock - 1) / kDepthFieldSubBlock;
  const int env_gx = (nx + kDepthFieldSuperBlock - 1) / kDepthFieldSuperBlock;
  constexpr int kBlocksPerSuper = kDepthFieldSuperBlock / kDepthFieldBlock;
  std::array<float, kMaxSuperBlocksPerSide * kMaxSuperBlocksPerSide> super_ub;
  std::array<int, kMaxSuperBlocksPerSide * kMaxSuperBlocksPerSide> super_order;
  int num_supers = 0;
  for (int tj = 0; tj < gy; ++tj) {
    for (int ti = 0; ti < gx; ++ti) {
      const int g = tj * gx + ti;
      const float a_lo = f.tool_super_min_m[static_cast<std::size_t>(g)];
      const float a_hi = f.tool_super_max_m[static_cast<std::size_t>(g)];
      if (!(a_lo <= a_hi)) continue;  // no tool node
      const int i0 = ti * kDepthFieldSuperBlock, i1 = std::min(tnx, i0 + kDepthFieldSuperBlock) - 1;
      const int j0 = tj * kDepthFieldSuperBlock, j1 = std::min(tny, j0 + kDepthFieldSuperBlock) - 1;
      const double ub = box_bound(i0, i1, j0, j1, a_lo, a_hi, f.env_super_bound_m.data(),
                                  kDepthFieldSuperBlock, env_gx);
      if (!(ub > -std::numeric_limits<double>::infinity())) continue;
      super_ub[static_cast<std::size_t>(g)] = static_cast<float>(ub);
      super_order[static_cast<std::size_t>(num_supers++)] = g;
    }
  }
  if (num_supers == 0) return out;  // no tool node over the environment: no overlap, valid
  // The deepest bound first (its best block sets the running maximum the others are pruned by).
  std::sort(super_order.begin(), super_order.begin() + num_supers, [&](int a, int b) noexcept {
    return super_ub[static_cast<std::size_t>(a)] > super_ub[static_cast<std::size_t>(b)];
  });
  std::array<float, kMaxBlocksPerSide * kMaxBlocksPerSide> block_ub;

  // Pass 2: the blocks whose bound reaches within the cutoff of the running maximum, the best
  // block first, their nodes by their cell's bound, summed as an online log-sum-exp (the sums
  // rescaled whenever the maximum rises).
  const double cutoff = kCutoffWidths * eps;
  double m_ref = -std::numeric_limits<double>::infinity();
  // The least depth a node must be able to reach to count: within the cutoff of the running
  // maximum (seed), or above 0 (pressure).
  const auto floor = [&]() noexcept { return kPressure ? 0.0 : m_ref - cutoff; };
  double S0 = 0.0;
  Vec6 S1 = Vec6::Zero();
  Mat6 S2 = Mat6::Zero();
  Vec6 J;
  // The pressure law's sums, each node standing for the tool area A.
  const double area = (f.node_stride * h) * (f.node_stride * h);
  PressureSums P;
  PressureLaneSums pressure_lanes;
  // Batched (AVX2): candidates gathered kBatch at a time, their sums kept per lane.
  NodeBatch batch;
  LaneSums lanes;
  const auto flush = [&]() noexcept {
#ifdef HT_DEPTH_FIELD_AVX2
    if (batch.n == 0) return;
    double d[kBatch], Jb[6][kBatch], w[kBatch], w2[kBatch];
    BatchDepthsAvx2(batch, env, nx, inv_h, c_F, d, Jb);
    // The weights as the scalar kernel takes them, in the nodes' order: each relative to the
    // running maximum when it is taken (whether it weighs in the curvature's sums), all relative
    // to the batch's last maximum in the end, the lanes' sums rescaled to it once.
    if constexpr (kPressure) {
      double w0[kBatch], w1[kBatch];
      for (int k = 0; k < kBatch; ++k) {
        const bool use = k < batch.n && std::isfinite(d[k]) && d[k] > 0.0;
        w0[k] = use ? area : 0.0;
        w1[k] = use ? area * d[k] : 0.0;
        if (k < batch.n && std::isfinite(d[k])) {
          ++out.nodes_evaluated;
          m_ref = std::max(m_ref, d[k]);
        }
        if (use) {
          ++out.overlapping_nodes;
        } else {
          d[k] = 0.0;  // a NaN must not reach the sums as 0·NaN
          for (auto& component : Jb) component[k] = 0.0;
        }
      }
      AccumulatePressureAvx2(w0, w1, d, Jb, pressure_lanes);
      batch.n = 0;
      return;
    }
    bool use[kBatch], curvature[kBatch];
    const double m_before = m_ref;
    const double curvature_cut = eps * std::log(kCurvatureWeight);
    for (int k = 0; k < kBatch; ++k) {
      // The scalar kernel's test against the running maximum as it stands at this node (the
      // candidates were tested against the maximum before the batch), so that both kernels
      // take the same nodes.
      use[k] = k < batch.n && std::isfinite(d[k]) && batch.bound[k] - batch.sz[k] >= floor();
      curvature[k] = false;
      if (!use[k]) continue;
      ++out.nodes_evaluated;
      m_ref = std::max(m_ref, d[k]);
      curvature[k] = d[k] - m_ref >= curvature_cut;
    }
    if (m_ref > m_before) {
      const double scale = std::isfinite(m_before) ? std::exp((m_before - m_ref) / eps) : 0.0;
      for (double& v : lanes.v) v *= scale;
    }
    BatchWeightsAvx2(d, use, m_ref, eps, w);
    for (int k = 0; k < kBatch; ++k) {
      w2[k] = curvature[k] ? w[k] : 0.0;
      // A node whose depth is not finite (its stencil reads a hole the cell's bound did not
      // see) adds nothing: its gradient, NaN too, must not reach the sums as 0·NaN.
      if (!use[k]) {
        for (auto& component : Jb) component[k] = 0.0;
      }
    }
    AccumulateAvx2(w, w2, Jb, lanes);
    batch.n = 0;
#endif
  };
  // The nodes [i0, i1) × [j0, j1), by their cell's bound.
  const auto visit_nodes = [&](int i0, int i1, int j0, int j1) noexcept {
#ifdef HT_DEPTH_FIELD_AVX2
    if (batched) {  // a row of (at most) four nodes at a time
      for (int j = j0; j < j1; ++j) {
        for (int i = i0; i < i1; i += 4) {
          int cell[4], tested = 0;
          double tu[4], tv[4], sx[4], sy[4], sz[4], cb[4];
          const glm::dvec3 first =
              origin + static_cast<double>(j) * step_j + static_cast<double>(i) * step_i;
          const int bits = RowCandidatesAvx2(tool + j * tnx + i, std::min(4, i1 - i), first, step_i,
                                             along_a, inv_h, nx, ny, bound, floor(), tested, cell,
                                             tu, tv, sx, sy, sz, cb);
          out.nodes_tested += tested;
          for (int k = 0; k < 4; ++k) {
            if ((bits >> k & 1) == 0) continue;
            const auto e = static_cast<std::size_t>(batch.n++);
            batch.cell[e] = cell[k];
            batch.tu[e] = tu[k];
            batch.tv[e] = tv[k];
            batch.sx[e] = sx[k];
            batch.sy[e] = sy[k];
            batch.sz[e] = sz[k];
            batch.bound[e] = cb[k];
            if (batch.n == kBatch) flush();
          }
        }
      }
      return;
    }
#endif
    for (int j = j0; j < j1; ++j) {
      const glm::dvec3 row = origin + static_cast<double>(j) * step_j;
      for (int i = i0; i < i1; ++i) {
        const float a = tool[j * tnx + i];
        if (!std::isfinite(a)) continue;
        const glm::dvec3 s =
            row + static_cast<double>(i) * step_i + static_cast<double>(a) * along_a;
        int cell;
        double tu, tv;
        ++out.nodes_tested;
        if (!locate(s, cell, tu, tv)) continue;
        const float cell_bound = bound[cell];
        if (!std::isfinite(cell_bound) || !(cell_bound - s.z >= floor())) continue;
        const double d = exact(i, j, s, cell, tu, tv, &J);
        if (!std::isfinite(d)) continue;
        ++out.nodes_evaluated;
        if constexpr (kPressure) {
          m_ref = std::max(m_ref, d);
          if (!(d > 0.0)) continue;
          ++out.overlapping_nodes;
          P.volume += area * d;
          P.squared += area * d * d;
          P.first.noalias() += (area * d) * J;
          P.second.selfadjointView<Eigen::Lower>().rankUpdate(J, area);
          P.weighted.selfadjointView<Eigen::Lower>().rankUpdate(J, area * d);
          continue;
        }
        if (d > m_ref) {
          const double scale = std::isfinite(m_ref) ? std::exp((m_ref - d) / eps) : 0.0;
          S0 *= scale;
          S1 *= scale;
          S2 *= scale;
          m_ref = d;
        }
        const double w = std::exp((d - m_ref) / eps);
        S0 += w;
        S1.noalias() += w * J;
        if (w >= kCurvatureWeight) S2.selfadjointView<Eigen::Lower>().rankUpdate(J, w);
      }
    }
  };
  // A block: each of its sub-blocks whose own bound reaches within the cutoff.
  const auto visit_block = [&](int b) noexcept {
    const int ti = b % bx, tj = b / bx;
    const int i_end = std::min(tnx, (ti + 1) * kDepthFieldBlock);
    const int j_end = std::min(tny, (tj + 1) * kDepthFieldBlock);
    for (int j0 = tj * kDepthFieldBlock; j0 < j_end; j0 += kDepthFieldSubBlock) {
      for (int i0 = ti * kDepthFieldBlock; i0 < i_end; i0 += kDepthFieldSubBlock) {
        const int i1 = std::min(i_end, i0 + kDepthFieldSubBlock);
        const int j1 = std::min(j_end, j0 + kDepthFieldSubBlock);
        const std::size_t sb =
            static_cast<std::size_t>(j0 / kDepthFieldSubBlock) * sbx + i0 / kDepthFieldSubBlock;
        const float a_lo = f.tool_sub_min_m[sb], a_hi = f.tool_sub_max_m[sb];
        if (!(a_lo <= a_hi)) continue;
        if (!(box_bound(i0, i1 - 1, j0, j1 - 1, a_lo, a_hi, f.env_sub_bound_m.data(),
                        kDepthFieldSubBlock, env_sbx) >= floor())) {
          continue;
        }
        if (out.nodes_evaluated >= max_nodes) return;  // over budget: stopped
        visit_nodes(i0, i1, j0, j1);
      }
    }
  };
  // The blocks' bounds of super-block k of super_order (once).
  int supers_bounded = 0;
  int best_block = -1;
  float best_ub = -std::numeric_limits<float>::infinity();
  const auto bound_blocks = [&](int k) noexcept {
    const int g = super_order[static_cast<std::size_t>(k)];
    const int bi0 = (g % gx) * kBlocksPerSuper, bj0 = (g / gx) * kBlocksPerSuper;
    const int bi1 = std::min(bx, bi0 + kBlocksPerSuper), bj1 = std::min(by, bj0 + kBlocksPerSuper);
    for (int tj = bj0; tj < bj1; ++tj) {
      for (int ti = bi0; ti < bi1; ++ti) {
        const int b = tj * bx + ti;
        float& ub = block_ub[static_cast<std::size_t>(b)];
        ub = -std::numeric_limits<float>::infinity();
        const float a_lo = f.tool_block_min_m[static_cast<std::size_t>(b)];
        const float a_hi = f.tool_block_max_m[static_cast<std::size_t>(b)];
        if (!(a_lo <= a_hi)) continue;  // no tool node
        const int i0 = ti * kDepthFieldBlock, i1 = std::min(tnx, i0 + kDepthFieldBlock) - 1;
        const int j0 = tj * kDepthFieldBlock, j1 = std::min(tny, j0 + kDepthFieldBlock) - 1;
        ub = static_cast<float>(box_bound(i0, i1, j0, j1, a_lo, a_hi, f.env_block_bound_m.data(),
                                          kDepthFieldBlock, env_bx));
        if (ub > best_ub) {
          best_ub = ub;
          best_block = b;
        }
      }
    }
    supers_bounded = std::max(supers_bounded, k + 1);
  };
  // The best block over all: super-blocks in order of their bounds until the next one's cannot
  // beat the best block's (a super-block's bound bounds its blocks').
  for (int k = 0; k < num_supers; ++k) {
    if (best_block >= 0 && !(super_ub[static_cast<std::size_t>(super_order[k])] > best_ub)) break;
    bound_blocks(k);
  }
  if (best_block < 0) return out;  // no tool node over the environment's interpolant
  const int first_block = best_block;
  visit_block(first_block);
  // Then each super-block whose bound reaches within the cutoff of the running maximum, in order:
  // its blocks that reach within it.
  for (int k = 0; k < num_supers && out.nodes_evaluated < max_nodes; ++k) {
    const int g = super_order[static_cast<std::size_t>(k)];
    if (!(super_ub[static_cast<std::size_t>(g)] >= floor())) break;  // nor any after it
    if (k >= supers_bounded) bound_blocks(k);
    const int bi0 = (g % gx) * kBlocksPerSuper, bj0 = (g / gx) * kBlocksPerSuper;
    const int bi1 = std::min(bx, bi0 + kBlocksPerSuper), bj1 = std::min(by, bj0 + kBlocksPerSuper);
    for (int tj = bj0; tj < bj1 && out.nodes_evaluated < max_nodes; ++tj) {
      for (int ti = bi0; ti < bi1 && out.nodes_evaluated < max_nodes; ++ti) {
        const int b = tj * bx + ti;
        if (b == first_block || !(block_ub[static_cast<std::size_t>(b)] >= floor())) {
          continue;
        }
        visit_block(b);
      }
    }
  }
  if (out.nodes_evaluated >= max_nodes) {
    out.over_budget = true;
    out.valid = false;
    out.depth_m = out.max_node_depth_m = -std::numeric_limits<double>::infinity();
    return out;
  }
  // To world axes: both halves turn with R_WF.
  const glm::dmat3 R_WF = glm::mat3_cast(f.X_WF.rotation);
  Mat6 B = Mat6::Zero();
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) {
      B(r, c) = R_WF[c][r];
      B(r + 3, c + 3) = R_WF[c][r];
    }
  }
  if constexpr (kPressure) {
    if (batched) {
      flush();
      const double* v = pressure_lanes.v.data();
      for (int l = 0; l < 4; ++l) {
        P.volume += v[l];
        P.squared += v[4 + l];
        for (int a = 0; a < 6; ++a) P.first[a] += v[4 * (2 + a) + l];
        int k = 8;
        for (int a = 0; a < 6; ++a) {
          for (int c = 0; c <= a; ++c, ++k) {
            P.second(a, c) += v[4 * k + l];
            P.weighted(a, c) += v[4 * (k + 21) + l];
          }
        }
      }
    }
    out.max_node_depth_m = m_ref;
    if (out.overlapping_nodes == 0 || !(P.squared > 0.0)) return out;  // depth_m −∞: no overlap
    const double a_ref = f.pressure_area_m2;
    const double depth = std::sqrt(P.squared / a_ref);
    const Vec6 grad = (B * P.first) / (a_ref * depth);
    const Mat6 second = B * Mat6(P.second.selfadjointView<Eigen::Lower>()) * B.transpose();
    out.depth_m = depth;
    out.gradient.d_translation_W = {grad[0], grad[1], grad[2]};
    out.gradient.d_rotation_W = {grad[3], grad[4], grad[5]};
    out.curvature = (second / a_ref - grad * grad.transpose()) / depth;
    out.curvature = 0.5 * (out.curvature + out.curvature.transpose()).eval();
    out.pressure_volume_m3 = P.volume;
    out.pressure_damping =
        B * Mat6(P.weighted.selfadjointView<Eigen::Lower>()) * B.transpose() / a_ref;
    if (!std::isfinite(depth) || !grad.allFinite() || !out.curvature.allFinite() ||
        !out.pressure_damping.allFinite()) {
      out.valid = false;  // the contact renders its linearization (counted as a fallback)
      out.depth_m = -std::numeric_limits<double>::infinity();
    }
    return out;
  }
  if (batched) {
    flush();
    // The lanes' sums into the scalar ones (S2's lower triangle).
    for (int l = 0; l < 4; ++l) {
      S0 += lanes.v[static_cast<std::size_t>(l)];
      for (int a = 0; a < 6; ++a) S1[a] += lanes.v[static_cast<std::size_t>(4 * (1 + a) + l)];
      int k = 7;
      for (int a = 0; a < 6; ++a) {
        for (int c = 0; c <= a; ++c, ++k) S2(a, c) += lanes.v[static_cast<std::size_t>(4 * k + l)];
      }
    }
  }
  if (!(S0 > 0.0)) return out;
  out.depth_m = m_ref + eps * std::log(S0);
  out.max_node_depth_m = m_ref;
  const Vec6 mean = S1 / S0;
  const Mat6 second = S2.selfadjointView<Eigen::Lower>();  // the sums' lower triangle, mirrored
  const Mat6 cov = second / S0 - mean * mean.transpose();
  const glm::dvec3 g_F(mean[0], mean[1], mean[2]), r_F(mean[3], mean[4], mean[5]);
  out.gradient.d_translation_W = R_WF * g_F;
  out.gradient.d_rotation_W = R_WF * r_F;
  out.curvature.noalias() = B * (cov / eps) * B.transpose();
  out.curvature = 0.5 * (out.curvature + out.curvature.transpose()).eval();
  return out;
}

}  // namespace

DepthFieldEvaluation DepthFieldDepthAt(const DepthField& f, const RigidTransform& X_WT) noexcept {
#ifdef HT_DEPTH_FIELD_AVX2
  return DepthFieldDepthAt(f, X_WT,
                           HasAvx2() ? DepthFieldKernel::kAvx2 : DepthFieldKernel::kScalar);
#else
  return DepthFieldDepthAt(f, X_WT, DepthFieldKernel::kScalar);
#endif
}

bool DepthFieldKernelAvailable(DepthFieldKernel kernel) noexcept {
#ifdef HT_DEPTH_FIELD_AVX2
  return kernel == DepthFieldKernel::kScalar || HasAvx2();
#else
  return kernel == DepthFieldKernel::kScalar;
#endif
}

DepthFieldEvaluation DepthFieldDepthAt(const DepthField& f, const RigidTransform& X_WT,
                                       DepthFieldKernel kernel, int max_nodes) noexcept {
#ifdef HT_DEPTH_FIELD_AVX2
  const bool batched = kernel == DepthFieldKernel::kAvx2 && HasAvx2();
#else
  const bool batched = false;
  (void)kernel;
#endif
  if (f.force_law != ForceLaw::kPressure) return EvaluateField<false>(f, X_WT, batched, max_nodes);
  DepthFieldEvaluation out = EvaluateField<true>(f, X_WT, batched, max_nodes);
  if (!out.valid || out.over_budget || out.overlapping_nodes > 0) return out;
  // No node overlaps: the seed's δ (at most 0) and ∇δ, which say how far apart the surfaces are
  // (a budget of its own: the pass above found nothing to sum).
  const DepthFieldEvaluation apart = EvaluateField<false>(f, X_WT, batched, max_nodes);
  out.over_budget = apart.over_budget;
  out.valid = apart.valid;
  out.nodes_evaluated += apart.nodes_evaluated;
  out.nodes_tested += apart.nodes_tested;
  out.max_node_depth_m = apart.max_node_depth_m;
  out.depth_m = std::min(apart.depth_m, 0.0);
  out.gradient = apart.gradient;
  return out;
}

void LimitDepthMapDescent(int nx, int ny, double cell_m, double max_slope,
                          std::vector<float>& heights_m) noexcept {
  if (nx < 1 || ny < 1 || !(cell_m > 0.0) || !(max_slope > 0.0) || !std::isfinite(max_slope) ||
      heights_m.size() != static_cast<std::size_t>(nx) * static_cast<std::size_t>(ny)) {
    return;
  }
  // Two raster passes of the cone's chamfer (a node's neighbours along the axes at one cell, on
  // the diagonals at √2 cells): b_i ← max(b_i, b_j − S·h·|i − j|) over the neighbours a pass has
  // already visited. NaN counts as no surface (−∞) and stays NaN where no cone reaches.
  const float drop = static_cast<float>(max_slope * cell_m);
  const float drop_diagonal = static_cast<float>(max_slope * cell_m * std::sqrt(2.0));
  constexpr float kNone = -std::numeric_limits<float>::infinity();
  float* b = heights_m.data();
  const auto at = [&](int i, int j) noexcept {
    const float v = b[static_cast<std::size_t>(j) * nx + i];
    return std::isnan(v) ? kNone : v;
  };
  const auto raise = [&](int i, int j, float v) noexcept {
    float& x = b[static_cast<std::size_t>(j) * nx + i];
    if (v > kNone && (std::isnan(x) || v > x)) x = v;
  };
  for (int j = 0; j < ny; ++j) {
    for (int i = 0; i < nx; ++i) {
      float v = kNone;
      if (i > 0) v = std::max(v, at(i - 1, j) - drop);
      if (j > 0) {
        v = std::max(v, at(i, j - 1) - drop);
        if (i > 0) v = std::max(v, at(i - 1, j - 1) - drop_diagonal);
        if (i + 1 < nx) v = std::max(v, at(i + 1, j - 1) - drop_diagonal);
      }
      raise(i, j, v);
    }
  }
  for (int j = ny - 1; j >= 0; --j) {
    for (int i = nx - 1; i >= 0; --i) {
      float v = kNone;
      if (i + 1 < nx) v = std::max(v, at(i + 1, j) - drop);
      if (j + 1 < ny) {
        v = std::max(v, at(i, j + 1) - drop);
        if (i + 1 < nx) v = std::max(v, at(i + 1, j + 1) - drop_diagonal);
        if (i > 0) v = std::max(v, at(i - 1, j + 1) - drop_diagonal);
      }
      raise(i, j, v);
    }
  }
}

DepthFieldCache::DepthFieldCache(int slots) {
  if (slots < 1) {
    throw std::invalid_argument("a depth-field cache needs at least 1 slot, got " +
                                std::to_string(slots));
  }
  slots_.resize(static_cast<std::size_t>(slots));
  for (DepthField& f : slots_) f.Reserve();
  stamp_.assign(static_cast<std::size_t>(slots), 0);
  memo_.assign(static_cast<std::size_t>(slots), Memo{});
  dense_.assign(static_cast<std::size_t>(slots), 0);
}

DepthFieldEvaluation DepthFieldCache::Evaluate(std::uint32_t id,
                                               const RigidTransform& X_WT) const noexcept {
  if (id == 0) return {};
  for (std::size_t k = 0; k < slots_.size(); ++k) {
    if (stamp_[k] == 0 || slots_[k].id != id) continue;
    if (dense_[k] != 0) {
      DepthFieldEvaluation dense;
      dense.over_budget = true;
      return dense;
    }
    Memo& m = memo_[k];
    if (m.stamp != stamp_[k] || m.X_WT.translation != X_WT.translation ||
        m.X_WT.rotation != X_WT.rotation) {
#ifdef HT_DEPTH_FIELD_AVX2
      const DepthFieldKernel kernel =
          HasAvx2() ? DepthFieldKernel::kAvx2 : DepthFieldKernel::kScalar;
#else
      const DepthFieldKernel kernel = DepthFieldKernel::kScalar;
#endif
      m.result = DepthFieldDepthAt(slots_[k], X_WT, kernel, kDepthFieldMaxNodes);
      m.X_WT = X_WT;
      m.stamp = stamp_[k];
      if (m.result.over_budget) {
        dense_[k] = 1;
        ++over_budget_;
      }
    }
    return m.result;
  }
  return {};
}

const DepthField* DepthFieldCache::Find(std::uint32_t id) const noexcept {
  if (id == 0) return nullptr;
  for (std::size_t k = 0; k < slots_.size(); ++k) {
    if (stamp_[k] != 0 && slots_[k].id == id) return &slots_[k];
  }
  return nullptr;
}

void DepthFieldCache::Clear() noexcept {
  std::fill(stamp_.begin(), stamp_.end(), std::uint64_t{0});
  std::fill(dense_.begin(), dense_.end(), std::uint8_t{0});
  for (Memo& m : memo_) m.stamp = 0;
}

bool DepthFieldCache::Take(DepthField& field, std::span<const std::uint32_t> keep) noexcept {
  if (!field.prepared || field.id == 0) {
    ++refused_;
    return false;
  }
  std::size_t slot = slots_.size();
  for (std::size_t k = 0; k < slots_.size() && slot == slots_.size(); ++k) {
    if (stamp_[k] != 0 && slots_[k].id == field.id) slot = k;
  }
  for (std::size_t k = 0; k < slots_.size() && slot == slots_.size(); ++k) {
    if (stamp_[k] == 0) slot = k;
  }
  if (slot == slots_.size()) {
    std::uint64_t oldest = ~std::uint64_t{0};
    for (std::size_t k = 0; k < slots_.size(); ++k) {
      if (std::find(keep.begin(), keep.end(), slots_[k].id) != keep.end()) continue;
      if (stamp_[k] < oldest) {
        oldest = stamp_[k];
        slot = k;
      }
    }
  }
  if (slot == slots_.size()) {
    ++refused_;
    return false;
  }
  std::swap(slots_[slot], field);
  stamp_[slot] = ++clock_;
  dense_[slot] = 0;
  ++taken_;
  return true;
}

}  // namespace ht
