// LoadGltfScene() against the glTF files of ../shared/data/gltf (located through
// HT_SHARED_DATA, else ../shared/data relative to the working directory, the repository root;
// the data tests are skipped when neither exists) and against small files written to the temp
// dir.

#include "codecs/gltf_scene.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <random>
#include <set>
#include <string>
#include <unordered_map>
#include <vector>

namespace ht {
namespace {

namespace fs = std::filesystem;

std::optional<fs::path> GltfDataDir() {
  fs::path base = "../shared/data";
  if (const char* env = std::getenv("HT_SHARED_DATA"); env != nullptr && *env != '\0') base = env;
  std::error_code ec;
  if (fs::is_directory(base / "gltf", ec)) return base / "gltf";
  return std::nullopt;
}

#define REQUIRE_GLTF_DATA(dir)                                                            \
  const std::optional<fs::path> dir = GltfDataDir();                                      \
  if (!dir) {                                                                             \
    GTEST_SKIP() << "glTF test data not found: set HT_SHARED_DATA to the shared data "    \
                    "directory (the one holding gltf/), or run from the repository root " \
                    "with ../shared/data/gltf present";                                   \
  }

// Expects LoadGltfScene(path) to throw std::runtime_error whose message starts with the path;
// returns the message.
std::string ExpectLoadError(const fs::path& path) {
  try {
    LoadGltfScene(path.string());
  } catch (const std::runtime_error& e) {
    const std::string message = e.what();
    EXPECT_EQ(message.rfind(path.string(), 0), 0u) << message;
    return message;
  } catch (...) {
    ADD_FAILURE() << path << ": threw something other than std::runtime_error";
    return "";
  }
  ADD_FAILURE() << path << ": loaded, expected an error";
  return "";
}

std::int64_t InstanceTriangles(const GltfScene& s) {
  std::int64_t n = 0;
  for (const GltfMeshInstance& i : s.instances) {
    n += static_cast<std::int64_t>(
        s.meshes[static_cast<std::size_t>(i.mesh)].mesh_N.triangles.size());
  }
  return n;
}

bool HasNoteContaining(const GltfScene& s, const std::string& text) {
  return std::any_of(s.notes.begin(), s.notes.end(),
                     [&](const std::string& n) { return n.find(text) != std::string::npos; });
}

glm::dvec3 ToWorld(const GltfMeshInstance& inst, const glm::dvec3& p_N) {
  return glm::dvec3(inst.X_WN * glm::dvec4(p_N, 1.0));
}

// World-space triangles of the whole scene (three corners each).
std::vector<std::array<glm::dvec3, 3>> WorldTriangles(const GltfScene& s) {
  std::vector<std::array<glm::dvec3, 3>> out;
  for (const GltfMeshInstance& inst : s.instances) {
    const TriangleMesh& m = s.meshes[static_cast<std::size_t>(inst.mesh)].mesh_N;
    for (const glm::ivec3& t : m.triangles) {
      out.push_back({ToWorld(inst, m.vertices[static_cast<std::size_t>(t.x)]),
                     ToWorld(inst, m.vertices[static_cast<std::size_t>(t.y)]),
                     ToWorld(inst, m.vertices[static_cast<std::size_t>(t.z)])});
    }
  }
  return out;
}

double Area(const std::array<glm::dvec3, 3>& t) {
  return 0.5 * glm::length(glm::cross(t[1] - t[0], t[2] - t[0]));
}

// Largest distance from a corner of `a`'s triangles to the nearest corner of `b`'s triangles
// (uniform grid of cell `cell`; distances beyond one cell count as the cell size times 10).
double MaxCornerDistance(const std::vector<std::array<glm::dvec3, 3>>& a,
                         const std::vector<std::array<glm::dvec3, 3>>& b, double cell) {
  auto key = [cell](const glm::dvec3& p) {
    return std::array<std::int64_t, 3>{static_cast<std::int64_t>(std::floor(p.x / cell)),
                                       static_cast<std::int64_t>(std::floor(p.y / cell)),
                                       static_cast<std::int64_t>(std::floor(p.z / cell))};
  };
  std::map<std::array<std::int64_t, 3>, std::vector<glm::dvec3>> grid;
  for (const auto& t : b) {
    for (const glm::dvec3& p : t) grid[key(p)].push_back(p);
  }
  double worst = 0.0;
  for (const auto& t : a) {
    for (const glm::dvec3& p : t) {
      const auto k = key(p);
      double best = 10.0 * cell;
      for (std::int64_t dx = -1; dx <= 1; ++dx) {
        for (std::int64_t dy = -1; dy <= 1; ++dy) {
          for (std::int64_t dz = -1; dz <= 1; ++dz) {
            auto it = grid.find({k[0] + dx, k[1] + dy, k[2] + dz});
            if (it == grid.end()) continue;
            for (const glm::dvec3& q : it->second) best = std::min(best, glm::length(p - q));
          }
        }
      }
      worst = std::max(worst, best);
    }
  }
  return worst;
}

double LargestWorldExtent(const std::vector<std::array<glm::dvec3, 3>>& tris) {
  glm::dvec3 lo(std::numeric_limits<double>::infinity());
  glm::dvec3 hi(-std::numeric_limits<double>::infinity());
  for (const auto& t : tris) {
    for (const glm::dvec3& p : t) {
      lo = glm::min(lo, p);
      hi = glm::max(hi, p);
    }
  }
  const glm::dvec3 e = hi - lo;
  return std::max({e.x, e.y, e.z});
}

// ----------------------------------------------------------------------------------------------
// The real files.

// Files that must load (valid glTF, possibly odd) and files that must be refused.
const std::set<std::string> kValidFiles = {
    "assimp_gltf2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb",
    "assimp_gltf2/draco/2CylinderEngine.gltf",
    "assimp_gltf2/BoxBadNormals-glTF-Binary/BoxBadNormals.glb",  // normals are not read
    "assimp_gltf2/TestNoRootNode/NoScene.gltf",
    "assimp_gltf2/TestNoRootNode/SceneWithoutNodes.gltf",
    "assimp_gltf2/cameras/Cameras.gltf",
    // Type errors only in fields that do not touch geometry (material, texture extension, node
    // name); tinygltf 2.7 ignores wrongly typed optional fields, so these load.
    "assimp_gltf2/wrongTypes/badExtension.gltf",
    "assimp_gltf2/wrongTypes/badObject.gltf",
    "assimp_gltf2/wrongTypes/badString.gltf",
    "assimp_gltf2/wrongTypes/badUint.gltf",
    "draco_testdata_gltf/Box/glTF/Box.gltf",
    "draco_testdata_gltf/BoxMetaDraco/glTF/BoxMetaDraco.gltf",
    "draco_testdata_gltf/CesiumMilkTruck/glTF/CesiumMilkTruck.gltf",
    "draco_testdata_gltf/CubeScaledInstances/glTF/cube_att.gltf",
    "draco_testdata_gltf/KhronosSampleModels/Duck/glTF/Duck.gltf",
    "draco_testdata_gltf/SpheresScaledInstances/glTF/spheres_scaled_instances.gltf",
    "draco_testdata_gltf/Triangle/glTF/Triangle.gltf",
    "draco_testdata_gltf/Triangle/glTF/Triangle_identity_matrix.gltf",
    "draco_testdata_gltf/Triangle/glTF/Triangle_translation_only_matrix.gltf",
    "draco_testdata_gltf/glTF_Binary/Box.glb",
    "draco_testdata_gltf/glTF_Binary/Box_Draco.glb",
    "draco_testdata_gltf/glTF_Binary/Duck.glb",
    "gltf_transform/core/test/in/BoxVertexColors.glb",
    "gltf_transform/core/test/in/Box_glTF-Binary/Box.glb",
    "gltf_transform/core/test/in/Box_glTF-Embedded/Box.gltf",
    "gltf_transform/core/test/in/Box_glTF/Box.gltf",
    "gltf_transform/extensions/test/in/BoxDraco.gltf",
    "gltf_transform/extensions/test/in/DracoSparseMesh.gltf",
    "gltf_transform/functions/test/in/ShapeCollection.glb",
    "gltf_transform/functions/test/in/TwoCubes.glb",
    "gltf_transform/functions/test/in/many-cubes.gltf",
    "tinygltf_tests/models/Cube-texture-ext/Cube-textransform.gltf",
    "tinygltf_tests/models/Cube/Cube.gltf",
    "tinygltf_tests/models/CubeImageUriSpaces/CubeImageUriMultipleSpaces.gltf",
    "tinygltf_tests/models/CubeImageUriSpaces/CubeImageUriSpaces.gltf",
    "tinygltf_tests/models/Extensions-issue97/test.gltf",
    "tinygltf_tests/models/Extensions-overwrite-issue261/issue-261.gltf",
    "tinygltf_tests/models/SparseMorphTargets-issue280/singleBlendshapeCube_sparse.glb",
    "tinygltf_tests/models/box01.glb",
    "tinygltf_tests/models/regression/unassigned-skeleton.gltf",
    "tinygltf_tests/models/regression/zero-sized-bin-chunk-issue-440.glb",
    "tinygltf_tests/tests/issue-416.gltf",
    "tinygltf_tests/tests/issue-492.glb",
};
const std::set<std::string> kMalformedFiles = {
    "assimp_gltf2/BoxWithInfinites-glTF-Binary/BoxWithInfinites.glb",
    "assimp_gltf2/IncorrectVertexArrays/Cube.gltf",
    "assimp_gltf2/IndexOutOfRange/AllIndicesOutOfRange.gltf",
    "assimp_gltf2/IndexOutOfRange/IndexOutOfRange.gltf",
    "assimp_gltf2/MissingBin/BoxTextured.gltf",
    "assimp_gltf2/RecursiveNodes/RecursiveNodes.gltf",
    // Refused, but because its BoxTextured0.bin is absent: tinygltf 2.7 would ignore the
    // wrongly typed `scene` (it reads it as absent).
    "assimp_gltf2/SchemaFailures/sceneWrongType.gltf",
    "assimp_gltf2/wrongTypes/badArray.gltf",   // meshes[0].primitives is not an array
    "assimp_gltf2/wrongTypes/badNumber.gltf",  // tinygltf: normalTexture without index
    "tinygltf_tests/models/BoundsChecking/integer-out-of-bounds.gltf",
    "tinygltf_tests/models/BoundsChecking/invalid-buffer-index.gltf",
    "tinygltf_tests/models/BoundsChecking/invalid-buffer-view-index.gltf",
    "tinygltf_tests/models/BoundsChecking/invalid-primitive-indices.gltf",
};

std::vector<std::string> ListGltfFiles(const fs::path& dir) {
  std::vector<std::string> out;
  for (const auto& e : fs::recursive_directory_iterator(dir)) {
    if (!e.is_regular_file()) continue;
    const std::string ext = e.path().extension().string();
    if (ext == ".gltf" || ext == ".glb")
      out.push_back(fs::relative(e.path(), dir).generic_string());
  }
  std::sort(out.begin(), out.end());
  return out;
}

TEST(GltfSceneData, EveryFileInTheDirectoryIsClassifiedAndBehavesAsClassified) {
  REQUIRE_GLTF_DATA(dir);
  const std::vector<std::string> files = ListGltfFiles(*dir);
  ASSERT_FALSE(files.empty());
  for (const std::string& rel : files) {
    SCOPED_TRACE(rel);
    const fs::path path = *dir / rel;
    const bool valid = kValidFiles.count(rel) > 0;
    const bool malformed = kMalformedFiles.count(rel) > 0;
    ASSERT_TRUE(valid != malformed) << rel << " is in neither list (or both): classify it";
    if (valid) {
      try {
        const GltfScene s = LoadGltfScene(path.string());
        std::int64_t mesh_triangles = 0;
        for (const GltfMesh& m : s.meshes) {
          mesh_triangles += static_cast<std::int64_t>(m.mesh_N.triangles.size());
        }
        std::cout << "[ loaded ] " << rel << ": " << s.instances.size() << " instances, "
                  << s.meshes.size() << " meshes, " << mesh_triangles << " mesh triangles, "
                  << InstanceTriangles(s) << " instance triangles\n";
        for (const std::string& n : s.notes) std::cout << "             note: " << n << "\n";
      } catch (const std::exception& e) {
        ADD_FAILURE() << e.what();
      }
    } else {
      const std::string message = ExpectLoadError(path);
      std::cout << "[ refused] " << message << "\n";
    }
  }
  // Every listed file exists (the lists follow MANIFEST.md).
  for (const auto* list : {&kValidFiles, &kMalformedFiles}) {
    for (const std::string& rel : *list) EXPECT_TRUE(fs::exists(*dir / rel)) << rel;
  }
}

TEST(GltfSceneData, MalformedFilesSayWhatIsWrong) {
  REQUIRE_GLTF_DATA(dir);
  const std::map<std::string, std::string> expected = {
      {"assimp_gltf2/BoxWithInfinites-glTF-Binary/BoxWithInfinites.glb", "not finite"},
      {"assimp_gltf2/IndexOutOfRange/AllIndicesOutOfRange.gltf", "out of range"},
      {"assimp_gltf2/IndexOutOfRange/IndexOutOfRange.gltf", "out of range"},
      {"assimp_gltf2/RecursiveNodes/RecursiveNodes.gltf", "cycle"},
      {"assimp_gltf2/IncorrectVertexArrays/Cube.gltf", "not a multiple of 3"},
      {"assimp_gltf2/MissingBin/BoxTextured.gltf", "BoxTextured0.bin"},
      {"assimp_gltf2/wrongTypes/badArray.gltf", "primitives is not an array"},
      {"tinygltf_tests/models/BoundsChecking/invalid-primitive-indices.gltf",
       "primitive indices accessor out of bounds"},
      {"tinygltf_tests/models/BoundsChecking/invalid-buffer-view-index.gltf",
       "accessor[0] invalid bufferView"},
      {"tinygltf_tests/models/BoundsChecking/integer-out-of-bounds.gltf", "not a positive integer"},
  };
  for (const auto& [rel, text] : expected) {
    const std::string message = ExpectLoadError(*dir / rel);
    EXPECT_NE(message.find(text), std::string::npos) << message << "\n  expected: " << text;
  }
}

TEST(GltfSceneData, BoxIsTwelveTrianglesOfAUnitCubeInEveryContainer) {
  REQUIRE_GLTF_DATA(dir);
  for (const char* rel :
       {"draco_testdata_gltf/Box/glTF/Box.gltf", "draco_testdata_gltf/glTF_Binary/Box.glb",
        "gltf_transform/core/test/in/Box_glTF/Box.gltf",
        "gltf_transform/core/test/in/Box_glTF-Binary/Box.glb",
        "gltf_transform/core/test/in/Box_glTF-Embedded/Box.gltf"}) {
    SCOPED_TRACE(rel);
    const GltfScene s = LoadGltfScene((*dir / rel).string());
    ASSERT_EQ(s.meshes.size(), 1u);
    ASSERT_EQ(s.instances.size(), 1u);
    EXPECT_EQ(s.meshes[0].mesh_N.triangles.size(), 12u);
    EXPECT_EQ(s.meshes[0].mesh_N.vertices.size(), 24u);
    // A unit cube: total area 6 (m²), in node frame and in W (the node matrix only rotates).
    double area = 0.0;
    for (const auto& t : WorldTriangles(s)) area += Area(t);
    EXPECT_NEAR(area, 6.0, 1e-5);
    const nlohmann::json j = SceneSummaryJson(s);
    EXPECT_EQ(j["totals"]["triangles"], 12);
    for (int k = 0; k < 3; ++k) {
      EXPECT_NEAR(
          j["totals"]["bbox_max_W"][k].get<double>() - j["totals"]["bbox_min_W"][k].get<double>(),
          1.0, 1e-6);
    }
  }
}

TEST(GltfSceneData, InstancedMeshesAreStoredOnce) {
  REQUIRE_GLTF_DATA(dir);
  const GltfScene cubes =
      LoadGltfScene((*dir / "draco_testdata_gltf/CubeScaledInstances/glTF/cube_att.gltf").string());
  // Node 0 has children 1..4, each of which has the mesh node 5 as child: 4 paths to the mesh.
  EXPECT_EQ(cubes.meshes.size(), 1u);
  EXPECT_EQ(cubes.instances.size(), 4u);
  // Scaled instances differ in size: at least two different world bounding boxes.
  const nlohmann::json j = SceneSummaryJson(cubes);
  std::set<double> widths;
  for (const auto& inst : j["instances"]) {
    widths.insert(std::round(
        1e6 * (inst["bbox_max_W"][0].get<double>() - inst["bbox_min_W"][0].get<double>())));
  }
  EXPECT_GT(widths.size(), 1u);

  const GltfScene many =
      LoadGltfScene((*dir / "gltf_transform/functions/test/in/many-cubes.gltf").string());
  EXPECT_LE(many.meshes.size(), 501u);
  EXPECT_GE(many.instances.size(), many.meshes.size());
  EXPECT_EQ(SceneSummaryJson(many)["totals"]["triangles"].get<std::int64_t>(),
            InstanceTriangles(many));
  std::cout << "many-cubes: " << many.instances.size() << " instances of " << many.meshes.size()
            << " meshes, " << InstanceTriangles(many) << " triangles\n";
}

TEST(GltfSceneData, SceneChoiceIsWrittenInNotes) {
  REQUIRE_GLTF_DATA(dir);
  const GltfScene none =
      LoadGltfScene((*dir / "assimp_gltf2/TestNoRootNode/NoScene.gltf").string());
  EXPECT_TRUE(none.instances.empty());
  EXPECT_TRUE(HasNoteContaining(none, "no scene")) << ::testing::PrintToString(none.notes);
  const GltfScene empty =
      LoadGltfScene((*dir / "assimp_gltf2/TestNoRootNode/SceneWithoutNodes.gltf").string());
  EXPECT_TRUE(empty.instances.empty());
  EXPECT_TRUE(HasNoteContaining(empty, "has no nodes")) << ::testing::PrintToString(empty.notes);
  const GltfScene cams = LoadGltfScene((*dir / "assimp_gltf2/cameras/Cameras.gltf").string());
  EXPECT_TRUE(HasNoteContaining(cams, "camera")) << ::testing::PrintToString(cams.notes);
}

TEST(GltfSceneData, TranslationOnlyMatrixMovesTheTriangleByOneInX) {
  REQUIRE_GLTF_DATA(dir);
  const fs::path base = *dir / "draco_testdata_gltf/Triangle/glTF";
  const auto plain = WorldTriangles(LoadGltfScene((base / "Triangle.gltf").string()));
  const auto identity =
      WorldTriangles(LoadGltfScene((base / "Triangle_identity_matrix.gltf").string()));
  const auto moved =
      WorldTriangles(LoadGltfScene((base / "Triangle_translation_only_matrix.gltf").string()));
  ASSERT_EQ(plain.size(), 1u);
  ASSERT_EQ(identity.size(), 1u);
  ASSERT_EQ(moved.size(), 1u);
  for (int c = 0; c < 3; ++c) {
    EXPECT_EQ(identity[0][c], plain[0][c]);
    EXPECT_NEAR(glm::length(moved[0][c] - (plain[0][c] + glm::dvec3(1, 0, 0))), 0.0, 1e-12);
  }
}

// Draco twins: the same model with and without KHR_draco_mesh_compression. The Draco encoder
// drops triangles that repeat an index; the loader drops them too. Every
// corner of one lies within the Draco quantization step of a corner of the other. The step of a
// primitive is (its largest extent) / (2^bits - 1); in W an extent can grow by up to sqrt(3)
// under rotation, so the bound used is sqrt(3) * (largest world extent of the scene) /
// (2^bits - 1), with the bits the files use (see each case).
void ExpectDracoTwins(const fs::path& plain_path, const fs::path& draco_path, int bits,
                      double area_rel_tol) {
  const GltfScene plain = LoadGltfScene(plain_path.string());
  const GltfScene draco = LoadGltfScene(draco_path.string());
  int draco_prims = 0;
  for (const GltfMesh& m : draco.meshes) draco_prims += m.draco_primitive_count;
  EXPECT_GT(draco_prims, 0);
  EXPECT_EQ(plain.instances.size(), draco.instances.size());
  const auto a = WorldTriangles(plain);
  const auto b = WorldTriangles(draco);
  // The Draco encoder merges points with equal attributes, so a triangle with two corners at
  // the same position (and same normal) collapses and is dropped; the loader drops only
  // triangles that repeat an index. Count the plain file's coincident-corner triangles.
  std::size_t coincident = 0;
  for (const auto& t : a) coincident += (t[0] == t[1] || t[1] == t[2] || t[2] == t[0]) ? 1 : 0;
  EXPECT_EQ(a.size() - coincident, b.size()) << coincident << " coincident-corner triangles";
  double area_a = 0.0;
  double area_b = 0.0;
  for (const auto& t : a) area_a += Area(t);
  for (const auto& t : b) area_b += Area(t);
  EXPECT_NEAR(area_b / area_a, 1.0, area_rel_tol);
  const double extent = LargestWorldExtent(a);
  const double step = std::sqrt(3.0) * extent / (std::ldexp(1.0, bits) - 1.0);
  const double ab = MaxCornerDistance(a, b, 2.0 * step);
  const double ba = MaxCornerDistance(b, a, 2.0 * step);
  std::cout << plain_path.filename() << " vs " << draco_path.filename() << ": " << a.size() << " / "
            << b.size() << " triangles, area " << area_a << " / " << area_b
            << ", max corner distance " << ab << " / " << ba << " (step bound " << step << ")\n";
  EXPECT_LE(ab, step);
  EXPECT_LE(ba, step);
}

TEST(GltfSceneData, DracoBoxMatchesThePlainBox) {
  REQUIRE_GLTF_DATA(dir);
  // Box_Draco.glb quantizes positions with 11 bits, read from its Draco stream with libdraco
  // (Decoder::SetSkipAttributeTransform + AttributeQuantizationTransform::quantization_bits).
  ExpectDracoTwins(*dir / "draco_testdata_gltf/glTF_Binary/Box.glb",
                   *dir / "draco_testdata_gltf/glTF_Binary/Box_Draco.glb", 11, 1e-6);
}

TEST(GltfSceneData, DracoEngineMatchesThePlainEngine) {
  REQUIRE_GLTF_DATA(dir);
  // All 34 Draco primitives of 2CylinderEngine.gltf quantize positions with 11 bits (read as for
  // the box). Area within 0.01 % (DEPENDENCIES.md trap 8). Triangle counts agree once the plain
  // file's 6 triangles with two coincident corners are set aside (the loader drops the 10,413
  // that repeat an index on both sides).
  ExpectDracoTwins(*dir / "assimp_gltf2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb",
                   *dir / "assimp_gltf2/draco/2CylinderEngine.gltf", 11, 1e-4);
}

TEST(GltfSceneData, TruncatedAndCorruptedGlbNeverCrash) {
  REQUIRE_GLTF_DATA(dir);
  const fs::path tmp = fs::temp_directory_path() / "gltf_scene_test_trunc";
  fs::create_directories(tmp);
  for (const char* rel : {"draco_testdata_gltf/glTF_Binary/Box.glb",
                          "draco_testdata_gltf/glTF_Binary/Box_Draco.glb"}) {
    std::ifstream in(*dir / rel, std::ios::binary);
    const std::vector<char> bytes{std::istreambuf_iterator<char>(in), {}};
    ASSERT_GT(bytes.size(), 100u);
    const fs::path out = tmp / "cut.glb";
    // Every truncation point is refused.
    for (std::size_t n = 0; n < bytes.size(); n += 1 + n / 16) {
      std::ofstream(out, std::ios::binary | std::ios::trunc)
          .write(bytes.data(), static_cast<std::streamsize>(n));
      const std::string message = ExpectLoadError(out);
      if (n == bytes.size() / 2) std::cout << "truncated to " << n << ": " << message << "\n";
    }
    // Random byte flips anywhere: loads or throws std::runtime_error, never crashes.
    std::mt19937 rng(7);
    int refused = 0;
    for (int trial = 0; trial < 300; ++trial) {
      std::vector<char> copy = bytes;
      for (int k = 0; k < 4; ++k) {
        copy[std::uniform_int_distribution<std::size_t>(0, copy.size() - 1)(rng)] =
            static_cast<char>(rng() & 0xFF);
      }
      std::ofstream(out, std::ios::binary | std::ios::trunc)
          .write(copy.data(), static_cast<std::streamsize>(copy.size()));
      try {
        LoadGltfScene(out.string());
      } catch (const std::runtime_error& e) {
        ++refused;
        EXPECT_EQ(std::string(e.what()).rfind(out.string(), 0), 0u);
      }
    }
    std::cout << rel << ": " << refused << " of 300 corrupted copies refused\n";
  }
  fs::remove_all(tmp);
}

// ----------------------------------------------------------------------------------------------
// Files made here.

class GltfSceneMadeFiles : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("gltf_scene_test_" +
            std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()));
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  // A one-mesh file: positions (float VEC3) at bin offset 0, then optional uint16 indices.
  // Returns the JSON for the test to edit; Write() saves it with `bin`.
  nlohmann::json Doc(const std::vector<glm::vec3>& positions,
                     const std::vector<std::uint16_t>& indices, int mode) {
    bin_.assign(positions.size() * 12, 0);
    std::memcpy(bin_.data(), positions.data(), bin_.size());
    const std::size_t index_offset = bin_.size();
    bin_.resize(index_offset + indices.size() * 2);
    if (!indices.empty())
      std::memcpy(bin_.data() + index_offset, indices.data(), indices.size() * 2);
    while (bin_.size() % 4 != 0) bin_.push_back(0);
    nlohmann::json prim = {{"attributes", {{"POSITION", 0}}}, {"mode", mode}};
    nlohmann::json doc = {
        {"asset", {{"version", "2.0"}}},
        {"scene", 0},
        {"scenes", {{{"nodes", {0}}}}},
        {"nodes", {{{"mesh", 0}, {"name", "n0"}}}},
        {"buffers", {{{"uri", "data.bin"}, {"byteLength", bin_.size()}}}},
        {"bufferViews",
         {{{"buffer", 0}, {"byteOffset", 0}, {"byteLength", positions.size() * 12}}}},
        {"accessors",
         {{{"bufferView", 0},
           {"componentType", 5126},
           {"type", "VEC3"},
           {"count", positions.size()}}}},
    };
    if (!indices.empty()) {
      doc["bufferViews"].push_back(
          {{"buffer", 0}, {"byteOffset", index_offset}, {"byteLength", indices.size() * 2}});
      doc["accessors"].push_back({{"bufferView", 1},
                                  {"componentType", 5123},
                                  {"type", "SCALAR"},
                                  {"count", indices.size()}});
      prim["indices"] = 1;
    }
    doc["meshes"] = {{{"name", "m0"}, {"primitives", {prim}}}};
    return doc;
  }

