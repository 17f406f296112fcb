// The texture stage's fast path (issue 15) against the reference it replaces, on random contacts
// of all six seed models (procedural full-resolution meshes, decimated and baked through the
// model cache at 512² textures to keep the test short):
//  - RenderPatchHeightsFast vs RenderPatchHeights, cell by cell, on the window and on the window
//    grown by a cell: the same cells covered, heights within a few float ulps;
//  - TexturePenetrationSolver kFast vs kReference: the 11 depth samples, δ0 and the gradient
//    within float rounding (the fast path reads the four in-plane translations as shifts of one
//    render);
//  - DirectionalPenetrationDepthShifted vs DirectionalPenetrationDepth on an explicitly shifted
//    buffer: the same sample;
//  - the coarse query with local reach vs the global query filtered by each pair's own
//    tolerance: the same pairs;
//  - the coarse query with internal GJK stopping within the tolerance vs run to the exact
//    distance, and on two threads vs one: the same pairs, contacts and order.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <exception>
#include <glm/gtc/quaternion.hpp>
#include <limits>
#include <map>
#include <memory>
#include <numbers>
#include <random>
#include <set>
#include <span>
#include <thread>
#include <utility>
#include <vector>

#include "haptic_core/accuracy/ground_truth_depth.h"
#include "haptic_core/contact_linearization.h"
#include "haptic_core/demo/procedural_models.h"
#include "haptic_core/demo/seed_models.h"
#include "haptic_core/depth_refinement.h"
#include "haptic_core/hull_proximity.h"
#include "haptic_core/model_build/haptic_model_build.h"
#include "haptic_core/penetration_depth.h"
#include "haptic_core/penetration_depth_backend.h"

