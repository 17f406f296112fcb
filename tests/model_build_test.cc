// The haptic model build: quadric decimation, the whole pipeline, mass properties and the cache.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <glm/glm.hpp>
#include <limits>
#include <map>
#include <numbers>
#include <set>
#include <utility>

#include "accuracy_test_meshes.h"
#include "haptic_core/model_build/haptic_model_build.h"
#include "haptic_core/model_build/mesh_decimation.h"
#include "haptic_core/model_build/surface_error.h"

namespace ht {
namespace {

using test::UvSphere;

// Counts one-sided edges and edges used in the same direction twice (orientation faults).
std::pair<int, int> BoundaryAndFlippedEdges(const TriangleMesh& m) {
  std::map<std::pair<int, int>, int> directed;
  for (const auto& t : m.triangles) {
    for (int c = 0; c < 3; ++c) ++directed[{t[c], t[(c + 1) % 3]}];
  }
  int boundary = 0, flipped = 0;
  for (const auto& [e, n] : directed) {
    if (n > 1) ++flipped;
    if (directed.find({e.second, e.first}) == directed.end()) ++boundary;
  }
  return {boundary, flipped};
}

double SignedVolume(const TriangleMesh& m) {
  double v = 0;
  for (const auto& t : m.triangles) {
    v += glm::dot(m.vertices[t.x], glm::cross(m.vertices[t.y], m.vertices[t.z])) / 6.0;
  }
  return v;
}

TEST(MeshDecimation, ClosedSphereStaysClosedOrientedAndNearTheTarget) {
  const TriangleMesh full = UvSphere(0.05, 60, 120);
  ASSERT_EQ(BoundaryAndFlippedEdges(full), std::make_pair(0, 0));
  const DecimationResult r = DecimateQuadric(full, 500);
  EXPECT_EQ(r.input_triangles, static_cast<std::int64_t>(full.triangles.size()));
  EXPECT_LE(r.mesh.triangles.size(), 500u);
  EXPECT_GE(r.mesh.triangles.size(), 490u);
  EXPECT_EQ(r.input_boundary_edges, 0);
  EXPECT_EQ(r.output_boundary_edges, 0);
  EXPECT_EQ(BoundaryAndFlippedEdges(r.mesh), std::make_pair(0, 0));
  // Euler characteristic of a sphere: V − E + F = 2 with E = 3F/2.
  EXPECT_EQ(static_cast<int>(r.mesh.vertices.size()) -
                static_cast<int>(3 * r.mesh.triangles.size() / 2) +
                static_cast<int>(r.mesh.triangles.size()),
            2);
  // Quadric collapses keep vertices near the surface: the volume stays near 4/3 π r³.
  const double exact = 4.0 / 3.0 * std::numbers::pi * std::pow(0.05, 3);
  EXPECT_NEAR(SignedVolume(r.mesh), exact, 0.03 * exact);
  for (const auto& p : r.mesh.vertices) EXPECT_NEAR(glm::length(p), 0.05, 0.002);
}

TEST(MeshDecimation, SplitVerticesAreWeldedSoACubeWithSeamsIsOneClosedSurface) {
  // A cube whose 6 faces each have their own 4 vertices (as glTF files store flat-shaded boxes).
  TriangleMesh cube;
  const glm::dvec3 n[6] = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
  for (const auto& normal : n) {
    const glm::dvec3 u = std::abs(normal.x) > 0.5 ? glm::dvec3(0, 1, 0) : glm::dvec3(1, 0, 0);
    const glm::dvec3 v = glm::cross(normal, u);
    const int base = static_cast<int>(cube.vertices.size());
    for (const auto& [a, b] : {std::pair{-1, -1}, {1, -1}, {1, 1}, {-1, 1}}) {
      cube.vertices.push_back(0.01 * (normal + double(a) * u + double(b) * v));
    }
    cube.triangles.emplace_back(base, base + 1, base + 2);
    cube.triangles.emplace_back(base, base + 2, base + 3);
  }
  const DecimationResult r = DecimateQuadric(cube, 100);
  EXPECT_EQ(r.input_vertices, 24);
  EXPECT_EQ(r.welded_vertices, 8);
  EXPECT_EQ(r.dropped_non_manifold_triangles, 0);
  EXPECT_EQ(r.input_boundary_edges, 0);
  EXPECT_EQ(r.mesh.triangles.size(), 12u);
  EXPECT_EQ(BoundaryAndFlippedEdges(r.mesh), std::make_pair(0, 0));
  EXPECT_NEAR(SignedVolume(r.mesh), 8e-6, 1e-12);
}

TEST(MeshDecimation, NonManifoldTrianglesAreCountedAndLeftOut) {
  TriangleMesh m;
  m.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0.5, 0.5, 1}};
  // Three triangles on edge (0,1): the third makes it non-manifold.
  m.triangles = {{0, 1, 2}, {1, 0, 3}, {0, 1, 4}};
  const DecimationResult r = DecimateQuadric(m, 100);
  EXPECT_EQ(r.dropped_non_manifold_triangles, 1);
  EXPECT_EQ(r.mesh.triangles.size(), 2u);
  EXPECT_EQ(r.output_boundary_edges, 4);
  EXPECT_EQ(r.mesh.vertices.size(), 4u);  // the isolated vertex is gone
}

