// One contact window of a speed_error_frontier run taken apart (issue 32): where the
// full-resolution truth has its maximum on the window, what the textured coarse models give there
// (PatchHeightAt at level 0 and at the grid's mip level), and the largest b − a a dense level-0
// scan of the whole window finds, beside what the method reported (contacts.csv delta_m). Tells a
// search that missed a peak the models hold (the scan finds more than the method reported) from
// models that do not hold it (the scan finds less than the truth).
//
// Usage: window_probe --out-dir FRONTIER_OUT --scene fig77 --setting default --pose 0 --contact 1
//        [--models seed|product] [--scan N] [--cache-dir DIR]

#include <CLI/CLI.hpp>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "haptic_core/accuracy/ground_truth_depth.h"
#include "haptic_core/depth_refinement.h"
#include "haptic_core/penetration_depth.h"
#include "slave_sim/benchmark_scenes.h"

namespace {

// The row of contacts.csv for (scene, setting, pose, contact), as name → text; throws when the
// file cannot be read or holds no such row.
std::map<std::string, std::string> FindRow(const std::string& path, const std::string& scene,
                                           const std::string& setting, int pose, int contact) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error("cannot read " + path);
  std::string line;
  std::getline(in, line);
  std::vector<std::string> cols;
  for (std::stringstream h(line); std::getline(h, line, ',');) cols.push_back(line);
  std::string row;
  while (std::getline(in, row)) {
    std::vector<std::string> cells;
    for (std::stringstream r(row); std::getline(r, line, ',');) cells.push_back(line);
    if (cells.size() != cols.size()) continue;
    std::map<std::string, std::string> m;
    for (std::size_t i = 0; i < cols.size(); ++i) m[cols[i]] = cells[i];
    if (m["scene"] == scene && m["setting"] == setting && m["pose_id"] == std::to_string(pose) &&
        m["contact"] == std::to_string(contact)) {
      return m;
    }
  }
  throw std::runtime_error(path + " has no row for scene " + scene + ", setting " + setting +
                           ", pose " + std::to_string(pose) + ", contact " +
                           std::to_string(contact));
}