namespace ht {
namespace {

// A seed model at the tests' parameters through the build's model cache, and its bake's largest
// error (m, TextureBakeReport::max_bake_error_m).
struct BuiltSeed {
  std::shared_ptr<const HapticModel> model;
  double bake_error_m = 0.0;
  bool from_cache = false;
};
BuiltSeed BuildSeed(SeedModel which) {
  HapticModelBuildParams params;
  params.coarse_triangles = static_cast<int>(SeedModelSpecOf(which).seed_coarse_triangles);
  params.texture.texture_size = 512;
  auto built = BuildHapticModelCached(SeedModelName(which), MakeSeedModelFullResolution(which),
                                      params, HapticModelCache(HT_TEST_MODEL_CACHE));
  return {built.model, built.report.bake.max_bake_error_m, built.report.from_cache};
}

// The model and its bake's largest error (m), built once per process. When the first model a
// process asks for is not in the cache (a fresh build folder), the other five are built then, two
// at a time, largest first (the decimation takes 6-36 s a model on one core).
const HapticModel& Seed(SeedModel which, double* bake_error_m = nullptr) {
  static std::map<SeedModel, BuiltSeed> models;
  static bool cold_start_done = false;
  auto it = models.find(which);
  if (it == models.end()) {
    it = models.emplace(which, BuildSeed(which)).first;
    if (!it->second.from_cache && !cold_start_done) {
      cold_start_done = true;
      std::vector<SeedModel> rest;
      for (const SeedModel m : {SeedModel::kHammer, SeedModel::kCadPart, SeedModel::kFile,
                                SeedModel::kGear, SeedModel::kBlock, SeedModel::kTorus}) {
        if (!models.contains(m)) rest.push_back(m);
      }
      std::vector<BuiltSeed> built(rest.size());
      std::vector<std::exception_ptr> errors(rest.size());
      std::atomic<std::size_t> next{0};
      const auto work = [&] {
        for (std::size_t k; (k = next++) < rest.size();) {
          try {
            built[k] = BuildSeed(rest[k]);
          } catch (...) {
            errors[k] = std::current_exception();
          }
        }
      };
      std::thread second(work);
      work();
      second.join();
      for (std::size_t k = 0; k < rest.size(); ++k) {
        if (errors[k]) std::rethrow_exception(errors[k]);
        models.emplace(rest[k], std::move(built[k]));
      }
    }
  }
  if (bake_error_m != nullptr) *bake_error_m = it->second.bake_error_m;
  return *it->second.model;
}

// The full-resolution mesh a seed model is baked from, as a ray-casting surface (built once).
const RayCastSurface& FullResolutionSurface(SeedModel which) {
  static std::map<SeedModel, std::unique_ptr<RayCastSurface>> surfaces;
  auto& slot = surfaces[which];
  if (!slot) slot = std::make_unique<RayCastSurface>(MakeSeedModelFullResolution(which));
  return *slot;
}

constexpr SeedModel kAll[] = {SeedModel::kBlock,   SeedModel::kGear, SeedModel::kHammer,
                              SeedModel::kCadPart, SeedModel::kFile, SeedModel::kTorus};

// A point on triangle `f` of `m` (frame O) and its unit face normal.
void PointOn(const HapticModel& m, int f, std::mt19937& rng, glm::dvec3& p, glm::dvec3& n) {
  std::uniform_real_distribution<double> U(0.0, 1.0);
  double a = U(rng), b = U(rng);
  if (a + b > 1.0) {
    a = 1.0 - a;
    b = 1.0 - b;
  }
  const glm::ivec3 t = m.triangles[f];
  const glm::dvec3 p0 = m.vertices_O[t[0]], p1 = m.vertices_O[t[1]], p2 = m.vertices_O[t[2]];
  p = p0 + a * (p1 - p0) + b * (p2 - p0);
  n = glm::normalize(glm::cross(p1 - p0, p2 - p0));
}

// A random contact: the environment at the identity, a window on one of its triangles, the tool
// turned so that one of its triangles faces that one, pressed in by up to 0.4 mm, tilted by up to
// 3° about a random axis.
struct Contact {
  RigidTransform X_WT, X_WO;
  ContactWindow window;
};

Contact RandomContact(const HapticModel& tool, const HapticModel& env, std::mt19937& rng,
                      int resolution) {
  std::uniform_int_distribution<int> tf(0, static_cast<int>(tool.triangles.size()) - 1);
  std::uniform_int_distribution<int> ef(0, static_cast<int>(env.triangles.size()) - 1);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  glm::dvec3 pe, ne, pt, nt;
  PointOn(env, ef(rng), rng, pe, ne);
  PointOn(tool, tf(rng), rng, pt, nt);
  Contact c;
  c.X_WO = RigidTransform::Identity();
  // Rotate the tool so that its triangle's normal points along −ne, then tilt.
  const glm::dvec3 to = -ne;
  const double c_ang = glm::dot(nt, to);
  const glm::dvec3 perp = std::abs(nt.x) < 0.9 ? glm::dvec3(1, 0, 0) : glm::dvec3(0, 1, 0);
  const glm::dquat align =
      c_ang < -1.0 + 1e-12 ? glm::angleAxis(std::numbers::pi, glm::normalize(glm::cross(nt, perp)))
                           : glm::normalize(glm::dquat(1.0 + c_ang, glm::cross(nt, to)));
  const glm::dvec3 axis = glm::normalize(glm::dvec3(U(rng), U(rng), U(rng)) + glm::dvec3(1e-9));
  const glm::dquat tilt = glm::angleAxis(3.0 * std::numbers::pi / 180.0 * U(rng), axis);
  c.X_WT.rotation = glm::normalize(tilt * align);
  const double press = 0.2e-3 * (1.0 + U(rng));
  c.X_WT.translation = pe - c.X_WT.rotation * pt - press * ne;
  c.window = ContactWindow::Make(pe, ne, 0.02, resolution);
  return c;
}

// The texture stage's query of a random contact on `env` (the stiffness of the refinement tests).
ContactQuery QueryFor(const HapticModel& env, const Contact& c) {
  ContactQuery q;
  q.environment = &env;
  q.X_WO = c.X_WO;
  q.window = c.window;
  q.stiffness_n_per_m = 8000.0;
  return q;
}

// One random contact of a seed pair linearized on the 50×50 grid (the CPU backend), for the
// refinement tests: the file and the block as tools on each of the six seed models, 4 contacts a
// pair; the ones whose grid δ0 is not finite are skipped.
struct SeedContact {
  SeedModel tool_which, env_which;
  const HapticModel* tool;
  const HapticModel* env;
  double tool_bake_m, env_bake_m;  // the models' bake errors (Seed)
  Contact c;
  ContactQuery q;
  std::array<DepthSample, kGradientSamples> samples;
  ContactLinearization lin;  // the grid's
};

// Calls f(SeedContact&) for each such contact, in a fixed order of pairs, drawing each contact
// from `rng` just before its call (f may draw from it too).
template <class F>
void ForEachSeedContact(std::mt19937& rng, CpuPenetrationDepthBackend& backend, F&& f) {
  for (const SeedModel which : kAll) {
    for (const SeedModel tool_which : {SeedModel::kFile, SeedModel::kBlock}) {
      SeedContact x{};
      x.env_which = which;
      x.tool_which = tool_which;
      x.env = &Seed(which, &x.env_bake_m);
      x.tool = &Seed(tool_which, &x.tool_bake_m);
      for (int trial = 0; trial < 4; ++trial) {
        x.c = RandomContact(*x.tool, *x.env, rng, 50);
        x.q = QueryFor(*x.env, x.c);
        x.samples = {};
        ASSERT_TRUE(backend.LinearizeBatch(*x.tool, x.c.X_WT, {&x.q, 1}, {&x.lin, 1}, x.samples));
        if (!std::isfinite(x.lin.depth_m)) continue;
        f(x);
      }
    }
  }
}

// The full-resolution truth's δ on the contact's window (GroundTruthDepthSolver, converged).
double FullResolutionDepth(const SeedContact& x) {
  GroundTruthDepthSolver truth(FullResolutionSurface(x.tool_which),
                               FullResolutionSurface(x.env_which));
  return truth.ConvergedDepth(x.c.X_WT, x.c.X_WO, x.c.window).depth_m;
}

double Ulp(float x) {
  return std::nextafter(std::abs(x), std::numeric_limits<float>::infinity()) - std::abs(x);
}

// Cell by cell: the same coverage, heights within 4 ulps. Returns the cells compared.
int ExpectSameHeights(const std::vector<float>& ref, const std::vector<float>& fast,
                      const char* what) {
  EXPECT_EQ(ref.size(), fast.size());
  int covered = 0, coverage_mismatch = 0, height_mismatch = 0;
  for (std::size_t k = 0; k < std::min(ref.size(), fast.size()); ++k) {
    const bool a = std::isfinite(ref[k]), b = std::isfinite(fast[k]);
    if (a != b) {
      ++coverage_mismatch;
      continue;
    }
    if (!a) continue;
    ++covered;
    if (std::abs(ref[k] - fast[k]) > 4.0 * Ulp(ref[k]) + 1e-12) ++height_mismatch;
  }
  EXPECT_EQ(coverage_mismatch, 0) << what;
  EXPECT_EQ(height_mismatch, 0) << what;
  return covered;
}

// The six seed models these tests use, built at the seed's coarse counts (ctest runs this first,
// alone, so that the other tests of this program and remote_step_alloc_test read them from the
// build's model cache): each decimated to about its seed count, textured, its bake error small
// against its size.
TEST(TextureStageParity, SixSeedModelsAreBuiltAtTheSeedsCoarseCounts) {
  for (const SeedModel which : kAll) {
    double bake_error_m = -1.0;
    const HapticModel& m = Seed(which, &bake_error_m);
    const auto seed = static_cast<double>(SeedModelSpecOf(which).seed_coarse_triangles);
    const auto n = static_cast<double>(m.triangles.size());
    EXPECT_GE(n, 0.5 * seed) << SeedModelName(which);
    EXPECT_LE(n, 1.5 * seed) << SeedModelName(which);
    EXPECT_TRUE(std::isfinite(bake_error_m) && bake_error_m >= 0.0) << SeedModelName(which);
    glm::dvec3 lo(std::numeric_limits<double>::infinity()), hi = -lo;
    for (const glm::dvec3& p : m.vertices_O) {
      lo = glm::min(lo, p);
      hi = glm::max(hi, p);
    }
    EXPECT_LT(bake_error_m, 0.1 * glm::length(hi - lo)) << SeedModelName(which);
  }
}

TEST(TextureStageParity, FastRenderDrawsTheReferenceHeightsOnAllSixSeedModels) {
  std::mt19937 rng(15);
  int covered = 0;
  std::vector<int> triangles;
  for (const SeedModel which : kAll) {
    const HapticModel& env = Seed(which);
    const HapticModel& tool = Seed(kAll[(static_cast<int>(which) + 1) % 6]);
    for (int trial = 0; trial < 8; ++trial) {
      // The last trial on a fine grid, where a large triangle's rows are longer than the fast
      // render's batch of cells (they go in chunks).
      const int n = trial == 7 ? 400 : trial % 2 == 0 ? 50 : 37;
      const Contact c = RandomContact(tool, env, rng, n);
      for (const PatchSide side : {PatchSide::kEnvironment, PatchSide::kTool}) {
        const HapticModel& m = side == PatchSide::kEnvironment ? env : tool;
        const RigidTransform& X = side == PatchSide::kEnvironment ? c.X_WO : c.X_WT;
        const float empty = side == PatchSide::kEnvironment
                                ? -std::numeric_limits<float>::infinity()
                                : std::numeric_limits<float>::infinity();
        // On the window.
        SelectPatchTriangles(m, X, c.window, side, 2.0 * c.window.cell_size_m(), triangles);
        std::vector<float> ref(static_cast<std::size_t>(n) * n, empty), fast = ref;
        RenderPatchHeights(m, X, triangles, c.window, side, ref);
        RenderPatchHeightsFast(m, X, triangles, c.window, side, 0, fast);
        covered += ExpectSameHeights(ref, fast, SeedModelName(which));
        // The SIMD rows and batched texture samples (AVX-512 or AVX2 here, and AVX2 even where
        // the CPU has AVX-512) against scalar rows and one SampleAt at a time: the same bits.
        std::vector<float> fast_scalar(ref.size(), empty), fast_avx2(ref.size(), empty);
        RenderPatchHeightsFast(m, X, triangles, c.window, side, 0, fast_scalar,
                               SampleKernel::kScalar);
        RenderPatchHeightsFast(m, X, triangles, c.window, side, 0, fast_avx2, SampleKernel::kAvx2);
        EXPECT_EQ(0, std::memcmp(fast.data(), fast_scalar.data(), fast.size() * sizeof(float)))
            << SeedModelName(which) << " " << SampleKernelName();
        EXPECT_EQ(0, std::memcmp(fast_avx2.data(), fast_scalar.data(), fast.size() * sizeof(float)))
            << SeedModelName(which) << " " << SampleKernelName(SampleKernel::kAvx2);
        // On the window grown by one cell: the reference on a window of (N+2)² cells, with the
        // window's own box depth R (the grown window's would be deeper; the fast path keeps R).
        const ContactWindow grown = ContactWindow::Make(c.window.center_W, c.window.normal_W,
                                                        c.window.extent_m * (n + 2) / n, n + 2);
        std::vector<float> ref_grown(static_cast<std::size_t>(n + 2) * (n + 2), empty),
            fast_grown = ref_grown;
        RenderPatchHeights(m, X, triangles, grown, side, ref_grown, c.window.depth_range_m());
        RenderPatchHeightsFast(m, X, triangles, c.window, side, 1, fast_grown);
        covered += ExpectSameHeights(ref_grown, fast_grown, SeedModelName(which));
      }
    }
  }
  EXPECT_GT(covered, 20000);  // the contacts really draw something
}

// RenderToolDepth draws only the cells that can be the deepest: on random contacts of all six
// seed models, at the base pose and at the rotation samples' poses, the same cell and depth bits
// as the depth scan of the whole render, with every kernel and whatever first cell it is given
// (the base's deepest, none, a random one); and it does cull (cells the whole render covers are
// left undrawn), so the comparison is not between two whole renders. With and without a
// TriangleBoundCache shared by a contact's renders, and with and without the environment's row
// blocks (EnvironmentRowMax), which skip whole rows of a triangle.
TEST(TextureStageParity, CulledToolRenderGivesTheWholeRendersDepth) {
  std::mt19937 rng(77);
  std::vector<int> env_triangles, tool_triangles;
  int compared = 0, in_contact = 0;
  long long whole_cells = 0, drawn_cells = 0, rows_skipped = 0;
  for (const SeedModel which : kAll) {
    const HapticModel& env = Seed(which);
    const HapticModel& tool = Seed(kAll[(static_cast<int>(which) + 2) % 6]);
    for (int trial = 0; trial < 6; ++trial) {
      const int n = trial % 3 == 2 ? 37 : 50;
      const Contact c = RandomContact(tool, env, rng, n);
      const auto cells = static_cast<std::size_t>(n) * n;
      std::vector<float> env_h(cells, -std::numeric_limits<float>::infinity());
      SelectPatchTriangles(env, c.X_WO, c.window, PatchSide::kEnvironment, 0.0, env_triangles);
      RenderPatchHeightsFast(env, c.X_WO, env_triangles, c.window, PatchSide::kEnvironment, 0,
                             env_h);
      EnvironmentMaxPyramid env_max;
      env_max.Reserve(n);
      env_max.Build(env_h, n);
      ASSERT_EQ(env_max.resolution(), n);
      EnvironmentRowMax row_max;
      row_max.Reserve(n);
      row_max.Build(env_h, n);
      ASSERT_EQ(row_max.resolution(), n);
      const GradientSteps h = GradientSteps::For(c.window);
      SelectPatchTriangles(tool, c.X_WT, c.window, PatchSide::kTool, 2.0 * h.h_x + 0.05,
                           tool_triangles, h.h_theta + 1e-9);
      const auto poses = GradientSamplePoses(c.X_WT, c.window);
      std::vector<float> whole(cells), partial(cells), partial_plain(cells);
      int base_cell = -1;
      // One cache of levels and texture bounds for the contact's renders (as the solver keeps),
      // filled by whichever render meets a triangle first.
      TriangleBoundCache bounds;
      bounds.Reserve(tool.triangles.size());
      bounds.Reset(tool, c.window.cell_size_m());
      for (const int p : {0, 5, 6, 7, 8, 9, 10}) {
        std::fill(whole.begin(), whole.end(), std::numeric_limits<float>::infinity());
        RenderPatchHeightsFast(tool, poses[p], tool_triangles, c.window, PatchSide::kTool, 0,
                               whole);
        const DepthSample want = DirectionalPenetrationDepth(env_h, whole);
        if (p == 0) base_cell = want.cell;
        if (want.cell >= 0) ++in_contact;
        const int random_cell = static_cast<int>(rng() % cells);
        for (const SampleKernel kernel :
             {SampleKernel::kBest, SampleKernel::kAvx2, SampleKernel::kScalar}) {
          for (const int first : {base_cell, -1, random_cell}) {
            ToolDepthCull hints;
            hints.first_cell = first;
            hints.env_max = first == base_cell ? &env_max : nullptr;
            hints.bounds = first != -1 ? &bounds : nullptr;
            // The row cull with the pyramid (as the solver uses them), alone, and not at all.
            hints.env_row_max = first != -1 || trial % 2 == 0 ? &row_max : nullptr;
            // Now and then a first pass with only some of the triangles (any subset is valid).
            std::vector<int> some;
            if (first == random_cell && p % 2 == 1) {
              for (std::size_t k = 0; k < tool_triangles.size(); k += 3) {
                some.push_back(tool_triangles[k]);
              }
              hints.first_triangles = some;
            }
            const DepthSample got = RenderToolDepth(tool, poses[p], tool_triangles, c.window, env_h,
                                                    partial, hints, kernel);
            if (hints.env_row_max != nullptr) {
              // The row cull skips only rows the per-cell cull would empty, and keeps their
              // flushes: without it, the very same partial render and count of cells drawn.
              ToolDepthCull plain = hints;
              plain.env_row_max = nullptr;
              const DepthSample without = RenderToolDepth(tool, poses[p], tool_triangles, c.window,
                                                          env_h, partial_plain, plain, kernel);
              ASSERT_EQ(without.cell, got.cell);
              ASSERT_EQ(std::memcmp(partial.data(), partial_plain.data(), cells * sizeof(float)), 0)
                  << SeedModelName(which) << " pose " << p;
              ASSERT_EQ(plain.cells_drawn, hints.cells_drawn);
              EXPECT_EQ(plain.rows_skipped, 0);
            }
            ASSERT_EQ(got.cell, want.cell) << SeedModelName(which) << " pose " << p;
            ASSERT_EQ(std::memcmp(&got.depth_m, &want.depth_m, sizeof(double)), 0)
                << SeedModelName(which) << " pose " << p << ": " << got.depth_m << " vs "
                << want.depth_m;
            ++compared;
            rows_skipped += hints.rows_skipped;
            if (kernel == SampleKernel::kBest && first == base_cell && want.cell >= 0) {
              for (std::size_t k = 0; k < cells; ++k) {
                whole_cells += std::isfinite(whole[k]) && std::isfinite(env_h[k]);
                drawn_cells += std::isfinite(partial[k]) && std::isfinite(env_h[k]);
              }
            }
          }
        }
      }
    }
  }
  EXPECT_GT(in_contact, 100);
  EXPECT_GT(compared, 2000);
  // It culls: fewer cells drawn than the whole renders cover (where the environment is too).
  EXPECT_LT(drawn_cells, whole_cells * 9 / 10) << drawn_cells << " of " << whole_cells;
  // The row cull does skip rows (so its comparisons above are not of a cull that never acts).
  EXPECT_GT(rows_skipped, 1000);
  RecordProperty("rows_skipped", std::to_string(rows_skipped));
  RecordProperty("drawn_cells", std::to_string(drawn_cells));
  RecordProperty("whole_cells", std::to_string(whole_cells));
}

// EnvironmentRowMax::MaxOver against a scan of the cells: at least every cell's height over the
// span (NaN heights passed over), never more than the largest over the blocks it reads, −∞ for an
// empty or all −∞ span; spans clamped to the window.
TEST(TextureStageParity, EnvironmentRowMaxBoundsEachSpan) {
  std::mt19937 rng(4711);
  std::uniform_real_distribution<float> U(-0.01f, 0.01f);
  for (const int n : {1, 7, 8, 9, 37, 50}) {
    std::vector<float> env(static_cast<std::size_t>(n) * n);
    for (float& h : env) {
      const auto r = rng() % 20;
      h = r == 0   ? -std::numeric_limits<float>::infinity()
          : r == 1 ? std::numeric_limits<float>::quiet_NaN()
                   : U(rng);
    }
    EnvironmentRowMax row_max;
    row_max.Reserve(n);
    row_max.Build(env, n);
    ASSERT_EQ(row_max.resolution(), n);
    for (int trial = 0; trial < 400; ++trial) {
      const int j = static_cast<int>(rng() % n);
      const int i0 = static_cast<int>(rng() % (n + 4)) - 2,
                i1 = static_cast<int>(rng() % (n + 4)) - 2;
      float want = -std::numeric_limits<float>::infinity();
      float blocks = -std::numeric_limits<float>::infinity();
      const int a = std::max(i0, 0), b = std::min(i1, n - 1);
      for (int i = a; i <= b; ++i) {
        const float h = env[static_cast<std::size_t>(j) * n + i];
        if (h > want) want = h;
      }
      if (a <= b) {
        const int k = EnvironmentRowMax::kBlock;
        for (int i = (a / k) * k; i < std::min(n, (b / k + 1) * k); ++i) {
          const float h = env[static_cast<std::size_t>(j) * n + i];
          if (h > blocks) blocks = h;
        }
      }
      const float got = row_max.MaxOver(j, i0, i1);
      EXPECT_GE(got, want) << n << " row " << j << " [" << i0 << ", " << i1 << "]";
      EXPECT_EQ(got, blocks) << n << " row " << j << " [" << i0 << ", " << i1 << "]";
    }
  }
  // A row with no environment (all −∞, or NaN) and an empty span: −∞, so no row is kept for them.
  {
    const int n = 20;
    std::vector<float> env(static_cast<std::size_t>(n) * n, 0.001f);
    for (int i = 0; i < n; ++i) {
      env[static_cast<std::size_t>(3) * n + i] = -std::numeric_limits<float>::infinity();
      env[static_cast<std::size_t>(4) * n + i] = std::numeric_limits<float>::quiet_NaN();
    }
    EnvironmentRowMax row_max;
    row_max.Reserve(n);
    row_max.Build(env, n);
    EXPECT_EQ(row_max.MaxOver(3, 0, n - 1), -std::numeric_limits<float>::infinity());
    EXPECT_EQ(row_max.MaxOver(4, 0, n - 1), -std::numeric_limits<float>::infinity());
    EXPECT_EQ(row_max.MaxOver(5, 9, 8), -std::numeric_limits<float>::infinity());
    EXPECT_EQ(row_max.MaxOver(5, 0, n - 1), 0.001f);
  }
  // Too small a reserve: nothing is built (and nothing allocated).
  EnvironmentRowMax small;
  small.Reserve(8);
  std::vector<float> env(50 * 50, 0.0f);
  small.Build(env, 50);
  EXPECT_EQ(small.resolution(), 0);
}

// Slivers, needles and triangles with an edge almost along a row: the fast render's row spans
// are computed bounds widened by a tiny slack, so cells exactly on or a rounding away from an
// edge are where a too-tight span would lose a cell the reference draws. Random triangles of all
// shapes over the window, untextured (the span alone decides), both sides, margin 0 and 1.
TEST(TextureStageParity, FastRenderCoversTheReferenceCellsOnSliversAndNeedles) {
  std::mt19937 rng(1507);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  const ContactWindow w = ContactWindow::Make({0, 0, 0}, {0, 0, 1}, 0.02, 50);
  const double cell = w.cell_size_m();
  int covered = 0;
  for (int trial = 0; trial < 300; ++trial) {
    HapticModel m;
    for (int t = 0; t < 20; ++t) {
      // Corners on cell centres or edges (exact ties), or anywhere; the third one nearly on the
      // line of the first two now and then (a sliver), or far along it (a needle).
      const auto corner = [&] {
        const int mode = static_cast<int>(rng() % 3);
        const double x = U(rng) * 0.012, y = U(rng) * 0.012;
        if (mode == 0)
          return glm::dvec3(std::round(x / cell) * cell, std::round(y / cell) * cell, 0);
        if (mode == 1) {
          return glm::dvec3((std::round(x / cell) + 0.5) * cell,
                            (std::round(y / cell) + 0.5) * cell, 0);
        }
        return glm::dvec3(x, y, 0);
      };
      glm::dvec3 a = corner(), b = corner(), c = corner();
      if (trial % 3 == 1)
        c = a + (b - a) * (0.5 + U(rng)) + glm::dvec3(-(b - a).y, (b - a).x, 0) * 1e-7 * U(rng);
      if (trial % 3 == 2) c = a + glm::dvec3(1.0, 1e-9 * U(rng), 0) * 0.02 * U(rng);
      a.z = 1e-3 * U(rng);
      b.z = 1e-3 * U(rng);
      c.z = 1e-3 * U(rng);
      // Facing +z for the environment's test, −z for the tool's: one of each orientation.
      const bool up = glm::cross(b - a, c - a).z > 0.0;
      const int base = static_cast<int>(m.vertices_O.size());
      m.vertices_O.insert(m.vertices_O.end(), {a, b, c});
      m.triangles.push_back(up == (t % 2 == 0) ? glm::ivec3(base, base + 1, base + 2)
                                               : glm::ivec3(base, base + 2, base + 1));
      for (int k = 0; k < 3; ++k) {
        m.corner_normals_O.push_back({0, 0, up == (t % 2 == 0) ? 1.0 : -1.0});
        m.corner_uvs.push_back({0.0f, 0.0f});
      }
      m.textured.push_back(0);
      m.texel_size_m.push_back(1e-4);
    }
    std::vector<int> all(m.triangles.size());
    for (std::size_t k = 0; k < all.size(); ++k) all[k] = static_cast<int>(k);
    for (const PatchSide side : {PatchSide::kEnvironment, PatchSide::kTool}) {
      const float empty = side == PatchSide::kEnvironment ? -std::numeric_limits<float>::infinity()
                                                          : std::numeric_limits<float>::infinity();
      std::vector<float> ref(2500, empty), fast = ref;
      RenderPatchHeights(m, RigidTransform::Identity(), all, w, side, ref);
      RenderPatchHeightsFast(m, RigidTransform::Identity(), all, w, side, 0, fast);
      covered += ExpectSameHeights(ref, fast, "slivers");
      const ContactWindow grown =
          ContactWindow::Make(w.center_W, w.normal_W, w.extent_m * 52 / 50, 52);
      std::vector<float> ref_grown(52 * 52, empty), fast_grown = ref_grown;
      RenderPatchHeights(m, RigidTransform::Identity(), all, grown, side, ref_grown,
                         w.depth_range_m());
      RenderPatchHeightsFast(m, RigidTransform::Identity(), all, w, side, 1, fast_grown);
      covered += ExpectSameHeights(ref_grown, fast_grown, "slivers, grown");
    }
  }
  EXPECT_GT(covered, 10000);
}

TEST(TextureStageParity, FastSolverGivesTheReferenceDepthsAndGradients) {
  std::mt19937 rng(1515);
  TexturePenetrationSolver reference(128, 4096, TextureStagePath::kReference);
  TexturePenetrationSolver fast(128, 4096, TextureStagePath::kFast);
  int in_contact = 0;
  double worst_depth = 0.0, worst_dx = 0.0, worst_dr = 0.0;
  for (const SeedModel which : kAll) {
    const HapticModel& env = Seed(which);
    for (const SeedModel tool_which : {SeedModel::kFile, SeedModel::kBlock, which}) {
      const HapticModel& tool = Seed(tool_which);
      for (int trial = 0; trial < 6; ++trial) {
        const Contact c = RandomContact(tool, env, rng, 50);
        std::array<DepthSample, kGradientSamples> sr{}, sf{};
        const ContactLinearization r =
            reference.Linearize(tool, c.X_WT, env, c.X_WO, c.window, 8000.0, sr);
        const ContactLinearization f =
            fast.Linearize(tool, c.X_WT, env, c.X_WO, c.window, 8000.0, sf);
        ASSERT_EQ(std::isfinite(r.depth_m), std::isfinite(f.depth_m)) << SeedModelName(which);
        if (!std::isfinite(r.depth_m)) continue;
        ++in_contact;
        for (int i = 0; i < kGradientSamples; ++i) {
          ASSERT_EQ(sr[i].cell >= 0, sf[i].cell >= 0) << "sample " << i;
          if (sr[i].cell < 0) continue;
          // Heights are floats of at most R = 2 cm: a few ulps there is ~1e-8 m.
          EXPECT_NEAR(sr[i].depth_m, sf[i].depth_m, 1e-8) << "sample " << i;
          worst_depth = std::max(worst_depth, std::abs(sr[i].depth_m - sf[i].depth_m));
        }
        // The gradient: central differences of those depths over h_x = 0.4 mm, h_θ = 0.04 rad.
        const glm::dvec3 dx = r.gradient.d_translation_W - f.gradient.d_translation_W;
        const glm::dvec3 dr = r.gradient.d_rotation_W - f.gradient.d_rotation_W;
        EXPECT_LT(glm::length(dx), 5e-5);
        EXPECT_LT(glm::length(dr), 5e-7);
        worst_dx = std::max(worst_dx, glm::length(dx));
        worst_dr = std::max(worst_dr, glm::length(dr));
      }
    }
  }
  EXPECT_GT(in_contact, 40);
  std::printf(
      "[ parity ] %d contacts in contact; worst |dδ| %.3g m, |dJ_x| %.3g, |dJ_θ| %.3g m/rad\n",
      in_contact, worst_depth, worst_dx, worst_dr);
}

// Stage 5b (issue 32) in the render's form (parallax off: the form the grid renders) on random
// contacts of the six seed models: the refined δ0 is never below the grid's (it climbs from the
// grid's deepest cells at the finest level, where a cell's filtered value is a mean of what the
// climb sees), and never above the full-resolution truth (Embree on the meshes the models were
// baked from, on the same window) by more than the two textures' own bake errors. (With parallax,
// the default, δ0 reads another surface than the grid's form where a facet is tilted from n, so
// it may lie below the grid's: the next test bounds it by the truth.)
TEST(TextureStageParity, RefinedDepthLiesBetweenTheGridAndTheFullResolutionTruth) {
  std::mt19937 rng(3232);
  CpuPenetrationDepthBackend backend(128);
  DepthRefinementOptions render_form;
  render_form.parallax = false;
  DepthRefiner refiner(render_form);
  int checked = 0;
  double raised_sum = 0.0, worst_below_grid = 0.0, worst_above_truth = 0.0;
  double grid_error_sum = 0.0, refined_error_sum = 0.0;
  ForEachSeedContact(rng, backend, [&](SeedContact& x) {
    const Contact& c = x.c;
    ContactLinearization& lin = x.lin;
    const double grid = lin.depth_m;
    ASSERT_TRUE(refiner.Refine(*x.tool, c.X_WT, x.q, x.samples, lin));
    const double gt_depth_m = FullResolutionDepth(x);
    if (!std::isfinite(gt_depth_m)) return;
    ++checked;
    SCOPED_TRACE(std::string(SeedModelName(x.tool_which)) + " on " + SeedModelName(x.env_which));
    EXPECT_GE(lin.depth_m, grid - 1e-7);
    EXPECT_LE(lin.depth_m, gt_depth_m + x.env_bake_m + x.tool_bake_m + 1e-6)
        << "bake errors " << x.env_bake_m << " + " << x.tool_bake_m;
    raised_sum += lin.depth_m - grid;
    grid_error_sum += std::abs(grid - gt_depth_m);
    refined_error_sum += std::abs(lin.depth_m - gt_depth_m);
    worst_below_grid = std::max(worst_below_grid, grid - lin.depth_m);
    worst_above_truth = std::max(worst_above_truth, lin.depth_m - gt_depth_m);
  });
  EXPECT_GT(checked, 20);
  // Over the contacts, the refined δ0 is closer to the truth than the grid's (the bake bounds
  // above are loose, millimetres at the 512² textures' sharp edges).
  EXPECT_LT(refined_error_sum, grid_error_sum);
  std::printf(
      "[ refine ] %d contacts: refined δ0 above the grid's by %.1f µm on average; worst below the "
      "grid %.3g m, worst above the truth %.3g m; mean |δ − δ_truth| grid %.1f µm, refined "
      "%.1f µm\n",
      checked, checked > 0 ? raised_sum / checked * 1e6 : 0.0, worst_below_grid, worst_above_truth,
      checked > 0 ? grid_error_sum / checked * 1e6 : 0.0,
      checked > 0 ? refined_error_sum / checked * 1e6 : 0.0);
}

// Stage 5b with parallax (issue 32, twelfth stop) on the same kind of random contacts of the six
// seed models: the refined δ0 is never above the full-resolution truth by more than the two
// textures' bake errors, and over the contacts it is closer to the truth than the render's form
// (parallax off) on these models, whose coarse facets lie at an angle to the windows under
// heights of up to millimetres.
TEST(TextureStageParity, ParallaxDepthIsBoundedByTheTruthAndCloserToItThanTheRendersForm) {
  std::mt19937 rng(3233);
  CpuPenetrationDepthBackend backend(128);
  DepthRefinementOptions off;
  off.parallax = false;
  DepthRefiner render_form(off);
  DepthRefinementOptions o;
  ASSERT_TRUE(o.parallax) << "parallax is the default";
  DepthRefiner parallax(o);
  int checked = 0;
  double render_error_sum = 0.0, parallax_error_sum = 0.0, worst_above_truth = 0.0;
  ForEachSeedContact(rng, backend, [&](SeedContact& x) {
    const Contact& c = x.c;
    ContactLinearization& lin = x.lin;
    ContactLinearization lin_p = lin;
    std::array<DepthSample, kGradientSamples> samples_p = x.samples;
    ASSERT_TRUE(render_form.Refine(*x.tool, c.X_WT, x.q, x.samples, lin));
    if (!parallax.Refine(*x.tool, c.X_WT, x.q, samples_p, lin_p)) return;
    const double gt_depth_m = FullResolutionDepth(x);
    if (!std::isfinite(gt_depth_m)) return;
    ++checked;
    SCOPED_TRACE(std::string(SeedModelName(x.tool_which)) + " on " + SeedModelName(x.env_which));
    EXPECT_LE(lin_p.depth_m, gt_depth_m + x.env_bake_m + x.tool_bake_m + 1e-6)
        << "bake errors " << x.env_bake_m << " + " << x.tool_bake_m;
    render_error_sum += std::abs(lin.depth_m - gt_depth_m);
    parallax_error_sum += std::abs(lin_p.depth_m - gt_depth_m);
    worst_above_truth = std::max(worst_above_truth, lin_p.depth_m - gt_depth_m);
  });
  EXPECT_GT(checked, 20);
  EXPECT_LT(parallax_error_sum, render_error_sum);
  std::printf(
      "[ parallax ] %d contacts: mean |δ − δ_truth| render's form %.1f µm, parallax %.1f µm; "
      "worst above the truth %.3g m\n",
      checked, checked > 0 ? render_error_sum / checked * 1e6 : 0.0,
      checked > 0 ? parallax_error_sum / checked * 1e6 : 0.0, worst_above_truth);
}

// The conservative screen (issue 32, sixth stop) on random contacts of the six seed models, two
// routes to the window's maximum of b − a at level 0: the refined δ0 is never below b − a at any
// of 3,000 random points of the window (PatchHeightAt at level 0 on every triangle of both
// models) by more than the screen's tolerance, and never below the seeds-only refinement's δ0.
// The seeds alone miss some (printed): what the screen is for.
TEST(TextureStageParity, ScreenedDepthIsNeverBelowAnyLevelZeroPointOfTheWindow) {
  std::mt19937 rng(3233);
  CpuPenetrationDepthBackend backend(128);
  DepthRefinementOptions on;
  on.conservative_screen = true;
  on.parallax = false;  // the screen bounds the render's form (PatchHeightAt at level 0, below)
  DepthRefiner screened(on);
  DepthRefinementOptions off;
  off.conservative_screen = false;
  off.parallax = false;
  DepthRefiner seeds_only(off);
  const double tolerance = DepthRefinementOptions{}.screen_tolerance_m;
  int checked = 0, seeds_missed = 0;
  double worst_below_points = -1.0, worst_seeds_below_points = -1.0, raised_sum = 0.0;
  std::uniform_real_distribution<double> U(-0.5, 0.5);
  for (const SeedModel which : kAll) {
    const HapticModel& env = Seed(which);
    std::vector<int> env_all(env.triangles.size());
    for (std::size_t f = 0; f < env_all.size(); ++f) env_all[f] = static_cast<int>(f);
    for (const SeedModel tool_which : {SeedModel::kFile, SeedModel::kBlock}) {
      const HapticModel& tool = Seed(tool_which);
      std::vector<int> tool_all(tool.triangles.size());
      for (std::size_t f = 0; f < tool_all.size(); ++f) tool_all[f] = static_cast<int>(f);
      for (int trial = 0; trial < 4; ++trial) {
        const Contact c = RandomContact(tool, env, rng, 50);
        const ContactQuery q = QueryFor(env, c);
        std::array<DepthSample, kGradientSamples> samples{};
        ContactLinearization lin;
        ASSERT_TRUE(backend.LinearizeBatch(tool, c.X_WT, {&q, 1}, {&lin, 1}, samples));
        if (!std::isfinite(lin.depth_m)) continue;
        std::array<DepthSample, kGradientSamples> samples_seeds = samples;
        ContactLinearization lin_seeds = lin;
        ASSERT_TRUE(screened.Refine(tool, c.X_WT, q, samples, lin));
        ASSERT_TRUE(seeds_only.Refine(tool, c.X_WT, q, samples_seeds, lin_seeds));
        SCOPED_TRACE(std::string(SeedModelName(tool_which)) + " on " + SeedModelName(which));
        EXPECT_GE(lin.depth_m, lin_seeds.depth_m - 1e-12);
        double points_max = -std::numeric_limits<double>::infinity();
        for (int k = 0; k < 3000; ++k) {
          const double s = U(rng) * c.window.extent_m, t = U(rng) * c.window.extent_m;
          const double b =
              PatchHeightAt(env, c.X_WO, env_all, c.window, PatchSide::kEnvironment, s, t, 0);
          const double a =
              PatchHeightAt(tool, c.X_WT, tool_all, c.window, PatchSide::kTool, s, t, 0);
          if (std::isfinite(a) && std::isfinite(b)) points_max = std::max(points_max, b - a);
        }
        if (!std::isfinite(points_max)) continue;
        ++checked;
        EXPECT_GE(lin.depth_m, points_max - tolerance - 1e-9);
        worst_below_points = std::max(worst_below_points, points_max - lin.depth_m);
        worst_seeds_below_points =
            std::max(worst_seeds_below_points, points_max - lin_seeds.depth_m);
        if (lin_seeds.depth_m < points_max - tolerance) ++seeds_missed;
        raised_sum += lin.depth_m - lin_seeds.depth_m;
      }
    }
  }
  EXPECT_GT(checked, 20);
  EXPECT_GT(screened.counters().screen_squares, 0u);
  std::printf(
      "[ screen ] %d contacts: screened δ0 at most %.3g m below the random points' max (seeds "
      "alone %.3g m, below it on %d contacts); screened above seeds-only by %.2f µm on average; "
      "%.0f squares, %.1f leaves per contact; %llu truncated\n",
      checked, worst_below_points, worst_seeds_below_points, seeds_missed,
      checked > 0 ? raised_sum / checked * 1e6 : 0.0,
      static_cast<double>(screened.counters().screen_squares) /
          std::max<double>(1.0, static_cast<double>(screened.counters().contacts)),
      static_cast<double>(screened.counters().screen_leaves) /
          std::max<double>(1.0, static_cast<double>(screened.counters().contacts)),
      static_cast<unsigned long long>(screened.counters().screen_truncated));
}

// EnvironmentMaxPyramid::MaxOver is at least the largest height of any box (random boxes on
// random heights with empty cells, odd and even sizes), exactly it for a single cell, and −∞ for
// an empty box.
// SelectPatchTriangles through a TriangleBoxTree against the whole scan (and the scan with the
// vertex scratch): the same triangles in the same order, on random contacts of the six seed
// models and the procedural gear (a convex model without a hull hierarchy), with windows of
// several sizes, margins and facing slacks, on both sides, at random poses, and on windows far
// from any triangle; also carried by a triangle subset (TriangleSubset::tree). A tree that does
// not fit the model (another model's counts) is not used; a model edited in place is selected
// right through a tree built again.
TEST(TextureStageParity, BoxTreeSelectsTheScansTriangles) {
  std::mt19937 rng(1515);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  const HapticModel gear = MakeRidgedGear();
  std::vector<const HapticModel*> models;
  for (const SeedModel which : kAll) models.push_back(&Seed(which));
  models.push_back(&gear);
  std::vector<int> scan, scratch_scan, through_tree;
  std::vector<double> scratch;
  long selected = 0, compared = 0, empty = 0;
  for (std::size_t k = 0; k < models.size(); ++k) {
    const HapticModel& env = *models[k];
    const HapticModel& tool = *models[(k + 1) % models.size()];
    TriangleBoxTree env_tree, tool_tree;
    env_tree.Build(env);
    tool_tree.Build(tool);
    ASSERT_TRUE(env_tree.Fits(env));
    ASSERT_TRUE(tool_tree.Fits(tool));
    EXPECT_EQ(env_tree.triangles().size(), env.triangles.size());
    std::vector<int> sorted;
    for (const TriangleBoxTree::Triangle& t : env_tree.triangles()) sorted.push_back(t.index);
    std::sort(sorted.begin(), sorted.end());
    for (std::size_t f = 0; f < sorted.size(); ++f) ASSERT_EQ(sorted[f], static_cast<int>(f));
    scratch.reserve(std::max(env.vertices_O.size(), tool.vertices_O.size()));
    for (int trial = 0; trial < 60; ++trial) {
      const int n = trial % 3 == 0 ? 25 : 50;
      Contact c = RandomContact(tool, env, rng, n);
      if (trial % 4 == 1) {  // another extent: a window many cells wide or one much smaller
        c.window = ContactWindow::Make(c.window.center_W, c.window.normal_W,
                                       trial % 8 == 1 ? 0.08 : 0.002, n);
      }
      if (trial % 10 == 9) {  // far from both models: no triangle
        c.window = ContactWindow::Make(c.window.center_W + glm::dvec3(3.0, -2.0, 1.0),
                                       c.window.normal_W, 0.02, n);
      }
      if (trial % 5 == 3) {  // a random pose of the environment too
        c.X_WO.rotation = glm::normalize(glm::dquat(U(rng), U(rng), U(rng), U(rng)));
        c.X_WO.translation = c.window.center_W - c.X_WO.rotation * c.window.center_W;
      }
      const double h_x = c.window.cell_size_m();
      for (const PatchSide side : {PatchSide::kEnvironment, PatchSide::kTool}) {
        const HapticModel& m = side == PatchSide::kEnvironment ? env : tool;
        const TriangleBoxTree& tree = side == PatchSide::kEnvironment ? env_tree : tool_tree;
        const TriangleBoxTree& other = side == PatchSide::kEnvironment ? tool_tree : env_tree;
        const RigidTransform& X = side == PatchSide::kEnvironment ? c.X_WO : c.X_WT;
        for (const double margin : {0.0, h_x, 2.0 * h_x + 0.05 * 0.1}) {
          for (const double slack : {0.0, 0.04}) {
            SelectPatchTriangles(m, X, c.window, side, margin, scan, slack);
            SelectPatchTriangles(m, X, c.window, side, margin, scratch_scan, slack, &scratch);
            SelectPatchTriangles(m, X, c.window, side, margin, through_tree, slack, nullptr, &tree);
            ASSERT_EQ(scan, scratch_scan) << m.name << " trial " << trial;
            ASSERT_EQ(scan, through_tree) << m.name << " trial " << trial << " margin " << margin;
            // The same tree carried by the subset.
            TriangleSubset all = TriangleSubset::All();
            all.tree = &tree;
            SelectPatchTrianglesIn(all, m, X, c.window, side, margin, through_tree, slack);
            ASSERT_EQ(scan, through_tree) << m.name << " (the subset's tree)";
            // A tree that does not fit the model is ignored: the scan.
            if (!other.Fits(m)) {
              SelectPatchTriangles(m, X, c.window, side, margin, through_tree, slack, nullptr,
                                   &other);
              ASSERT_EQ(scan, through_tree) << m.name << " (another model's tree)";
            }
            selected += static_cast<long>(scan.size());
            ++compared;
            empty += scan.empty() ? 1 : 0;
          }
        }
      }
    }
  }
  // Both outcomes occur: windows with triangles and windows without.
  EXPECT_GT(selected, 1000);
  EXPECT_GT(empty, 10);
  EXPECT_GT(compared - empty, compared / 2);

  // A model edited in place (its frame shifted, as ShiftModelFrame does) is derived anew: its
  // tree built again selects what the scan selects.
  HapticModel edited = Seed(SeedModel::kCadPart);
  ShiftModelFrame(edited, glm::dvec3(0.01, 0.0, 0.0));
  TriangleBoxTree tree;
  tree.Build(edited);
  ASSERT_TRUE(tree.Fits(edited));
  const Contact c = RandomContact(Seed(SeedModel::kFile), edited, rng, 50);
  SelectPatchTriangles(edited, c.X_WO, c.window, PatchSide::kEnvironment, 0.0, scan);
  SelectPatchTriangles(edited, c.X_WO, c.window, PatchSide::kEnvironment, 0.0, through_tree, 0.0,
                       nullptr, &tree);
  EXPECT_EQ(scan, through_tree);
  EXPECT_FALSE(scan.empty());
}

// TriangleBoxTree::ForModel: a tree that fits for a model of many triangles, none (the scan) for
// one of fewer than kMinTriangles; a cleared tree fits no model with triangles.
TEST(TextureStageParity, BoxTreeForModelSkipsSmallModels) {
  const HapticModel& part = Seed(SeedModel::kCadPart);
  const std::unique_ptr<TriangleBoxTree> tree = TriangleBoxTree::ForModel(part);
  ASSERT_NE(tree, nullptr);
  EXPECT_TRUE(tree->Fits(part));
  const HapticModel& block = Seed(SeedModel::kBlock);
  ASSERT_LT(block.triangles.size(), TriangleBoxTree::kMinTriangles);
  EXPECT_EQ(TriangleBoxTree::ForModel(block), nullptr);
  tree->Clear();
  EXPECT_FALSE(tree->Fits(part));
}

// The tool's triangles with each triangle's own rotation margin (2 h_x + h_θ·r, r its farthest
// corner from the tool's origin) against the margin of the tool's farthest vertex that the solver
// used before: a subset, and the same render bits at all eleven sample poses (on the window, and
// on the window grown by a cell at the base pose), on random contacts of the six seed models.
TEST(TextureStageParity, PerTriangleRotationMarginKeepsEveryRender) {
  std::mt19937 rng(2015);
  std::vector<int> local, global;
  long local_total = 0, global_total = 0, covered = 0;
  for (const SeedModel which : kAll) {
    const HapticModel& env = Seed(which);
    const HapticModel& tool = Seed(kAll[(static_cast<int>(which) + 3) % 6]);
    double radius = 0.0;
    for (const glm::dvec3& p : tool.vertices_O) radius = std::max(radius, glm::length(p));
    TriangleBoxTree tree;
    tree.Build(tool);
    for (int trial = 0; trial < 8; ++trial) {
      const int n = trial % 2 == 0 ? 50 : 25;
      const Contact c = RandomContact(tool, env, rng, n);
      const GradientSteps h = GradientSteps::For(c.window);
      SelectPatchTriangles(tool, c.X_WT, c.window, PatchSide::kTool,
                           2.0 * h.h_x + h.h_theta * radius, global, h.h_theta + 1e-9);
      SelectPatchTriangles(tool, c.X_WT, c.window, PatchSide::kTool, 2.0 * h.h_x, local,
                           h.h_theta + 1e-9, nullptr, trial % 2 == 0 ? &tree : nullptr, h.h_theta);
      ASSERT_TRUE(std::includes(global.begin(), global.end(), local.begin(), local.end()));
      local_total += static_cast<long>(local.size());
      global_total += static_cast<long>(global.size());
      const auto poses = GradientSamplePoses(c.X_WT, c.window);
      const auto cells = static_cast<std::size_t>(n) * n;
      for (std::size_t p = 0; p < poses.size(); ++p) {
        for (const int margin : {0, 1}) {
          if (margin == 1 && p != 0) continue;
          const auto size = static_cast<std::size_t>(n + 2 * margin) * (n + 2 * margin);
          std::vector<float> a(size, std::numeric_limits<float>::infinity()), b = a;
          RenderPatchHeightsFast(tool, poses[p], global, c.window, PatchSide::kTool, margin, a);
          RenderPatchHeightsFast(tool, poses[p], local, c.window, PatchSide::kTool, margin, b);
          ASSERT_EQ(0, std::memcmp(a.data(), b.data(), size * sizeof(float)))
              << SeedModelName(which) << " trial " << trial << " pose " << p;
          if (margin == 0) {
            for (std::size_t k = 0; k < cells; ++k) covered += std::isfinite(a[k]) ? 1 : 0;
          }
        }
      }
    }
  }
  EXPECT_GT(covered, 20000);             // the renders draw
  EXPECT_LT(local_total, global_total);  // and the own margins leave triangles out
  RecordProperty("local_triangles", std::to_string(local_total));
  RecordProperty("global_triangles", std::to_string(global_total));
}

TEST(TextureStageParity, EnvironmentMaxPyramidBoundsEveryBox) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> h(-1e-3f, 1e-3f);
  for (const int n : {1, 2, 37, 50, 64}) {
    std::vector<float> env(static_cast<std::size_t>(n) * n);
    for (float& e : env) e = rng() % 5 == 0 ? -std::numeric_limits<float>::infinity() : h(rng);
    EnvironmentMaxPyramid pyramid;
    pyramid.Reserve(64);
    pyramid.Build(env, n);
    ASSERT_EQ(pyramid.resolution(), n);
    for (int trial = 0; trial < 2000; ++trial) {
      int i0 = static_cast<int>(rng() % n), i1 = static_cast<int>(rng() % n);
      int j0 = static_cast<int>(rng() % n), j1 = static_cast<int>(rng() % n);
      if (i0 > i1) std::swap(i0, i1);
      if (j0 > j1) std::swap(j0, j1);
      if (trial % 4 == 0) i1 = i0, j1 = j0;
      float want = -std::numeric_limits<float>::infinity();
      for (int j = j0; j <= j1; ++j)
        for (int i = i0; i <= i1; ++i) want = std::max(want, env[j * n + i]);
      const float got = pyramid.MaxOver(i0, i1, j0, j1);
      ASSERT_GE(got, want) << n << ": [" << i0 << ", " << i1 << "] x [" << j0 << ", " << j1 << "]";
      if (i0 == i1 && j0 == j1) {
        ASSERT_EQ(got, want);
      }
    }
    EXPECT_EQ(pyramid.MaxOver(3, 2, 0, 0), -std::numeric_limits<float>::infinity());
  }
  EnvironmentMaxPyramid small;
  small.Reserve(8);
  std::vector<float> big(100 * 100, 0.0f);
  small.Build(big, 100);  // beyond the reserve: builds nothing, allocates nothing
  EXPECT_EQ(small.resolution(), 0);
}

// The solver's rotation samples rendered culled (always, never, or where the base render says it
// pays): the same eleven samples, cells and linearizations, bit for bit, on random contacts of
// the six seed models; and the default both culls and does not over those contacts.
TEST(TextureStageParity, CulledRotationSamplesEqualTheWholeRenders) {
  std::mt19937 rng(2711);
  using C = TexturePenetrationSolver::CullRotations;
  TexturePenetrationSolver never(128, 4096), always(128, 4096), pays(128, 4096);
  never.set_cull_rotations(C::kNever);
  always.set_cull_rotations(C::kAlways);
  int in_contact = 0;
  for (const SeedModel which : kAll) {
    const HapticModel& env = Seed(which);
    for (const SeedModel tool_which : {SeedModel::kFile, SeedModel::kBlock, which}) {
      const HapticModel& tool = Seed(tool_which);
      for (int trial = 0; trial < 4; ++trial) {
        const Contact c = RandomContact(tool, env, rng, trial == 3 ? 37 : 50);
        std::array<DepthSample, kGradientSamples> sn{}, sa{}, sp{};
        const ContactLinearization n =
            never.Linearize(tool, c.X_WT, env, c.X_WO, c.window, 8000.0, sn);
        const ContactLinearization a =
            always.Linearize(tool, c.X_WT, env, c.X_WO, c.window, 8000.0, sa);
        const ContactLinearization p =
            pays.Linearize(tool, c.X_WT, env, c.X_WO, c.window, 8000.0, sp);
        in_contact += std::isfinite(n.depth_m) ? 1 : 0;
        for (int i = 0; i < kGradientSamples; ++i) {
          ASSERT_EQ(sa[i].cell, sn[i].cell) << SeedModelName(which) << " sample " << i;
          ASSERT_EQ(sp[i].cell, sn[i].cell) << SeedModelName(which) << " sample " << i;
          ASSERT_EQ(0, std::memcmp(&sa[i].depth_m, &sn[i].depth_m, sizeof(double))) << i;
          ASSERT_EQ(0, std::memcmp(&sp[i].depth_m, &sn[i].depth_m, sizeof(double))) << i;
        }
        EXPECT_EQ(a.gradient.d_rotation_W, n.gradient.d_rotation_W);
        EXPECT_EQ(p.gradient.d_rotation_W, n.gradient.d_rotation_W);
        EXPECT_EQ(p.gradient.d_translation_W, n.gradient.d_translation_W);
      }
    }
  }
  EXPECT_GT(in_contact, 30);
  EXPECT_EQ(never.culled_contacts(), 0u);
  EXPECT_EQ(always.culled_contacts(), static_cast<std::uint64_t>(in_contact));
  // The default culls some contacts and renders others whole.
  EXPECT_GT(pays.culled_contacts(), 0u);
  EXPECT_LT(pays.culled_contacts(), static_cast<std::uint64_t>(in_contact));
  std::printf("[ parity ] %d contacts in contact; culled by default: %llu\n", in_contact,
              static_cast<unsigned long long>(pays.culled_contacts()));
}

TEST(TextureStageParity, ABatchOnTwoThreadsEqualsTheBatchOnOne) {
  // Contacts of one tool against two seed models, as one batch: the same linearizations, bit for
  // bit, whichever thread of the pool takes a contact.
  std::mt19937 rng(99);
  const HapticModel& tool = Seed(SeedModel::kFile);
  std::vector<ContactQuery> queries;
  RigidTransform X_WT;
  for (int i = 0; i < 14; ++i) {
    const HapticModel& env = Seed(i % 2 == 0 ? SeedModel::kCadPart : SeedModel::kGear);
    const Contact c = RandomContact(tool, env, rng, 50);
    if (i == 0) X_WT = c.X_WT;
    // One tool pose for the batch (as in a remote step): windows where the first contact put it.
    queries.push_back({&env, c.X_WO, c.window, 8000.0});
  }
  CpuPenetrationDepthBackend one(128, TextureStagePath::kFast, 1);
  CpuPenetrationDepthBackend two(128, TextureStagePath::kFast, 2);
  EXPECT_EQ(two.threads(), 2);
  std::vector<ContactLinearization> a(queries.size()), b(queries.size());
  std::vector<DepthSample> sa(queries.size() * kGradientSamples),
      sb(queries.size() * kGradientSamples);
  for (int repeat = 0; repeat < 3; ++repeat) {
    ASSERT_TRUE(one.LinearizeBatch(tool, X_WT, queries, a, sa));
    ASSERT_TRUE(two.LinearizeBatch(tool, X_WT, queries, b, sb));
    for (std::size_t i = 0; i < queries.size(); ++i) {
      EXPECT_EQ(a[i].depth_m, b[i].depth_m) << i;
      EXPECT_EQ(a[i].gradient.d_translation_W, b[i].gradient.d_translation_W) << i;
      EXPECT_EQ(a[i].gradient.d_rotation_W, b[i].gradient.d_rotation_W) << i;
    }
    for (std::size_t k = 0; k < sa.size(); ++k) EXPECT_EQ(sa[k].cell, sb[k].cell) << k;
  }
  // One contact: its seven tool renders become tasks of the two threads; the same result.
  for (std::size_t i = 0; i < queries.size(); ++i) {
    const std::span<const ContactQuery> single(&queries[i], 1);
    ContactLinearization la, lb;
    ASSERT_TRUE(one.LinearizeBatch(tool, X_WT, single, std::span<ContactLinearization>(&la, 1)));
    ASSERT_TRUE(two.LinearizeBatch(tool, X_WT, single, std::span<ContactLinearization>(&lb, 1)));
    EXPECT_EQ(la.depth_m, lb.depth_m) << i;
    EXPECT_EQ(la.gradient.d_translation_W, lb.gradient.d_translation_W) << i;
    EXPECT_EQ(la.gradient.d_rotation_W, lb.gradient.d_rotation_W) << i;
  }
  EXPECT_EQ(one.faults().missing_overlap, two.faults().missing_overlap);
}

// The coarse query's local reach (issue 15): two routes to one set of pairs. With local reach on,
// the query must report exactly those pairs of the global-tolerance query whose signed distance
// is within the pair's own tolerance (the two leaves' reaches plus the margin).
TEST(LocalReach, ReportsTheGlobalPairsWithinEachPairsOwnTolerance) {
  const HapticModel& file = Seed(SeedModel::kFile);
  const HapticModel& part = Seed(SeedModel::kCadPart);
  HullProximityQuery global_query(1 << 14), local_query(1 << 14);
  const HullBounds file_bounds = HullBounds::Of(file), part_bounds = HullBounds::Of(part);
  // Node reaches: within [0, OutwardReach()], a parent at least its children.
  for (const HapticModel* m : {&file, &part}) {
    const auto& nodes = m->hull_hierarchy.nodes;
    const HullBounds& bounds = m == &file ? file_bounds : part_bounds;
    ASSERT_FALSE(nodes.empty());
    for (std::size_t k = 0; k < nodes.size(); ++k) {
      const double r = bounds.Reach(static_cast<int>(k));
      EXPECT_GE(r, 0.0);
      EXPECT_LE(r, m->OutwardReach());
      for (const int c : nodes[k].children) {
        if (c >= 0) {
          EXPECT_GE(r, bounds.Reach(c));
        }
      }
    }
  }
  const double margin = 0.5e-3;
  std::mt19937 rng(77);
  int compared = 0, dropped = 0;
  for (int trial = 0; trial < 12; ++trial) {
    const Contact c = RandomContact(file, part, rng, 50);
    ProximityQueryOptions global;
    global.tolerance_m = file.OutwardReach() + part.OutwardReach() + margin;
    global.max_pairs = 1 << 14;
    global.temporal_coherence = false;
    ProximityQueryOptions local = global;
    local.local_reach_margin_m = margin;
    const auto g = global_query.Query(file, file_bounds, c.X_WT, part, part_bounds, c.X_WO, global);
    std::set<std::pair<int, int>> want;
    for (const HullPairContact& p : g) {
      const double own = std::min(
          global.tolerance_m, file_bounds.Reach(p.node_A) + part_bounds.Reach(p.node_B) + margin);
      if (p.signed_distance_m <= own) {
        want.insert({p.node_A, p.node_B});
      } else {
        ++dropped;
      }
    }
    std::set<std::pair<int, int>> got;
    for (const HullPairContact& p :
         local_query.Query(file, file_bounds, c.X_WT, part, part_bounds, c.X_WO, local)) {
      got.insert({p.node_A, p.node_B});
    }
    // Pairs within 1e-9 m of their tolerance may go either way (GJK's early exit): compare the
    // rest exactly.
    for (const HullPairContact& p : g) {
      const double own = std::min(
          global.tolerance_m, file_bounds.Reach(p.node_A) + part_bounds.Reach(p.node_B) + margin);
      if (std::abs(p.signed_distance_m - own) < 1e-9) {
        want.erase({p.node_A, p.node_B});
        got.erase({p.node_A, p.node_B});
      }
    }
    EXPECT_EQ(want, got) << "trial " << trial;
    compared += static_cast<int>(g.size());
  }
  EXPECT_GT(compared, 100);
  EXPECT_GT(dropped, 0);  // local reach really drops far pairs on these models
}

TEST(TextureStageParity, ShiftedDepthEqualsTheDepthOfAnExplicitlyShiftedBuffer) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> U(-1e-3f, 1e-3f);
  const int n = 20, nt = n + 2;
  std::vector<float> b(n * n), a_ext(nt * nt);
  for (float& v : b) v = U(rng);
  for (float& v : a_ext) v = U(rng);
  b[17] = -std::numeric_limits<float>::infinity();
  a_ext[40] = std::numeric_limits<float>::infinity();
  for (int dj = -1; dj <= 1; ++dj) {
    for (int di = -1; di <= 1; ++di) {
      std::vector<float> a(n * n);
      for (int j = 0; j < n; ++j) {
        for (int i = 0; i < n; ++i) a[j * n + i] = a_ext[(j + 1 + dj) * nt + (i + 1 + di)];
      }
      const DepthSample want = DirectionalPenetrationDepth(b, a);
      const DepthSample got = DirectionalPenetrationDepthShifted(b, n, a_ext, 1, di, dj);
      EXPECT_EQ(want.cell, got.cell);
      EXPECT_EQ(want.depth_m, got.depth_m);
    }
  }
  // Out-of-range offsets give no overlap rather than reading outside the buffer.
  EXPECT_EQ(DirectionalPenetrationDepthShifted(b, n, a_ext, 1, 2, 0).cell, -1);
}