  fs::path Write(const nlohmann::json& doc) {
    std::ofstream(dir_ / "data.bin", std::ios::binary | std::ios::trunc)
        .write(reinterpret_cast<const char*>(bin_.data()),
               static_cast<std::streamsize>(bin_.size()));
    const fs::path path = dir_ / "scene.gltf";
    std::ofstream(path, std::ios::trunc) << doc.dump(1);
    return path;
  }

  // Six vertices on a zigzag in the z = 0 plane (for strips) or around a centre (for fans).
  static std::vector<glm::vec3> Zigzag() {
    return {{0, 0, 0}, {0, 1, 0}, {1, 0, 0}, {1, 1, 0}, {2, 0, 0}, {2, 1, 0}};
  }
  static std::vector<glm::vec3> FanPoints() {
    std::vector<glm::vec3> p = {{0, 0, 0}};
    for (int i = 0; i < 5; ++i) {
      const float a = static_cast<float>(i) * 0.5f;
      p.emplace_back(std::cos(a), std::sin(a), 0.0f);
    }
    return p;
  }

  fs::path dir_;
  std::vector<std::uint8_t> bin_;
};

// All triangles of a planar counter-clockwise strip/fan face +z.
void ExpectAllFacePlusZ(const GltfScene& s) {
  for (const auto& t : WorldTriangles(s)) {
    EXPECT_GT(glm::cross(t[1] - t[0], t[2] - t[0]).z, 0.0);
  }
}