double Num(const std::map<std::string, std::string>& m, const std::string& k) {
  const auto it = m.find(k);
  if (it == m.end()) throw std::runtime_error("contacts.csv has no column " + k);
  return std::stod(it->second);
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "One contact window of a speed_error_frontier run: the truth's maximum against "
      "the textured models' level-0 heights there and a level-0 scan of the window"};
  std::string dir, scene = "fig77", setting = "default", models = "product";
  std::string cache_dir = ht::HapticModelCache::DefaultDir();
  int pose = 0, contact = 0, scan = 400;
  app.add_option("--out-dir", dir, "the frontier's output folder (its contacts.csv)")->required();
  app.add_option("--scene", scene, "scene")->capture_default_str();
  app.add_option("--setting", setting, "setting whose row to take")->capture_default_str();
  app.add_option("--pose", pose, "pose_id")->capture_default_str();
  app.add_option("--contact", contact, "contact index at that pose")->capture_default_str();
  app.add_option("--models", models,
                 "which models to probe: seed (the seed's Table 6 counts, 1024²) or product "
                 "(ProductModelSettings); they must be the setting's")
      ->check(CLI::IsMember({"seed", "product"}))
      ->capture_default_str();
  app.add_option("--scan", scan, "level-0 scan points per side")
      ->check(CLI::Range(2, 4000))
      ->capture_default_str();
  app.add_option("--cache-dir", cache_dir, "model cache folder")->capture_default_str();
  CLI11_PARSE(app, argc, argv);
  try {
    const auto row = FindRow(dir + "/contacts.csv", scene, setting, pose, contact);
    ht::RigidTransform X_WFt, X_WO;
    X_WFt.translation = {Num(row, "tool_px"), Num(row, "tool_py"), Num(row, "tool_pz")};
    X_WFt.rotation = glm::dquat(Num(row, "tool_qw"), Num(row, "tool_qx"), Num(row, "tool_qy"),
                                Num(row, "tool_qz"));
    X_WO.translation = {Num(row, "obj_px"), Num(row, "obj_py"), Num(row, "obj_pz")};
    X_WO.rotation =
        glm::dquat(Num(row, "obj_qw"), Num(row, "obj_qx"), Num(row, "obj_qy"), Num(row, "obj_qz"));
    const glm::dvec3 c{Num(row, "window_cx"), Num(row, "window_cy"), Num(row, "window_cz")};
    const glm::dvec3 n{Num(row, "window_nx"), Num(row, "window_ny"), Num(row, "window_nz")};
    const double extent = Num(row, "window_extent_m");
    const ht::BenchmarkModelSettings settings =
        models == "product" ? ht::ProductModelSettings(scene) : ht::BenchmarkModelSettings{};
    std::fprintf(stderr, "window_probe: building %s (%s models, cache %s)\n", scene.c_str(),
                 models.c_str(), cache_dir.c_str());
    const ht::BenchmarkScene sc =
        ht::MakeBenchmarkScene(scene, settings, ht::HapticModelCache(cache_dir));
    const ht::RigidTransform X_WT = X_WFt * sc.X_TFt.Inverse();
    const ht::ContactWindow w = ht::ContactWindow::Make(c, glm::normalize(n), extent, 50);
    const ht::HapticModel& tool = *sc.haptic.tool;
    const ht::HapticModel& env = *sc.haptic.touchables.at(0).model;
    const ht::RayCastSurface tool_rays(*sc.tool_mesh_Ft), env_rays(*sc.object_mesh_Fe);
    ht::GroundTruthDepthSolver truth(tool_rays, env_rays);
    const ht::GroundTruthDepth d = truth.ConvergedDepth(X_WFt, X_WO, w);
    std::printf("method (contacts.csv): delta %.1f um; its truth on the window %.1f um\n",
                Num(row, "delta_m") * 1e6, Num(row, "delta_gt_m") * 1e6);
    std::printf("truth: delta %.1f um at (%.3f, %.3f) mm on the window (M %d)\n", d.depth_m * 1e6,
                d.at_uv_m.x * 1e3, d.at_uv_m.y * 1e3, d.samples_per_side);
    std::vector<int> tool_tris, env_tris;
    ht::SelectPatchTriangles(tool, X_WT, w, ht::PatchSide::kTool, w.cell_size_m(), tool_tris);
    ht::SelectPatchTriangles(env, X_WO, w, ht::PatchSide::kEnvironment, w.cell_size_m(), env_tris);
    std::printf("window: %zu tool and %zu object triangles, box +-%.2f mm along n\n",
                tool_tris.size(), env_tris.size(), w.depth_range_m() * 1e3);
    for (const int level : {0, -1}) {
      const double b = ht::PatchHeightAt(env, X_WO, env_tris, w, ht::PatchSide::kEnvironment,
                                         d.at_uv_m.x, d.at_uv_m.y, level);
      const double a = ht::PatchHeightAt(tool, X_WT, tool_tris, w, ht::PatchSide::kTool,
                                         d.at_uv_m.x, d.at_uv_m.y, level);
      std::printf(
          "models at the truth's maximum, %s: object b %.1f um, tool a %.1f um, "
          "b - a %.1f um\n",
          level == 0 ? "level 0" : "the grid's level", b * 1e6, a * 1e6, (b - a) * 1e6);
    }
    double best = -std::numeric_limits<double>::infinity(), best_s = 0.0, best_t = 0.0;
    for (int i = 0; i < scan; ++i) {
      for (int j = 0; j < scan; ++j) {
        const double s = ((i + 0.5) / scan - 0.5) * extent, t = ((j + 0.5) / scan - 0.5) * extent;
        const double b =
            ht::PatchHeightAt(env, X_WO, env_tris, w, ht::PatchSide::kEnvironment, s, t, 0);
        const double a = ht::PatchHeightAt(tool, X_WT, tool_tris, w, ht::PatchSide::kTool, s, t, 0);
        if (std::isfinite(a) && std::isfinite(b) && b - a > best) {
          best = b - a;
          best_s = s;
          best_t = t;
        }
      }
    }
    std::printf("level-0 scan (%d x %d): largest b - a %.1f um at (%.3f, %.3f) mm\n", scan, scan,
                best * 1e6, best_s * 1e3, best_t * 1e3);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "window_probe: error: %s\n", e.what());
    return 2;
  }
  return 0;
}