// The coarse-query parity tests' scenes (tool, object): the seed's Fig. 77 and Fig. 73.
constexpr std::pair<SeedModel, SeedModel> kCoarseScenes[] = {
    {SeedModel::kFile, SeedModel::kCadPart}, {SeedModel::kHammer, SeedModel::kTorus}};

// Pair by pair: the same leaf nodes, and the same signed distance, normal and witness bits.
void ExpectSamePairs(const std::vector<HullPairContact>& want, std::span<const HullPairContact> got,
                     const char* what) {
  ASSERT_EQ(want.size(), got.size()) << what;
  for (std::size_t k = 0; k < want.size(); ++k) {
    ASSERT_EQ(want[k].node_A, got[k].node_A) << what << " pair " << k;
    ASSERT_EQ(want[k].node_B, got[k].node_B) << what << " pair " << k;
    EXPECT_EQ(want[k].signed_distance_m, got[k].signed_distance_m) << what << " pair " << k;
    EXPECT_EQ(want[k].normal_W, got[k].normal_W) << what << " pair " << k;
    EXPECT_EQ(want[k].point_A_W, got[k].point_A_W) << what << " pair " << k;
    EXPECT_EQ(want[k].point_B_W, got[k].point_B_W) << what << " pair " << k;
  }
}