TEST_F(GltfSceneMadeFiles, StripOfSixVerticesGivesFourTrianglesWithOneWinding) {
  // Strip v0..v5 zigzag: (0,2,1) would face -z; glTF's rule flips every other triangle.
  std::vector<glm::vec3> p = {{0, 1, 0}, {0, 0, 0}, {1, 1, 0}, {1, 0, 0}, {2, 1, 0}, {2, 0, 0}};
  const GltfScene s = LoadGltfScene(Write(Doc(p, {}, 5)).string());
  ASSERT_EQ(s.meshes.size(), 1u);
  EXPECT_EQ(s.meshes[0].mesh_N.triangles.size(), 4u);
  ExpectAllFacePlusZ(s);
  // Indexed strip of the same vertices, and a restart by repeated index (degenerates dropped).
  const GltfScene indexed = LoadGltfScene(Write(Doc(p, {0, 1, 2, 3, 4, 5}, 5)).string());
  EXPECT_EQ(indexed.meshes[0].mesh_N.triangles.size(), 4u);
  ExpectAllFacePlusZ(indexed);
  const GltfScene restart = LoadGltfScene(Write(Doc(p, {0, 1, 2, 2, 2, 3, 4, 5}, 5)).string());
  EXPECT_EQ(restart.meshes[0].dropped_degenerate_triangles, 3);
}

