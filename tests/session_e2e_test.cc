// The operator station and the remote node, both with real UDP sockets on 127.0.0.1 (in one test
// process, on their own threads): the session survives a flood of garbage, forged and oversized
// datagrams at both ends, and the operator reconnects to a remote node that died and came back on
// the same port, without restarting.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <random>
#include <thread>

#include "haptic_core/demo/demo_scenes.h"
#include "master_station/experiment.h"
#include "master_station/operator_station.h"
#include "master_station/simulated_operator.h"
#include "slave_sim/remote_node.h"
#include "transport/link.h"
#include "transport/messages.h"

namespace ht {
namespace {

std::uint16_t FreePort() {
  UdpSocket probe(SocketAddress::Parse("127.0.0.1:0"));
  return probe.local_address().port();
}

SocketAddress Loopback(std::uint16_t port) {
  return SocketAddress::Parse("127.0.0.1:" + std::to_string(port));
}

RemoteNodeConfig RemoteConfig(const MacKey& key, std::uint16_t port) {
  RemoteNodeConfig c;
  c.listen_address = Loopback(port);
  c.progress_period_s = 0.0;
  c.key = key;
  c.exit_on_goodbye = true;
  c.scene_objects.push_back(
      {1, ht::wire::SceneObjectKind::kDracoMesh, std::vector<std::uint8_t>(20000, 0x11)});
  c.pd_backend = PdBackendChoice::kCpu;
  return c;
}

StationConfig OperatorConfig(const MacKey& key, std::uint16_t remote_port,
                             std::uint16_t local_port) {
  StationConfig c;
  c.remote_address = Loopback(remote_port);
  c.local_address = Loopback(local_port);
  c.key = key;
  c.progress_period_s = 0.0;
  c.X_WM = BlockOnGearHomePose();
  c.tool_inertia = BlockOnGearToolInertia();
  return c;
}

TEST(SessionEndToEnd, AFloodOfBadDatagramsIsDroppedAndCountedWhileTheSessionHolds) {
  const MacKey key = MacKey::Generate(), wrong = MacKey::Generate();
  const HapticScene scene = MakeBlockOnGearScene();
  const std::uint16_t remote_port = FreePort(), operator_port = FreePort();
  std::atomic<bool> stop_remote{false}, stop_flood{false};
  nlohmann::json remote_summary;
  std::thread remote(
      [&] { remote_summary = RunRemoteNode(RemoteConfig(key, remote_port), scene, stop_remote); });
  std::atomic<std::uint64_t> flood_sent{0};
  std::thread flood([&] {
    UdpSocket s(SocketAddress::Parse("127.0.0.1:0"));
    SecureLink forger(s, wrong, LinkRole::kOperator);
    std::mt19937 rng(4);
    std::array<std::uint8_t, 2000> junk{};
    wire::ToolStateMessage state;
    state.X_WT = BlockOnGearHomePose();
    const auto next = [&](std::int64_t period_ns) {
      std::this_thread::sleep_for(std::chrono::nanoseconds(period_ns));
    };
    while (!stop_flood.load()) {
      for (int burst = 0; burst < 20; ++burst) {
        for (auto& b : junk) b = static_cast<std::uint8_t>(rng());
        const SocketAddress to = Loopback(burst % 2 ? remote_port : operator_port);
        s.SendTo({junk.data(), 16 + rng() % 200}, to);  // garbage
        s.SendTo(junk, to);                             // oversized
        wire::Header h = forger.NextHeader(wire::MessageType::kToolState, rng());
        s.SendTo(wire::EncodeToolState(h, state, wrong).view(), to);  // forged (wrong key)
        s.SendTo(wire::EncodeHello(h, {}, wrong).view(), to);         // forged Hello
        s.SendTo(wire::EncodeContactModel(h, {}, wrong).view(), to);  // forged model
        s.SendTo(wire::EncodeWelcome(h, {}, wrong).view(), to);       // forged Welcome
        flood_sent += 6;
      }
      next(2000000);  // ~40k datagrams per second in all
    }
  });
  StationConfig config = OperatorConfig(key, remote_port, operator_port);
  const auto experiment = MakeExperiment("fig75", 2.0);
  SimulatedOperatorDevice device(*experiment);
  const nlohmann::json s = RunOperatorStation(config, device, *experiment);
  stop_flood = true;
  flood.join();
  for (int i = 0; i < 200 && !remote_summary.is_object(); ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  stop_remote = true;
  remote.join();

  const auto& t = s["transport"];
  EXPECT_EQ(s["nonfinite_count"].get<int>(), 0);
  EXPECT_EQ(s["ticks"].get<int>(), 2000);
  EXPECT_EQ(t["sessions"].get<int>(), 1);
  EXPECT_EQ(t["peers_lost"].get<int>(), 0);
  EXPECT_TRUE(t["scene"]["complete"].get<bool>());
  // Contact models come as compact_contact_model (the default encoding) or contact_model.
  EXPECT_GT(
      t["streams"].value("compact_contact_model", nlohmann::json::object()).value("received", 0) +
          t["streams"].value("contact_model", nlohmann::json::object()).value("received", 0),
      100);
  // Both ends counted the flood by reason and accepted none of it.
  const nlohmann::json& remote_transport = remote_summary["transport"];
  for (const nlohmann::json* side : {&t, &remote_transport}) {
    const auto& r = (*side)["rejected_by_reason"];
    EXPECT_GT(r.value("bad_mac", 0) + r.value("wrong_session", 0), 0) << side->dump();
    EXPECT_GT(r.value("too_long", 0), 0);
    EXPECT_GT((*side)["rejected_total"].get<std::uint64_t>(), 1000u);
  }
  EXPECT_EQ(remote_summary["transport"]["sessions"].get<int>(), 1);  // no forged Hello opened one
  EXPECT_LE(remote_summary["transport"]["rejected_total"].get<std::uint64_t>() +
                t["rejected_total"].get<std::uint64_t>(),
            flood_sent.load());
  std::printf("[flood] %llu bad datagrams sent; operator loop %.1f Hz, tick p99 %.1f us\n",
              static_cast<unsigned long long>(flood_sent.load()),
              s["operator_rate_hz"].get<double>(), s["operator_tick_p99_us"].get<double>());
}

TEST(SessionEndToEnd, TheOperatorReconnectsToARestartedRemoteNode) {
  const MacKey key = MacKey::Generate();
  const HapticScene scene = MakeBlockOnGearScene();
  const std::uint16_t remote_port = FreePort(), operator_port = FreePort();
  std::atomic<bool> stop_first{false}, stop_second{false};
  nlohmann::json first_summary, second_summary;
  RemoteNodeConfig crashing = RemoteConfig(key, remote_port);
  crashing.goodbye_on_stop = false;  // it dies without a word
  std::thread first([&] { first_summary = RunRemoteNode(crashing, scene, stop_first); });
  std::thread supervisor([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(1200));
    stop_first = true;  // dies without a goodbye
    first.join();
    std::this_thread::sleep_for(std::chrono::milliseconds(900));
    second_summary = RunRemoteNode(RemoteConfig(key, remote_port), scene, stop_second);
  });
  StationConfig config = OperatorConfig(key, remote_port, operator_port);
  const auto experiment = MakeExperiment("fig75", 4.0);
  SimulatedOperatorDevice device(*experiment);
  const nlohmann::json s = RunOperatorStation(config, device, *experiment);
  for (int i = 0; i < 200 && !second_summary.is_object(); ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  stop_second = true;
  supervisor.join();

  const auto& t = s["transport"];
  EXPECT_EQ(s["nonfinite_count"].get<int>(), 0);
  EXPECT_EQ(s["ticks"].get<int>(), 4000);  // the loop ran on through the outage
  EXPECT_EQ(t["peers_lost"].get<int>(), 1);
  EXPECT_EQ(t["sessions"].get<int>(), 2);
  ASSERT_EQ(t["peer_lost_detected_after_ms"].size(), 1u);
  const double detected = t["peer_lost_detected_after_ms"][0].get<double>();
  EXPECT_GE(detected, config.peer_timeout_ms);
  EXPECT_LT(detected, config.peer_timeout_ms + 100.0);  // stated: timeout + one poll (0.2 ms)
  EXPECT_TRUE(t["scene"]["complete"].get<bool>());      // sent again to the new session
  EXPECT_EQ(second_summary["transport"]["sessions"].get<int>(), 1);
  // Tool states come as compact_tool_state (the default encoding) or tool_state.
  const nlohmann::json& second_streams = second_summary["transport"]["streams"];
  EXPECT_GT(
      second_streams.value("compact_tool_state", nlohmann::json::object()).value("received", 0) +
          second_streams.value("tool_state", nlohmann::json::object()).value("received", 0),
      100);
  EXPECT_EQ(second_summary["transport"]["goodbyes"].get<int>(), 1);
}

}  // namespace
}  // namespace ht

namespace ht {
namespace {

// The header's sequence is a u32 (protocol version 8): an operator whose stream nears its end opens
// a new session (without a Goodbye, which would stop a node run without --stay, as this one is),
// and the remote node never sees a number past the mark.
TEST(SessionEndToEnd, TheOperatorRenewsASessionWhoseSequenceNumbersRunLow) {
  const MacKey key = MacKey::Generate();
  const HapticScene scene = MakeBlockOnGearScene();
  const std::uint16_t remote_port = FreePort(), operator_port = FreePort();
  std::atomic<bool> stop_remote{false};
  nlohmann::json remote_summary;
  std::thread remote(
      [&] { remote_summary = RunRemoteNode(RemoteConfig(key, remote_port), scene, stop_remote); });
  StationConfig config = OperatorConfig(key, remote_port, operator_port);
  config.start_sequences_at = wire::kSequenceRenewAt - 50;  // each session's streams, near the end
  const auto experiment = MakeExperiment("fig75", 2.5);
  SimulatedOperatorDevice device(*experiment);
  const nlohmann::json s = RunOperatorStation(config, device, *experiment);
  stop_remote = true;
  remote.join();

  const auto& t = s["transport"];
  EXPECT_EQ(s["ticks"].get<int>(), 2500);
  EXPECT_EQ(s["nonfinite_count"].get<int>(), 0);
  EXPECT_GE(t["sessions_renewed"].get<int>(), 1);
  EXPECT_GE(t["sessions"].get<int>(), 2);
  EXPECT_EQ(t["peers_lost"].get<int>(), 0);
  const auto& r = remote_summary["transport"];
  EXPECT_EQ(r["goodbyes"].get<int>(), 0);  // it ran on: the renewal said no Goodbye
  EXPECT_GE(r["sessions"].get<int>(), 2);
  // Nothing the operator sent went past the mark and came back refused as a replay.
  EXPECT_EQ(r["rejected_by_reason"].value("replayed", 0), 0);
}

TEST(SessionEndToEnd, AStopRequestWhileWaitingForTheRemoteNodeEndsTheWait) {
  // Nobody listens at the remote port: without the stop the station would wait the whole
  // 30 s connect timeout and then report that no remote node answered.
  StationConfig config = OperatorConfig(MacKey::Generate(), FreePort(), FreePort());
  config.connect_timeout_s = 30.0;
  std::atomic<bool> stop{false};
  config.stop_requested = &stop;
  const auto experiment = MakeExperiment("fig75", 1.0);
  SimulatedOperatorDevice device(*experiment);
  std::thread signal([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
    stop = true;
  });
  std::string error;
  try {
    RunOperatorStation(config, device, *experiment);
  } catch (const std::runtime_error& e) {
    error = e.what();
  }
  signal.join();
  EXPECT_NE(error.find("stopped on request while waiting for the session"), std::string::npos)
      << error;
}

TEST(SessionEndToEnd, StopSettingsAreValidated) {
  StationConfig config = OperatorConfig(MacKey::Generate(), 47000, 0);
  config.run_until_stopped = true;  // and no stop_requested: it would never end
  EXPECT_THROW(config.Validate(), std::invalid_argument);
  std::atomic<bool> stop{false};
  config.stop_requested = &stop;
  EXPECT_NO_THROW(config.Validate());
  config.stop_ramp_s = -1.0;
  EXPECT_THROW(config.Validate(), std::invalid_argument);
}

}  // namespace
}  // namespace ht
