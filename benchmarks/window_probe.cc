// One contact window of a speed_error_frontier run taken apart (issue 32): where the
// full-resolution truth has its maximum on the window, what the textured coarse models give there
// (PatchHeightAt at level 0 and at the grid's mip level), and the largest b − a a dense level-0
// scan of the whole window finds, beside what the method reported (contacts.csv delta_m). Tells a
// search that missed a peak the models hold (the scan finds more than the method reported) from
// models that do not hold it (the scan finds less than the truth). Also the full-resolution
// surfaces' own heights at the truth's maximum, the models' surface error (MeasureSurfaceError)
// within 2 mm of it, and the same reads and scan with parallax (DepthRefinementOptions::parallax,
// issue 32's twelfth stop).
//
// Usage: window_probe --out-dir FRONTIER_OUT --scene fig77 --setting default --pose 0 --contact 1
//        [--models seed|product] [--scan N] [--cache-dir DIR]
// Debugging: WINDOW_PROBE_TRIANGLES=1 lists every triangle under the point (its coarse height,
// N·n, texture height and the render's value) and every triangle whose parallax alone holds it;
// WINDOW_PROBE_AT_MM=S,T probes window point (S, T) mm instead of the truth's maximum;
// WINDOW_PROBE_DISPLACED_UM=R lists the object's displaced-surface samples within R µm of the
// point's line along n.

#include <CLI/CLI.hpp>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "haptic_core/accuracy/ground_truth_depth.h"
#include "haptic_core/depth_refinement.h"
#include "haptic_core/model_build/surface_error.h"
#include "haptic_core/penetration_depth.h"
#include "slave_sim/benchmark_scenes.h"

