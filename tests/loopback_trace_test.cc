// Checks the trace of the loopback fig75 run (tests/CMakeLists.txt runs deploy/run-loopback
// first): the seed's qualitative results of Fig. 75 and the safety properties.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "trace_csv.h"

namespace {

std::string OutDir() {
  const char* d = std::getenv("HT_LOOPBACK_OUT");
  return d ? d : "loopback_fig75";
}

Trace LoadTrace() { return LoadTrace(OutDir()); }

double Rms(const std::vector<double>& v) {
  double s = 0;
  for (double x : v) s += x * x;
  return v.empty() ? 0.0 : std::sqrt(s / static_cast<double>(v.size()));
}

TEST(LoopbackFig75, TraceHasTheRequiredColumnsAndFiniteValues) {
  const Trace t = LoadTrace();
  for (const char* c :
       {"t_s", "phase", "tool_x", "tool_y", "tool_z", "tool_rx", "tool_ry", "tool_rz", "fx", "fy",
        "fz", "tx", "ty", "tz", "contacts", "model_age_ms"}) {
    EXPECT_NE(std::find(t.columns.begin(), t.columns.end(), c), t.columns.end()) << c;
  }
  ASSERT_GE(t.phase.size(), 1500u) << "fig75 needs at least 1,500 frames";
  for (const auto& [name, v] : t.values) {
    for (double x : v) ASSERT_TRUE(std::isfinite(x)) << "non-finite value in column " << name;
  }
}

TEST(LoopbackFig75, ForceAlongTheRidgesStaysSmall) {
  const Trace t = LoadTrace();
  const auto fx = t.Select("fx", "x"), fy = t.Select("fy", "x"), fz = t.Select("fz", "x");
  std::vector<double> mag;
  for (size_t i = 0; i < fx.size(); ++i) mag.push_back(std::hypot(fx[i], fy[i], fz[i]));
  ASSERT_GT(Rms(mag), 0.2) << "the block must press on the gear during the x phase";
  EXPECT_LT(Rms(fx), 0.05 * Rms(mag));
}

TEST(LoopbackFig75, CrossingTheRidgesGivesAStaircaseInZ) {
  const Trace t = LoadTrace();
  const auto y = t.Select("tool_y", "y"), z = t.Select("tool_z", "y");
  ASSERT_FALSE(z.empty());
  // Count rises of at least 0.15 mm (crests climbed): the block rests on a ridge, then drops.
  int rises = 0;
  double low = z[0], high = z[0];
  bool climbing = false;
  for (double v : z) {
    low = std::min(low, v);
    if (!climbing && v - low > 0.15e-3) {
      climbing = true;
      high = v;
    }
    if (climbing) {
      high = std::max(high, v);
      if (high - v > 0.15e-3) {
        ++rises;
        climbing = false;
        low = v;
      }
    }
  }
  const double travel =
      *std::max_element(y.begin(), y.end()) - *std::min_element(y.begin(), y.end());
  EXPECT_GT(travel, 6e-3) << "the block must cross several 3 mm ridges";
  EXPECT_GE(rises, 4);
  // Along x the ridges do not change: z stays much flatter there than while crossing.
  const auto zx = t.Select("tool_z", "x");
  auto range = [](const std::vector<double>& v) {
    return *std::max_element(v.begin(), v.end()) - *std::min_element(v.begin(), v.end());
  };
  EXPECT_LT(range(std::vector<double>(zx.begin() + zx.size() / 3, zx.end())), range(z));
}

TEST(LoopbackFig75, ForcesStayWithinTheDeviceLimits) {
  const Trace t = LoadTrace();
  std::ifstream in(OutDir() + "/summary.json");
  ASSERT_TRUE(in.good());
  const nlohmann::json s = nlohmann::json::parse(in);
  const double max_force = s["device_max_force_n"].get<double>();
  const double max_torque = s["device_max_torque_nm"].get<double>();
  const auto& fx = t.values.at("device_fx");
  for (size_t i = 0; i < fx.size(); ++i) {
    const double f = std::hypot(fx[i], t.values.at("device_fy")[i], t.values.at("device_fz")[i]);
    const double tq = std::hypot(t.values.at("device_tx")[i], t.values.at("device_ty")[i],
                                 t.values.at("device_tz")[i]);
    ASSERT_LE(f, max_force * (1 + 1e-9));
    ASSERT_LE(tq, max_torque * (1 + 1e-9));
  }
  EXPECT_EQ(s["nonfinite_count"].get<int>(), 0);
  EXPECT_GE(s["contacts_max"].get<int>(), 1);
  for (const char* k : {"operator_rate_hz", "operator_tick_p99_us", "remote_rate_hz",
                        "remote_step_of_models_p50_us", "rtt_ms_p50"}) {
    EXPECT_TRUE(s.contains(k)) << k;
  }
  // One name, one figure: the remote node's step time as the models carried it here is named
  // for that, apart from the node's own over every step (remote.step_p50_us).
  EXPECT_FALSE(s.contains("remote_step_p50_us"));
  EXPECT_TRUE(s["remote"].contains("step_p50_us"));
  // Contact models arrive in the compact encoding by default (the float one with --float-models).
  const auto& streams = s["transport"]["streams"];
  const auto received = [&](const char* type) {
    return streams.contains(type) ? streams[type].value("received", 0) : 0;
  };
  EXPECT_GT(received("contact_model") + received("compact_contact_model"), 0);
  // Two routes to one number: both processes read the same steady clock here, so the true offset
  // is 0; the NTP-style estimate must find it within its stated uncertainty (half the best RTT).
  const auto& clock = s["transport"]["clock"];
  ASSERT_GT(clock["samples"].get<int>(), 10);
  EXPECT_LE(std::abs(clock["offset_ms"].get<double>()),
            clock["offset_uncertainty_ms"].get<double>() + 1e-3);
  // The scene arrived whole, as a scene (its graph and the block's and gear's meshes), and
  // decoded on the operator side.
  EXPECT_TRUE(s["transport"]["scene"]["complete"].get<bool>());
  EXPECT_EQ(s["transport"]["scene"]["verified_objects"].get<int>(), 3);
  int graphs = 0, meshes = 0;
  for (const auto& o : s["transport"]["scene"]["decoded"]) {
    EXPECT_FALSE(o.contains("error")) << o.dump();
    graphs += o.value("kind", "") == "scene_graph";
    meshes += o.value("kind", "") == "draco_mesh";
  }
  EXPECT_EQ(graphs, 1);
  EXPECT_EQ(meshes, 2);
  EXPECT_EQ(s["transport"]["rejected_total"].get<int>(), 0);
}

}  // namespace

