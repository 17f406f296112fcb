// Scenes from files: WriteGlb round trip, scene descriptions, roles, scaled instances, shared
// builds, the cache through BuildScene, the real files of ../shared/data/gltf, and the CLI's JSON.

#include "slave_sim/scene_build.h"

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <glm/glm.hpp>
#include <glm/gtc/matrix_transform.hpp>
#include <map>
#include <nlohmann/json.hpp>
#include <numbers>
#include <optional>
#include <set>
#include <thread>

#include "codecs/draco_mesh_codec.h"
#include "codecs/glb_writer.h"
#include "codecs/gltf_scene.h"
#include "gltf_test_data.h"
#include "haptic_core/remote_step.h"
#include "slave_sim/display_scene.h"
#include "slave_sim/watched_scene.h"

namespace ht {
namespace {

namespace fs = std::filesystem;

// A closed box with a ridged top (ridges along x), centred on the origin: 2·n² + 8 triangles.
TriangleMesh RidgedSlab(double half_x, double half_y, double half_z, int n) {
  TriangleMesh m;
  for (int j = 0; j <= n; ++j) {
    for (int i = 0; i <= n; ++i) {
      const double x = -half_x + 2 * half_x * i / n, y = -half_y + 2 * half_y * j / n;
      const bool edge = i == 0 || j == 0 || i == n || j == n;
      const double z = half_z + (edge ? 0.0 : 0.3e-3 * std::sin(2 * std::numbers::pi * y / 3e-3));
      m.vertices.emplace_back(x, y, z);
    }
  }
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      const int a = j * (n + 1) + i, b = a + 1, c = a + n + 1, d = c + 1;
      m.triangles.emplace_back(a, b, d);
      m.triangles.emplace_back(a, d, c);
    }
  }
  // Bottom corners and the four sides down to them.
  const int base = static_cast<int>(m.vertices.size());
  m.vertices.emplace_back(-half_x, -half_y, -half_z);
  m.vertices.emplace_back(half_x, -half_y, -half_z);
  m.vertices.emplace_back(half_x, half_y, -half_z);
  m.vertices.emplace_back(-half_x, half_y, -half_z);
  m.triangles.emplace_back(base, base + 2, base + 1);
  m.triangles.emplace_back(base, base + 3, base + 2);
  // Side walls as fans from the bottom corners (each side: top edge vertices + 2 bottom corners).
  const auto top = [&](int i, int j) { return j * (n + 1) + i; };
  for (int i = 0; i < n; ++i) {
    m.triangles.emplace_back(top(i, 0), base, top(i + 1, 0));      // y = −h side
    m.triangles.emplace_back(top(i + 1, n), base + 2, top(i, n));  // y = +h side
    m.triangles.emplace_back(top(0, i + 1), base + 3, top(0, i));  // x = −h side
    m.triangles.emplace_back(top(n, i), base + 1, top(n, i + 1));  // x = +h side
  }
  m.triangles.emplace_back(top(n, 0), base, base + 1);
  m.triangles.emplace_back(top(n, n), base + 1, base + 2);
  m.triangles.emplace_back(top(0, n), base + 2, base + 3);
  m.triangles.emplace_back(top(0, 0), base + 3, base);
  return m;
}

class SceneBuildTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("ht_scene_build_" +
            std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string Write(const std::string& name, const std::string& text) {
    const fs::path p = dir_ / name;
    std::ofstream(p) << text;
    return p.string();
  }
  fs::path dir_;
};

TEST_F(SceneBuildTest, WrittenGlbLoadsBackWithTheSameTrianglesAndPoses) {
  const TriangleMesh slab = RidgedSlab(0.03, 0.03, 0.005, 20);
  GlbNode a{"slab", slab, glm::dmat4(1.0), ""};
  GlbNode b{"moved", slab, glm::translate(glm::dmat4(1.0), glm::dvec3(0.1, 0.2, 0.3)), ""};
  const std::string path = (dir_ / "two.glb").string();
  WriteGlb(path, {a, b});
  const GltfScene scene = LoadGltfScene(path);
  ASSERT_EQ(scene.instances.size(), 2u);
  ASSERT_EQ(scene.meshes.size(), 2u);
  const TriangleMesh& back = scene.meshes[0].mesh_N;
  ASSERT_EQ(back.triangles.size(), slab.triangles.size());
  ASSERT_EQ(back.vertices.size(), slab.vertices.size());
  for (std::size_t i = 0; i < slab.vertices.size(); ++i) {
    EXPECT_LT(glm::length(back.vertices[i] - slab.vertices[i]), 1e-8);  // float32 rounding
  }
  for (std::size_t i = 0; i < slab.triangles.size(); ++i) {
    EXPECT_EQ(back.triangles[i], slab.triangles[i]);
  }
  EXPECT_EQ(scene.instances[1].node_name, "moved");
  EXPECT_NEAR(scene.instances[1].X_WN[3].y, 0.2, 1e-12);
  TriangleMesh bad = slab;
  bad.triangles[0].x = 100000;
  EXPECT_THROW(WriteGlb(path, {{"bad", bad, glm::dmat4(1.0), ""}}), std::invalid_argument);
}