// Internal node pairs' GJK stopping once the hulls are within the tolerance (the default without
// a budget) against running it to the exact distance: the same leaf pairs, contacts and order,
// bit for bit, over a sequence of nearby poses with temporal coherence on (so the coherent
// directions carried from call to call are compared too), at the product's tolerance (both
// outward reaches plus the pipeline's margin) on the file and CAD part and on hammer and torus.
TEST(CoarseQueryParity, StoppingInternalGjkWithinTheToleranceReportsTheSamePairs) {
  std::mt19937 rng(1501);
  int compared = 0;
  for (const auto& [tool_model, env_model] : kCoarseScenes) {
    const HapticModel& tool = Seed(tool_model);
    const HapticModel& env = Seed(env_model);
    const HullBounds tool_bounds = HullBounds::Of(tool), env_bounds = HullBounds::Of(env);
    HullProximityQuery exact_query(1 << 14), near_query(1 << 14);
    ProximityQueryOptions exact;
    exact.tolerance_m = tool.OutwardReach() + env.OutwardReach() + 0.5e-3;
    exact.max_pairs = 1 << 14;
    exact.exact_internal_distances = true;
    ProximityQueryOptions near = exact;
    near.exact_internal_distances = false;
    std::uniform_real_distribution<double> U(-1.0, 1.0);
    for (int trial = 0; trial < 6; ++trial) {
      Contact c = RandomContact(tool, env, rng, 50);
      for (int frame = 0; frame < 5; ++frame) {
        // Slide by up to 0.2 mm per frame.
        c.X_WT.translation += 0.2e-3 * glm::dvec3(U(rng), U(rng), U(rng));
        const auto a = exact_query.Query(tool, tool_bounds, c.X_WT, env, env_bounds, c.X_WO, exact);
        const std::vector<HullPairContact> want(a.begin(), a.end());
        ExpectSamePairs(want,
                        near_query.Query(tool, tool_bounds, c.X_WT, env, env_bounds, c.X_WO, near),
                        SeedModelName(tool_model));
        compared += static_cast<int>(want.size());
      }
    }
  }
  EXPECT_GT(compared, 500);
}