namespace {

TEST(LoopbackFig75, SummaryNamesThePenetrationDepthBackend) {
  std::ifstream in(OutDir() + "/summary.json");
  ASSERT_TRUE(in.good());
  const nlohmann::json s = nlohmann::json::parse(in);
  ASSERT_TRUE(s.contains("pd_backend")) << "merge-summary did not add the remote backend";
  const std::string used = s["pd_backend"].get<std::string>();
  EXPECT_TRUE(used == "cpu" || used == "gpu") << used;
  if (const char* expected = std::getenv("HT_EXPECT_PD_BACKEND")) {
    EXPECT_EQ(used, expected);
  }
  // A GPU run records its renderer; a CPU run has none.
  EXPECT_EQ(used == "gpu", !s["gl_renderer"].get<std::string>().empty());
  EXPECT_EQ(s["remote"]["pd_backend"]["failures"].get<int>(), 0);
}

TEST(LoopbackFig75, TheDefaultDeadbandHoldsBackMostToolStatesAndModels) {
  std::ifstream in(OutDir() + "/summary.json");
  ASSERT_TRUE(in.good());
  const nlohmann::json s = nlohmann::json::parse(in);
  const auto& d = s["transport"]["deadband"];
  ASSERT_TRUE(d.is_object()) << "no transport.deadband in summary.json";
  const double k = d["tool_state_deadband"].get<double>();
  if (k == 0.0) GTEST_SKIP() << "run without a deadband";
  // Two routes to one count: the deadband's own decisions and the link's datagram counter.
  const auto offered = d["tool_states_offered"].get<std::int64_t>();
  const auto held = d["tool_states_held_back"].get<std::int64_t>();
  // Tool states go as compact_tool_state (the default encoding) or tool_state.
  const nlohmann::json& streams = s["transport"]["streams"];
  const auto stream_value = [&](const char* key) {
    return streams.value("compact_tool_state", nlohmann::json::object()).value(key, 0.0) +
           streams.value("tool_state", nlohmann::json::object()).value(key, 0.0);
  };
  const auto sent = static_cast<std::int64_t>(stream_value("sent"));
  EXPECT_GT(offered, 1000);
  EXPECT_EQ(sent, offered - held + d["tool_states_idle_keepalives"].get<std::int64_t>());
  // The scripted press and slides are predictable: far fewer tool states than ticks, and far
  // fewer models than remote steps, yet the trace checks above hold.
  EXPECT_LT(sent, offered / 2);
  const auto& r = s["remote"]["transport"]["deadband"];
  EXPECT_EQ(r["model_deadband"].get<double>(), d["model_deadband"].get<double>());
  EXPECT_GT(r["models_held_back"].get<std::int64_t>(), 0);
  EXPECT_GT(stream_value("packets_per_s"), 0.0);
}

// With depth fields the operator evaluates the surfaces at its own pose: the remote node steps at
// once on each tool state, and on the extrapolated pose at most every kFieldPoseStepPeriodNs
// (10 ms), so its pose_moved steps are bounded by its run time over that period, however fast
// its steps run.
TEST(LoopbackFig75, WithDepthFieldsTheExtrapolatedStepsComeAtMostEveryTenMilliseconds) {
  std::ifstream in(OutDir() + "/summary.json");
  ASSERT_TRUE(in.good());
  const nlohmann::json s = nlohmann::json::parse(in);
  const nlohmann::json& r = s["remote"];
  if (!r["transport"]["depth_fields"].value("agreed", false)) {
    GTEST_SKIP() << "run without depth fields";
  }
  const auto& by_cause = r["transport"]["deadband"]["steps_by_cause"];
  const auto pose_moved = by_cause["pose_moved"].get<std::int64_t>();
  const double wall_s = r["wall_s_since_first_step"].get<double>();
  EXPECT_GT(by_cause["tool_state"].get<std::int64_t>(), 0);
  EXPECT_GT(pose_moved, 0) << "the slides extrapolate the pose between tool states";
  EXPECT_LE(static_cast<double>(pose_moved), wall_s / 0.010 + 1.0) << wall_s << " s";
}

}  // namespace
