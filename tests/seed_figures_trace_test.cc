// The seed's Figs. 76 and 77 run through both processes (deploy/run-loopback): checks of the
// qualitative results on the runs' files. HT_FIG76_OUT: a striped-blocks run of experiment fig76;
// HT_FIG77_OUT: a file-on-cad-part (or hammer-on-torus) run of experiment fig77. Each test skips
// when its variable is not set (ctest sets them).

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <map>
#include <numeric>
#include <sstream>
#include <string>
#include <vector>

#include "trace_csv.h"

namespace {

double Mean(const std::vector<double>& v) {
  return v.empty() ? 0.0 : std::accumulate(v.begin(), v.end(), 0.0) / static_cast<double>(v.size());
}

double Correlation(const std::vector<double>& a, const std::vector<double>& b) {
  const double ma = Mean(a), mb = Mean(b);
  double num = 0, da = 0, db = 0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    num += (a[i] - ma) * (b[i] - mb);
    da += (a[i] - ma) * (a[i] - ma);
    db += (b[i] - mb) * (b[i] - mb);
  }
  return da > 0 && db > 0 ? num / std::sqrt(da * db) : std::nan("");
}

// remote_steps.csv: every column a number.
std::map<std::string, std::vector<double>> LoadSteps(const std::string& path) {
  std::map<std::string, std::vector<double>> out;
  std::ifstream in(path);
  EXPECT_TRUE(in.good()) << "cannot read " << path;
  std::string line;
  std::getline(in, line);
  std::vector<std::string> cols;
  std::stringstream h(line);
  for (std::string c; std::getline(h, c, ',');) cols.push_back(c);
  while (std::getline(in, line)) {
    std::stringstream r(line);
    std::string cell;
    for (std::size_t i = 0; std::getline(r, cell, ',') && i < cols.size(); ++i) {
      out[cols[i]].push_back(std::strtod(cell.c_str(), nullptr));
    }
  }
  return out;
}

const char* DirOrSkip(const char* var) { return std::getenv(var); }

// Seed Fig. 76: the top block rises along n as soon as it rotates, and the torque about n
// opposes the rotation.
// HT_FIG76_FORCE_LAW (seed or pressure): the law the node's summary must say it rendered.
TEST(Fig76Trace, TheBlockRisesWhenRotatedAndTheTorqueOpposesTheRotation) {
  const char* dir = DirOrSkip("HT_FIG76_OUT");
  if (dir == nullptr) GTEST_SKIP() << "HT_FIG76_OUT not set";
  if (const char* law = std::getenv("HT_FIG76_FORCE_LAW")) {
    std::ifstream in(std::string(dir) + "/remote_summary.json");
    std::stringstream summary;
    summary << in.rdbuf();
    EXPECT_NE(summary.str().find(std::string("\"force_law\": \"") + law + "\""), std::string::npos)
        << "remote_summary.json does not say the node rendered the " << law << " law";
  }
  const Trace t = LoadTrace(dir);
  const std::vector<double> z = t.Select("tool_z", "rotate");
  const std::vector<double> rz = t.Select("tool_rz", "rotate");
  const std::vector<double> tz = t.Select("tz", "rotate");
  const std::vector<double> contacts = t.Select("contacts", "rotate");
  ASSERT_GT(z.size(), 5000u) << "the rotate phase should last seconds at 1 kHz";
  double theta_max = 0.0;
  for (double v : rz) theta_max = std::max(theta_max, std::abs(v));
  EXPECT_GT(theta_max, 0.01) << "the block hardly rotated";
  std::vector<double> abs_rz;
  for (double v : rz) abs_rz.push_back(std::abs(v));
  const double rise = Correlation(z, abs_rz);
  EXPECT_GT(rise, 0.6) << "height along n vs |rotation about n|";
  int in_contact = 0, rotated = 0, opposing = 0;
  for (std::size_t i = 0; i < rz.size(); ++i) {
    if (contacts[i] < 1) continue;
    ++in_contact;
    if (std::abs(rz[i]) < 0.25 * theta_max) continue;
    ++rotated;
    opposing += rz[i] * tz[i] < 0.0;
  }
  EXPECT_GT(in_contact, static_cast<int>(0.8 * rz.size()));
  ASSERT_GT(rotated, 500);
  EXPECT_GT(opposing, static_cast<int>(0.8 * rotated))
      << opposing << " of " << rotated << " rotated in-contact ticks have the torque opposing";
  std::printf(
      "fig76: %zu rotate ticks, |theta| max %.4f rad, corr(z, |theta|) %.3f, torque opposes "
      "in %d of %d rotated in-contact ticks\n",
      rz.size(), theta_max, rise, opposing, rotated);
}