TEST(MeshDecimation, BadInputThrows) {
  TriangleMesh m = UvSphere(1.0, 4, 6);
  EXPECT_THROW(DecimateQuadric(m, 3), std::invalid_argument);
  TriangleMesh out_of_range = m;
  out_of_range.triangles[2].y = 1000;
  EXPECT_THROW(DecimateQuadric(out_of_range, 10), std::invalid_argument);
  TriangleMesh nan = m;
  nan.vertices[3].x = std::nan("");
  EXPECT_THROW(DecimateQuadric(nan, 10), std::invalid_argument);
  EXPECT_THROW(DecimateQuadric(TriangleMesh{}, 10), std::runtime_error);
}

// A sphere of radius r whose surface carries bumps of amplitude a: r(θ,φ) = r +
// a·sin(10θ)·sin(12φ).
TriangleMesh BumpySphere(double r, double a, int n_lat, int n_lon) {
  TriangleMesh m = UvSphere(1.0, n_lat, n_lon);
  for (glm::dvec3& p : m.vertices) {
    const double th = std::acos(std::clamp(p.z, -1.0, 1.0)), ph = std::atan2(p.y, p.x);
    p *= r + a * std::sin(10 * th) * std::sin(12 * ph);
  }
  return m;
}

HapticModelBuildParams SmallParams() {
  HapticModelBuildParams p;
  p.coarse_triangles = 300;
  p.texture.texture_size = 256;
  p.texture.validation_samples = 4000;
  return p;
}

TEST(HapticModelBuild, BumpySphereGivesAClosedCoarseMeshATextureThatHoldsTheBumpsAndHulls) {
  const double r = 0.05, a = 0.5e-3;
  const TriangleMesh full = BumpySphere(r, a, 100, 200);
  const HapticModelBuild b = BuildHapticModel("bumpy", full, SmallParams());
  const HapticModel& m = *b.model;
  EXPECT_NO_THROW(m.Validate());
  EXPECT_EQ(b.report.full_triangles, static_cast<std::int64_t>(full.triangles.size()));
  EXPECT_EQ(m.full_resolution_triangles, b.report.full_triangles);
  EXPECT_LE(b.report.coarse_triangles, 300);
  EXPECT_GE(b.report.coarse_triangles, 290);
  EXPECT_EQ(b.report.coarse_boundary_edges, 0);
  // The texture holds what the coarse mesh dropped: heights of the order of the bumps (plus the
  // coarse mesh's chordal gap), and the bake reproduces its own rays to a small fraction of them.
  EXPECT_GT(b.report.bake.max_abs_height_m, 0.5 * a);
  EXPECT_LT(b.report.bake.max_abs_height_m, 10 * a);
  EXPECT_LT(b.report.bake.rms_bake_error_m, 0.2 * a);
  EXPECT_EQ(b.report.bake.misses, 0);
  EXPECT_EQ(b.report.texture_size, 256);
  // Hulls: a valid hierarchy whose root bounds every coarse vertex.
  ASSERT_GE(b.report.hull_nodes, 1);
  EXPECT_NO_THROW(m.hull_hierarchy.Validate(m.vertices_O, m.triangles, 1e-6));
  EXPECT_EQ(m.hull_vertices_O.size(), m.hull_hierarchy.nodes.front().hull.vertices_O.size());
  // Mass properties of a solid sphere at 1000 kg/m³: m = ρ·4/3·π·r³, I = 2/5·m·r².
  const double mass = 1000.0 * 4.0 / 3.0 * std::numbers::pi * r * r * r;
  EXPECT_NEAR(m.mass_kg, mass, 0.05 * mass);
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(m.inertia_diagonal_O[i], 0.4 * mass * r * r, 0.08 * 0.4 * mass * r * r);
    EXPECT_NEAR(m.center_of_mass_O[i], 0.0, 1e-3 * r);
  }
}