// The remote node's file watching (issue 17): a scene file rewritten on disk is rebuilt on the
// watcher thread and adopted by TakeReload; the new version's model and display mesh are the new
// file's; a broken file is counted and the current version stays; the description's glTF is
// watched too.
TEST_F(SceneBuildTest, AWatchedSceneIsRebuiltWhenItsFileChangesAndKeptWhenTheNewFileIsBroken) {
  const std::string glb = (dir_ / "watched.glb").string();
  WriteGlb(glb, {{"slab", RidgedSlab(0.03, 0.03, 0.005, 10), glm::dmat4(1.0), ""}});
  const std::string desc = Write("watched.json", R"({"scene": "watched.glb",
    "defaults": {"coarse_triangles": 40, "texture_size": 64}})");
  WatchedScene w(desc, "", HapticModelCache(""));
  ASSERT_EQ(w.watched_files().size(), 2u);  // the description and its glTF
  ASSERT_EQ(w.haptic().touchables.size(), 1u);
  const auto extent_x = [](const HapticScene& s) {
    double hi = 0.0;
    for (const glm::dvec3& p : s.touchables[0].model->vertices_O) hi = std::max(hi, p.x);
    return hi;
  };
  EXPECT_NEAR(extent_x(w.haptic()), 0.03, 1e-6);
  const std::vector<std::uint8_t> mesh_before = w.stream().objects.at(1).bytes;
  const HapticScene* before = &w.haptic();
  EXPECT_FALSE(w.TakeReload());
  w.StartWatching(0.05);
  const auto wait_reload = [&] {
    for (int i = 0; i < 400; ++i) {
      if (w.TakeReload()) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(25));
    }
    return false;
  };
  // A wider slab: the rebuilt model and the streamed mesh follow the file.
  std::this_thread::sleep_for(std::chrono::milliseconds(20));  // a new modification time
  WriteGlb(glb, {{"slab", RidgedSlab(0.05, 0.03, 0.005, 10), glm::dmat4(1.0), ""}});
  ASSERT_TRUE(wait_reload()) << w.StatsJson().dump();
  EXPECT_NE(&w.haptic(), before);
  EXPECT_NEAR(extent_x(w.haptic()), 0.05, 1e-6);
  EXPECT_NE(w.stream().objects.at(1).bytes, mesh_before);
  double min_x = 0.0;
  for (const glm::dvec3& p : DecodeMeshDraco(w.stream().objects.at(1).bytes).vertices)
    min_x = std::min(min_x, p.x);
  EXPECT_NEAR(min_x, -0.05, 1e-4);  // Draco's 14-bit positions
  EXPECT_EQ(w.StatsJson()["reloads"], 1);
  // A broken file: counted with its message, and the current version stays.
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  { std::ofstream(glb, std::ios::binary | std::ios::trunc) << "glTF but not really"; }
  for (int i = 0; i < 400 && w.StatsJson()["builds_failed"] == 0; ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(25));
  EXPECT_EQ(w.StatsJson()["builds_failed"], 1);
  EXPECT_NE(w.StatsJson()["last_error"].get<std::string>().find("watched.glb"), std::string::npos)
      << w.StatsJson().dump();
  EXPECT_FALSE(w.TakeReload());
  EXPECT_NEAR(extent_x(w.haptic()), 0.05, 1e-6);
}

TEST_F(SceneBuildTest, DescriptionRolesScaleAndSharedInstances) {
  const TriangleMesh slab = RidgedSlab(0.03, 0.03, 0.005, 30);
  const glm::dmat4 scaled =
      glm::scale(glm::translate(glm::dmat4(1.0), glm::dvec3(0.2, 0, 0)), glm::dvec3(2.0, 2.0, 2.0));
  WriteGlb((dir_ / "scene.glb").string(),
           {{"floor", slab, glm::dmat4(1.0), ""},
            {"floor_copy", slab, glm::translate(glm::dmat4(1.0), glm::dvec3(0, 0.1, 0)), ""},
            {"big", slab, scaled, ""},
            {"decor", slab, glm::translate(glm::dmat4(1.0), glm::dvec3(0, 0, 1)), ""}});
  const std::string desc = Write("scene.json", R"({
    "scene": "scene.glb",
    "defaults": {"coarse_triangles": 60, "texture_size": 128, "stiffness_n_per_m": 5000},
    "nodes": {"decor": {"role": "display"}, "big": {"stiffness_n_per_m": 12000}}
  })");
  const SceneDescription d = LoadSceneInput(desc);
  EXPECT_EQ(fs::path(d.gltf_path), (dir_ / "scene.glb").lexically_normal());
  const BuiltScene s = BuildScene(d, HapticModelCache(""));
  ASSERT_EQ(s.objects.size(), 4u);
  EXPECT_TRUE(s.builtin_probe);
  ASSERT_EQ(s.haptic.touchables.size(), 3u);
  EXPECT_EQ(s.objects[3].spec.role, NodeRole::kDisplay);
  EXPECT_EQ(s.objects[3].model, nullptr);
  // Two unscaled instances of one mesh share one model; the scaled one has its own, twice as big.
  EXPECT_EQ(s.objects[0].model, s.objects[1].model);
  EXPECT_NE(s.objects[0].model, s.objects[2].model);
  EXPECT_EQ(s.haptic.touchables[2].stiffness_n_per_m, 12000.0);
  EXPECT_EQ(s.haptic.touchables[0].stiffness_n_per_m, 5000.0);
  const auto extent_x = [](const HapticModel& m) {
    double lo = 1e9, hi = -1e9;
    for (const auto& p : m.vertices_O) {
      lo = std::min(lo, p.x);
      hi = std::max(hi, p.x);
    }
    return hi - lo;
  };
  EXPECT_NEAR(extent_x(*s.objects[2].model), 2 * extent_x(*s.objects[0].model), 1e-6);
  EXPECT_NEAR(s.objects[2].X_WO.translation.x, 0.2, 1e-12);
  EXPECT_NEAR(std::abs(s.objects[2].X_WO.rotation.w), 1.0, 1e-12);  // no rotation left in scale
  EXPECT_LE(s.objects[0].report.coarse_triangles, 60);
  // The probe starts above every touchable (+Y is up in glTF).
  double top = -1e9;
  for (const auto& t : s.haptic.touchables) {
    for (const auto& p : t.model->vertices_O) top = std::max(top, (t.X_WO * p).y);
  }
  for (const auto& p : s.haptic.tool->vertices_O) {
    EXPECT_GT((s.haptic.X_WT_home * p).y, top);
  }
  const nlohmann::json j = InspectJson(s);
  ASSERT_EQ(j["objects"].size(), 4u);
  EXPECT_EQ(j["objects"][3]["role"], "display");
  EXPECT_FALSE(j["objects"][3].contains("coarse_triangles"));
  EXPECT_EQ(j["objects"][2]["role"], "touchable");
  for (const char* key :
       {"coarse_triangles", "hull_count", "texture_size", "bake_max_error_m", "seconds"}) {
    EXPECT_TRUE(j["objects"][0].contains(key)) << key;
  }
}