TEST_F(GltfSceneMadeFiles, FanOfSixVerticesGivesFourTriangles) {
  const GltfScene s = LoadGltfScene(Write(Doc(FanPoints(), {}, 6)).string());
  EXPECT_EQ(s.meshes[0].mesh_N.triangles.size(), 4u);
  ExpectAllFacePlusZ(s);
  const GltfScene indexed = LoadGltfScene(Write(Doc(FanPoints(), {0, 1, 2, 3, 4, 5}, 6)).string());
  EXPECT_EQ(indexed.meshes[0].mesh_N.triangles.size(), 4u);
}

TEST_F(GltfSceneMadeFiles, PointsAndLinesAreSkippedWithANote) {
  const GltfScene s = LoadGltfScene(Write(Doc(Zigzag(), {}, 1)).string());
  ASSERT_EQ(s.meshes.size(), 1u);
  EXPECT_TRUE(s.meshes[0].mesh_N.triangles.empty());
  EXPECT_TRUE(HasNoteContaining(s, "points or lines")) << ::testing::PrintToString(s.notes);
}

TEST_F(GltfSceneMadeFiles, NodeTransformsComposeFromTheRootDown) {
  // Parent translates by (1, 2, 3); child rotates 90° about z then scales by 2 (T·R·S):
  // p_N = (1, 0, 0) -> S (2, 0, 0) -> R (0, 2, 0) -> T of the parent (1, 4, 3).
  nlohmann::json doc = Doc({{1, 0, 0}, {0, 1, 0}, {0, 0, 1}}, {}, 4);
  const double h = std::sqrt(0.5);
  doc["nodes"] = {
      {{"name", "parent"}, {"translation", {1, 2, 3}}, {"children", {1}}},
      {{"name", "child"}, {"mesh", 0}, {"rotation", {0, 0, h, h}}, {"scale", {2, 2, 2}}}};
  const GltfScene s = LoadGltfScene(Write(doc).string());
  ASSERT_EQ(s.instances.size(), 1u);
  EXPECT_EQ(s.instances[0].node_name, "child");
  const glm::dvec3 p_W = ToWorld(s.instances[0], {1, 0, 0});
  EXPECT_NEAR(glm::length(p_W - glm::dvec3(1, 4, 3)), 0.0, 1e-12);
  // The same pose as one column-major matrix on the child gives the same point.
  doc["nodes"][1].erase("rotation");
  doc["nodes"][1].erase("scale");
  doc["nodes"][1]["matrix"] = {0, 2, 0, 0, -2, 0, 0, 0, 0, 0, 2, 0, 0, 0, 0, 1};
  const GltfScene m = LoadGltfScene(Write(doc).string());
  EXPECT_NEAR(glm::length(ToWorld(m.instances[0], {1, 0, 0}) - glm::dvec3(1, 4, 3)), 0.0, 1e-12);
}

