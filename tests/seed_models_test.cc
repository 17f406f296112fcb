#include "haptic_core/demo/seed_models.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <glm/geometric.hpp>
#include <limits>
#include <map>
#include <numbers>
#include <stdexcept>
#include <string>
#include <vector>

#include "haptic_core/demo/procedural_models.h"

namespace ht {
namespace {

// Generated once per test binary: the large models take a few tenths of a second each.
const TriangleMesh& Model(SeedModel m) {
  static std::map<SeedModel, TriangleMesh> cache;
  auto it = cache.find(m);
  if (it == cache.end()) it = cache.emplace(m, MakeSeedModelFullResolution(m)).first;
  return it->second;
}

// Directed edges (a, b) → triangle, sorted: the adjacency of a closed oriented mesh.
struct DirectedEdge {
  std::uint64_t key;
  int triangle;
  bool operator<(const DirectedEdge& o) const { return key < o.key; }
};
std::uint64_t EdgeKey(int a, int b) {
  return (static_cast<std::uint64_t>(static_cast<std::uint32_t>(a)) << 32) |
         static_cast<std::uint32_t>(b);
}
std::vector<DirectedEdge> SortedDirectedEdges(const TriangleMesh& mesh) {
  std::vector<DirectedEdge> edges;
  edges.reserve(3 * mesh.triangles.size());
  for (size_t t = 0; t < mesh.triangles.size(); ++t) {
    const glm::ivec3 f = mesh.triangles[t];
    for (int c = 0; c < 3; ++c)
      edges.push_back({EdgeKey(f[c], f[(c + 1) % 3]), static_cast<int>(t)});
  }
  std::sort(edges.begin(), edges.end());
  return edges;
}
int OppositeTriangle(const std::vector<DirectedEdge>& edges, int a, int b) {
  const auto it = std::lower_bound(edges.begin(), edges.end(), DirectedEdge{EdgeKey(b, a), 0});
  return it != edges.end() && it->key == EdgeKey(b, a) ? it->triangle : -1;
}

// Closed 2-manifold, consistently oriented: every directed edge appears once and its reverse once,
// so every undirected edge is shared by exactly two triangles traversing it in opposite
// directions. (Vertices with two fans would pass this; the Euler characteristic below catches the
// pinches that matter here.)
void ExpectClosedAndOriented(const TriangleMesh& mesh, const std::vector<DirectedEdge>& edges) {
  const int nv = static_cast<int>(mesh.vertices.size());
  for (const glm::ivec3& f : mesh.triangles) {
    for (int c = 0; c < 3; ++c) ASSERT_TRUE(f[c] >= 0 && f[c] < nv) << "index out of range";
    ASSERT_TRUE(f[0] != f[1] && f[1] != f[2] && f[2] != f[0]) << "repeated vertex in a triangle";
  }
  for (size_t i = 0; i + 1 < edges.size(); ++i) {
    ASSERT_NE(edges[i].key, edges[i + 1].key)
        << "directed edge " << (edges[i].key >> 32) << "->" << (edges[i].key & 0xffffffffu)
        << " used twice the same way";
  }
  for (const DirectedEdge& e : edges) {
    const int a = static_cast<int>(e.key >> 32), b = static_cast<int>(e.key & 0xffffffffu);
    ASSERT_GE(OppositeTriangle(edges, a, b), 0) << "edge " << a << "-" << b << " is on a boundary";
  }
}

double SignedVolume(const TriangleMesh& m) {
  double vol = 0.0;
  for (const glm::ivec3& f : m.triangles) {
    vol += glm::dot(m.vertices[f[0]], glm::cross(m.vertices[f[1]], m.vertices[f[2]])) / 6.0;
  }
  return vol;
}

glm::dvec3 FaceNormal(const TriangleMesh& m, int t) {
  const glm::ivec3 f = m.triangles[t];
  return glm::cross(m.vertices[f[1]] - m.vertices[f[0]], m.vertices[f[2]] - m.vertices[f[0]]);
}

// Generalized winding number (Jacobson et al. 2013): Σ solid angles / 4π; 1 inside a closed
// outward-oriented surface, 0 outside.
double WindingNumber(const TriangleMesh& m, const glm::dvec3& p) {
  double sum = 0.0;
  for (const glm::ivec3& f : m.triangles) {
    const glm::dvec3 a = m.vertices[f[0]] - p, b = m.vertices[f[1]] - p, c = m.vertices[f[2]] - p;
    const double la = glm::length(a), lb = glm::length(b), lc = glm::length(c);
    const double det = glm::dot(a, glm::cross(b, c));
    const double den =
        la * lb * lc + glm::dot(a, b) * lc + glm::dot(a, c) * lb + glm::dot(b, c) * la;
    sum += 2.0 * std::atan2(det, den);
  }
  return sum / (4.0 * std::numbers::pi);
}

// Largest angle (deg) between the normals of two triangles sharing an edge.
double MaxDihedralDeg(const TriangleMesh& m, const std::vector<DirectedEdge>& edges) {
  double worst = 0.0;
  for (size_t t = 0; t < m.triangles.size(); ++t) {
    const glm::ivec3 f = m.triangles[t];
    const glm::dvec3 n = glm::normalize(FaceNormal(m, static_cast<int>(t)));
    for (int c = 0; c < 3; ++c) {
      const int o = OppositeTriangle(edges, f[c], f[(c + 1) % 3]);
      if (o < static_cast<int>(t)) continue;
      const glm::dvec3 no = glm::normalize(FaceNormal(m, o));
      worst = std::max(
          worst, std::acos(std::clamp(glm::dot(n, no), -1.0, 1.0)) * 180.0 / std::numbers::pi);
    }
  }
  return worst;
}

// Largest distance between corresponding vertices of two meshes with the same connectivity.
double MaxDisplacement(const TriangleMesh& a, const TriangleMesh& b) {
  EXPECT_EQ(a.vertices.size(), b.vertices.size());
  EXPECT_EQ(a.triangles, b.triangles);
  double worst = 0.0;
  for (size_t i = 0; i < std::min(a.vertices.size(), b.vertices.size()); ++i) {
    worst = std::max(worst, glm::length(a.vertices[i] - b.vertices[i]));
  }
  return worst;
}

int ArgExtreme(const TriangleMesh& m, const glm::dvec3& direction) {
  int best = 0;
  for (size_t i = 1; i < m.vertices.size(); ++i) {
    if (glm::dot(m.vertices[i], direction) > glm::dot(m.vertices[best], direction)) {
      best = static_cast<int>(i);
    }
  }
  return best;
}

// ------------------------------------------------------------------------------------------------
// Properties every model must have.

class SeedModelMeshTest : public ::testing::TestWithParam<SeedModel> {};

TEST_P(SeedModelMeshTest, HasTheSeedsTriangleCountWithinOnePercent) {
  const SeedModelSpec& spec = SeedModelSpecOf(GetParam());
  const auto count = static_cast<double>(Model(GetParam()).triangles.size());
  EXPECT_NEAR(count, static_cast<double>(spec.seed_full_triangles),
              0.01 * static_cast<double>(spec.seed_full_triangles))
      << spec.name;
}

TEST_P(SeedModelMeshTest, IsAClosedConsistentlyOrientedGenusAsDesigned) {
  const TriangleMesh& mesh = Model(GetParam());
  const std::vector<DirectedEdge> edges = SortedDirectedEdges(mesh);
  ExpectClosedAndOriented(mesh, edges);
  // V − E + F = 2 − 2g: the torus has genus 1, every other model is a sphere. Every vertex used.
  const auto v = static_cast<std::int64_t>(mesh.vertices.size());
  const auto e = static_cast<std::int64_t>(edges.size() / 2);
  const auto f = static_cast<std::int64_t>(mesh.triangles.size());
  EXPECT_EQ(v - e + f, GetParam() == SeedModel::kTorus ? 0 : 2);
  std::vector<char> used(mesh.vertices.size(), 0);
  for (const glm::ivec3& t : mesh.triangles) used[t[0]] = used[t[1]] = used[t[2]] = 1;
  EXPECT_EQ(std::count(used.begin(), used.end(), 0), 0) << "unreferenced vertices";
}

TEST_P(SeedModelMeshTest, HasFiniteVerticesAndNoDegenerateTriangles) {
  const TriangleMesh& mesh = Model(GetParam());
  for (const glm::dvec3& v : mesh.vertices) {
    ASSERT_TRUE(std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z));
    ASSERT_LT(glm::length(v), 0.2) << "vertex far outside a 0.3 m model";
  }
  double min_area = std::numeric_limits<double>::infinity(), total = 0.0;
  for (size_t t = 0; t < mesh.triangles.size(); ++t) {
    const double area = 0.5 * glm::length(FaceNormal(mesh, static_cast<int>(t)));
    min_area = std::min(min_area, area);
    total += area;
  }
  const double mean = total / static_cast<double>(mesh.triangles.size());
  EXPECT_GT(min_area, 1e-12) << "a triangle below 1 µm²";
  EXPECT_GT(min_area, 0.02 * mean) << "a sliver: min area " << min_area << " mean " << mean;
}

TEST_P(SeedModelMeshTest, IsWoundOutwardWithWindingNumberOneInside) {
  const TriangleMesh& mesh = Model(GetParam());
  EXPECT_GT(SignedVolume(mesh), 0.0);
  // A point inside the material, and one outside the bounding box.
  const glm::dvec3 inside = GetParam() == SeedModel::kTorus     ? glm::dvec3(0.05, 0.0, 0.0)
                            : GetParam() == SeedModel::kCadPart ? glm::dvec3(0.0, 0.0, -0.006)
                                                                : glm::dvec3(0.0);
  EXPECT_NEAR(WindingNumber(mesh, inside), 1.0, 1e-6);
  EXPECT_NEAR(WindingNumber(mesh, glm::dvec3(0.3, 0.01, 0.02)), 0.0, 1e-6);
}

TEST_P(SeedModelMeshTest, HasNoFolds) {
  // Neighbouring triangles never turn back on each other (no flipped or folded triangle, which
  // a closed, outward-wound mesh could still hide).
  const TriangleMesh& mesh = Model(GetParam());
  EXPECT_LT(MaxDihedralDeg(mesh, SortedDirectedEdges(mesh)), 120.0);
}

INSTANTIATE_TEST_SUITE_P(AllSeedModels, SeedModelMeshTest,
                         ::testing::Values(SeedModel::kBlock, SeedModel::kGear, SeedModel::kHammer,
                                           SeedModel::kCadPart, SeedModel::kFile,
                                           SeedModel::kTorus),
                         [](const ::testing::TestParamInfo<SeedModel>& param_info) {
                           return std::string(SeedModelName(param_info.param));
                         });

// Non-convex models: two surface vertices whose midpoint lies outside the solid.
TEST(SeedModels, HammerCadPartFileAndTorusAreNotConvex) {
  struct Witness {
    SeedModel model;
    glm::dvec3 dir_a, dir_b;
  };
  const Witness witnesses[] = {
      {SeedModel::kHammer, {1, 0, 0}, {0, 0, -1}},     // head end, handle bottom
      {SeedModel::kCadPart, {-1, 0, 40}, {1, 0, 40}},  // boss top, pin top
      {SeedModel::kFile, {-0.2, 0, 1}, {1, 0, 0}},     // handle top, blade tip
      {SeedModel::kTorus, {1, 0, 0}, {-1, 0, 0}},      // across the hole
  };
  for (const Witness& w : witnesses) {
    const TriangleMesh& mesh = Model(w.model);
    const glm::dvec3 a = mesh.vertices[ArgExtreme(mesh, w.dir_a)];
    const glm::dvec3 b = mesh.vertices[ArgExtreme(mesh, w.dir_b)];
    EXPECT_LT(WindingNumber(mesh, 0.5 * (a + b)), 0.5) << SeedModelName(w.model);
  }
}

// ------------------------------------------------------------------------------------------------
// Volumes against the dimensions, and the detail.

TEST(SeedModels, BlockAndGearVolumesMatchTheirDimensions) {
  const RidgedBlockParams block;
  const glm::dvec3 h = block.half_extents_m;
  EXPECT_NEAR(SignedVolume(Model(SeedModel::kBlock)), 8.0 * h.x * h.y * h.z,
              0.01 * 8.0 * h.x * h.y * h.z);
  const RidgedGearParams gear;
  const double cylinder = std::numbers::pi * gear.radius_m * gear.radius_m * gear.length_m;
  EXPECT_NEAR(SignedVolume(Model(SeedModel::kGear)), cylinder, 0.02 * cylinder);
}

TEST(SeedModels, TorusVolumeAndWrinkles) {
  const WrinkledTorusParams p;
  const double R = p.major_radius_m, r = p.minor_radius_m, A = p.wrinkle_amplitude_m;
  WrinkledTorusParams smooth = p;
  smooth.detail_scale = 0.0;
  EXPECT_NEAR(SignedVolume(MakeWrinkledTorusFullResolution(smooth)),
              2 * std::numbers::pi * std::numbers::pi * R * r * r,
              0.002 * 2 * std::numbers::pi * std::numbers::pi * R * r * r);
  // ∫∫∫ over the tube of radius r + A sin(…): the sine averages out, A² adds 2π²R·A²/2.
  const double wrinkled = 2 * std::numbers::pi * std::numbers::pi * R * (r * r + 0.5 * A * A);
  EXPECT_NEAR(SignedVolume(Model(SeedModel::kTorus)), wrinkled, 0.005 * wrinkled);
  // Distance from the tube's centre circle spans r ± A.
  double lo = 1.0, hi = 0.0;
  for (const glm::dvec3& v : Model(SeedModel::kTorus).vertices) {
    const double d = std::hypot(std::hypot(v.x, v.y) - R, v.z);
    lo = std::min(lo, d);
    hi = std::max(hi, d);
  }
  EXPECT_GT(lo, r - A - 1e-9);
  EXPECT_LT(hi, r + A + 1e-9);
  EXPECT_LT(lo, r - 0.95 * A);
  EXPECT_GT(hi, r + 0.95 * A);
}

TEST(SeedModels, HammerVolumeSmoothBaseAndKnurl) {
  const TexturedHammerParams p;
  TexturedHammerParams smooth = p;
  smooth.detail_scale = 0.0;
  const TriangleMesh base = MakeTexturedHammerFullResolution(smooth);
  const glm::dvec3 hh = p.head_half_extents_m;
  const double R = p.handle_radius_m;
  const double sharp =
      8.0 * hh.x * hh.y * hh.z + std::numbers::pi * R * R * (p.length_m - 2.0 * hh.z);
  EXPECT_NEAR(SignedVolume(base), sharp, 0.03 * sharp);
  EXPECT_LT(MaxDihedralDeg(base, SortedDirectedEdges(base)), 25.0) << "base shape not smooth";
  const double reach = MaxDisplacement(base, Model(SeedModel::kHammer));
  EXPECT_LE(reach, std::max(p.knurl_amplitude_m, p.peen_amplitude_m) + 1e-9);
  EXPECT_GT(reach, 0.9 * p.knurl_amplitude_m);
  // Knurl: in the middle of the grip, the radius about the handle axis spans R ± A_k.
  const double z_mid = -0.5 * p.length_m + p.grip_start_m + 0.5 * p.grip_length_m;
  double lo = 1.0, hi = 0.0;
  for (const glm::dvec3& v : Model(SeedModel::kHammer).vertices) {
    if (std::abs(v.z - z_mid) > 0.01) continue;
    lo = std::min(lo, std::hypot(v.x, v.y));
    hi = std::max(hi, std::hypot(v.x, v.y));
  }
  EXPECT_NEAR(lo, R - p.knurl_amplitude_m, 0.1 * p.knurl_amplitude_m);
  EXPECT_NEAR(hi, R + p.knurl_amplitude_m, 0.1 * p.knurl_amplitude_m);
}

TEST(SeedModels, CadPartVolumeSmoothBaseAndMillMarks) {
  const RoughCadPartParams p;
  RoughCadPartParams smooth = p;
  smooth.detail_scale = 0.0;
  const TriangleMesh base = MakeRoughCadPartFullResolution(smooth);
  const double hx = p.plate_half_extents_m.x, hy = p.plate_half_extents_m.y;
  const double plate = 4.0 * hx * hy * (p.plate_top_z_m - p.bottom_z_m);
  const double step =
      (hx - p.step_start_x_m) * 2.0 * hy * (p.step_top_z_m - p.plate_top_z_m) -
      (hx - p.slot_start_x_m) * 2.0 * p.slot_half_width_m * (p.step_top_z_m - p.slot_floor_z_m);
  const double bosses = 2.0 * std::numbers::pi * p.boss_radius_m * p.boss_radius_m *
                        (p.boss_top_z_m - p.plate_top_z_m);
  const double pins =
      2.0 * std::numbers::pi * p.pin_radius_m * p.pin_radius_m * (p.pin_top_z_m - p.step_top_z_m);
  const double sharp = plate + step + bosses + pins;
  EXPECT_NEAR(SignedVolume(base), sharp, 0.03 * sharp);
  EXPECT_LT(MaxDihedralDeg(base, SortedDirectedEdges(base)), 25.0) << "base shape not smooth";
  const double bound = std::max(p.mill_amplitude_m, p.wall_amplitude_m) + p.rough_amplitude_m;
  const double reach = MaxDisplacement(base, Model(SeedModel::kCadPart));
  EXPECT_LE(reach, bound + 1e-9);
  EXPECT_GT(reach, 0.9 * p.mill_amplitude_m);
  // Mill marks on the low plate's top, away from edges and bosses: heights span about ±A_m.
  double lo = 1.0, hi = -1.0;
  for (const glm::dvec3& v : Model(SeedModel::kCadPart).vertices) {
    if (v.x < -0.045 || v.x > -0.040 || std::abs(v.y) > 0.004 || v.z < p.plate_top_z_m - 1e-3) {
      continue;
    }
    lo = std::min(lo, v.z);
    hi = std::max(hi, v.z);
  }
  EXPECT_GT(hi - lo, 2.0 * p.mill_amplitude_m - 2.0 * p.rough_amplitude_m);
  EXPECT_LT(hi - lo, 2.0 * bound + 1e-9);
}

TEST(SeedModels, FileVolumeSmoothBaseAndTeeth) {
  const ToothedFileParams p;
  ToothedFileParams smooth = p;
  smooth.detail_scale = 0.0;
  const TriangleMesh base = MakeToothedFileFullResolution(smooth);
  // Blade cross-section 4·w·t scaled by a(t)·b(t) over the taper, integrated numerically.
  double taper = 0.0;
  const int steps = 10000;
  for (int i = 0; i < steps; ++i) {
    const double t = (i + 0.5) / steps;
    taper += (1.0 - (1.0 - p.tip_width_scale) * t * t) *
             (1.0 - (1.0 - p.tip_thickness_scale) * t * t) / steps;
  }
  const double blade_section = 4.0 * p.blade_half_width_m * p.blade_half_thickness_m;
  const double sharp =
      std::numbers::pi * p.handle_radius_m * p.handle_radius_m * p.handle_length_m +
      4.0 * p.neck_half_width_m * p.neck_half_thickness_m * p.neck_length_m +
      blade_section * (p.blade_length_m - p.taper_length_m + p.taper_length_m * taper);
  EXPECT_NEAR(SignedVolume(base), sharp, 0.03 * sharp);
  EXPECT_LT(MaxDihedralDeg(base, SortedDirectedEdges(base)), 25.0) << "base shape not smooth";
  const double reach = MaxDisplacement(base, Model(SeedModel::kFile));
  EXPECT_LE(reach,
            std::max({p.tooth_amplitude_m, p.edge_tooth_amplitude_m, p.grip_amplitude_m}) + 1e-9);
  EXPECT_GT(reach, 0.9 * p.tooth_amplitude_m);
  // Teeth on the upper face of the blade, before the taper: heights above the face in
  // [0, A_t], and the full range is used.
  const double x_blade = -0.5 * p.TotalLength() + p.handle_length_m + p.neck_length_m;
  double lo = 1.0, hi = -1.0;
  for (const glm::dvec3& v : Model(SeedModel::kFile).vertices) {
    if (v.x < x_blade + 0.01 || v.x > x_blade + 0.03 ||
        std::abs(v.y) > 0.5 * p.blade_half_width_m || v.z < 0.0) {
      continue;
    }
    lo = std::min(lo, v.z - p.blade_half_thickness_m);
    hi = std::max(hi, v.z - p.blade_half_thickness_m);
  }
  EXPECT_GT(lo, -1e-9);
  EXPECT_LT(lo, 0.1 * p.tooth_amplitude_m);
  EXPECT_LT(hi, p.tooth_amplitude_m + 1e-9);
  EXPECT_GT(hi, 0.9 * p.tooth_amplitude_m);
}

// ------------------------------------------------------------------------------------------------

TEST(SeedModels, TableMatchesTheSeed) {
  const auto& specs = SeedModelSpecs();
  ASSERT_EQ(specs.size(), 6u);
  const std::int64_t expected[6][3] = {{65536, 16, 1},     {25600, 1600, 1},   {433152, 518, 210},
                                       {658432, 720, 390}, {285824, 632, 113}, {128000, 532, 114}};
  for (size_t i = 0; i < specs.size(); ++i) {
    EXPECT_EQ(static_cast<size_t>(specs[i].model), i);
    EXPECT_EQ(specs[i].seed_full_triangles, expected[i][0]) << specs[i].name;
    EXPECT_EQ(specs[i].seed_coarse_triangles, expected[i][1]) << specs[i].name;
    EXPECT_EQ(specs[i].seed_bounding_volumes, expected[i][2]) << specs[i].name;
  }
}

TEST(SeedModels, NamesRoundTripAndBadNamesAreRejected) {
  for (const SeedModelSpec& s : SeedModelSpecs()) {
    EXPECT_EQ(ParseSeedModelName(s.name), s.model);
    EXPECT_STREQ(SeedModelName(s.model), s.name);
  }
  try {
    ParseSeedModelName("Hammer");
    FAIL() << "no exception";
  } catch (const std::invalid_argument& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("'Hammer'"), std::string::npos) << what;
    EXPECT_NE(what.find("block, gear, hammer, cad_part, file, torus"), std::string::npos) << what;
  }
}

TEST(SeedModels, GeneratorsRejectBadParameters) {
  TexturedHammerParams hammer;
  hammer.handle_radius_m = 0.018;  // leaves no ledge under the head
  EXPECT_THROW(MakeTexturedHammerFullResolution(hammer), std::invalid_argument);
  RoughCadPartParams cad;
  cad.cell_size_m.y = 0.0;
  EXPECT_THROW(MakeRoughCadPartFullResolution(cad), std::invalid_argument);
  ToothedFileParams file;
  file.tip_width_scale = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(MakeToothedFileFullResolution(file), std::invalid_argument);
  WrinkledTorusParams torus;
  torus.wrinkle_amplitude_m = 0.01;  // more than half the tube radius
  EXPECT_THROW(MakeWrinkledTorusFullResolution(torus), std::invalid_argument);
}

}  // namespace
}  // namespace ht