// "texture_size": "auto" (issue 32): each node's atlas from its surface's detail, the choice and
// its trials in inspect; a node's own fixed size still wins.
TEST_F(SceneBuildTest, AutoTextureSizeIsChosenPerNodeAndReportedByInspect) {
  WriteGlb((dir_ / "a.glb").string(),
           {{"floor", RidgedSlab(0.05, 0.05, 0.005, 20), glm::dmat4(1.0), ""},
            {"plate", RidgedSlab(0.05, 0.05, 0.005, 20),
             glm::translate(glm::dmat4(1.0), glm::dvec3(0.2, 0, 0)), ""}});
  const std::string desc = Write("a.json", R"({"scene": "a.glb",
    "defaults": {"coarse_triangles": 60, "texture_size": "auto", "texture_budget_um": 20},
    "nodes": {"plate": {"texture_size": 128}}})");
  const SceneDescription d = LoadSceneInput(desc);
  EXPECT_EQ(d.defaults.texture_size, 0);
  EXPECT_DOUBLE_EQ(d.defaults.texture_budget_m, 20e-6);
  const BuiltScene s = BuildScene(d, HapticModelCache(""));
  const nlohmann::json j = InspectJson(s);
  ASSERT_EQ(j["objects"].size(), 2u);
  const nlohmann::json& floor = j["objects"][0];
  ASSERT_TRUE(floor.contains("texture_size_chosen")) << floor.dump();
  const nlohmann::json& trials = floor["texture_size_chosen"]["trials"];
  ASSERT_GE(trials.size(), 1u);
  bool chosen_was_tried = false;
  for (const nlohmann::json& t : trials) {
    chosen_was_tried |= t["size"] == floor["texture_size"];
  }
  EXPECT_TRUE(chosen_was_tried) << floor.dump();
  EXPECT_FALSE(floor["texture_size_chosen"]["reason"].get<std::string>().empty());
  EXPECT_EQ(j["objects"][1]["texture_size"], 128);
  EXPECT_FALSE(j["objects"][1].contains("texture_size_chosen"));
}

TEST_F(SceneBuildTest, ANodeCanBeTheTool) {
  const TriangleMesh slab = RidgedSlab(0.01, 0.01, 0.005, 10);
  WriteGlb((dir_ / "t.glb").string(),
           {{"floor", RidgedSlab(0.05, 0.05, 0.005, 20), glm::dmat4(1.0), ""},
            {"probe", slab, glm::translate(glm::dmat4(1.0), glm::dvec3(0.3, 0.5, 0.7)), ""}});
  const BuiltScene s =
      BuildScene(LoadSceneInput((dir_ / "t.glb").string(), "probe"), HapticModelCache(""));
  EXPECT_FALSE(s.builtin_probe);
  EXPECT_EQ(s.objects[1].spec.role, NodeRole::kTool);
  EXPECT_EQ(s.haptic.touchables.size(), 1u);
  EXPECT_EQ(s.haptic.tool, s.objects[1].model);
  // T is at the tool's centre of mass, and the pose moved with it: the tool's surface in W is
  // where the node put it (the slab's top is at z = 0.7 + 0.005 in W).
  EXPECT_LT(glm::length(s.haptic.tool->center_of_mass_O), 1e-12);
  double top = -1e9;
  for (const auto& p : s.haptic.tool->vertices_O) top = std::max(top, (s.objects[1].X_WO * p).z);
  EXPECT_NEAR(top, 0.7 + 0.005 + 0.3e-3, 0.35e-3);
  EXPECT_NO_THROW(s.haptic.tool->hull_hierarchy.Validate(s.haptic.tool->vertices_O,
                                                         s.haptic.tool->triangles, 1e-9));
  EXPECT_NO_THROW(HapticTexturePipeline(s.haptic, PipelineOptions{}));
  EXPECT_THROW(
      BuildScene(LoadSceneInput((dir_ / "t.glb").string(), "nobody"), HapticModelCache("")),
      std::runtime_error);
}