namespace {

// Level 0's texture height (m) of model m's face f at barycentrics (b0, b1, b2) of its corners
// (the corners' texture coordinates interpolated, bilinear); 0 on an untextured face.
double Level0HeightAt(const ht::HapticModel& m, std::size_t f, double b0, double b1, double b2) {
  if (!m.textured[f]) return 0.0;
  const std::size_t k = 3 * f;
  const auto u = static_cast<float>(b0 * m.corner_uvs[k].x + b1 * m.corner_uvs[k + 1].x +
                                    b2 * m.corner_uvs[k + 2].x);
  const auto v = static_cast<float>(b0 * m.corner_uvs[k].y + b1 * m.corner_uvs[k + 1].y +
                                    b2 * m.corner_uvs[k + 2].y);
  return m.texture.SampleAt(0, m.texture.level(0), u, v);
}

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
    ht::GroundTruthDepth d = truth.ConvergedDepth(X_WFt, X_WO, w);
    std::printf("method (contacts.csv): delta %.1f um; its truth on the window %.1f um\n",
                Num(row, "delta_m") * 1e6, Num(row, "delta_gt_m") * 1e6);
    std::printf("truth: delta %.1f um at (%.3f, %.3f) mm on the window (M %d)\n", d.depth_m * 1e6,
                d.at_uv_m.x * 1e3, d.at_uv_m.y * 1e3, d.samples_per_side);
    {
      // The full-resolution surfaces' heights along n at the truth's maximum: the first facing
      // hit of a ray from the box's far side (the truth's own rule), in each mesh's frame.
      const glm::dvec3 q_W = w.center_W + d.at_uv_m.x * w.axis_u_W + d.at_uv_m.y * w.axis_v_W;
      const double R = w.depth_range_m();
      const ht::RigidTransform X_FeW = X_WO.Inverse(), X_FtW = X_WFt.Inverse();
      const double tb = env_rays.FirstFacingHit(X_FeW * (q_W + R * w.normal_W),
                                                X_FeW.rotation * (-w.normal_W), 2.0 * R);
      const double ta = tool_rays.FirstFacingHit(X_FtW * (q_W - R * w.normal_W),
                                                 X_FtW.rotation * w.normal_W, 2.0 * R);
      std::printf("full resolution at the truth's maximum: object b %.1f um, tool a %.1f um\n",
                  tb < 0 ? NAN : (R - tb) * 1e6, ta < 0 ? NAN : (ta - R) * 1e6);
      // The models' surface error (MeasureSurfaceError) within 2 mm of those two points.
      ht::TriangleMesh tool_T = *sc.tool_mesh_Ft;
      for (auto& p : tool_T.vertices) p = sc.X_TFt * p;
      const ht::RigidTransform X_TW = X_WT.Inverse();
      for (const bool is_tool : {false, true}) {
        if ((is_tool ? ta : tb) < 0) continue;
        ht::SurfaceErrorParams sp;
        sp.samples = 2048;
        sp.region_radius_m = 2e-3;
        const glm::dvec3 hit_W =
            is_tool ? q_W + (ta - R) * w.normal_W : q_W + (R - tb) * w.normal_W;
        sp.region_center_O = is_tool ? X_TW * hit_W : X_FeW * hit_W;
        const ht::SurfaceErrorReport e = ht::MeasureSurfaceError(
            is_tool ? tool : env, is_tool ? tool_T : *sc.object_mesh_Fe, sp);
        std::printf(
            "  %s model within 2 mm: distance p50 %.1f p95 %.1f max %.1f um; outside p99 %.1f um, "
            "share outside 25 um %.2f\n",
            is_tool ? "tool" : "object", e.p50_m * 1e6, e.p95_m * 1e6, e.max_m * 1e6,
            e.outside_p99_m * 1e6, e.share_outside);
      }
    }
    if (const char* at = std::getenv("WINDOW_PROBE_AT_MM")) {  // probe this point instead
      double ps = 0.0, pt = 0.0;
      if (std::sscanf(at, "%lf,%lf", &ps, &pt) == 2) d.at_uv_m = {ps * 1e-3, pt * 1e-3};
      std::printf("probing (%.3f, %.3f) mm instead of the truth's maximum\n", ps, pt);
    }
    std::vector<int> tool_tris, env_tris;
    ht::SelectPatchTriangles(tool, X_WT, w, ht::PatchSide::kTool, w.cell_size_m(), tool_tris);
    ht::SelectPatchTriangles(env, X_WO, w, ht::PatchSide::kEnvironment, w.cell_size_m(), env_tris);
    std::printf("window: %zu tool and %zu object triangles, box +-%.2f mm along n\n",
                tool_tris.size(), env_tris.size(), w.depth_range_m() * 1e3);
    {
      std::vector<int> all_tool(tool.triangles.size()), all_env(env.triangles.size());
      for (std::size_t i = 0; i < all_tool.size(); ++i) all_tool[i] = static_cast<int>(i);
      for (std::size_t i = 0; i < all_env.size(); ++i) all_env[i] = static_cast<int>(i);
      const double b = ht::PatchHeightAt(env, X_WO, all_env, w, ht::PatchSide::kEnvironment,
                                         d.at_uv_m.x, d.at_uv_m.y, 0);
      const double a = ht::PatchHeightAt(tool, X_WT, all_tool, w, ht::PatchSide::kTool, d.at_uv_m.x,
                                         d.at_uv_m.y, 0);
      std::printf(
          "models at the truth's maximum over all their triangles: object b %.1f um, "
          "tool a %.1f um\n",
          b * 1e6, a * 1e6);
    }
    if (const char* near_um = std::getenv("WINDOW_PROBE_DISPLACED_UM")) {
      // The object's displaced surface p + h·N sampled densely (each triangle with a corner
      // within 5 mm of the point, 120 steps a side): the samples whose position on the window
      // plane lies within the given distance of the point, with their height along n. Tells a
      // displaced surface that holds the point (the parallax's fixed point missed it) from one
      // with a hole there.
      const double r = std::atof(near_um) * 1e-6;
      const glm::dvec3 q_W = w.center_W + d.at_uv_m.x * w.axis_u_W + d.at_uv_m.y * w.axis_v_W;
      double best = -INFINITY;
      int hits = 0;
      constexpr int kSteps = 120;
      for (std::size_t f = 0; f < env.triangles.size(); ++f) {
        glm::dvec3 P[3], N[3];
        bool near = false;
        for (int k = 0; k < 3; ++k) {
          P[k] = X_WO * env.vertices_O[static_cast<std::size_t>(env.triangles[f][k])];
          N[k] = X_WO.rotation * env.corner_normals_O[3 * f + static_cast<std::size_t>(k)];
          near = near || glm::length(P[k] - q_W) < 5e-3;
        }
        if (!near) continue;
        double f_best = -INFINITY, f_h = 0.0, f_nn = 0.0, f_lat = 0.0;
        int f_hits = 0;
        for (int i = 0; i <= kSteps; ++i) {
          for (int j = 0; i + j <= kSteps; ++j) {
            const double b1 = double(i) / kSteps, b2 = double(j) / kSteps, b0 = 1.0 - b1 - b2;
            const glm::dvec3 pq = b0 * P[0] + b1 * P[1] + b2 * P[2];
            const glm::dvec3 Nq = glm::normalize(b0 * N[0] + b1 * N[1] + b2 * N[2]);
            const double h = Level0HeightAt(env, f, b0, b1, b2);
            const glm::dvec3 rq = pq + h * Nq - q_W;
            const double lat = std::hypot(glm::dot(rq, w.axis_u_W), glm::dot(rq, w.axis_v_W));
            if (lat > r) continue;
            ++f_hits;
            const double along = glm::dot(rq, w.normal_W);
            if (along > f_best) {
              f_best = along;
              f_h = h;
              f_nn = glm::dot(Nq, w.normal_W);
              f_lat = lat;
            }
          }
        }
        if (f_hits == 0) continue;
        hits += f_hits;
        best = std::max(best, f_best);
        const glm::dvec3 cr = glm::cross(P[1] - P[0], P[2] - P[0]);
        std::printf(
            "  displaced object tri %zu: %d samples within %.0f um, highest along n %.1f um "
            "(h %.1f um, N.n %.3f, %.1f um off the line), facing %+.3f\n",
            f, f_hits, r * 1e6, f_best * 1e6, f_h * 1e6, f_nn, f_lat * 1e6,
            glm::dot(cr, w.normal_W) / glm::length(cr));
      }
      std::printf("displaced object surface near the point: %d samples, highest %.1f um\n", hits,
                  best * 1e6);
    }
    if (std::getenv("WINDOW_PROBE_TRIANGLES") != nullptr) {
      // Every object triangle under the truth's maximum: its coarse height along n, N·n, the
      // texture's height and the render's value (debugging aid).
      for (const bool is_tool : {false, true}) {
        const ht::HapticModel& m = is_tool ? tool : env;
        const ht::RigidTransform X = is_tool ? X_WT : X_WO;
        for (std::size_t f = 0; f < m.triangles.size(); ++f) {
          glm::dvec3 p[3];
          double x[3], y[3], dd[3], nn[3];
          for (int k = 0; k < 3; ++k) {
            p[k] = X * m.vertices_O[m.triangles[f][k]] - w.center_W;
            x[k] = glm::dot(p[k], w.axis_u_W);
            y[k] = glm::dot(p[k], w.axis_v_W);
            dd[k] = glm::dot(p[k], w.normal_W);
            nn[k] = glm::dot(X.rotation * m.corner_normals_O[3 * f + k], w.normal_W);
          }
          const std::vector<int> one{static_cast<int>(f)};
          const ht::PatchSide side = is_tool ? ht::PatchSide::kTool : ht::PatchSide::kEnvironment;
          const double v1 =
              ht::PatchHeightAt(m, X, one, w, side, d.at_uv_m.x, d.at_uv_m.y, 0, true);
          if (std::isfinite(v1) && std::abs(v1) < 5e-3)
            std::printf("  [any] %s tri %zu parallax alone %.1f um textured %d\n",
                        is_tool ? "tool" : "object", f, v1 * 1e6, int(m.textured[f]));
          const double area = (x[1] - x[0]) * (y[2] - y[0]) - (x[2] - x[0]) * (y[1] - y[0]);
          if (std::abs(area) < 1e-18) continue;
          const double s0 = d.at_uv_m.x, t0 = d.at_uv_m.y;
          const double b0 = ((x[1] - s0) * (y[2] - t0) - (x[2] - s0) * (y[1] - t0)) / area;
          const double b1 = ((x[2] - s0) * (y[0] - t0) - (x[0] - s0) * (y[2] - t0)) / area;
          const double b2 = 1.0 - b0 - b1;
          if (b0 < -1e-9 || b1 < -1e-9 || b2 < -1e-9) continue;
          const glm::dvec3 cr = glm::cross(p[1] - p[0], p[2] - p[0]);
          const double facing = glm::dot(cr, w.normal_W) / glm::length(cr);
          const double hc = b0 * dd[0] + b1 * dd[1] + b2 * dd[2];
          const double h = Level0HeightAt(m, f, b0, b1, b2);
          // N·n of the corners' plain interpolation (the render normalizes it; its value below is
          // the library's own, PatchHeightAt).
          const double ndn = b0 * nn[0] + b1 * nn[1] + b2 * nn[2];
          const double render = ht::PatchHeightAt(m, X, one, w, side, s0, t0, 0);
          std::printf(
              "  %s tri %zu facing %+.3f coarse %.1f um h %.1f um N.n %.3f render's value %.1f um "
              "textured %d\n",
              is_tool ? "tool" : "object", f, facing, hc * 1e6, h * 1e6, ndn, render * 1e6,
              int(m.textured[f]));
        }
      }
    }
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
    {
      const double b = ht::PatchHeightAt(env, X_WO, env_tris, w, ht::PatchSide::kEnvironment,
                                         d.at_uv_m.x, d.at_uv_m.y, 0, true);
      const double a = ht::PatchHeightAt(tool, X_WT, tool_tris, w, ht::PatchSide::kTool,
                                         d.at_uv_m.x, d.at_uv_m.y, 0, true);
      std::printf(
          "models at the truth's maximum, level 0 with parallax: object b %.1f um, tool a "
          "%.1f um, b - a %.1f um\n",
          b * 1e6, a * 1e6, (b - a) * 1e6);
    }
    for (const bool parallax : {false, true}) {
      double best = -std::numeric_limits<double>::infinity(), best_s = 0.0, best_t = 0.0;
      for (int i = 0; i < scan; ++i) {
        for (int j = 0; j < scan; ++j) {
          const double s = ((i + 0.5) / scan - 0.5) * extent, t = ((j + 0.5) / scan - 0.5) * extent;
          const double b = ht::PatchHeightAt(env, X_WO, env_tris, w, ht::PatchSide::kEnvironment, s,
                                             t, 0, parallax);
          const double a =
              ht::PatchHeightAt(tool, X_WT, tool_tris, w, ht::PatchSide::kTool, s, t, 0, parallax);
          if (std::isfinite(a) && std::isfinite(b) && b - a > best) {
            best = b - a;
            best_s = s;
            best_t = t;
          }
        }
      }
      std::printf("level-0 scan%s (%d x %d): largest b - a %.1f um at (%.3f, %.3f) mm\n",
                  parallax ? " with parallax" : "", scan, scan, best * 1e6, best_s * 1e3,
                  best_t * 1e3);
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "window_probe: error: %s\n", e.what());
    return 2;
  }
  return 0;
}
