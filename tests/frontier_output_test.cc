// Checks the files a `speed_error_frontier --quick` run wrote (HT_FRONTIER_OUT): every promised
// file and column is there, nothing half-written is left, the force error in frontier.csv is
// recomputed from contacts.csv by a second route, and the seed-style qualitative results hold
// (a finer grid is closer to the full-resolution truth; the textures matter).

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

namespace {

struct Table {
  std::vector<std::string> columns;
  std::vector<std::map<std::string, std::string>> rows;
};

Table ReadCsv(const std::string& path) {
  Table t;
  std::ifstream in(path);
  EXPECT_TRUE(in.good()) << "cannot read " << path;
  std::string line;
  if (!std::getline(in, line)) return t;
  std::stringstream header(line);
  for (std::string c; std::getline(header, c, ',');) t.columns.push_back(c);
  while (std::getline(in, line)) {
    std::vector<std::string> cells;
    std::stringstream row(line);
    for (std::string c; std::getline(row, c, ',');) cells.push_back(c);
    if (!line.empty() && line.back() == ',') cells.emplace_back();
    EXPECT_EQ(cells.size(), t.columns.size()) << path << ": " << line;
    std::map<std::string, std::string> r;
    for (std::size_t i = 0; i < cells.size() && i < t.columns.size(); ++i)
      r[t.columns[i]] = cells[i];
    t.rows.push_back(r);
  }
  return t;
}

double Num(const std::map<std::string, std::string>& r, const std::string& c) {
  return std::strtod(r.at(c).c_str(), nullptr);
}

class FrontierOutput : public ::testing::Test {
 protected:
  void SetUp() override {
    const char* dir = std::getenv("HT_FRONTIER_OUT");
    if (dir == nullptr) GTEST_SKIP() << "HT_FRONTIER_OUT not set (ctest sets it)";
    dir_ = dir;
  }
  const std::map<std::string, std::string>* Row(const Table& t, const std::string& scene,
                                                const std::string& setting) const {
    for (const auto& r : t.rows) {
      if (r.at("scene") == scene && r.at("setting") == setting) return &r;
    }
    return nullptr;
  }
  std::string dir_;
};

TEST_F(FrontierOutput, EveryFileIsThereAndNothingHalfWritten) {
  for (const char* f :
       {"frontier.csv", "contacts.csv", "patches.csv", "summary.md", "frontier.png"}) {
    EXPECT_TRUE(std::filesystem::exists(dir_ + "/" + f)) << f;
  }
  for (const auto& e : std::filesystem::recursive_directory_iterator(dir_)) {
    EXPECT_EQ(e.path().string().find(".partial"), std::string::npos) << e.path();
  }
  std::ifstream png(dir_ + "/frontier.png", std::ios::binary);
  char magic[8] = {};
  png.read(magic, 8);
  EXPECT_EQ(std::string(magic + 1, 3), "PNG");
  std::ifstream md(dir_ + "/summary.md");
  std::stringstream text;
  text << md.rdbuf();
  EXPECT_NE(text.str().find("## fig75"), std::string::npos);
  EXPECT_NE(text.str().find("Texture-stage ground truth:"), std::string::npos);
  EXPECT_NE(text.str().find("Pipeline truth:"), std::string::npos);
}

TEST_F(FrontierOutput, ContactsCsvHasTheColumnsToRecomputeAGroundTruth) {
  const Table c = ReadCsv(dir_ + "/contacts.csv");
  const std::vector<std::string> need = {"scene",     "setting",
                                         "pose_id",   "contact",
                                         "tool",      "object",
                                         "tool_px",   "tool_py",
                                         "tool_pz",   "tool_qw",
                                         "tool_qx",   "tool_qy",
                                         "tool_qz",   "obj_px",
                                         "obj_py",    "obj_pz",
                                         "obj_qw",    "obj_qx",
                                         "obj_qy",    "obj_qz",
                                         "window_cx", "window_cy",
                                         "window_cz", "window_nx",
                                         "window_ny", "window_nz",
                                         "window_ux", "window_uy",
                                         "window_uz", "window_extent_m",
                                         "grid",      "stiffness_n_per_m",
                                         "delta_m",   "delta_gt_m",
                                         "fx",        "fy",
                                         "fz",        "tx",
                                         "ty",        "tz",
                                         "fx_gt",     "fy_gt",
                                         "fz_gt",     "tx_gt",
                                         "ty_gt",     "tz_gt"};
  for (const std::string& n : need) {
    EXPECT_NE(std::find(c.columns.begin(), c.columns.end(), n), c.columns.end()) << n;
  }
  ASSERT_FALSE(c.rows.empty());
  for (const auto& r : c.rows) {
    EXPECT_TRUE(std::filesystem::exists(dir_ + "/meshes/" + r.at("tool"))) << r.at("tool");
    EXPECT_TRUE(std::filesystem::exists(dir_ + "/meshes/" + r.at("object"))) << r.at("object");
    double qn = 0.0;
    for (const char* q : {"tool_qw", "tool_qx", "tool_qy", "tool_qz"}) qn += Num(r, q) * Num(r, q);
    EXPECT_NEAR(qn, 1.0, 1e-6);  // unit quaternions
  }
}

// Two routes: frontier.csv's force error, and the same figure summed from contacts.csv's rows.
TEST_F(FrontierOutput, ForceErrorRecomputesFromTheContacts) {
  const Table f = ReadCsv(dir_ + "/frontier.csv");
  const Table c = ReadCsv(dir_ + "/contacts.csv");
  int checked = 0;
  for (const auto& row : f.rows) {
    if (row.at("method") != "texture" || !row.at("skipped").empty()) continue;
    std::map<int, std::array<double, 6>> per_pose;  // F − F_gt, F_gt (force only)
    for (const auto& r : c.rows) {
      if (r.at("scene") != row.at("scene") || r.at("setting") != row.at("setting")) continue;
      auto& a = per_pose[static_cast<int>(Num(r, "pose_id"))];
      a[0] += Num(r, "fx") - Num(r, "fx_gt");
      a[1] += Num(r, "fy") - Num(r, "fy_gt");
      a[2] += Num(r, "fz") - Num(r, "fz_gt");
      a[3] += Num(r, "fx_gt");
      a[4] += Num(r, "fy_gt");
      a[5] += Num(r, "fz_gt");
    }
    double num = 0, den = 0;
    for (const auto& [pose, a] : per_pose) {
      num += a[0] * a[0] + a[1] * a[1] + a[2] * a[2];
      den += a[3] * a[3] + a[4] * a[4] + a[5] * a[5];
    }
    if (den == 0.0) continue;
    SCOPED_TRACE(row.at("scene") + " " + row.at("setting"));
    EXPECT_NEAR(std::sqrt(num / den), Num(row, "force_rel_rms"),
                2e-3 * Num(row, "force_rel_rms") + 1e-6);
    ++checked;
  }
  EXPECT_GE(checked, 4);
}

// The pipeline truth (issue 31): patches.csv has the columns to recompute each patch from the
// meshes, every pose of the quick run (all intersect at full resolution) has a non-zero truth, and
// frontier.csv's pipeline force error recomputes from patches.csv and contacts.csv (two routes).
TEST_F(FrontierOutput, PipelineTruthOwnsItsPatchesAndItsErrorRecomputes) {
  const Table p = ReadCsv(dir_ + "/patches.csv");
  for (const char* n :
       {"scene", "pose_id", "patch", "tool", "object", "tool_px", "tool_py", "tool_pz", "tool_qw",
        "tool_qx", "tool_qy", "tool_qz", "obj_px", "obj_py", "obj_pz", "obj_qw", "obj_qx", "obj_qy",
        "obj_qz", "window_cx", "window_cy", "window_cz", "window_nx", "window_ny", "window_nz",
        "window_ux", "window_uy", "window_uz", "window_extent_m", "delta_gt_m", "fx_gt", "fy_gt",
        "fz_gt", "tx_gt", "ty_gt", "tz_gt",
        // Step 4a of the truth: each patch's share and the gap that sets it.
        "share", "gap_to_neighbour_m"}) {
    EXPECT_NE(std::find(p.columns.begin(), p.columns.end(), n), p.columns.end()) << n;
  }
  ASSERT_FALSE(p.rows.empty());
  std::map<std::string, std::map<int, std::array<double, 3>>> truth;  // scene → pose → F_gt
  for (const auto& r : p.rows) {
    EXPECT_GT(Num(r, "delta_gt_m"), 0.0);
    // Each patch's own Φ_gt times its share of a penalty shared with neighbouring patches
    // (contact_patch_truth.h, step 4a).
    const double share = Num(r, "share");
    EXPECT_GT(share, 0.0);
    EXPECT_LE(share, 1.0);
    auto& f = truth[r.at("scene")][static_cast<int>(Num(r, "pose_id"))];
    f[0] += share * Num(r, "fx_gt");
    f[1] += share * Num(r, "fy_gt");
    f[2] += share * Num(r, "fz_gt");
  }
  const Table f = ReadCsv(dir_ + "/frontier.csv");
  const Table c = ReadCsv(dir_ + "/contacts.csv");
  int checked = 0;
  for (const auto& row : f.rows) {
    if (row.at("method") != "texture" || !row.at("skipped").empty()) continue;
    const auto& gt = truth[row.at("scene")];
    // The quick run's fig75 poses are rows of a live loopback trace that had a contact in the
    // operator's model; a few of them need not intersect at full resolution (2 of 12 in a run
    // with issue 32's refined depth, which the operator feels at shallower presses): the truth
    // has a patch at each pose that does, and the method no force where it has none.
    EXPECT_LE(static_cast<double>(gt.size()), Num(row, "poses")) << row.at("scene");
    EXPECT_GE(2.0 * static_cast<double>(gt.size()), Num(row, "poses")) << row.at("scene");
    std::map<int, std::array<double, 3>> method;
    for (const auto& r : c.rows) {
      if (r.at("scene") != row.at("scene") || r.at("setting") != row.at("setting")) continue;
      auto& a = method[static_cast<int>(Num(r, "pose_id"))];
      a[0] += Num(r, "fx");
      a[1] += Num(r, "fy");
      a[2] += Num(r, "fz");
    }
    double num = 0, den = 0;
    for (const auto& [pose, g] : gt) {
      const auto it = method.find(pose);
      const std::array<double, 3> m = it == method.end() ? std::array<double, 3>{} : it->second;
      for (int i = 0; i < 3; ++i) {
        num += (m[i] - g[i]) * (m[i] - g[i]);
        den += g[i] * g[i];
      }
    }
    SCOPED_TRACE(row.at("scene") + " " + row.at("setting"));
    ASSERT_GT(den, 0.0);
    EXPECT_NEAR(std::sqrt(num / den), Num(row, "pipeline_force_rel_rms"),
                2e-3 * Num(row, "pipeline_force_rel_rms") + 1e-6);
    EXPECT_EQ(Num(row, "poses_force_without_truth"), 0.0);
    ++checked;
  }
  EXPECT_GE(checked, 4);
}

TEST_F(FrontierOutput, FinerGridsAreCloserToTheTruthAndTheRefinedDepthIsNot) {
  const Table f = ReadCsv(dir_ + "/frontier.csv");
  const auto* def = Row(f, "fig75", "default");
  const auto* grid = Row(f, "fig75", "grid_only");
  const auto* fine = Row(f, "fig75", "grid100");
  const auto* coarse = Row(f, "fig75", "grid16");
  const auto* untextured = Row(f, "fig75", "coarse_only");
  const auto* refined16 = Row(f, "fig75", "grid16_refined");
  ASSERT_TRUE(def && grid && fine && coarse && untextured && refined16);
  // The grid's δ error shrinks with its cell (it samples cell centres of a mip level of the
  // cell's size; the truth is exact).
  EXPECT_LT(Num(*fine, "delta_err_p50_um"), Num(*grid, "delta_err_p50_um"));
  EXPECT_LT(Num(*grid, "delta_err_p50_um"), Num(*coarse, "delta_err_p50_um"));
  // Issue 32's refined δ (the default) converges as the texture does, not as the grid does:
  // within a few micrometres at N = 50 and at N = 16 (1.7 µm at both in one run) where the grid
  // alone is tens of micrometres low.
  EXPECT_LT(Num(*def, "delta_err_p50_um"), 0.5 * Num(*grid, "delta_err_p50_um"));
  EXPECT_LT(Num(*def, "delta_err_p50_um"), 10.0);
  EXPECT_LT(Num(*refined16, "delta_err_p50_um"), 10.0);
  EXPECT_LT(Num(*refined16, "delta_err_p50_um"), Num(*coarse, "delta_err_p50_um"));
  // The force error orders the coarse grid behind the default with a wide margin (0.87–0.98
  // against 0.35–0.38 in two runs). Between the default and grid 100 it does not order them
  // reliably on the quick run's 12 poses, which come from a live loopback run's trace and differ
  // run to run: 0.38 / 0.35 in one run, 0.35 / 0.43 in another (issue 31's third stop, fig75's
  // window 4.2 cm); the δ error above orders them every time (48 / 9 µm).
  EXPECT_LT(Num(*def, "force_rel_rms"), Num(*coarse, "force_rel_rms"));
  // Without the textures the ridges are gone: worse than with them.
  EXPECT_GT(Num(*untextured, "force_rel_rms"), Num(*def, "force_rel_rms"));
  // Every setting that ran was timed, and the default is one of them.
  for (const auto& r : f.rows) {
    if (!r.at("skipped").empty()) continue;
    EXPECT_GT(Num(r, "total_p50_us"), 0.0) << r.at("setting");
    EXPECT_GE(Num(r, "total_p95_us"), Num(r, "total_p50_us")) << r.at("setting");
  }
}

// Two routes to one error (issue 15): the fast texture path and the reference it replaced are
// the same method within float rounding, so the frontier measures the same error for both.
TEST_F(FrontierOutput, TheReferenceTexturePathHasTheDefaultsError) {
  const Table f = ReadCsv(dir_ + "/frontier.csv");
  const auto* def = Row(f, "fig75", "default");
  const auto* ref = Row(f, "fig75", "reference");
  ASSERT_TRUE(def && ref);
  EXPECT_NE(def->at("renderer"), ref->at("renderer"));
  EXPECT_NEAR(Num(*ref, "force_rel_rms"), Num(*def, "force_rel_rms"),
              1e-3 * Num(*def, "force_rel_rms") + 1e-6);
  EXPECT_NEAR(Num(*ref, "delta_err_p50_um"), Num(*def, "delta_err_p50_um"), 0.01);
  EXPECT_EQ(Num(*ref, "contacts_mean"), Num(*def, "contacts_mean"));
}

}  // namespace