TEST_F(SceneBuildTest, TheHomePoseMapsTheDevicesUpToTheScenesUpWhateverTheToolNodesRotation) {
  // A Y-up glTF scene (issue 33): the home pose (the operator's workspace frame M) maps M's +z to
  // +Y and M's +y (away from the user) to −Z, with the built-in probe, a tool node without
  // rotation and a tool node turned about two axes; a tool node keeps its own orientation and
  // place at rest (its surface in W is where the file put it).
  const TriangleMesh slab = RidgedSlab(0.01, 0.02, 0.005, 10);
  const glm::dmat4 turn = glm::translate(glm::dmat4(1.0), glm::dvec3(0.01, 0.05, -0.02)) *
                          glm::rotate(glm::dmat4(1.0), 0.6, glm::dvec3(0.0, 0.0, 1.0)) *
                          glm::rotate(glm::dmat4(1.0), 1.1, glm::dvec3(1.0, 0.0, 0.0));
  for (const glm::dmat4& X_WN :
       {glm::translate(glm::dmat4(1.0), glm::dvec3(0.0, 0.05, 0.0)), turn}) {
    WriteGlb((dir_ / "up.glb").string(),
             {{"floor", RidgedSlab(0.05, 0.05, 0.005, 20), glm::dmat4(1.0), ""},
              {"probe", slab, X_WN, ""}});
    for (const std::string tool : {"", "probe"}) {
      const BuiltScene s =
          BuildScene(LoadSceneInput((dir_ / "up.glb").string(), tool), HapticModelCache(""));
      const glm::dquat& R_WM = s.haptic.X_WT_home.rotation;
      EXPECT_LT(glm::length(R_WM * glm::dvec3(0, 0, 1) - glm::dvec3(0, 1, 0)), 1e-12) << tool;
      EXPECT_LT(glm::length(R_WM * glm::dvec3(0, 1, 0) - glm::dvec3(0, 0, -1)), 1e-12) << tool;
      if (tool.empty()) continue;
      // At rest the tool's coarse vertices are where the node's matrix puts the slab: its
      // bounding box in W matches the full mesh's to the coarse mesh's tolerance.
      glm::dvec3 lo(1e9), hi(-1e9), mesh_lo(1e9), mesh_hi(-1e9);
      for (const glm::dvec3& p_T : s.haptic.tool->vertices_O) {
        lo = glm::min(lo, s.objects[1].X_WO * p_T);
        hi = glm::max(hi, s.objects[1].X_WO * p_T);
      }
      for (const glm::dvec3& p : slab.vertices) {
        const glm::dvec3 p_W(X_WN * glm::dvec4(p, 1.0));
        mesh_lo = glm::min(mesh_lo, p_W);
        mesh_hi = glm::max(mesh_hi, p_W);
      }
      EXPECT_LT(glm::length(lo - mesh_lo), 1e-3);
      EXPECT_LT(glm::length(hi - mesh_hi), 1e-3);
      // T's rest rotation is M's: pressing the device down moves the tool along −Y.
      EXPECT_LT(glm::length(s.objects[1].X_WO.rotation * glm::dvec3(0, 0, 1) - glm::dvec3(0, 1, 0)),
                1e-12);
    }
  }
}

TEST_F(SceneBuildTest, PipelineOnAFileSceneCullsFarObjectsAndFindsContactOnTheNearOne) {
  WriteGlb((dir_ / "p.glb").string(),
           {{"floor", RidgedSlab(0.05, 0.05, 0.005, 30), glm::dmat4(1.0), ""},
            {"far", RidgedSlab(0.05, 0.05, 0.005, 30),
             glm::translate(glm::dmat4(1.0), glm::dvec3(1.0, 0.0, 0.0)), ""}});
  SceneDescription d = SceneDescription::ForGltf((dir_ / "p.glb").string());
  d.defaults.texture_size = 128;
  d.defaults.coarse_triangles = 100;
  const BuiltScene s = BuildScene(d, HapticModelCache(""));
  HapticTexturePipeline pipeline(s.haptic, PipelineOptions{});
  StepTimings timings;
  // Home is above the middle of both slabs' bounds (x = 0.5 m), far from each: both culled.
  pipeline.Step(s.haptic.X_WT_home, 1, timings);
  EXPECT_EQ(timings.broad_phase_culled, 2);
  EXPECT_EQ(timings.convex_pairs, 0);
  // Pressed 0.2 mm into the floor's ridged top (the slab's +z face): the probe's textured face
  // (−z in T) down onto it. Contacts come from the hierarchy query, clustering and the texture.
  RigidTransform X_WT;
  double top = -1e9;
  for (const auto& p : s.haptic.touchables[0].model->vertices_O) top = std::max(top, p.z);
  double below = 0.0;
  for (const auto& p : s.haptic.tool->vertices_O) below = std::max(below, -p.z);
  X_WT.translation = glm::dvec3(0.0, 0.0, top + below - 0.2e-3);
  const ContactModel m = pipeline.Step(X_WT, 2, timings);
  EXPECT_EQ(timings.broad_phase_culled, 1);
  EXPECT_EQ(timings.convex_pairs, 1);
  EXPECT_GE(timings.leaf_pairs, 1);
  EXPECT_GE(timings.clusters, 1);
  EXPECT_GE(m.num_contacts, 1);
  EXPECT_GT(m.F_T_W_at_q0.force.z, 0.0);  // pushed up, out of the floor
}

