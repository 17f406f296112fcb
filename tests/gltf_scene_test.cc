// LoadGltfScene() against the glTF files of ../shared/data/gltf (located through
// HT_SHARED_DATA, else ../shared/data relative to the working directory, the repository root;
// the data tests are skipped when neither exists) and against small files written to the temp
// dir.

#include "codecs/gltf_scene.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtc/quaternion.hpp>
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

#include "codecs/draco_mesh_codec.h"
#include "codecs/json_nesting.h"
#include "gltf_test_data.h"

namespace ht {
namespace {

namespace fs = std::filesystem;

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
  // The first perspective camera is kept for display (node 1 of the file; the orthographic one on
  // node 2 is not used), with the file's numbers.
  ASSERT_GE(cams.camera.scene_node, 0);
  EXPECT_EQ(cams.nodes[static_cast<std::size_t>(cams.camera.scene_node)].node_index, 1);
  EXPECT_DOUBLE_EQ(cams.camera.yfov_rad, 0.7);
  EXPECT_DOUBLE_EQ(cams.camera.znear_m, 0.01);
  EXPECT_DOUBLE_EQ(cams.camera.zfar_m, 100.0);
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
// Animations in the real files.

// The FLOAT elements (`components` numbers each) of accessor `a` of a .gltf whose buffers are
// external files, read straight from the JSON and the .bin (no tinygltf, no loader code): the
// second route to the keys.
std::vector<float> ReadFloatAccessor(const nlohmann::json& doc, const fs::path& dir, int a,
                                     int components) {
  const nlohmann::json& acc = doc["accessors"][static_cast<std::size_t>(a)];
  EXPECT_EQ(acc["componentType"], 5126);
  const nlohmann::json& view = doc["bufferViews"][acc["bufferView"].get<std::size_t>()];
  EXPECT_FALSE(view.contains("byteStride")) << "this reader wants tightly packed elements";
  const nlohmann::json& buffer = doc["buffers"][view["buffer"].get<std::size_t>()];
  std::ifstream in(dir / buffer["uri"].get<std::string>(), std::ios::binary);
  const std::vector<char> bytes{std::istreambuf_iterator<char>(in), {}};
  const std::size_t offset =
      view.value("byteOffset", std::size_t{0}) + acc.value("byteOffset", std::size_t{0});
  std::vector<float> out(acc["count"].get<std::size_t>() * static_cast<std::size_t>(components));
  EXPECT_LE(offset + out.size() * 4, bytes.size());
  if (offset + out.size() * 4 <= bytes.size())
    std::memcpy(out.data(), bytes.data() + offset, out.size() * 4);
  return out;
}

double MaxAbsDifference(const glm::dmat4& a, const glm::dmat4& b) {
  double worst = 0.0;
  for (int c = 0; c < 4; ++c) {
    for (int r = 0; r < 4; ++r) worst = std::max(worst, std::abs(a[c][r] - b[c][r]));
  }
  return worst;
}

std::size_t InstanceOfNode(const GltfScene& s, int node_index) {
  for (std::size_t i = 0; i < s.instances.size(); ++i) {
    if (s.instances[i].node_index == node_index) return i;
  }
  ADD_FAILURE() << "no instance of node " << node_index;
  return 0;
}

TEST(GltfSceneData, OnlyTheTruckAndTheSkeletonHaveTransformAnimations) {
  REQUIRE_GLTF_DATA(dir);
  // Found by grepping every .gltf and every .glb JSON chunk for "animations": the milk truck
  // (wheel rotations), unassigned-skeleton.gltf (a bone's rotation and scale) and the sparse
  // morph cube (one `weights` channel, ignored).
  for (const std::string& rel : ListGltfFiles(*dir)) {
    if (kValidFiles.count(rel) == 0) continue;
    const GltfScene s = LoadGltfScene((*dir / rel).string());
    std::size_t channels = 0;
    for (const GltfAnimation& a : s.animations) channels += a.channels.size();
    if (!s.animations.empty()) {
      std::cout << rel << ": " << s.animations.size() << " animation(s), " << channels
                << " channel(s), first lasts " << s.animations[0].duration_s << " s\n";
    }
    const bool expect_channels =
        rel == "draco_testdata_gltf/CesiumMilkTruck/glTF/CesiumMilkTruck.gltf" ||
        rel == "tinygltf_tests/models/regression/unassigned-skeleton.gltf";
    EXPECT_EQ(channels > 0, expect_channels) << rel;
  }
  const GltfScene morph = LoadGltfScene(
      (*dir / "tinygltf_tests/models/SparseMorphTargets-issue280/singleBlendshapeCube_sparse.glb")
          .string());
  ASSERT_EQ(morph.animations.size(), 1u);
  EXPECT_EQ(morph.animations[0].name, "Take 001");
  EXPECT_TRUE(morph.animations[0].channels.empty());
  EXPECT_TRUE(HasNoteContaining(morph, "weights")) << ::testing::PrintToString(morph.notes);

  // The skeleton: bone_2 (node 2, under bone_1 at (0, 1, 0)) turns and scales; its keys are
  // interleaved with a 32-byte stride. It shows no mesh, so the instances stay at rest.
  const GltfScene bones =
      LoadGltfScene((*dir / "tinygltf_tests/models/regression/unassigned-skeleton.gltf").string());
  ASSERT_EQ(bones.animations.size(), 1u);
  ASSERT_EQ(bones.animations[0].channels.size(), 2u);
  EXPECT_NEAR(bones.animations[0].duration_s, 5.466667175292969, 1e-9);
  for (const GltfAnimationChannel& c : bones.animations[0].channels) {
    EXPECT_EQ(c.node, 2);
    EXPECT_EQ(c.times_s.size(), 165u);
    EXPECT_EQ(bones.nodes[static_cast<std::size_t>(c.scene_node)].node_index, 2);
  }
  EXPECT_EQ(bones.animations[0].channels[0].path, GltfAnimationChannel::Path::kRotation);
  EXPECT_EQ(bones.animations[0].channels[1].path, GltfAnimationChannel::Path::kScale);
  const std::vector<glm::dmat4> X = PoseInstancesAt(bones, 0, 2.0);
  ASSERT_EQ(X.size(), bones.instances.size());
  for (std::size_t i = 0; i < X.size(); ++i)
    EXPECT_EQ(MaxAbsDifference(X[i], bones.instances[i].X_WN), 0.0);
}

TEST(GltfSceneData, MilkTruckWheelsTurnAboutTheirAxlesThroughTheKeys) {
  REQUIRE_GLTF_DATA(dir);
  const fs::path path = *dir / "draco_testdata_gltf/CesiumMilkTruck/glTF/CesiumMilkTruck.gltf";
  const GltfScene s = LoadGltfScene(path.string());
  std::ifstream in(path);
  const nlohmann::json doc = nlohmann::json::parse(in);

  // One animation, two LINEAR rotation channels (wheels: nodes 2 and 4), 31 keys over 1.25 s.
  ASSERT_EQ(s.animations.size(), 1u);
  const GltfAnimation& anim = s.animations[0];
  ASSERT_EQ(anim.channels.size(), 2u);
  const nlohmann::json& samplers = doc["animations"][0]["samplers"];
  const double max_time = doc["accessors"][samplers[0]["input"].get<int>()]["max"][0];
  EXPECT_EQ(anim.duration_s, max_time);
  EXPECT_NEAR(anim.duration_s, 1.25, 1e-12);
  const nlohmann::json summary = SceneSummaryJson(s);
  ASSERT_EQ(summary["animations"].size(), 1u);
  EXPECT_EQ(summary["animations"][0]["channels"], 2);
  EXPECT_EQ(summary["animations"][0]["duration_s"].get<double>(), anim.duration_s);

  // The rest pose is the loader's X_WN, exactly.
  const std::vector<glm::dmat4> rest = PoseInstancesAt(s, -1, 0.0);
  ASSERT_EQ(rest.size(), s.instances.size());
  for (std::size_t i = 0; i < rest.size(); ++i)
    EXPECT_EQ(MaxAbsDifference(rest[i], s.instances[i].X_WN), 0.0);

  const std::size_t body = InstanceOfNode(s, 0);
  for (std::size_t c = 0; c < 2; ++c) {
    const nlohmann::json& channel = doc["animations"][0]["channels"][c];
    const int node = channel["target"]["node"];
    SCOPED_TRACE("wheel node " + std::to_string(node));
    ASSERT_EQ(channel["target"]["path"], "rotation");
    const nlohmann::json& sampler = samplers[channel["sampler"].get<std::size_t>()];
    const std::vector<float> times =
        ReadFloatAccessor(doc, path.parent_path(), sampler["input"], 1);
    const std::vector<float> quats =
        ReadFloatAccessor(doc, path.parent_path(), sampler["output"], 4);
    ASSERT_EQ(times.size(), 31u);
    ASSERT_EQ(quats.size(), 4 * times.size());
    // The wheel's parent: the node whose children hold it, a translation-only matrix under the
    // untransformed root.
    glm::dmat4 X_WP(1.0);
    for (const nlohmann::json& n : doc["nodes"]) {
      const std::vector<int> children = n.value("children", std::vector<int>{});
      if (n.contains("matrix") && std::count(children.begin(), children.end(), node) == 1) {
        for (int k = 0; k < 16; ++k) X_WP[k / 4][k % 4] = n["matrix"][k].get<double>();
      }
    }
    ASSERT_NE(X_WP[3].x, 0.0);
    auto key = [&](std::size_t k) {
      return glm::normalize(
          glm::dquat(quats[4 * k + 3], quats[4 * k], quats[4 * k + 1], quats[4 * k + 2]));
    };
    const std::size_t wheel = InstanceOfNode(s, node);

    // At every key time the pose is the key value (no loop, so the last key is not wrapped).
    for (std::size_t k = 0; k < times.size(); ++k) {
      const std::vector<glm::dmat4> X = PoseInstancesAt(s, 0, times[k], /*loop=*/false);
      EXPECT_LT(MaxAbsDifference(X[wheel], X_WP * glm::mat4_cast(key(k))), 1e-12) << "key " << k;
      EXPECT_LT(MaxAbsDifference(X[body], s.instances[body].X_WN), 1e-15);
    }
    // Halfway between two keys: slerp of the two (glm::slerp, shorter arc).
    for (std::size_t k = 0; k + 1 < times.size(); k += 7) {
      const double t = 0.5 * (double{times[k]} + double{times[k + 1]});
      const std::vector<glm::dmat4> X = PoseInstancesAt(s, 0, t, false);
      EXPECT_LT(
          MaxAbsDifference(X[wheel], X_WP * glm::mat4_cast(glm::slerp(key(k), key(k + 1), 0.5))),
          1e-9)
          << "between keys " << k << " and " << k + 1;
    }
    // At half the duration the wheel has turned about its axle (z of its parent frame): its
    // origin and axle stay where they were at rest, its spokes do not.
    const std::vector<glm::dmat4> half = PoseInstancesAt(s, 0, 0.5 * anim.duration_s);
    const glm::dmat4& X_rest = s.instances[wheel].X_WN;
    const glm::dmat4& X_half = half[wheel];
    EXPECT_LT(glm::length(glm::dvec3(X_half[3]) - glm::dvec3(X_rest[3])), 1e-12);
    EXPECT_LT(glm::length(glm::dvec3(X_half[2]) - glm::dvec3(X_rest[2])), 1e-9);
    const double turned =
        std::acos(std::clamp(glm::dot(glm::dvec3(X_half[0]), glm::dvec3(X_rest[0])), -1.0, 1.0));
    std::cout << "wheel node " << node << " at " << 0.5 * anim.duration_s << " s: turned by "
              << turned << " rad from rest\n";
    EXPECT_GT(turned, 0.1);

    // Looping wraps by the duration (either way); without loop, later times hold the last key.
    const double t = 0.4;
    const glm::dmat4 X_t = PoseInstancesAt(s, 0, t, false)[wheel];
    EXPECT_LT(MaxAbsDifference(PoseInstancesAt(s, 0, t + 3 * anim.duration_s, true)[wheel], X_t),
              1e-9);
    EXPECT_LT(MaxAbsDifference(PoseInstancesAt(s, 0, t - anim.duration_s, true)[wheel], X_t), 1e-9);
    EXPECT_LT(MaxAbsDifference(PoseInstancesAt(s, 0, 100.0, false)[wheel],
                               X_WP * glm::mat4_cast(key(times.size() - 1))),
              1e-12);
    // Odd times never throw: NaN is the rest pose, infinities hold the end keys.
    EXPECT_EQ(MaxAbsDifference(
                  PoseInstancesAt(s, 0, std::numeric_limits<double>::quiet_NaN())[wheel], X_rest),
              0.0);
    EXPECT_LT(
        MaxAbsDifference(PoseInstancesAt(s, 0, -std::numeric_limits<double>::infinity())[wheel],
                         X_WP * glm::mat4_cast(key(0))),
        1e-12);
    EXPECT_LT(
        MaxAbsDifference(PoseInstancesAt(s, 0, std::numeric_limits<double>::infinity())[wheel],
                         X_WP * glm::mat4_cast(key(times.size() - 1))),
        1e-12);
    EXPECT_TRUE(std::isfinite(PoseInstancesAt(s, 0, 1e300)[wheel][0][0]));
  }
}

// ---- Texture coordinates and per-triangle materials in the real files.

// Every coordinate in [0, 1] and one per vertex, the material of every triangle the mesh's.
void ExpectDuckTextureCoordinates(const GltfScene& s, const std::string& what) {
  ASSERT_EQ(s.meshes.size(), 1u) << what;
  const GltfMesh& m = s.meshes[0];
  ASSERT_EQ(m.uv_N.size(), m.mesh_N.vertices.size()) << what;
  ASSERT_FALSE(m.uv_N.empty()) << what;
  for (const glm::dvec2& uv : m.uv_N) {
    ASSERT_TRUE(uv.x >= 0.0 && uv.x <= 1.0 && uv.y >= 0.0 && uv.y <= 1.0)
        << what << ": (" << uv.x << ", " << uv.y << ")";
  }
  ASSERT_EQ(m.triangle_material.size(), m.mesh_N.triangles.size()) << what;
  EXPECT_TRUE(std::all_of(m.triangle_material.begin(), m.triangle_material.end(), [&](int k) {
    return k == m.material;
  })) << what;
  EXPECT_EQ(m.material, 0) << what;
}

TEST(GltfSceneData, DuckHasTextureCoordinatesInTheUnitSquareForEveryVertex) {
  REQUIRE_GLTF_DATA(dir);
  const fs::path gltf = *dir / "draco_testdata_gltf/KhronosSampleModels/Duck/glTF/Duck.gltf";
  const GltfScene a = LoadGltfScene(gltf.string());
  ExpectDuckTextureCoordinates(a, "Duck.gltf");
  // Second route: the accessor's min/max in the file's JSON bound the coordinates read.
  std::ifstream in(gltf);
  const nlohmann::json doc = nlohmann::json::parse(in);
  const int accessor = doc["meshes"][0]["primitives"][0]["attributes"]["TEXCOORD_0"];
  const nlohmann::json& acc = doc["accessors"][static_cast<std::size_t>(accessor)];
  glm::dvec2 lo(1e9), hi(-1e9);
  for (const glm::dvec2& uv : a.meshes[0].uv_N) {
    lo = glm::min(lo, uv);
    hi = glm::max(hi, uv);
  }
  for (int k = 0; k < 2; ++k) {
    EXPECT_NEAR(lo[k], acc["min"][static_cast<std::size_t>(k)].get<double>(), 1e-6);
    EXPECT_NEAR(hi[k], acc["max"][static_cast<std::size_t>(k)].get<double>(), 1e-6);
  }
  const GltfScene b = LoadGltfScene((*dir / "draco_testdata_gltf/glTF_Binary/Duck.glb").string());
  ExpectDuckTextureCoordinates(b, "Duck.glb");
  EXPECT_EQ(a.meshes[0].uv_N, b.meshes[0].uv_N);
}

// The shared data holds no Draco Duck: one is made here from the plain Duck with this project's
// Draco encoder (14-bit positions, 12-bit coordinates) and written as a .gltf with
// KHR_draco_mesh_compression. Loaded, every vertex (position, uv) lies within half a
// quantization step of a vertex of the plain Duck, and every plain vertex has such a twin.
TEST(GltfSceneData, DracoDuckAgreesWithThePlainDuckWithinTheQuantizationSteps) {
  REQUIRE_GLTF_DATA(dir);
  const GltfScene plain = LoadGltfScene(
      (*dir / "draco_testdata_gltf/KhronosSampleModels/Duck/glTF/Duck.gltf").string());
  ASSERT_EQ(plain.meshes.size(), 1u);
  const GltfMesh& p = plain.meshes[0];
  const DracoEncodeOptions options;  // 14 and 12 bits
  const std::vector<std::uint8_t> draco = EncodeMeshDracoWithUv(p.mesh_N, p.uv_N, options);
  const std::size_t points = DecodeMeshDracoWithUv(draco).mesh.vertices.size();

  const fs::path out = fs::temp_directory_path() / "gltf_scene_test_draco_duck";
  fs::create_directories(out);
  std::ofstream(out / "duck.bin", std::ios::binary | std::ios::trunc)
      .write(reinterpret_cast<const char*>(draco.data()),
             static_cast<std::streamsize>(draco.size()));
  const nlohmann::json doc = {
      {"asset", {{"version", "2.0"}}},
      {"extensionsUsed", {"KHR_draco_mesh_compression"}},
      {"extensionsRequired", {"KHR_draco_mesh_compression"}},
      {"scene", 0},
      {"scenes", {{{"nodes", {0}}}}},
      {"nodes", {{{"mesh", 0}}}},
      {"meshes",
       {{{"name", "duck"},
         {"primitives",
          {{{"attributes", {{"POSITION", 0}, {"TEXCOORD_0", 1}}},
            {"mode", 4},
            {"extensions",
             {{"KHR_draco_mesh_compression",
               {{"bufferView", 0}, {"attributes", {{"POSITION", 0}, {"TEXCOORD_0", 1}}}}}}}}}}}}},
      {"accessors",
       {{{"componentType", 5126}, {"type", "VEC3"}, {"count", points}},
        {{"componentType", 5126}, {"type", "VEC2"}, {"count", points}}}},
      {"bufferViews", {{{"buffer", 0}, {"byteOffset", 0}, {"byteLength", draco.size()}}}},
      {"buffers", {{{"uri", "duck.bin"}, {"byteLength", draco.size()}}}},
  };
  std::ofstream(out / "duck.gltf", std::ios::trunc) << doc.dump(1);
  const GltfScene d = LoadGltfScene((out / "duck.gltf").string());
  fs::remove_all(out);
  ASSERT_EQ(d.meshes.size(), 1u);
  const GltfMesh& m = d.meshes[0];
  EXPECT_EQ(m.draco_primitive_count, 1);
  ASSERT_EQ(m.uv_N.size(), m.mesh_N.vertices.size());
  EXPECT_EQ(m.mesh_N.triangles.size(), p.mesh_N.triangles.size());

  // Half a step, plus float32 rounding (about 6e-8 of the coordinates' magnitude, 160 here).
  double magnitude = 0.0;
  for (const glm::dvec3& v : p.mesh_N.vertices)
    magnitude = std::max({magnitude, std::abs(v.x), std::abs(v.y), std::abs(v.z)});
  const double position_half_step =
      0.5 * DracoQuantizationStep(p.mesh_N, options.position_quantization_bits) +
      1.2e-7 * magnitude;
  glm::dvec2 lo(1e9), hi(-1e9);
  for (const glm::dvec2& uv : p.uv_N) {
    lo = glm::min(lo, uv);
    hi = glm::max(hi, uv);
  }
  const double uv_half_step =
      0.5 * std::max(hi.x - lo.x, hi.y - lo.y) / ((1 << options.uv_quantization_bits) - 1) + 1e-6;
  auto twin = [&](const glm::dvec3& q, const glm::dvec2& t, const GltfMesh& in) {
    for (std::size_t j = 0; j < in.mesh_N.vertices.size(); ++j) {
      const glm::dvec3 dp = glm::abs(q - in.mesh_N.vertices[j]);
      const glm::dvec2 dt = glm::abs(t - in.uv_N[j]);
      if (std::max({dp.x, dp.y, dp.z}) <= position_half_step &&
          std::max(dt.x, dt.y) <= uv_half_step)
        return true;
    }
    return false;
  };
  std::size_t lonely = 0;
  for (std::size_t i = 0; i < m.mesh_N.vertices.size(); ++i)
    lonely += twin(m.mesh_N.vertices[i], m.uv_N[i], p) ? 0 : 1;
  EXPECT_EQ(lonely, 0u) << "Draco vertices without a plain twin";
  std::vector<char> used(p.mesh_N.vertices.size(), 0);
  for (const glm::ivec3& t : p.mesh_N.triangles)
    for (int c = 0; c < 3; ++c) used[static_cast<std::size_t>(t[c])] = 1;
  lonely = 0;
  for (std::size_t j = 0; j < p.mesh_N.vertices.size(); ++j)
    lonely += !used[j] || twin(p.mesh_N.vertices[j], p.uv_N[j], m) ? 0 : 1;
  EXPECT_EQ(lonely, 0u) << "plain vertices without a Draco twin";
}

// A Draco file from another encoder (Cesium's BoxMetaDraco, 36 points): TEXCOORD_0 is read from
// the Draco attribute the extension names, one per vertex, finite.
TEST(GltfSceneData, DracoBoxMetaHasTextureCoordinatesFromItsDracoStream) {
  REQUIRE_GLTF_DATA(dir);
  const GltfScene s =
      LoadGltfScene((*dir / "draco_testdata_gltf/BoxMetaDraco/glTF/BoxMetaDraco.gltf").string());
  ASSERT_EQ(s.meshes.size(), 1u);
  const GltfMesh& m = s.meshes[0];
  EXPECT_EQ(m.draco_primitive_count, 1);
  ASSERT_EQ(m.uv_N.size(), m.mesh_N.vertices.size());
  EXPECT_EQ(m.mesh_N.vertices.size(), 36u);
  for (const glm::dvec2& uv : m.uv_N) {
    EXPECT_TRUE(std::isfinite(uv.x) && std::isfinite(uv.y));
    EXPECT_TRUE(uv.x >= -1e-6 && uv.x <= 1.0 + 1e-6 && uv.y >= -1e-6 && uv.y <= 1.0 + 1e-6)
        << uv.x << ", " << uv.y;
  }
  EXPECT_EQ(m.triangle_material, std::vector<int>(m.mesh_N.triangles.size(), 0));
}

// CesiumMilkTruck's body mesh merges three primitives (truck, glass, window_trim): each triangle
// names its primitive's material, in the file's primitive order, and each material's triangle
// count is its primitive's index count / 3 (read from the JSON: the second route). Only the body
// primitive has TEXCOORD_0; glass and trim have no texture, so the body keeps its coordinates
// and theirs are (0, 0), with a note.
TEST(GltfSceneData, MilkTruckBodyHasOneMaterialPerPrimitiveInTriangleMaterial) {
  REQUIRE_GLTF_DATA(dir);
  const fs::path path = *dir / "draco_testdata_gltf/CesiumMilkTruck/glTF/CesiumMilkTruck.gltf";
  const GltfScene s = LoadGltfScene(path.string());
  std::ifstream in(path);
  const nlohmann::json doc = nlohmann::json::parse(in);
  const GltfMesh* truck = nullptr;
  for (const GltfMesh& m : s.meshes) {
    if (m.name == "Cesium_Milk_Truck") truck = &m;
  }
  ASSERT_NE(truck, nullptr);
  ASSERT_EQ(truck->triangle_material.size(), truck->mesh_N.triangles.size());
  EXPECT_EQ(truck->dropped_degenerate_triangles, 0);
  std::map<int, std::size_t> count;
  for (int k : truck->triangle_material) ++count[k];
  EXPECT_GT(count.size(), 1u);
  std::map<int, std::size_t> expected;
  for (const nlohmann::json& prim : doc["meshes"][truck->gltf_mesh_index]["primitives"]) {
    const int indices = prim["indices"];
    expected[prim["material"].get<int>()] +=
        doc["accessors"][static_cast<std::size_t>(indices)]["count"].get<std::size_t>() / 3;
  }
  EXPECT_EQ(count, expected);
  EXPECT_TRUE(std::is_sorted(truck->triangle_material.begin(), truck->triangle_material.end()))
      << "primitives 0, 1, 2 merged in order";
  EXPECT_EQ(truck->material, truck->triangle_material.front());
  // Coordinates: complete; the textured body's span the texture, the others' are (0, 0).
  ASSERT_EQ(truck->uv_N.size(), truck->mesh_N.vertices.size());
  for (std::size_t f = 0; f < truck->mesh_N.triangles.size(); ++f) {
    if (truck->triangle_material[f] == 0) continue;
    for (int c = 0; c < 3; ++c) {
      EXPECT_EQ(truck->uv_N[static_cast<std::size_t>(truck->mesh_N.triangles[f][c])],
                glm::dvec2(0.0));
    }
  }
  EXPECT_TRUE(HasNoteContaining(s, "no TEXCOORD_0 and no base-colour texture"))
      << ::testing::PrintToString(s.notes);
}

TEST(GltfSceneData, BoxWithoutTexCoordHasNoCoordinatesAndNoNote) {
  REQUIRE_GLTF_DATA(dir);
  for (const char* rel :
       {"draco_testdata_gltf/Box/glTF/Box.gltf", "draco_testdata_gltf/glTF_Binary/Box_Draco.glb"}) {
    const GltfScene s = LoadGltfScene((*dir / rel).string());
    ASSERT_EQ(s.meshes.size(), 1u) << rel;
    EXPECT_TRUE(s.meshes[0].uv_N.empty()) << rel;
    EXPECT_EQ(s.meshes[0].triangle_material.size(), s.meshes[0].mesh_N.triangles.size()) << rel;
    EXPECT_FALSE(HasNoteContaining(s, "TEXCOORD")) << rel;
  }
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

  // Appends `bytes` (TEXCOORD_0 data of `count` elements) to the bin, with a buffer view and an
  // accessor of `component_type` and `type`, and names it TEXCOORD_0 of primitive `prim` of
  // mesh 0.
  void AddTexCoords(nlohmann::json& doc, const std::vector<std::uint8_t>& bytes, std::size_t count,
                    int component_type, const std::string& type, bool normalized, int prim = 0) {
    const std::size_t offset = bin_.size();
    bin_.insert(bin_.end(), bytes.begin(), bytes.end());
    while (bin_.size() % 4 != 0) bin_.push_back(0);
    doc["buffers"][0]["byteLength"] = bin_.size();
    const std::size_t view = doc["bufferViews"].size();
    doc["bufferViews"].push_back(
        {{"buffer", 0}, {"byteOffset", offset}, {"byteLength", bytes.size()}});
    const std::size_t accessor = doc["accessors"].size();
    nlohmann::json a = {
        {"bufferView", view}, {"componentType", component_type}, {"type", type}, {"count", count}};
    if (normalized) a["normalized"] = true;
    doc["accessors"].push_back(a);
    doc["meshes"][0]["primitives"][prim]["attributes"]["TEXCOORD_0"] = accessor;
  }

  template <typename T>
  static std::vector<std::uint8_t> Bytes(const std::vector<T>& values) {
    std::vector<std::uint8_t> out(values.size() * sizeof(T));
    std::memcpy(out.data(), values.data(), out.size());
    return out;
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

  // Adds to animation 0 of `doc` (made if absent) a channel moving `node`'s `path` with its own
  // sampler, whose key times (FLOAT SCALAR) and values (FLOAT `value_type`, VEC3 or VEC4) lie in
  // a new base64-embedded buffer. Returns the index of the values' accessor (the times' is the
  // one before).
  static int AddChannel(nlohmann::json& doc, int node, const std::string& path,
                        const std::string& interpolation, const std::vector<float>& times,
                        const std::vector<float>& values, const std::string& value_type) {
    std::vector<std::uint8_t> bytes((times.size() + values.size()) * 4);
    std::memcpy(bytes.data(), times.data(), times.size() * 4);
    std::memcpy(bytes.data() + times.size() * 4, values.data(), values.size() * 4);
    const std::size_t buffer = doc["buffers"].size();
    doc["buffers"].push_back({{"uri", "data:application/octet-stream;base64," + Base64(bytes)},
                              {"byteLength", bytes.size()}});
    const std::size_t view = doc["bufferViews"].size();
    doc["bufferViews"].push_back(
        {{"buffer", buffer}, {"byteOffset", 0}, {"byteLength", times.size() * 4}});
    doc["bufferViews"].push_back(
        {{"buffer", buffer}, {"byteOffset", times.size() * 4}, {"byteLength", values.size() * 4}});
    const std::size_t accessor = doc["accessors"].size();
    doc["accessors"].push_back({{"bufferView", view},
                                {"componentType", 5126},
                                {"type", "SCALAR"},
                                {"count", times.size()}});
    const std::size_t components = value_type == "VEC4" ? 4 : 3;
    doc["accessors"].push_back({{"bufferView", view + 1},
                                {"componentType", 5126},
                                {"type", value_type},
                                {"count", values.size() / components}});
    if (!doc.contains("animations")) {
      nlohmann::json anim = nlohmann::json::object();
      anim["name"] = "anim";
      anim["channels"] = nlohmann::json::array();
      anim["samplers"] = nlohmann::json::array();
      doc["animations"] = nlohmann::json::array({anim});
    }
    nlohmann::json& anim = doc["animations"][0];
    const std::size_t sampler = anim["samplers"].size();
    anim["samplers"].push_back(
        {{"input", accessor}, {"output", accessor + 1}, {"interpolation", interpolation}});
    anim["channels"].push_back(
        {{"sampler", sampler}, {"target", {{"node", node}, {"path", path}}}});
    return static_cast<int>(accessor + 1);
  }

  static std::string Base64(const std::vector<std::uint8_t>& bytes) {
    static const char* kAlphabet =
        "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    std::string out;
    for (std::size_t i = 0; i < bytes.size(); i += 3) {
      const std::uint32_t b0 = bytes[i];
      const std::uint32_t b1 = i + 1 < bytes.size() ? bytes[i + 1] : 0;
      const std::uint32_t b2 = i + 2 < bytes.size() ? bytes[i + 2] : 0;
      const std::uint32_t v = (b0 << 16) | (b1 << 8) | b2;
      out.push_back(kAlphabet[(v >> 18) & 63]);
      out.push_back(kAlphabet[(v >> 12) & 63]);
      out.push_back(i + 1 < bytes.size() ? kAlphabet[(v >> 6) & 63] : '=');
      out.push_back(i + 2 < bytes.size() ? kAlphabet[v & 63] : '=');
    }
    return out;
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

TEST_F(GltfSceneMadeFiles, ImageInAViewPastItsBufferIsRefusedNotReadPastTheEnd) {
  // tinygltf hands an image in a buffer view to the image callback without checking the view
  // against its buffer (the scene loader's fuzz target found a read 16 kB past a buffer's end).
  nlohmann::json doc = Doc(Zigzag(), {}, 4);
  const std::size_t view = doc["bufferViews"].size();
  doc["bufferViews"].push_back({{"buffer", 0}, {"byteOffset", 60}, {"byteLength", 16302}});
  doc["images"] = nlohmann::json::array({{{"bufferView", view}, {"mimeType", "image/png"}}});
  EXPECT_NE(ExpectLoadError(Write(doc)).find("runs past its buffer of 72 bytes"),
            std::string::npos);
  // Inside the buffer the bytes are kept as they are.
  doc["bufferViews"][view]["byteLength"] = 12;
  EXPECT_NO_THROW(LoadGltfScene(Write(doc).string()));
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

// A few hundred kilobytes of nested arrays used to overflow the stack of the JSON parsers (issue
// 16): refused by depth before any parser runs, in .gltf and in a .glb's JSON chunk.
TEST_F(GltfSceneMadeFiles, DeeplyNestedJsonIsRefusedNotACrash) {
  const std::string nest = std::string(150000, '[') + std::string(150000, ']');
  const std::string text = R"({"asset": {"version": "2.0"}, "extras": )" + nest + "}";
  const fs::path gltf = dir_ / "deep.gltf";
  std::ofstream(gltf, std::ios::binary) << text;
  try {
    LoadGltfScene(gltf.string());
    ADD_FAILURE() << "accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("nests 150001 levels deep"), std::string::npos)
        << e.what();
    EXPECT_EQ(std::string(e.what()).rfind(gltf.string(), 0), 0u) << e.what();
  }
  // The same JSON as the JSON chunk of a GLB.
  std::string chunk = text;
  while (chunk.size() % 4 != 0) chunk.push_back(' ');
  std::vector<std::uint8_t> glb;
  const auto u32 = [&](std::uint32_t v) {
    for (int i = 0; i < 4; ++i) glb.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
  };
  u32(0x46546C67);  // "glTF"
  u32(2);
  u32(static_cast<std::uint32_t>(12 + 8 + chunk.size()));
  u32(static_cast<std::uint32_t>(chunk.size()));
  u32(0x4E4F534A);  // "JSON"
  glb.insert(glb.end(), chunk.begin(), chunk.end());
  const fs::path glb_path = dir_ / "deep.glb";
  std::ofstream(glb_path, std::ios::binary)
      .write(reinterpret_cast<const char*>(glb.data()), static_cast<std::streamsize>(glb.size()));
  ExpectLoadError(glb_path);
  // Shallow nesting inside strings does not count; escapes are honoured.
  EXPECT_EQ(JsonNestingDepth(R"({"a": "[[[[\"[[[", "b": [{}]})"), 3u);
  EXPECT_EQ(JsonNestingDepth("]]]][[}{"), 2u);
  EXPECT_EQ(JsonNestingDepth(""), 0u);
}

// ---- Texture coordinates and per-triangle materials in files made here.

TEST_F(GltfSceneMadeFiles, FloatTexCoordsAreReadAsTheFileHasThem) {
  nlohmann::json doc = Doc(Zigzag(), {}, 5);
  const std::vector<float> uv = {0.f, 1.f, 0.f, 0.f, 0.5f, 1.f, 0.5f, 0.f, 1.f, 1.f, 2.5f, -0.5f};
  AddTexCoords(doc, Bytes(uv), 6, 5126, "VEC2", false);
  const GltfScene s = LoadGltfScene(Write(doc).string());
  ASSERT_EQ(s.meshes[0].uv_N.size(), 6u);
  for (std::size_t i = 0; i < 6; ++i) {
    EXPECT_EQ(s.meshes[0].uv_N[i], glm::dvec2(uv[2 * i], uv[2 * i + 1])) << i;  // no flip
  }
}

TEST_F(GltfSceneMadeFiles, NormalizedIntegerTexCoordsAreDividedByTheirMaximum) {
  nlohmann::json doc = Doc(Zigzag(), {}, 5);
  const std::vector<std::uint8_t> u8 = {0, 255, 51, 102, 255, 0, 1, 2, 3, 4, 128, 127};
  AddTexCoords(doc, u8, 6, 5121, "VEC2", true);
  GltfScene s = LoadGltfScene(Write(doc).string());
  ASSERT_EQ(s.meshes[0].uv_N.size(), 6u);
  for (std::size_t i = 0; i < 6; ++i) {
    EXPECT_DOUBLE_EQ(s.meshes[0].uv_N[i].x, u8[2 * i] / 255.0);
    EXPECT_DOUBLE_EQ(s.meshes[0].uv_N[i].y, u8[2 * i + 1] / 255.0);
  }
  doc = Doc(Zigzag(), {}, 5);
  const std::vector<std::uint16_t> u16 = {0, 65535, 13107, 32768, 65535, 0, 1, 2, 3, 4, 5, 6};
  AddTexCoords(doc, Bytes(u16), 6, 5123, "VEC2", true);
  s = LoadGltfScene(Write(doc).string());
  ASSERT_EQ(s.meshes[0].uv_N.size(), 6u);
  for (std::size_t i = 0; i < 6; ++i) {
    EXPECT_DOUBLE_EQ(s.meshes[0].uv_N[i].x, u16[2 * i] / 65535.0);
    EXPECT_DOUBLE_EQ(s.meshes[0].uv_N[i].y, u16[2 * i + 1] / 65535.0);
  }
}

TEST_F(GltfSceneMadeFiles, OtherTexCoordTypesAndNonFiniteValuesAreRefused) {
  const std::vector<float> f12(12, 0.5f), f18(18, 0.5f);
  nlohmann::json doc = Doc(Zigzag(), {}, 5);
  AddTexCoords(doc, std::vector<std::uint8_t>(12, 7), 6, 5121, "VEC2", false);  // not normalized
  EXPECT_NE(ExpectLoadError(Write(doc)).find("wrong component type"), std::string::npos);
  doc = Doc(Zigzag(), {}, 5);
  AddTexCoords(doc, std::vector<std::uint8_t>(24, 7), 6, 5122, "VEC2", true);  // SHORT
  EXPECT_NE(ExpectLoadError(Write(doc)).find("wrong component type"), std::string::npos);
  doc = Doc(Zigzag(), {}, 5);
  AddTexCoords(doc, Bytes(f18), 6, 5126, "VEC3", false);
  EXPECT_NE(ExpectLoadError(Write(doc)).find("wrong type"), std::string::npos);
  for (const float bad :
       {std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity()}) {
    std::vector<float> uv = f12;
    uv[7] = bad;
    doc = Doc(Zigzag(), {}, 5);
    AddTexCoords(doc, Bytes(uv), 6, 5126, "VEC2", false);
    EXPECT_NE(ExpectLoadError(Write(doc)).find("not finite"), std::string::npos) << bad;
  }
  doc = Doc(Zigzag(), {}, 5);
  AddTexCoords(doc, Bytes(f12), 6, 5126, "VEC2", false);
  doc["accessors"][1]["count"] = 7;  // past its view, and longer than POSITION
  ExpectLoadError(Write(doc));
}

// Three primitives over the same points: material 1 with coordinates, none without, material 0
// (textured) without. Each triangle names its primitive's material, degenerate ones dropped with
// theirs; the coordinates are complete while only an untextured primitive lacks them, and
// dropped (with a note) once a textured one does.
TEST_F(GltfSceneMadeFiles, TriangleMaterialFollowsThePrimitivesAndCoordinatesStayComplete) {
  nlohmann::json doc = Doc(Zigzag(), {0, 1, 2, 2, 2, 3, 2, 3, 4}, 4);
  AddTexCoords(doc, Bytes(std::vector<float>(12, 0.25f)), 6, 5126, "VEC2", false);
  doc["materials"] = {
      {{"name", "textured"}, {"pbrMetallicRoughness", {{"baseColorTexture", {{"index", 0}}}}}},
      {{"name", "plain"}}};
  nlohmann::json& prims = doc["meshes"][0]["primitives"];
  prims[0]["material"] = 1;
  nlohmann::json second = {{"attributes", {{"POSITION", 0}}}, {"indices", 1}, {"mode", 4}};
  prims.push_back(second);  // no material, no coordinates
  GltfScene s = LoadGltfScene(Write(doc).string());
  const GltfMesh& m = s.meshes[0];
  // Per primitive: (0,1,2) kept, (2,2,3) dropped, (2,3,4) kept.
  EXPECT_EQ(m.dropped_degenerate_triangles, 2);
  EXPECT_EQ(m.triangle_material, (std::vector<int>{1, 1, -1, -1}));
  EXPECT_EQ(m.material, 1);
  ASSERT_EQ(m.uv_N.size(), 12u);
  EXPECT_EQ(m.uv_N[0], glm::dvec2(0.25));
  EXPECT_EQ(m.uv_N[6], glm::dvec2(0.0));
  EXPECT_TRUE(HasNoteContaining(s, "primitive(s) 1 have no TEXCOORD_0"))
      << ::testing::PrintToString(s.notes);

  prims.push_back(second);
  prims[2]["material"] = 0;  // textured, without coordinates
  s = LoadGltfScene(Write(doc).string());
  EXPECT_TRUE(s.meshes[0].uv_N.empty());
  EXPECT_EQ(s.meshes[0].triangle_material, (std::vector<int>{1, 1, -1, -1, 0, 0}));
  EXPECT_TRUE(HasNoteContaining(s, "primitive 2 has no TEXCOORD_0 but its material has"))
      << ::testing::PrintToString(s.notes);
}

// ---- Animations in files made here.

// Origin of an instance's frame N in W.
glm::dvec3 Origin(const glm::dmat4& X_WN) { return glm::dvec3(X_WN[3]); }

TEST_F(GltfSceneMadeFiles, LinearTranslationIsInterpolatedClampedAndLooped) {
  // Node 0 moves from (0,0,0) at t = 0 s to (1,0,0) at t = 2 s.
  nlohmann::json doc = Doc(Zigzag(), {}, 4);
  AddChannel(doc, 0, "translation", "LINEAR", {0, 2}, {0, 0, 0, 1, 0, 0}, "VEC3");
  const GltfScene s = LoadGltfScene(Write(doc).string());
  ASSERT_EQ(s.animations.size(), 1u);
  EXPECT_EQ(s.animations[0].name, "anim");
  EXPECT_EQ(s.animations[0].duration_s, 2.0);
  ASSERT_EQ(s.animations[0].channels.size(), 1u);
  EXPECT_EQ(s.animations[0].channels[0].interpolation, GltfInterpolation::kLinear);
  EXPECT_NEAR(PoseInstancesAt(s, 0, 0.5)[0][3].x, 0.25, 1e-15);
  EXPECT_NEAR(PoseInstancesAt(s, 0, 1.5)[0][3].x, 0.75, 1e-15);
  EXPECT_EQ(PoseInstancesAt(s, 0, 0.0)[0][3].x, 0.0);
  EXPECT_EQ(PoseInstancesAt(s, 0, -1.0, false)[0][3].x, 0.0);  // before the first key
  EXPECT_EQ(PoseInstancesAt(s, 0, 2.0, false)[0][3].x, 1.0);
  EXPECT_EQ(PoseInstancesAt(s, 0, 7.0, false)[0][3].x, 1.0);  // after the last key
  EXPECT_NEAR(PoseInstancesAt(s, 0, 2.5, true)[0][3].x, 0.25, 1e-15);
  EXPECT_NEAR(PoseInstancesAt(s, 0, -1.5, true)[0][3].x, 0.25, 1e-15);
  // The mesh's points move with the node: p_W = X_WN p_N.
  const glm::dvec3 p_W = glm::dvec3(PoseInstancesAt(s, 0, 1.0)[0] * glm::dvec4(0, 1, 0, 1));
  EXPECT_NEAR(glm::length(p_W - glm::dvec3(0.5, 1, 0)), 0.0, 1e-15);
  const nlohmann::json j = SceneSummaryJson(s);
  EXPECT_EQ(j["animations"][0]["name"], "anim");
  EXPECT_EQ(j["animations"][0]["channels"], 1);
  EXPECT_EQ(j["animations"][0]["duration_s"], 2.0);
}

TEST_F(GltfSceneMadeFiles, StepHoldsThePreviousKey) {
  nlohmann::json doc = Doc(Zigzag(), {}, 4);
  AddChannel(doc, 0, "translation", "STEP", {0, 1, 2}, {0, 0, 0, 5, 0, 0, 7, 0, 0}, "VEC3");
  const GltfScene s = LoadGltfScene(Write(doc).string());
  ASSERT_EQ(s.animations[0].channels.size(), 1u);
  EXPECT_EQ(s.animations[0].channels[0].interpolation, GltfInterpolation::kStep);
  for (const auto& [t, x] : std::vector<std::pair<double, double>>{
           {0.0, 0.0}, {0.99, 0.0}, {1.0, 5.0}, {1.5, 5.0}, {1.999, 5.0}, {2.0, 7.0}, {9.0, 7.0}}) {
    EXPECT_EQ(PoseInstancesAt(s, 0, t, false)[0][3].x, x) << "t = " << t;
  }
}

TEST_F(GltfSceneMadeFiles, RotationSlerpsAndChildrenFollowTheirAnimatedParent) {
  // Parent (node 0) turns 0 -> 90° about z over 1 s; child (node 1) sits at (1,0,0) in it.
  nlohmann::json doc = Doc(Zigzag(), {}, 4);
  doc["nodes"] = {{{"name", "parent"}, {"mesh", 0}, {"children", {1}}},
                  {{"name", "child"}, {"mesh", 0}, {"translation", {1, 0, 0}}}};
  const float h = static_cast<float>(std::sqrt(0.5));
  AddChannel(doc, 0, "rotation", "LINEAR", {0, 1}, {0, 0, 0, 1, 0, 0, h, h}, "VEC4");
  const GltfScene s = LoadGltfScene(Write(doc).string());
  ASSERT_EQ(s.instances.size(), 2u);
  ASSERT_EQ(s.nodes.size(), 2u);
  EXPECT_EQ(s.nodes[1].parent, 0);
  EXPECT_EQ(s.instances[1].scene_node, 1);
  const double pi = std::acos(-1.0);
  // Slerp turns at a constant rate: 45° at 0.5 s, 22.5° at 0.25 s (normalized linear
  // interpolation would give 21.6° there). The float key limits the accuracy to ~1e-7.
  for (const double t : {0.0, 0.25, 0.5, 0.75, 1.0}) {
    const double angle = 0.5 * pi * t;
    const std::vector<glm::dmat4> X = PoseInstancesAt(s, 0, t, /*loop=*/false);  // t = 1: end
    const glm::dvec3 child_W = Origin(X[1]);
    EXPECT_NEAR(glm::length(child_W - glm::dvec3(std::cos(angle), std::sin(angle), 0)), 0.0, 1e-7)
        << "t = " << t;
    // The parent turns in place; the child's axes turn with it.
    EXPECT_NEAR(glm::length(Origin(X[0])), 0.0, 1e-15);
    EXPECT_NEAR(glm::length(glm::dvec3(X[1][0]) - glm::dvec3(std::cos(angle), std::sin(angle), 0)),
                0.0, 1e-7);
  }
  // The same rotation as the negated quaternion (-q is q): slerp takes the shorter arc, 45°.
  doc = Doc(Zigzag(), {}, 4);
  doc["nodes"] = {{{"mesh", 0}, {"children", {1}}}, {{"mesh", 0}, {"translation", {1, 0, 0}}}};
  AddChannel(doc, 0, "rotation", "LINEAR", {0, 1}, {0, 0, 0, 1, 0, 0, -h, -h}, "VEC4");
  const GltfScene neg = LoadGltfScene(Write(doc).string());
  EXPECT_NEAR(glm::length(Origin(PoseInstancesAt(neg, 0, 0.5)[1]) -
                          glm::dvec3(std::sqrt(0.5), std::sqrt(0.5), 0)),
              0.0, 1e-7);
}

TEST_F(GltfSceneMadeFiles, ScaleIsAnimatedAndTheOtherPropertiesKeepTheirRestValues) {
  // Rest translation (5,0,0) and rotation 90° about z stay; scale goes 1 -> 3 over 1 s.
  nlohmann::json doc = Doc(Zigzag(), {}, 4);
  const double h = std::sqrt(0.5);
  doc["nodes"][0]["translation"] = {5, 0, 0};
  doc["nodes"][0]["rotation"] = {0, 0, h, h};
  AddChannel(doc, 0, "scale", "LINEAR", {0, 1}, {1, 1, 1, 3, 3, 3}, "VEC3");
  const GltfScene s = LoadGltfScene(Write(doc).string());
  const glm::dmat4 X = PoseInstancesAt(s, 0, 0.5)[0];
  // (1,0,0) in N -> scaled by 2 -> turned to (0,2,0) -> moved to (5,2,0).
  EXPECT_NEAR(glm::length(glm::dvec3(X * glm::dvec4(1, 0, 0, 1)) - glm::dvec3(5, 2, 0)), 0.0,
              1e-12);
  // At t = 0 (scale 1) the pose equals the rest pose.
  EXPECT_LT(MaxAbsDifference(PoseInstancesAt(s, 0, 0.0)[0], s.instances[0].X_WN), 1e-15);
}

TEST_F(GltfSceneMadeFiles, CubicSplineFollowsTheHermiteSplineOfValuesAndTangents) {
  // x from 0 to 1 over 2 s, out-tangent of key 0 = 0.5 /s, in-tangent of key 1 = 0:
  // p(u) = (3u² - 2u³)·1 + (u³ - 2u² + u)·dt·0.5 with dt = 2.
  nlohmann::json doc = Doc(Zigzag(), {}, 4);
  AddChannel(doc, 0, "translation", "CUBICSPLINE", {0, 2},
             {0, 0, 0, /*v0*/ 0, 0, 0, /*b0*/ 0.5f, 0, 0,  // key 0: in, value, out
              /*a1*/ 0, 0, 0, /*v1*/ 1, 0, 0, 0, 0, 0},    // key 1: in, value, out
             "VEC3");
  // Rotation with zero tangents from identity to 90° about z: symmetric, so 45° at the middle.
  const float h = static_cast<float>(std::sqrt(0.5));
  AddChannel(doc, 0, "rotation", "CUBICSPLINE", {0, 2},
             {0, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, h, h, 0, 0, 0, 0}, "VEC4");
  const GltfScene s = LoadGltfScene(Write(doc).string());
  ASSERT_EQ(s.animations[0].channels.size(), 2u);
  EXPECT_EQ(s.animations[0].channels[0].values.size(), 6u);
  for (const double t : {0.0, 0.3, 1.0, 1.7, 2.0}) {
    const double u = t / 2.0;
    const double x = (3 * u * u - 2 * u * u * u) + (u * u * u - 2 * u * u + u) * 2.0 * 0.5;
    EXPECT_NEAR(PoseInstancesAt(s, 0, t, false)[0][3].x, x, 1e-12) << "t = " << t;
  }
  const glm::dmat4 X = PoseInstancesAt(s, 0, 1.0)[0];
  const double pi = std::acos(-1.0);
  EXPECT_NEAR(glm::length(glm::dvec3(X[0]) - glm::dvec3(std::cos(pi / 4), std::sin(pi / 4), 0)),
              0.0, 1e-7);
  EXPECT_NEAR(glm::length(glm::dvec3(X[0])), 1.0, 1e-12);  // normalized: no scale creeps in
}

TEST_F(GltfSceneMadeFiles, AnimatedNodeUnderTwoParentsMovesOnEveryPath) {
  nlohmann::json doc = Doc(Zigzag(), {}, 4);
  doc["scenes"][0]["nodes"] = {0, 1};
  doc["nodes"] = {{{"children", {2}}, {"translation", {10, 0, 0}}},
                  {{"children", {2}}, {"translation", {20, 0, 0}}},
                  {{"mesh", 0}}};
  AddChannel(doc, 2, "translation", "LINEAR", {0, 1}, {0, 0, 0, 0, 4, 0}, "VEC3");
  const GltfScene s = LoadGltfScene(Write(doc).string());
  ASSERT_EQ(s.instances.size(), 2u);
  const std::vector<glm::dmat4> X = PoseInstancesAt(s, 0, 0.5);
  EXPECT_EQ(Origin(X[0]), glm::dvec3(10, 2, 0));
  EXPECT_EQ(Origin(X[1]), glm::dvec3(20, 2, 0));
}

TEST_F(GltfSceneMadeFiles, RestPoseForNoAnimationAndTheReusedVectorIsNotReallocated) {
  nlohmann::json doc = Doc(Zigzag(), {}, 4);
  doc["nodes"][0]["translation"] = {1, 2, 3};
  const GltfScene plain = LoadGltfScene(Write(doc).string());
  EXPECT_TRUE(plain.animations.empty());
  EXPECT_EQ(SceneSummaryJson(plain)["animations"], nlohmann::json::array());
  for (const int a : {-1, 0, 3}) {
    const std::vector<glm::dmat4> X = PoseInstancesAt(plain, a, 1.0);
    ASSERT_EQ(X.size(), 1u);
    EXPECT_EQ(MaxAbsDifference(X[0], plain.instances[0].X_WN), 0.0);
  }
  AddChannel(doc, 0, "translation", "LINEAR", {0, 1}, {0, 0, 0, 1, 0, 0}, "VEC3");
  const GltfScene s = LoadGltfScene(Write(doc).string());
  std::vector<glm::dmat4> X;
  PoseInstancesAt(s, 0, 0.5, true, &X);
  const glm::dmat4* data = X.data();
  for (const double t : {0.1, 0.7, std::numeric_limits<double>::quiet_NaN(), -1e308, 1e308,
                         std::numeric_limits<double>::infinity()}) {
    PoseInstancesAt(s, 0, t, true, &X);
    EXPECT_EQ(X.data(), data) << "t = " << t;
    ASSERT_EQ(X.size(), 1u);
    EXPECT_TRUE(std::isfinite(X[0][3].x)) << "t = " << t;
  }
  PoseInstancesAt(s, 0, std::numeric_limits<double>::quiet_NaN(), true, &X);
  EXPECT_EQ(MaxAbsDifference(X[0], s.instances[0].X_WN), 0.0);
  PoseInstancesAt(s, 1, 0.5, true, &X);  // no animation 1: rest
  EXPECT_EQ(MaxAbsDifference(X[0], s.instances[0].X_WN), 0.0);
}

TEST_F(GltfSceneMadeFiles, WeightsUnreachedAndMatrixChannelsAreIgnoredWithANote) {
  nlohmann::json doc = Doc(Zigzag(), {}, 4);
  doc["nodes"] = {{{"mesh", 0}},
                  {{"mesh", 0}},  // not in the scene
                  {{"matrix", {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1}}}};
  doc["scenes"][0]["nodes"] = {0, 2};
  AddChannel(doc, 0, "weights", "LINEAR", {0, 1}, {0, 0, 0, 1, 1, 1}, "VEC3");
  AddChannel(doc, 1, "translation", "LINEAR", {0, 1}, {0, 0, 0, 1, 1, 1}, "VEC3");
  AddChannel(doc, 2, "translation", "LINEAR", {0, 1}, {0, 0, 0, 1, 1, 1}, "VEC3");
  const GltfScene s = LoadGltfScene(Write(doc).string());
  ASSERT_EQ(s.animations.size(), 1u);
  EXPECT_TRUE(s.animations[0].channels.empty());
  EXPECT_EQ(s.animations[0].duration_s, 0.0);
  EXPECT_TRUE(HasNoteContaining(s, "weights")) << ::testing::PrintToString(s.notes);
  EXPECT_TRUE(HasNoteContaining(s, "not reached from the scene"));
  EXPECT_TRUE(HasNoteContaining(s, "gives a matrix"));
  EXPECT_EQ(MaxAbsDifference(PoseInstancesAt(s, 0, 0.5)[0], s.instances[0].X_WN), 0.0);
}

TEST_F(GltfSceneMadeFiles, MalformedAnimationsAreRefusedNamingTheFileAndChannel) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  struct Case {
    const char* what;
    std::function<void(nlohmann::json&)> make;
    const char* expected;
  };
  const std::vector<Case> cases = {
      {"decreasing times",
       [](nlohmann::json& d) {
         AddChannel(d, 0, "translation", "LINEAR", {0, 2, 1}, std::vector<float>(9, 0.0f), "VEC3");
       },
       "non-decreasing"},
      {"negative time",
       [](nlohmann::json& d) {
         AddChannel(d, 0, "translation", "LINEAR", {-1, 1}, std::vector<float>(6, 0.0f), "VEC3");
       },
       "negative"},
      {"NaN time",
       [nan](nlohmann::json& d) {
         AddChannel(d, 0, "translation", "LINEAR", {0, nan}, std::vector<float>(6, 0.0f), "VEC3");
       },
       "not finite"},
      {"output count",
       [](nlohmann::json& d) {
         AddChannel(d, 0, "translation", "LINEAR", {0, 1, 2}, std::vector<float>(6, 0.0f), "VEC3");
       },
       "expected 3"},
      {"cubic output count",
       [](nlohmann::json& d) {
         AddChannel(d, 0, "translation", "CUBICSPLINE", {0, 1}, std::vector<float>(6, 0.0f),
                    "VEC3");
       },
       "3 per key"},
      {"target out of range",
       [](nlohmann::json& d) {
         AddChannel(d, 7, "translation", "LINEAR", {0, 1}, std::vector<float>(6, 0.0f), "VEC3");
       },
       "target node 7 out of range"},
      {"NaN value",
       [nan](nlohmann::json& d) {
         AddChannel(d, 0, "translation", "LINEAR", {0, 1}, {0, 0, 0, 1, nan, 0}, "VEC3");
       },
       "not finite"},
      {"rotation as VEC3",
       [](nlohmann::json& d) {
         AddChannel(d, 0, "rotation", "LINEAR", {0, 1}, std::vector<float>(6, 0.0f), "VEC3");
       },
       "FLOAT VEC4 is required"},
      {"zero rotation",
       [](nlohmann::json& d) {
         AddChannel(d, 0, "rotation", "LINEAR", {0, 1}, {0, 0, 0, 1, 0, 0, 0, 0}, "VEC4");
       },
       "zero length"},
      {"integer times",
       [](nlohmann::json& d) {
         const int out =
             AddChannel(d, 0, "translation", "LINEAR", {0, 1}, std::vector<float>(6, 0.0f), "VEC3");
         d["accessors"][out - 1]["componentType"] = 5125;  // UNSIGNED_INT
       },
       "FLOAT SCALAR is required"},
      {"unknown interpolation",
       [](nlohmann::json& d) {
         AddChannel(d, 0, "translation", "BEZIER", {0, 1}, std::vector<float>(6, 0.0f), "VEC3");
       },
       "BEZIER"},
      {"sampler out of range",
       [](nlohmann::json& d) {
         AddChannel(d, 0, "translation", "LINEAR", {0, 1}, std::vector<float>(6, 0.0f), "VEC3");
         d["animations"][0]["channels"][0]["sampler"] = 4;
       },
       "sampler 4 out of range"},
      {"same target twice",
       [](nlohmann::json& d) {
         AddChannel(d, 0, "scale", "LINEAR", {0, 1}, std::vector<float>(6, 1.0f), "VEC3");
         AddChannel(d, 0, "scale", "STEP", {0, 1}, std::vector<float>(6, 1.0f), "VEC3");
       },
       "already animated by channel 0"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.what);
    nlohmann::json doc = Doc(Zigzag(), {}, 4);
    c.make(doc);
    const std::string message = ExpectLoadError(Write(doc));
    EXPECT_NE(message.find("animation 0"), std::string::npos) << message;
    EXPECT_NE(message.find(c.expected), std::string::npos)
        << message << "\n  expected: " << c.expected;
    std::cout << "[ refused] " << c.what << ": " << message << "\n";
  }
}

std::vector<std::uint8_t> FileBytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// The display's materials: the Duck's base-colour texture is kept as the file has it (an external
// PNG in .gltf, a buffer view in .glb: the same bytes either way), its factor and the mesh's
// material index.
TEST(GltfSceneData, DuckKeepsItsBaseColourTextureBytesAsTheFileHasThem) {
  REQUIRE_GLTF_DATA(dir);
  const fs::path gltf = *dir / "draco_testdata_gltf/KhronosSampleModels/Duck/glTF/Duck.gltf";
  const GltfScene s = LoadGltfScene(gltf.string());
  ASSERT_EQ(s.materials.size(), 1u);
  ASSERT_EQ(s.images.size(), 1u);
  ASSERT_EQ(s.meshes.size(), 1u);
  EXPECT_EQ(s.meshes[0].material, 0);
  EXPECT_EQ(s.materials[0].base_colour_image, 0);
  EXPECT_EQ(s.images[0].mime_type, "image/png");
  const std::vector<std::uint8_t> png = FileBytes(gltf.parent_path() / "DuckCM.png");
  ASSERT_FALSE(png.empty());
  EXPECT_EQ(s.images[0].bytes, png);
  for (int c = 0; c < 4; ++c) {
    EXPECT_GE(s.materials[0].base_colour_rgba[c], 0.0);
    EXPECT_LE(s.materials[0].base_colour_rgba[c], 1.0);
  }
  const GltfScene glb = LoadGltfScene((*dir / "draco_testdata_gltf/glTF_Binary/Duck.glb").string());
  ASSERT_EQ(glb.images.size(), 1u);
  EXPECT_EQ(glb.images[0].mime_type, "image/png");
  EXPECT_EQ(glb.images[0].bytes, png);  // same image, stored in the GLB's BIN chunk
}

// AnimatedNodePosesAt gives the local poses that PoseInstancesAt composes: each wheel's parent
// world pose times its local pose is its instance pose (two routes to one number), and the
// wheels' rotations change over time while their translations do not.
TEST(GltfSceneData, AnimatedLocalPosesComposeToTheInstancePoses) {
  REQUIRE_GLTF_DATA(dir);
  const GltfScene s = LoadGltfScene(
      (*dir / "draco_testdata_gltf/CesiumMilkTruck/glTF/CesiumMilkTruck.gltf").string());
  std::vector<GltfNodePose> poses;
  AnimatedNodePosesAt(s, 7, 0.3, true, &poses);  // no such animation
  EXPECT_TRUE(poses.empty());
  AnimatedNodePosesAt(s, 0, std::nan(""), true, &poses);
  EXPECT_TRUE(poses.empty());
  std::vector<glm::dquat> first;
  for (const double t : {0.1, 0.45, 0.9}) {
    AnimatedNodePosesAt(s, 0, t, true, &poses);
    ASSERT_EQ(poses.size(), 2u);
    const std::vector<glm::dmat4> X = PoseInstancesAt(s, 0, t);
    const std::vector<glm::dmat4> rest = PoseInstancesAt(s, -1, 0.0);
    for (std::size_t k = 0; k < poses.size(); ++k) {
      const GltfNodePose& p = poses[k];
      ASSERT_GE(p.scene_node, 0);
      const GltfNode& node = s.nodes[static_cast<std::size_t>(p.scene_node)];
      ASSERT_GE(node.parent, 0);
      ASSERT_GE(node.mesh, 0);
      // The parent is not animated: its world pose is its rest pose, found through any instance
      // below it (X_WP = X_WN_rest · X_PN_rest⁻¹).
      std::size_t inst = s.instances.size();
      for (std::size_t i = 0; i < s.instances.size(); ++i)
        if (s.instances[i].scene_node == p.scene_node) inst = i;
      ASSERT_LT(inst, s.instances.size());
      const glm::dmat4 X_WP = rest[inst] * glm::inverse(node.X_PN);
      const glm::dmat4 X_PN = glm::translate(glm::dmat4(1.0), p.translation) *
                              glm::mat4_cast(p.rotation) * glm::scale(glm::dmat4(1.0), p.scale);
      EXPECT_LT(MaxAbsDifference(X_WP * X_PN, X[inst]), 1e-9) << "t " << t << " node " << k;
      EXPECT_LT(glm::length(p.translation - node.translation), 1e-12);
      EXPECT_NEAR(glm::length(p.rotation), 1.0, 1e-12);
      if (first.size() < poses.size()) {
        first.push_back(p.rotation);
      } else {
        EXPECT_LT(std::abs(glm::dot(first[k], p.rotation)), 1.0 - 1e-6) << "it turned";
      }
    }
  }
}

}  // namespace
}  // namespace ht