TEST_F(GltfSceneMadeFiles, BufferShorterThanItsAccessorIsRefused) {
  nlohmann::json doc = Doc(Zigzag(), {}, 4);
  doc["accessors"][0]["count"] = 7;  // 84 bytes from a 72-byte view
  EXPECT_NE(ExpectLoadError(Write(doc)).find("out of buffer range"), std::string::npos);
  doc = Doc(Zigzag(), {}, 4);
  doc["bufferViews"][0]["byteLength"] = 80;  // view past the 72-byte buffer
  doc["accessors"][0]["count"] = 6;
  ExpectLoadError(Write(doc));
  doc = Doc(Zigzag(), {}, 4);
  doc["buffers"][0]["byteLength"] = 100;  // the file has 72 bytes
  ExpectLoadError(Write(doc));
}

TEST_F(GltfSceneMadeFiles, AttributesOfDifferentLengthsAreRefused) {
  nlohmann::json doc = Doc(Zigzag(), {}, 4);
  doc["accessors"].push_back(doc["accessors"][0]);
  doc["accessors"][1]["count"] = 3;
  doc["meshes"][0]["primitives"][0]["attributes"]["NORMAL"] = 1;
  EXPECT_NE(ExpectLoadError(Write(doc)).find("different lengths"), std::string::npos);
}