TEST_F(SceneBuildTest, AZeroScaledNodeIsShownOnlyWithANote) {
  WriteGlb((dir_ / "z.glb").string(),
           {{"floor", RidgedSlab(0.05, 0.05, 0.005, 10), glm::dmat4(1.0), ""},
            {"hidden", RidgedSlab(0.05, 0.05, 0.005, 10),
             glm::scale(glm::dmat4(1.0), glm::dvec3(0.0)), ""}});
  SceneDescription d = SceneDescription::ForGltf((dir_ / "z.glb").string());
  d.defaults.texture_size = 128;
  d.defaults.coarse_triangles = 50;
  const BuiltScene s = BuildScene(d, HapticModelCache(""));
  ASSERT_EQ(s.objects.size(), 2u);
  EXPECT_EQ(s.objects[1].spec.role, NodeRole::kDisplay);
  EXPECT_EQ(s.objects[1].model, nullptr);
  EXPECT_EQ(s.haptic.touchables.size(), 1u);
  ASSERT_EQ(s.notes.size(), 1u);
  EXPECT_NE(s.notes[0].find("'hidden'"), std::string::npos) << s.notes[0];
}

TEST_F(SceneBuildTest, BadDescriptionsAreRefusedNamingTheFileAndTheKey) {
  WriteGlb((dir_ / "s.glb").string(),
           {{"floor", RidgedSlab(0.05, 0.05, 0.005, 4), glm::dmat4(1.0), ""}});
  const struct {
    const char* text;
    const char* expect;
  } cases[] = {
      {R"({"scene": "s.glb", "nodes": {"floor": {"role": "wall"}}})", "role 'wall'"},
      {R"({"scene": "s.glb", "defaults": {"texture_size": 100}})", "power of two"},
      {R"({"scene": "s.glb", "defaults": {"texture_size": "big"}})", "or \"auto\""},
      {R"({"scene": "s.glb", "defaults": {"texture_budget_um": 0}})", "micrometres > 0"},
      {R"({"scene": "s.glb", "defaults": {"stiffness_n_per_m": -1}})", "positive stiffness"},
      {R"({"scene": "s.glb", "defaults": {"coarse_triangles": 2}})", "coarse_triangles"},
      {R"({"scene": "s.glb", "defaults": {"stifness_n_per_m": 10}})", "unknown key"},
      {R"({"scene": "s.glb", "colour": 1})", "unknown key 'colour'"},
      {R"({"nodes": {}})", "no \"scene\""},
      {R"({"scene": "s.glb",)", "not valid JSON"},
      {R"({"scene": "s.glb", "units": "furlong"})", "units must be one of m, cm, mm, in, ft"},
      {R"({"scene": "s.glb", "scale": 0})", "scale must be a number > 0"},
      {R"({"scene": "s.glb", "scale": "mm"})", "scale must be a number > 0"},
      {R"({"scene": "s.glb", "scale": 0.001, "units": "mm"})", "not both"},
      {R"({"scene": "s.glb", "units": "mm", "scale": 0.001})", "not both"},
  };
  // Deeply nested JSON: refused before the (recursive) parser sees it, not a stack overflow.
  const std::string deep_text =
      R"({"scene": "s.glb", "x": )" + std::string(200000, '[') + std::string(200000, ']') + "}";
  const std::string deep = Write("deep.json", deep_text);
  try {
    LoadSceneInput(deep);
    ADD_FAILURE() << "accepted a 200,000-deep description";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("nests 200001 levels deep"), std::string::npos)
        << e.what();
  }
  for (const auto& c : cases) {
    const std::string path = Write("bad.json", c.text);
    try {
      LoadSceneInput(path);
      ADD_FAILURE() << "accepted: " << c.text;
    } catch (const std::runtime_error& e) {
      const std::string what = e.what();
      EXPECT_EQ(what.rfind(path, 0), 0u) << what;
      EXPECT_NE(what.find(c.expect), std::string::npos) << what;
    }
  }
  const std::string unknown_node =
      Write("n.json", R"({"scene": "s.glb", "nodes": {"ceiling": {"role": "display"}}})");
  try {
    BuildScene(LoadSceneInput(unknown_node), HapticModelCache(""));
    ADD_FAILURE() << "accepted a description naming no node";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("'ceiling'"), std::string::npos) << e.what();
  }
}

// A scene with nothing to touch (a glTF without a node, or whose every node is the tool or
// display) is refused by the remote node's scene, with what to do; `slave_sim inspect`'s
// BuildScene still reports it (no objects).
TEST_F(SceneBuildTest, AWatchedSceneWithNothingToTouchIsRefused) {
  const std::string empty = Write("empty.gltf", R"({"asset": {"version": "2.0"}})");
  EXPECT_TRUE(BuildScene(LoadSceneInput(empty), HapticModelCache("")).haptic.touchables.empty());
  WriteGlb((dir_ / "decor.glb").string(),
           {{"decor", RidgedSlab(0.03, 0.03, 0.005, 10), glm::dmat4(1.0), ""}});
  const std::string decor = Write("decor.json", R"({"scene": "decor.glb",
    "defaults": {"role": "display"}})");
  for (const std::string& path : {empty, decor}) {
    try {
      WatchedScene w(path, "", HapticModelCache(""));
      ADD_FAILURE() << "accepted " << path << " with " << w.haptic().touchables.size()
                    << " touchable(s)";
    } catch (const std::runtime_error& e) {
      const std::string what = e.what();
      EXPECT_EQ(what.rfind(path, 0), 0u) << what;
      EXPECT_NE(what.find("nothing to touch"), std::string::npos) << what;
    }
  }
}