// Seed Fig. 77: at least 500 remote frames in contact, each with leaf pairs, contacts and the
// collision / texture / total split; the total is about their sum.
TEST(Fig77Trace, RemoteStepsSplitCollisionAndTextureTime) {
  const char* dir = DirOrSkip("HT_FIG77_OUT");
  if (dir == nullptr) GTEST_SKIP() << "HT_FIG77_OUT not set";
  auto steps = LoadSteps(std::string(dir) + "/remote_steps.csv");
  for (const char* c : {"step", "t_s", "leaf_pairs", "clusters", "contacts", "collision_us",
                        "texture_us", "total_us", "windows", "cells", "grid_1", "grid_14"}) {
    ASSERT_TRUE(steps.count(c)) << "remote_steps.csv has no column " << c;
  }
  std::vector<double> pairs, contacts, texture, total_minus_sum, total;
  for (std::size_t i = 0; i < steps["step"].size(); ++i) {
    if (steps["contacts"][i] < 1) continue;
    pairs.push_back(steps["leaf_pairs"][i]);
    contacts.push_back(steps["contacts"][i]);
    texture.push_back(steps["texture_us"][i]);
    total.push_back(steps["total_us"][i]);
    total_minus_sum.push_back(steps["total_us"][i] - steps["collision_us"][i] -
                              steps["texture_us"][i]);
    EXPECT_GE(steps["leaf_pairs"][i], steps["contacts"][i]) << "step " << i + 1;
    EXPECT_LE(steps["contacts"][i], 14.0);
    // Each window's grid N (issue 32): a number per window, 0 past the last, and their squares
    // sum to the step's cells.
    const double windows = steps["windows"][i];
    double cells = 0.0;
    for (int k = 1; k <= 14; ++k) {
      const double n = steps["grid_" + std::to_string(k)][i];
      if (k <= windows) {
        EXPECT_GE(n, 2.0) << "step " << i + 1 << " window " << k;
      } else {
        EXPECT_EQ(n, 0.0) << "step " << i + 1 << " window " << k;
      }
      cells += n * n;
    }
    if (windows <= 14) EXPECT_EQ(steps["cells"][i], cells) << "step " << i + 1;
  }
  EXPECT_GE(contacts.size(), 500u) << "the seed's Fig. 77 has 500 frames";
  // Total ≈ collision + texture (the rest is assembly): within 5 % of the total on average.
  EXPECT_LT(std::abs(Mean(total_minus_sum)), 0.05 * Mean(total));
  // And the operator really scraped: in contact over most of the scrape.
  const Trace t = LoadTrace(dir);
  const std::vector<double> c = t.Select("contacts", "scrape");
  ASSERT_FALSE(c.empty());
  int touching = 0;
  for (double v : c) touching += v >= 1;
  EXPECT_GT(touching, static_cast<int>(0.5 * c.size()));
  std::printf(
      "fig77: %zu remote steps in contact: leaf pairs mean %.1f, contacts mean %.2f, "
      "texture us mean %.0f, total us mean %.0f; in contact %d of %zu scrape ticks\n",
      contacts.size(), Mean(pairs), Mean(contacts), Mean(texture), Mean(total), touching, c.size());
}

}  // namespace