TEST(HapticModelBuild, BoxMassPropertiesMatchTheClosedForm) {
  // An off-centre 4 × 2 × 1 cm box: m = ρabc, I_xx = m(b²+c²)/12, centre of mass at its centre.
  TriangleMesh box;
  const glm::dvec3 c{0.1, -0.2, 0.3}, h{0.02, 0.01, 0.005};
  for (int i = 0; i < 8; ++i) {
    box.vertices.push_back(c +
                           glm::dvec3(i & 1 ? h.x : -h.x, i & 2 ? h.y : -h.y, i & 4 ? h.z : -h.z));
  }
  box.triangles = {{0, 2, 1}, {1, 2, 3}, {4, 5, 6}, {5, 7, 6}, {0, 1, 4}, {1, 5, 4},
                   {2, 6, 3}, {3, 6, 7}, {0, 4, 2}, {2, 4, 6}, {1, 3, 5}, {3, 7, 5}};
  ASSERT_EQ(BoundaryAndFlippedEdges(box), std::make_pair(0, 0));
  ASSERT_GT(SignedVolume(box), 0.0);
  HapticModelBuildParams p = SmallParams();
  p.texture.texture_size = 64;
  p.density_kg_per_m3 = 2700.0;
  const HapticModelBuild b = BuildHapticModel("box", box, p);
  const double a = 2 * h.x, bb = 2 * h.y, cc = 2 * h.z, mass = 2700.0 * a * bb * cc;
  EXPECT_NEAR(b.model->mass_kg, mass, 1e-9 * mass);
  EXPECT_NEAR(b.model->center_of_mass_O.x, c.x, 1e-12);
  EXPECT_NEAR(b.model->center_of_mass_O.y, c.y, 1e-12);
  EXPECT_NEAR(b.model->center_of_mass_O.z, c.z, 1e-12);
  EXPECT_NEAR(b.model->inertia_diagonal_O.x, mass * (bb * bb + cc * cc) / 12, 1e-9 * mass * a * a);
  EXPECT_NEAR(b.model->inertia_diagonal_O.y, mass * (a * a + cc * cc) / 12, 1e-9 * mass * a * a);
  EXPECT_NEAR(b.model->inertia_diagonal_O.z, mass * (a * a + bb * bb) / 12, 1e-9 * mass * a * a);
  // A box is convex: one hull.
  EXPECT_EQ(b.report.hull_nodes, 1);
  EXPECT_EQ(b.report.coarse_triangles, 12);
}

class HapticModelCacheTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() /
           ("ht_model_cache_" + std::to_string(::testing::UnitTest::GetInstance()->random_seed()) +
            "_" + ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::remove_all(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::filesystem::path dir_;
};

void ExpectSameModel(const HapticModel& a, const HapticModel& b) {
  ASSERT_EQ(a.vertices_O.size(), b.vertices_O.size());
  for (std::size_t i = 0; i < a.vertices_O.size(); ++i) EXPECT_EQ(a.vertices_O[i], b.vertices_O[i]);
  ASSERT_EQ(a.triangles.size(), b.triangles.size());
  for (std::size_t i = 0; i < a.triangles.size(); ++i) EXPECT_EQ(a.triangles[i], b.triangles[i]);
  EXPECT_EQ(a.corner_uvs, b.corner_uvs);
  EXPECT_EQ(a.textured, b.textured);
  EXPECT_EQ(a.texel_size_m, b.texel_size_m);
  ASSERT_EQ(a.texture.num_levels(), b.texture.num_levels());
  for (int l = 0; l < a.texture.num_levels(); ++l) {
    EXPECT_EQ(a.texture.level(l).texels, b.texture.level(l).texels) << "level " << l;
  }
  ASSERT_EQ(a.hull_hierarchy.nodes.size(), b.hull_hierarchy.nodes.size());
  for (std::size_t i = 0; i < a.hull_hierarchy.nodes.size(); ++i) {
    EXPECT_EQ(a.hull_hierarchy.nodes[i].triangles, b.hull_hierarchy.nodes[i].triangles);
    EXPECT_EQ(a.hull_hierarchy.nodes[i].hull.vertices_O.size(),
              b.hull_hierarchy.nodes[i].hull.vertices_O.size());
  }
  EXPECT_EQ(a.mass_kg, b.mass_kg);
  EXPECT_EQ(a.inertia_diagonal_O, b.inertia_diagonal_O);
}

TEST_F(HapticModelCacheTest, SecondBuildComesFromTheCacheAndEqualsTheFirst) {
  const TriangleMesh full = BumpySphere(0.05, 0.5e-3, 40, 80);
  const HapticModelCache cache(dir_.string());
  const HapticModelBuild first = BuildHapticModelCached("s", full, SmallParams(), cache);
  EXPECT_FALSE(first.report.from_cache);
  EXPECT_EQ(first.report.cache_note, "");
  EXPECT_TRUE(std::filesystem::exists(dir_ / (first.report.cache_key + ".htmodel")));
  const HapticModelBuild second = BuildHapticModelCached("s", full, SmallParams(), cache);
  EXPECT_TRUE(second.report.from_cache);
  EXPECT_EQ(second.report.cache_key, first.report.cache_key);
  EXPECT_EQ(second.report.hull_nodes, first.report.hull_nodes);
  EXPECT_EQ(second.report.bake.max_bake_error_m, first.report.bake.max_bake_error_m);
  ExpectSameModel(*first.model, *second.model);
}

TEST_F(HapticModelCacheTest, AChangedMeshOrParameterRebuilds) {
  TriangleMesh full = BumpySphere(0.05, 0.5e-3, 30, 60);
  const HapticModelCache cache(dir_.string());
  const std::string key = HapticModelCacheKey(full, SmallParams());
  EXPECT_EQ(key.size(), 64u);
  EXPECT_EQ(key, HapticModelCacheKey(full, SmallParams()));
  BuildHapticModelCached("s", full, SmallParams(), cache);
  HapticModelBuildParams other = SmallParams();
  other.texture.texture_size = 512;
  EXPECT_NE(HapticModelCacheKey(full, other), key);
  EXPECT_FALSE(BuildHapticModelCached("s", full, other, cache).report.from_cache);
  other = SmallParams();
  other.coarse_triangles = 200;
  EXPECT_NE(HapticModelCacheKey(full, other), key);
  full.vertices[7].x = std::nextafter(full.vertices[7].x, 1.0);  // one ulp
  EXPECT_NE(HapticModelCacheKey(full, SmallParams()), key);
  EXPECT_FALSE(BuildHapticModelCached("s", full, SmallParams(), cache).report.from_cache);
  EXPECT_EQ(std::distance(std::filesystem::directory_iterator(dir_),
                          std::filesystem::directory_iterator()),
            3);
}

TEST_F(HapticModelCacheTest, DamagedEntriesAreRebuiltAndOverwritten) {
  const TriangleMesh full = BumpySphere(0.05, 0.5e-3, 30, 60);
  const HapticModelCache cache(dir_.string());
  const HapticModelBuild first = BuildHapticModelCached("s", full, SmallParams(), cache);
  const auto path = dir_ / (first.report.cache_key + ".htmodel");
  const auto size = std::filesystem::file_size(path);
  // Truncated.
  std::filesystem::resize_file(path, size / 2);
  HapticModelBuild again = BuildHapticModelCached("s", full, SmallParams(), cache);
  EXPECT_FALSE(again.report.from_cache);
  EXPECT_TRUE(again.report.cache_note.find("truncated") != std::string::npos ||
              again.report.cache_note.find("exceeds the file") != std::string::npos)
      << again.report.cache_note;
  EXPECT_EQ(std::filesystem::file_size(path), size);  // rewritten whole
  // A NaN written over a vertex coordinate (bytes just past the name).
  {
    std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(8 + 4 + 8 + 64 + 8 + 1 + 8);
    const double nan = std::nan("");
    f.write(reinterpret_cast<const char*>(&nan), 8);
  }
  again = BuildHapticModelCached("s", full, SmallParams(), cache);
  EXPECT_FALSE(again.report.from_cache);
  EXPECT_NE(again.report.cache_note.find("non-finite"), std::string::npos)
      << again.report.cache_note;
  // Garbage.
  { std::ofstream(path, std::ios::binary | std::ios::trunc) << "not a model at all"; }
  again = BuildHapticModelCached("s", full, SmallParams(), cache);
  EXPECT_FALSE(again.report.from_cache);
  EXPECT_FALSE(again.report.cache_note.empty());
  EXPECT_TRUE(BuildHapticModelCached("s", full, SmallParams(), cache).report.from_cache);
}

// TextureSizingParams' rule (issue 32) on surface errors of a known form e(S) = floor + c / S
// (the texture's share halves with each doubling, the coarse mesh's floor stays).
TEST(TextureSizing, SmallestSizeWithinBudgetElseBeforeADoublingThatDoesNotHelpElseTheLargest) {
  const auto curve = [](double floor_um, double c_um_texels) {
    return [=](int size) {
      SurfaceErrorReport r;
      r.samples = 4096;
      r.p99_m = (floor_um + c_um_texels / size) * 1e-6;
      return r;
    };
  };
  TextureSizingParams p;  // budget 10 µm, 15 %, 256..4096
  // 2 + 7168/S: 30, 16, 9 µm at 256, 512, 1024: the budget is met at 1024.
  TextureSizeChoice c = ChooseTextureSize(p, curve(2.0, 7168.0));
  EXPECT_EQ(c.size, 1024);
  ASSERT_EQ(c.trials.size(), 3u);
  EXPECT_EQ(c.trials[0].size, 256);
  EXPECT_EQ(c.trials[2].size, 1024);
  EXPECT_NEAR(c.trials[2].surface_p99_m, 9e-6, 1e-12);
  EXPECT_NE(c.reason.find("within the budget"), std::string::npos) << c.reason;
  // 20 + 7168/S: 48, 34, 27, 23.5 µm: 1024 → 2048 lowers it by 13 % (< 15 %), so 1024.
  c = ChooseTextureSize(p, curve(20.0, 7168.0));
  EXPECT_EQ(c.size, 1024);
  ASSERT_EQ(c.trials.size(), 4u);
  EXPECT_NE(c.reason.find("coarse mesh"), std::string::npos) << c.reason;
  // A floor of 40 µm and little texture detail: 256 already is as good as 512.
  c = ChooseTextureSize(p, curve(40.0, 512.0));
  EXPECT_EQ(c.size, 256);
  // Steady gains but a budget out of reach within max_size.
  p.max_size = 1024;
  c = ChooseTextureSize(p, curve(0.0, 20480.0));
  EXPECT_EQ(c.size, 1024);
  EXPECT_NE(c.reason.find("largest"), std::string::npos) << c.reason;
  // No measure: the first size is kept.
  c = ChooseTextureSize(p, [](int) { return SurfaceErrorReport{}; });
  EXPECT_EQ(c.size, 256);
  EXPECT_EQ(c.trials.size(), 1u);
  // Bad parameters.
  for (const auto& bad :
       {std::pair{100, 1024}, std::pair{512, 256}, std::pair{8, 64}, std::pair{256, 16384}}) {
    TextureSizingParams b;
    b.min_size = bad.first;
    b.max_size = bad.second;
    EXPECT_THROW(ChooseTextureSize(b, curve(0, 1)), std::invalid_argument);
  }
  TextureSizingParams b;
  b.surface_budget_m = 0.0;
  EXPECT_THROW(b.Validate(), std::invalid_argument);
  b = {};
  b.min_improvement = 1.0;
  EXPECT_THROW(b.Validate(), std::invalid_argument);
}

// The build chooses per object: at a 5 µm budget a smooth sphere (its texture holds the coarse
// mesh's chordal gap) needs a smaller atlas than the same sphere with 0.5 mm bumps (measured here:
// 17 / 4.7 / 1.7 µm at 256 / 512 / 1024 against 66 / 11 / 3.5 µm); the chosen model's surface
// error is the trial's (two routes: the trial measured a probe model, the report the finished
// one), and the choice survives the cache.
TEST_F(HapticModelCacheTest, TextureSizeFromDetailGrowsWithTheSurfacesDetailAndIsCached) {
  HapticModelBuildParams p = SmallParams();
  p.texture_sizing.from_detail = true;
  p.texture_sizing.min_size = 32;
  p.texture_sizing.max_size = 1024;
  p.texture_sizing.surface_budget_m = 5e-6;
  const HapticModelCache cache(dir_.string());
  const HapticModelBuild smooth =
      BuildHapticModelCached("smooth", UvSphere(0.05, 100, 200), p, cache);
  const TriangleMesh bumpy_mesh = BumpySphere(0.05, 0.5e-3, 100, 200);
  const HapticModelBuild bumpy = BuildHapticModelCached("bumpy", bumpy_mesh, p, cache);
  for (const HapticModelBuild* b : {&smooth, &bumpy}) {
    const HapticModelBuildReport& r = b->report;
    SCOPED_TRACE(r.name + ": " + r.texture_size_reason);
    for (const TextureSizeTrial& t : r.texture_trials) {
      std::printf("%s: %d texels, surface p99 %.3g um (%.2f s)\n", r.name.c_str(), t.size,
                  t.surface_p99_m * 1e6, t.seconds);
    }
    ASSERT_FALSE(r.texture_trials.empty());
    // 32² cannot hold 300 charts: the first size tried is the smallest that can.
    EXPECT_EQ(r.texture_trials.front().size, SmallestAtlasSize(300, 2));
    EXPECT_GT(r.texture_trials.front().size, 32);
    for (std::size_t i = 1; i < r.texture_trials.size(); ++i) {
      EXPECT_EQ(r.texture_trials[i].size, 2 * r.texture_trials[i - 1].size);
    }
    EXPECT_EQ(b->model->texture.level(0).width, r.texture_size);
    const auto chosen =
        std::find_if(r.texture_trials.begin(), r.texture_trials.end(),
                     [&](const TextureSizeTrial& t) { return t.size == r.texture_size; });
    ASSERT_NE(chosen, r.texture_trials.end());
    EXPECT_DOUBLE_EQ(chosen->surface_p99_m, r.surface.p99_m);
  }
  EXPECT_GT(bumpy.report.texture_size, smooth.report.texture_size);
  EXPECT_NE(HapticModelCacheKey(bumpy_mesh, p), HapticModelCacheKey(bumpy_mesh, SmallParams()));
  // Keys: a fixed-size build's does not see the sizing fields (older entries stay valid); a
  // sized build's does not see the bake's own size, and does see the budget.
  HapticModelBuildParams fixed = SmallParams();
  const std::string fixed_key = HapticModelCacheKey(bumpy_mesh, fixed);
  fixed.texture_sizing.surface_budget_m = 1e-6;
  fixed.texture_sizing.max_size = 512;
  EXPECT_EQ(HapticModelCacheKey(bumpy_mesh, fixed), fixed_key);
  HapticModelBuildParams sized = p;
  sized.texture.texture_size = 2048;
  EXPECT_EQ(HapticModelCacheKey(bumpy_mesh, sized), HapticModelCacheKey(bumpy_mesh, p));
  sized.texture_sizing.surface_budget_m = 4e-6;
  EXPECT_NE(HapticModelCacheKey(bumpy_mesh, sized), HapticModelCacheKey(bumpy_mesh, p));
  const HapticModelBuild again = BuildHapticModelCached("bumpy", bumpy_mesh, p, cache);
  EXPECT_TRUE(again.report.from_cache);
  EXPECT_EQ(again.report.texture_size, bumpy.report.texture_size);
  EXPECT_EQ(again.report.texture_size_reason, bumpy.report.texture_size_reason);
  ASSERT_EQ(again.report.texture_trials.size(), bumpy.report.texture_trials.size());
  EXPECT_EQ(again.report.texture_trials.back().surface_p99_m,
            bumpy.report.texture_trials.back().surface_p99_m);
  ExpectSameModel(*bumpy.model, *again.model);
}

TEST(HapticModelBuild, BadInputNamesTheModel) {
  TriangleMesh full = UvSphere(0.05, 10, 20);
  full.vertices[3].y = std::numeric_limits<double>::infinity();
  try {
    BuildHapticModel("wing", full, SmallParams());
    FAIL() << "expected a throw";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("wing"), std::string::npos) << e.what();
  }
  HapticModelBuildParams p = SmallParams();
  p.coarse_triangles = 2;
  EXPECT_THROW(BuildHapticModel("wing", UvSphere(0.05, 10, 20), p), std::invalid_argument);
}

