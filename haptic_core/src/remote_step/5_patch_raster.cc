// Stage 5's renders of a window (penetration_depth.h): the reference raster (RenderPatchHeights),
// the fast one (RenderPatchHeightsFast) and the culled tool render (RenderToolDepth), and the
// directional penetration depth of two height buffers (DirectionalPenetrationDepth, Shifted).

#include <algorithm>
#include <cmath>
#include <glm/geometric.hpp>
#include <glm/gtc/quaternion.hpp>
#include <limits>
#include <span>

#include "5_raster_largest_difference.h"
#include "haptic_core/penetration_depth.h"

namespace ht {

using namespace raster_kernels;  // NOLINT(google-build-using-namespace): this stage's own kernels

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