// Issue 35: a file authored in millimetres (a 60 mm slab written as 60 units, 150 units off the
// origin) is a 60 m slab until its description says "units": "mm"; then the scene is the one
// written in metres, node for node, and nothing warns. Unnamed nodes are called by their mesh's
// name or "#index".
TEST_F(SceneBuildTest, UnitsScaleAFileInMillimetresToTheSceneInMetres) {
  const TriangleMesh slab_m = RidgedSlab(0.03, 0.03, 0.005, 10);
  TriangleMesh slab_mm = slab_m;
  for (glm::dvec3& p : slab_mm.vertices) p *= 1000.0;
  WriteGlb((dir_ / "m.glb").string(),
           {{"slab", slab_m, glm::translate(glm::dmat4(1.0), glm::dvec3(0.15, 0, 0)), ""},
            {"", slab_m, glm::translate(glm::dmat4(1.0), glm::dvec3(0, 0, 0.15)), ""}});
  WriteGlb((dir_ / "mm.glb").string(),
           {{"slab", slab_mm, glm::translate(glm::dmat4(1.0), glm::dvec3(150, 0, 0)), ""},
            {"", slab_mm, glm::translate(glm::dmat4(1.0), glm::dvec3(0, 0, 150)), ""}});
  SceneDescription m = SceneDescription::ForGltf((dir_ / "m.glb").string());
  m.defaults.texture_size = 128;
  m.defaults.coarse_triangles = 50;
  const BuiltScene in_m = BuildScene(m, HapticModelCache(""));
  EXPECT_TRUE(in_m.warnings.empty());
  SceneDescription raw = SceneDescription::ForGltf((dir_ / "mm.glb").string());
  raw.defaults = m.defaults;
  const BuiltScene unscaled = BuildScene(raw, HapticModelCache(""));
  ASSERT_EQ(unscaled.warnings.size(), 1u);
  EXPECT_NE(unscaled.warnings[0].find("larger than a desk"), std::string::npos)
      << unscaled.warnings[0];
  EXPECT_NE(unscaled.warnings[0].find("\"units\": \"mm\""), std::string::npos);
  const std::string desc = Write("mm.json", R"({"scene": "mm.glb", "units": "mm",
    "defaults": {"texture_size": 128, "coarse_triangles": 50}})");
  const BuiltScene in_mm = BuildScene(LoadSceneInput(desc), HapticModelCache(""));
  EXPECT_DOUBLE_EQ(in_mm.description.scale, 0.001);
  EXPECT_TRUE(in_mm.warnings.empty()) << in_mm.warnings[0];
  ASSERT_EQ(in_mm.haptic.touchables.size(), 2u);
  for (std::size_t k = 0; k < 2; ++k) {
    EXPECT_LT(glm::length(in_mm.haptic.touchables[k].X_WO.translation -
                          in_m.haptic.touchables[k].X_WO.translation),
              1e-9);
    // The same model, to float32 rounding of the file (the decimation may break ties apart):
    // the same bounding box.
    const auto box = [](const HapticModel& model) {
      glm::dvec3 lo{1e9}, hi{-1e9};
      for (const glm::dvec3& p : model.vertices_O) {
        lo = glm::min(lo, p);
        hi = glm::max(hi, p);
      }
      return std::pair{lo, hi};
    };
    const auto [lo_mm, hi_mm] = box(*in_mm.haptic.touchables[k].model);
    const auto [lo_m, hi_m] = box(*in_m.haptic.touchables[k].model);
    EXPECT_LT(glm::length(lo_mm - lo_m), 1e-6);
    EXPECT_LT(glm::length(hi_mm - hi_m), 1e-6);
  }
  EXPECT_LT(glm::length(in_mm.haptic.X_WT_home.translation - in_m.haptic.X_WT_home.translation),
            1e-6);
  EXPECT_EQ(in_mm.objects[0].label, "slab");
  EXPECT_EQ(in_mm.objects[1].label, "#1");  // no node name, no mesh name
  const nlohmann::json j = InspectJson(in_mm);
  EXPECT_EQ(j["objects"][1]["name"], in_mm.objects[1].label);
  EXPECT_EQ(j["objects"][1]["node_name"], "");
  EXPECT_EQ(j["scale"], 0.001);
  EXPECT_GT(j["objects"][0]["bake_texels"].get<double>(), 0.0);
}

TEST_F(SceneBuildTest, CacheMakesTheSecondBuildOfASceneComeFromDisk) {
  WriteGlb((dir_ / "c.glb").string(),
           {{"floor", RidgedSlab(0.05, 0.05, 0.005, 40), glm::dmat4(1.0), ""}});
  const HapticModelCache cache((dir_ / "cache").string());
  SceneDescription d = SceneDescription::ForGltf((dir_ / "c.glb").string());
  d.defaults.texture_size = 256;
  const BuiltScene first = BuildScene(d, cache);
  const BuiltScene second = BuildScene(d, cache);
  EXPECT_FALSE(first.objects[0].report.from_cache);
  EXPECT_TRUE(second.objects[0].report.from_cache);
  EXPECT_EQ(first.objects[0].model->vertices_O, second.objects[0].model->vertices_O);
  d.defaults.coarse_triangles = 100;
  EXPECT_FALSE(BuildScene(d, cache).objects[0].report.from_cache);
}