// The coarse query's traversal on two threads against one: the same pairs, contacts, order and
// counts, over a sequence of nearby poses with coherence (each side carries its own directions
// and its own front, which two threads re-test in blocks on their workers), at the product's
// tolerance, with and without local reach.
TEST(CoarseQueryParity, TwoThreadsReportWhatOneReports) {
  std::mt19937 rng(1502);
  int compared = 0, culls = 0, fronts = 0;
  for (const auto& [tool_model, env_model] : kCoarseScenes) {
    const HapticModel& tool = Seed(tool_model);
    const HapticModel& env = Seed(env_model);
    const HullBounds tool_bounds = HullBounds::Of(tool), env_bounds = HullBounds::Of(env);
    for (const bool local : {false, true}) {
      HullProximityQuery one(1 << 14), two(1 << 14);
      two.SetThreads(2);
      ASSERT_EQ(two.threads(), 2);
      ProximityQueryOptions options;
      options.tolerance_m = tool.OutwardReach() + env.OutwardReach() + 0.5e-3;
      options.max_pairs = 1 << 14;
      if (local) options.local_reach_margin_m = 0.5e-3;
      std::uniform_real_distribution<double> U(-1.0, 1.0);
      for (int trial = 0; trial < 4; ++trial) {
        Contact c = RandomContact(tool, env, rng, 50);
        for (int frame = 0; frame < 5; ++frame) {
          c.X_WT.translation += 0.2e-3 * glm::dvec3(U(rng), U(rng), U(rng));
          ProximityQueryStats s1, s2;
          const auto a =
              one.Query(tool, tool_bounds, c.X_WT, env, env_bounds, c.X_WO, options, &s1);
          const std::vector<HullPairContact> want(a.begin(), a.end());
          const auto got =
              two.Query(tool, tool_bounds, c.X_WT, env, env_bounds, c.X_WO, options, &s2);
          ExpectSamePairs(want, got, SeedModelName(tool_model));
          EXPECT_EQ(s1.node_pairs_tested, s2.node_pairs_tested);
          EXPECT_EQ(s1.leaf_pairs_tested, s2.leaf_pairs_tested);
          EXPECT_EQ(s1.node_pairs_culled, s2.node_pairs_culled);
          EXPECT_EQ(s1.coherent_hits, s2.coherent_hits);
          EXPECT_EQ(s1.coherent_culls, s2.coherent_culls);
          EXPECT_EQ(s1.front_pairs, s2.front_pairs);
          fronts += s1.front_pairs > 0;
          EXPECT_EQ(s1.pairs_dropped, s2.pairs_dropped);
          compared += static_cast<int>(want.size());
          culls += s1.coherent_culls;
        }
      }
    }
  }
  EXPECT_GT(compared, 500);
  EXPECT_GT(culls, 0);   // the previous call's separating directions were used on both sides
  EXPECT_GT(fronts, 0);  // and their fronts (on the workers with two threads)
  HullProximityQuery q;
  EXPECT_THROW(q.SetThreads(0), std::invalid_argument);
  EXPECT_THROW(q.SetThreads(257), std::invalid_argument);
}

}  // namespace
}  // namespace ht