// MeasureSurfaceError (issue 32), a closed form: a 1 cm square model at z = 0 (corner normals +z)
// under a full-resolution square at z = +50 µm. Untextured, every full-resolution point lies
// 50 µm outside the model; with a texture of constant h = 50 µm the model holds the surface
// exactly; a full-resolution square 50 µm below lies inside (distance 50 µm, none outside).
TEST(SurfaceError, AFlatSquareUnderAnOffsetSurfaceGivesTheOffset) {
  const double side = 0.01, off = 50e-6;
  HapticModel m;
  m.name = "square";
  m.vertices_O = {{0, 0, 0}, {side, 0, 0}, {side, side, 0}, {0, side, 0}};
  m.triangles = {{0, 1, 2}, {0, 2, 3}};
  m.corner_normals_O.assign(6, glm::dvec3(0, 0, 1));
  m.corner_uvs = {{0, 0}, {1, 0}, {1, 1}, {0, 0}, {1, 1}, {0, 1}};
  m.textured = {0, 0};
  m.texel_size_m = {side / 16, side / 16};
  m.texture = HeightField(16, 16, std::vector<float>(256, static_cast<float>(off)), false, false);
  const auto square_at = [&](double z) {
    TriangleMesh t;
    t.vertices = {{0, 0, z}, {side, 0, z}, {side, side, z}, {0, side, z}};
    t.triangles = {{0, 1, 2}, {0, 2, 3}};
    return t;
  };
  SurfaceErrorParams params;
  params.samples = 500;
  const SurfaceErrorReport untextured = MeasureSurfaceError(m, square_at(off), params);
  EXPECT_EQ(untextured.samples, 500);
  EXPECT_NEAR(untextured.p50_m, off, 1e-9);
  EXPECT_NEAR(untextured.max_m, off, 1e-9);
  EXPECT_NEAR(untextured.outside_p99_m, off, 1e-9);
  EXPECT_DOUBLE_EQ(untextured.share_outside, 1.0);
  const SurfaceErrorReport below = MeasureSurfaceError(m, square_at(-off), params);
  EXPECT_NEAR(below.p99_m, off, 1e-9);
  EXPECT_DOUBLE_EQ(below.outside_p99_m, 0.0);
  EXPECT_DOUBLE_EQ(below.share_outside, 0.0);
  m.textured = {1, 1};
  const SurfaceErrorReport textured = MeasureSurfaceError(m, square_at(off), params);
  EXPECT_LT(textured.max_m, 1e-9);
  EXPECT_DOUBLE_EQ(textured.share_outside, 0.0);
  // The same seed gives the same samples.
  EXPECT_DOUBLE_EQ(MeasureSurfaceError(m, square_at(off), params).p50_m, textured.p50_m);
  // A region: only the triangles near its centre are sampled; one that holds none throws.
  params.region_center_O = {0.25 * side, 0.75 * side, off};
  params.region_radius_m = 0.6 * side;
  m.textured = {0, 0};
  EXPECT_NEAR(MeasureSurfaceError(m, square_at(off), params).p50_m, off, 1e-9);
  params.region_center_O = {5 * side, 0, 0};
  EXPECT_THROW(MeasureSurfaceError(m, square_at(off), params), std::invalid_argument);
  params.region_radius_m = 0.0;
  params.samples = 0;
  EXPECT_THROW(MeasureSurfaceError(m, square_at(off), params), std::invalid_argument);
  EXPECT_THROW(MeasureSurfaceError(m, TriangleMesh{}, {}), std::invalid_argument);
}

// A built model: the bumpy sphere's texture holds the bumps that its coarse mesh drops, so the
// full-resolution surface lies far closer to the textured model than to its coarse mesh alone.
TEST(SurfaceError, TheBakedTextureHoldsTheBumpsTheCoarseMeshDrops) {
  const double r = 0.05, a = 0.5e-3;
  const TriangleMesh full = BumpySphere(r, a, 100, 200);
  const HapticModelBuild b = BuildHapticModel("bumpy", full, SmallParams());
  HapticModel coarse = *b.model;
  std::fill(coarse.textured.begin(), coarse.textured.end(), std::uint8_t{0});
  const SurfaceErrorReport with = MeasureSurfaceError(*b.model, full);
  const SurfaceErrorReport without = MeasureSurfaceError(coarse, full);
  EXPECT_GT(without.p95_m, 0.5 * a);
  EXPECT_LT(with.p95_m, 0.2 * a);
  EXPECT_LT(with.share_outside, 0.5 * without.share_outside);
}

}  // namespace
}  // namespace ht