TEST(SceneBuildData, DuckBuildsAClosedTexturedModel) {
  REQUIRE_GLTF_DATA(dir);
  const BuiltScene s = BuildScene(
      SceneDescription::ForGltf((*dir / "draco_testdata_gltf/glTF_Binary/Duck.glb").string()),
      HapticModelCache(""));
  ASSERT_EQ(s.haptic.touchables.size(), 1u);
  const HapticModelBuildReport& r = s.objects[0].report;
  EXPECT_EQ(r.full_triangles, 4212);
  EXPECT_LE(r.coarse_triangles, 500);
  EXPECT_GE(r.coarse_triangles, 480);
  // The duck's coarse surface lies within the ray range of its full surface almost everywhere;
  // the few texels whose rays miss (thin bill and tail) are filled from their neighbours.
  EXPECT_LT(r.bake.misses, r.bake.texels_baked / 100) << r.bake.misses << " misses";
  EXPECT_LT(r.bake.rms_bake_error_m, 0.01 * 2.0);  // the duck is ~2 units across
  EXPECT_GE(r.hull_nodes, 1);
  EXPECT_NO_THROW(s.objects[0].model->Validate());
}

TEST(SceneBuildData, DracoBoxAndItsTwinBuildTheSameModel) {
  REQUIRE_GLTF_DATA(dir);
  const auto build = [&](const char* rel) {
    return BuildScene(SceneDescription::ForGltf((*dir / rel).string()), HapticModelCache(""));
  };
  const BuiltScene draco = build("draco_testdata_gltf/glTF_Binary/Box_Draco.glb");
  const BuiltScene plain = build("draco_testdata_gltf/glTF_Binary/Box.glb");
  ASSERT_EQ(draco.objects.size(), plain.objects.size());
  for (std::size_t i = 0; i < draco.objects.size(); ++i) {
    EXPECT_EQ(draco.objects[i].report.coarse_triangles, plain.objects[i].report.coarse_triangles);
    EXPECT_EQ(draco.objects[i].report.hull_nodes, plain.objects[i].report.hull_nodes);
    EXPECT_NEAR(draco.objects[i].model->mass_kg, plain.objects[i].model->mass_kg,
                1e-3 * plain.objects[i].model->mass_kg);
  }
}

// The CesiumMilkTruck built small (100 coarse triangles, 256² textures), no cache.
BuiltScene BuildSmallMilkTruck(const fs::path& data) {
  SceneDescription d = SceneDescription::ForGltf(
      (data / "draco_testdata_gltf/CesiumMilkTruck/glTF/CesiumMilkTruck.gltf").string());
  d.defaults.coarse_triangles = 100;
  d.defaults.texture_size = 256;
  return BuildScene(d, HapticModelCache(""));
}

TEST(SceneBuildData, MilkTruckWheelsTurnWhenTheAnimationPlays) {
  REQUIRE_GLTF_DATA(dir);
  BuiltScene s = BuildSmallMilkTruck(*dir);
  ASSERT_EQ(s.gltf.animations.size(), 1u);
  ASSERT_EQ(s.touchable_objects.size(), s.haptic.touchables.size());
  std::vector<RigidTransform> rest;
  for (const auto& t : s.haptic.touchables) rest.push_back(t.X_WO);
  std::vector<glm::dmat4> scratch;
  const double half = 0.5 * s.gltf.animations[0].duration_s;
  AnimateScene(s, 0, half, &scratch);
  int turned = 0;
  for (std::size_t k = 0; k < rest.size(); ++k) {
    const RigidTransform& now = s.haptic.touchables[k].X_WO;
    // Wheels turn about their axle: the origin stays, the rotation changes; the rest stays put.
    EXPECT_LT(glm::length(now.translation - rest[k].translation), 1e-9);
    const double angle =
        2.0 * std::acos(std::min(1.0, std::abs(glm::dot(now.rotation, rest[k].rotation))));
    if (angle > 0.5) ++turned;
    EXPECT_EQ(s.objects[s.touchable_objects[k]].X_WO.rotation, now.rotation);
  }
  EXPECT_GE(turned, 2);  // the two wheel nodes (each possibly several instances)
  // Back at the start of the loop (and for a NaN time) every object is at rest again.
  AnimateScene(s, 0, std::nan(""), &scratch);
  for (std::size_t k = 0; k < rest.size(); ++k) {
    EXPECT_LT(std::abs(glm::dot(s.haptic.touchables[k].X_WO.rotation, rest[k].rotation)) - 1.0,
              1e-9);
    EXPECT_GT(std::abs(glm::dot(s.haptic.touchables[k].X_WO.rotation, rest[k].rotation)),
              1.0 - 1e-9);
  }
  const nlohmann::json j = InspectJson(s);
  ASSERT_EQ(j["animations"].size(), 1u);
  EXPECT_EQ(j["animations"][0]["channels"], 2);
}