TEST_F(GltfSceneMadeFiles, WrongComponentTypesAreRefused) {
  nlohmann::json doc = Doc(Zigzag(), {}, 4);
  doc["accessors"][0]["componentType"] = 5123;  // UNSIGNED_SHORT positions
  EXPECT_NE(ExpectLoadError(Write(doc)).find("wrong component type"), std::string::npos);
  doc = Doc(Zigzag(), {0, 1, 2}, 4);
  doc["accessors"][1]["componentType"] = 5126;  // FLOAT indices
  EXPECT_NE(ExpectLoadError(Write(doc)).find("wrong component type"), std::string::npos);
}

TEST_F(GltfSceneMadeFiles, IndexOutOfRangeIsRefused) {
  EXPECT_NE(ExpectLoadError(Write(Doc(Zigzag(), {0, 1, 6}, 4))).find("index 6"), std::string::npos);
}

TEST_F(GltfSceneMadeFiles, NodeCyclesAreRefusedWithoutRecursingForever) {
  nlohmann::json doc = Doc(Zigzag(), {}, 4);
  doc["nodes"] = {{{"children", {1}}}, {{"children", {2}}, {"mesh", 0}}, {{"children", {1}}}};
  EXPECT_NE(ExpectLoadError(Write(doc)).find("cycle"), std::string::npos);
  doc["nodes"] = {{{"children", {0}}}};  // its own child
  EXPECT_NE(ExpectLoadError(Write(doc)).find("cycle"), std::string::npos);
  doc["nodes"] = {{{"mesh", 0}}, {{"children", {2}}}, {{"children", {1}}}};  // cycle off-scene
  EXPECT_NE(ExpectLoadError(Write(doc)).find("cycle"), std::string::npos);
}