// The milk truck as the operator's display receives it: the graph decodes from the stream's first
// object, each mesh is a Draco object in its own frame, the built-in probe is the tool, and the
// wheels are the moving nodes. Two routes to each touchable's pose: the haptic scene's animated
// X_WO (AnimateScene) against the display graph composed with the streamed local poses
// (DisplayNodePosesAt), at several times.
TEST(SceneBuildData, MilkTruckDisplayStreamPlacesEveryTouchableWhereTheHapticSceneHasIt) {
  REQUIRE_GLTF_DATA(dir);
  BuiltScene s = BuildSmallMilkTruck(*dir);
  const DisplayStream stream = MakeDisplayStream(s);
  ASSERT_FALSE(stream.objects.empty());
  ASSERT_EQ(stream.objects[0].kind, wire::SceneObjectKind::kSceneGraph);
  SceneGraphDescription graph;
  std::string error;
  ASSERT_TRUE(DecodeSceneGraph(stream.objects[0].bytes, &graph, &error)) << error;
  EXPECT_EQ(EncodeSceneGraph(graph), stream.objects[0].bytes);
  // One Draco object per mesh (plus the probe), decoding to the mesh's triangle count.
  std::map<std::uint32_t, const StreamObject*> by_id;
  for (const StreamObject& o : stream.objects) by_id[o.id] = &o;
  EXPECT_EQ(by_id.size(), stream.objects.size()) << "object ids are distinct";
  int tools = 0;
  for (const SceneGraphNode& n : graph.nodes) {
    tools += (n.flags & kSceneNodeTool) != 0;
    if (n.mesh_object == 0) continue;
    ASSERT_EQ(by_id.count(n.mesh_object), 1u) << n.name;
    EXPECT_EQ(by_id[n.mesh_object]->kind, wire::SceneObjectKind::kDracoMesh);
    if (n.material >= 0) {
      ASSERT_LT(static_cast<std::size_t>(n.material), graph.materials.size());
    }
  }
  EXPECT_EQ(tools, 1);
  // Each node's mesh arrives whole: its part on the node plus the further material parts on
  // child nodes (part_of), their triangles adding up to the glTF mesh's.
  ASSERT_EQ(stream.part_of.size(), graph.nodes.size());
  for (std::size_t e = 0; e < s.gltf.nodes.size(); ++e) {
    const int m = s.gltf.nodes[e].mesh;
    if (m < 0) continue;
    const int node = stream.graph_node_of_entry[e];
    std::size_t triangles = 0;
    std::set<int> materials;
    for (std::size_t v = 0; v < graph.nodes.size(); ++v) {
      if (static_cast<int>(v) != node && stream.part_of[v] != node) continue;
      const DracoMesh part = DecodeMeshDracoWithUv(by_id[graph.nodes[v].mesh_object]->bytes);
      triangles += part.mesh.triangles.size();
      materials.insert(graph.nodes[v].material);
      EXPECT_EQ(part.uv.size(), s.gltf.meshes[static_cast<std::size_t>(m)].uv_N.empty()
                                    ? 0u
                                    : part.mesh.vertices.size());
    }
    EXPECT_EQ(triangles, s.gltf.meshes[static_cast<std::size_t>(m)].mesh_N.triangles.size());
    if (s.gltf.meshes[static_cast<std::size_t>(m)].name == "Cesium_Milk_Truck") {
      EXPECT_EQ(materials.size(), 3u);  // the body's three materials, each its own part
    }
  }
  // Materials that have a base-colour texture carry it as a kImage object.
  for (const SceneMaterial& m : graph.materials) {
    if (m.base_colour_texture_object == 0) continue;
    ASSERT_EQ(by_id.count(m.base_colour_texture_object), 1u);
    EXPECT_EQ(by_id[m.base_colour_texture_object]->kind, wire::SceneObjectKind::kImage);
    EXPECT_EQ(m.texture_mime, "image/png");
  }
  ASSERT_EQ(stream.moving_nodes.size(), 2u);  // the two wheel nodes

  std::vector<glm::dmat4> scratch;
  std::vector<GltfNodePose> pose_scratch;
  std::vector<wire::NodePose> poses;
  for (const double t : {0.0, 0.3, 0.77}) {
    AnimateScene(s, 0, t, &scratch);
    DisplayNodePosesAt(s, stream, t, &pose_scratch, &poses);
    ASSERT_EQ(poses.size(), 2u);
    std::vector<SceneNodeTransform> local = RestTransforms(graph);
    for (const wire::NodePose& p : poses) {
      ASSERT_LT(p.node, local.size());
      EXPECT_TRUE(graph.nodes[p.node].flags & kSceneNodeMoving);
      local[p.node] = {glm::dvec3(p.translation), glm::dquat(p.rotation), glm::dvec3(p.scale)};
    }
    const std::vector<glm::dmat4> X_WN = ComposeWorldPoses(graph, local);
    for (std::size_t k = 0; k < s.haptic.touchables.size(); ++k) {
      const int e = s.gltf.instances[static_cast<std::size_t>(s.touchable_objects[k])].scene_node;
      const glm::dmat4& X =
          X_WN[static_cast<std::size_t>(stream.graph_node_of_entry[static_cast<std::size_t>(e)])];
      const RigidTransform& X_WO = s.haptic.touchables[k].X_WO;
      const glm::dmat3 residual =
          s.objects[static_cast<std::size_t>(s.touchable_objects[k])].rest_residual;
      // Display: X_WN = [R·S | p] with f32 poses on the wire; haptics: X_WO = [R | p].
      EXPECT_LT(glm::length(glm::dvec3(X[3]) - X_WO.translation), 1e-5) << "t " << t;
      const glm::dmat3 R_display = glm::dmat3(X) * glm::inverse(residual);
      const glm::dmat3 R_haptic = glm::mat3_cast(X_WO.rotation);
      for (int c = 0; c < 3; ++c)
        EXPECT_LT(glm::length(R_display[c] - R_haptic[c]), 1e-5) << "t " << t << " col " << c;
    }
  }
}

}  // namespace
}  // namespace ht