TEST_F(GltfSceneMadeFiles, NodeUnderTwoParentsIsShownOncePerPathAndItsMeshStoredOnce) {
  nlohmann::json doc = Doc(Zigzag(), {}, 4);
  doc["scenes"][0]["nodes"] = {0, 1};
  doc["nodes"] = {{{"children", {2}}, {"translation", {10, 0, 0}}},
                  {{"children", {2}}, {"translation", {20, 0, 0}}},
                  {{"mesh", 0}}};
  const GltfScene s = LoadGltfScene(Write(doc).string());
  ASSERT_EQ(s.instances.size(), 2u);
  EXPECT_EQ(s.meshes.size(), 1u);
  EXPECT_EQ(s.instances[0].X_WN[3].x, 10.0);
  EXPECT_EQ(s.instances[1].X_WN[3].x, 20.0);
  EXPECT_TRUE(HasNoteContaining(s, "several parents"));
}

TEST_F(GltfSceneMadeFiles, SharedChildrenThatMultiplyPathsAreCapped) {
  // 40 layers of two nodes, each pointing at both nodes of the next layer: 2^40 paths.
  nlohmann::json doc = Doc(Zigzag(), {}, 4);
  doc["nodes"] = nlohmann::json::array();
  for (int layer = 0; layer < 40; ++layer) {
    for (int k = 0; k < 2; ++k) {
      nlohmann::json node = {{"mesh", 0}};
      if (layer < 39) node["children"] = {2 * layer + 2, 2 * layer + 3};
      doc["nodes"].push_back(node);
    }
  }
  doc["scenes"][0]["nodes"] = {0, 1};
  EXPECT_NE(ExpectLoadError(Write(doc)).find("node visits"), std::string::npos);
}

TEST_F(GltfSceneMadeFiles, NanPositionIsRefused) {
  std::vector<glm::vec3> p = Zigzag();
  p[3].y = std::numeric_limits<float>::quiet_NaN();
  EXPECT_NE(ExpectLoadError(Write(Doc(p, {}, 4))).find("vertex 3"), std::string::npos);
}

TEST_F(GltfSceneMadeFiles, AbsurdCountIsRefusedWithoutAllocating) {
  nlohmann::json doc = Doc(Zigzag(), {}, 4);
  doc["accessors"][0].erase("bufferView");  // all zeros, no bytes to bound the count
  doc["accessors"][0]["count"] = 2'000'000'000;
  ExpectLoadError(Write(doc));
}

TEST_F(GltfSceneMadeFiles, MissingFileIsRefused) { ExpectLoadError(dir_ / "absent.gltf"); }

}  // namespace
}  // namespace ht
