// The remote node on a real UDP socket: a session opens with Hello/Welcome, tool states are
// answered with contact models, and garbage, forged, replayed and out-of-session datagrams are
// dropped and counted by reason.
#include "slave_sim/remote_node.h"

#include <gtest/gtest.h>

#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <limits>
#include <thread>
#include <vector>

#include "haptic_core/contact_model.h"
#include "haptic_core/demo/demo_scenes.h"
#include "legacy_datagram.h"
#include "transport/auth.h"
#include "transport/messages.h"

namespace ht {
namespace {

MacKey TestKey(std::uint8_t seed) {
  MacKey k;
  for (std::size_t i = 0; i < k.bytes.size(); ++i)
    k.bytes[i] = static_cast<std::uint8_t>(seed + 3 * i);
  return k;
}

/// Waits for a datagram of `type` that opens under `key`; returns its body bytes' decode target.
template <typename Decode>
bool Await(UdpSocket& socket, const MacKey& key, wire::MessageType type, wire::Header& h,
           Decode&& decode) {
  std::array<std::uint8_t, wire::kMaxDatagramBytes> buf{};
  for (int i = 0; i < 300; ++i) {
    socket.WaitReadable(10);
    SocketAddress from;
    while (auto n = socket.ReceiveFrom(buf, from)) {
      std::span<const std::uint8_t> body;
      if (wire::OpenDatagram({buf.data(), *n}, key, h, body) == wire::DecodeStatus::kOk &&
          h.type == type && decode(body)) {
        return true;
      }
    }
  }
  return false;
}

/// The UDP port the node wrote to `port_file` once bound (0 when none came within 4 s).
std::uint16_t AwaitPort(const std::string& port_file) {
  for (int i = 0; i < 400; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
    if (FILE* f = std::fopen(port_file.c_str(), "r")) {
      unsigned p = 0;
      const bool read = std::fscanf(f, "%u", &p) == 1;
      std::fclose(f);
      if (read && p != 0) return static_cast<std::uint16_t>(p);
    }
  }
  return 0;
}

/// The tool at the scene's home pose pressed 0.5 mm down (onto the gear's ridges), at rest.
wire::ToolStateMessage PressedAtHome(const HapticScene& scene) {
  wire::ToolStateMessage state;
  state.X_WT = scene.X_WT_home;
  state.X_WT.translation.z -= 0.5e-3;
  return state;
}

/// Sends `hello` to `remote` and waits for the Welcome that echoes its nonce, into `welcome`;
/// returns the session it opened, 0 when none came.
std::uint32_t OpenSession(UdpSocket& socket, const SocketAddress& remote, const MacKey& key,
                          const wire::HelloMessage& hello, wire::WelcomeMessage& welcome) {
  socket.SendTo(wire::EncodeHello({wire::MessageType::kHello, 0, 1, 0}, hello, key).view(), remote);
  wire::Header h;
  if (!Await(socket, key, wire::MessageType::kWelcome, h, [&](auto body) {
        return wire::DecodeWelcome(body, welcome) == wire::DecodeStatus::kOk &&
               welcome.client_nonce == hello.client_nonce;
      })) {
    return 0;
  }
  return h.session_id;
}

/// Sends a Ping reporting the operator's round trip `rtt_us` (µs) in `session` with the next
/// `sequence`, and waits for the node's Pong; false when none came.
bool PingWithRoundTrip(UdpSocket& socket, const SocketAddress& remote, const MacKey& key,
                       std::uint32_t session, std::uint32_t& sequence, std::uint32_t rtt_us) {
  socket.SendTo(
      wire::EncodePing({wire::MessageType::kPing, session, sequence++, 0}, {rtt_us}, key).view(),
      remote);
  wire::Header h;
  wire::PongMessage pong;
  return Await(socket, key, wire::MessageType::kPong, h,
               [&](auto body) { return wire::DecodePong(body, pong) == wire::DecodeStatus::kOk; });
}

/// A node running `config` on `scene` on its own thread for one test: started at construction,
/// `remote` its bound address (port 0: it wrote no port file within 4 s). Stop() ends the run and
/// returns its summary; the destructor stops and joins it however the test leaves its scope (an
/// ASSERT returns early; a joinable std::thread destroyed would end the whole test binary).
/// `config` and `scene` must outlive it.
class RunningNode {
 public:
  RunningNode(const RemoteNodeConfig& config, const HapticScene& scene)
      : thread_([this, &config, &scene] { summary_ = RunRemoteNode(config, scene, stop_); }) {
    port = AwaitPort(config.port_file);
    remote = SocketAddress::Parse("127.0.0.1:" + std::to_string(port));
  }
  RunningNode(const RunningNode&) = delete;
  RunningNode& operator=(const RunningNode&) = delete;
  ~RunningNode() { Stop(); }
  /// Stops the node and waits for it; its summary (RunRemoteNode's).
  const nlohmann::json& Stop() {
    stop_ = true;
    if (thread_.joinable()) thread_.join();
    return summary_;
  }
  std::uint16_t port = 0;
  SocketAddress remote;

 private:
  std::atomic<bool> stop_{false};
  nlohmann::json summary_;
  std::thread thread_;  // last: started once the members it writes exist
};

/// A node on 127.0.0.1 (any port, written to TempDir()/port_file_name, stale file removed),
/// quiet, staying up after a goodbye, authenticating with `key`.
RemoteNodeConfig LocalNodeConfig(const MacKey& key, const std::string& port_file_name) {
  RemoteNodeConfig config;
  config.listen_address = SocketAddress::Parse("127.0.0.1:0");
  config.progress_period_s = 0.0;
  config.key = key;
  config.exit_on_goodbye = false;
  config.port_file = ::testing::TempDir() + "/" + port_file_name;
  std::remove(config.port_file.c_str());
  return config;
}

TEST(RemoteNode, OpensASessionAnswersToolStatesAndCountsWhatItDrops) {
  const HapticScene scene = MakeBlockOnGearScene();
  RemoteNodeConfig config = LocalNodeConfig(TestKey(11), "remote_node_test.port");
  config.scene_objects.push_back(
      {5, ht::wire::SceneObjectKind::kDracoMesh, std::vector<std::uint8_t>(3000, 0x42)});
  RunningNode node(config, scene);

  ASSERT_NE(node.port, 0);
  const SocketAddress remote = node.remote;
  UdpSocket socket(SocketAddress::Parse("127.0.0.1:0"));

  const std::uint8_t garbage[] = {1,  2,  3,  4,  5,  6,  7,  8,  9,  10, 11, 12, 13, 14, 15,
                                  16, 17, 18, 19, 20, 21, 22, 23, 24, 25, 26, 27, 28, 29, 30};
  for (int i = 0; i < 5; ++i) socket.SendTo(garbage, remote);
  const wire::ToolStateMessage state = PressedAtHome(scene);
  // Before any session, even an authenticated tool state is refused.
  socket.SendTo(
      wire::EncodeToolState({wire::MessageType::kToolState, 77, 1, 0}, state, config.key).view(),
      remote);
  // A Hello under another key is refused as bad_mac.
  wire::HelloMessage hello;
  hello.client_nonce = 1234;
  socket.SendTo(wire::EncodeHello({wire::MessageType::kHello, 0, 1, 0}, hello, TestKey(99)).view(),
                remote);
  const wire::Datagram hello_datagram =
      wire::EncodeHello({wire::MessageType::kHello, 0, 2, 0}, hello, config.key);
  ASSERT_TRUE(socket.SendTo(hello_datagram.view(), remote));
  wire::Header h;
  wire::WelcomeMessage welcome;
  ASSERT_TRUE(Await(socket, config.key, wire::MessageType::kWelcome, h, [&](auto body) {
    return wire::DecodeWelcome(body, welcome) == wire::DecodeStatus::kOk;
  }));
  const std::uint32_t session = h.session_id;
  EXPECT_NE(session, 0u);
  EXPECT_EQ(welcome.client_nonce, 1234u);
  EXPECT_EQ(welcome.scene_objects, 1);
  EXPECT_EQ(welcome.grid, config.pipeline.grid_resolution);

  const wire::Datagram d =
      wire::EncodeToolState({wire::MessageType::kToolState, session, 1, 0}, state, config.key);
  ASSERT_TRUE(socket.SendTo(d.view(), remote));
  wire::ContactModelMessage model;
  ASSERT_TRUE(Await(socket, config.key, wire::MessageType::kContactModel, h, [&](auto body) {
    return wire::DecodeContactModel(body, model) == wire::DecodeStatus::kOk;
  }));
  EXPECT_EQ(h.session_id, session);
  EXPECT_EQ(model.model.tool_state_seq, 1u);
  ASSERT_EQ(model.model.num_contacts, 1);
  EXPECT_GT(model.model.contacts[0].depth_m, 0.0);
  EXPECT_GT(model.model.F_T_W_at_q0.force.z, 0.0);  // pushes the block up, away from the gear

  socket.SendTo(d.view(), remote);  // replayed
  wire::Datagram forged =
      wire::EncodeToolState({wire::MessageType::kToolState, session, 2, 0}, state, config.key);
  forged.bytes[40] ^= 0x10;
  socket.SendTo(forged.view(), remote);  // forged
  // The same Hello again (a retransmission) is welcomed into the same session.
  socket.SendTo(hello_datagram.view(), remote);
  ASSERT_TRUE(Await(socket, config.key, wire::MessageType::kWelcome, h, [&](auto body) {
    return wire::DecodeWelcome(body, welcome) == wire::DecodeStatus::kOk;
  }));
  EXPECT_EQ(h.session_id, session);
  // A new Hello while this session is live is deferred (a replayed Hello cannot take a live
  // session over); once the session ends, the retransmitted Hello opens a new one; after that
  // the first Hello played again opens nothing.
  hello.client_nonce = 999;
  socket.SendTo(wire::EncodeHello({wire::MessageType::kHello, 0, 3, 0}, hello, config.key).view(),
                remote);
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  socket.SendTo(
      wire::EncodeGoodbye({wire::MessageType::kGoodbye, session, 1, 0}, config.key).view(), remote);
  socket.SendTo(wire::EncodeHello({wire::MessageType::kHello, 0, 4, 0}, hello, config.key).view(),
                remote);
  ASSERT_TRUE(Await(socket, config.key, wire::MessageType::kWelcome, h, [&](auto body) {
    return wire::DecodeWelcome(body, welcome) == wire::DecodeStatus::kOk &&
           welcome.client_nonce == 999;
  }));
  const std::uint32_t session2 = h.session_id;
  EXPECT_NE(session2, session);
  socket.SendTo(hello_datagram.view(), remote);
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  const nlohmann::json summary = node.Stop();
  const nlohmann::json& t = summary["transport"];
  EXPECT_EQ(t["rejected_by_reason"]["bad_magic"].get<int>(), 5);
  EXPECT_EQ(t["rejected_by_reason"]["bad_mac"].get<int>(), 2);
  EXPECT_EQ(t["rejected_by_reason"]["wrong_session"].get<int>(), 1);
  EXPECT_EQ(t["rejected_by_reason"]["replayed"].get<int>(), 2);
  EXPECT_EQ(t["hello_replayed"].get<int>(), 1);
  EXPECT_EQ(t["hello_retransmits"].get<int>(), 1);
  EXPECT_EQ(t["hello_deferred"].get<int>(), 1);
  EXPECT_EQ(t["sessions"].get<int>(), 2);
  EXPECT_EQ(t["goodbyes"].get<int>(), 1);
  EXPECT_EQ(t["streams"]["tool_state"]["received"].get<int>(), 1);
  EXPECT_EQ(t["streams"]["tool_state"]["duplicate"].get<int>(), 1);
  EXPECT_EQ(t["streams"]["hello"]["received"].get<int>(),
            4);  // A, A again, 999 twice (A replayed is rejected)
  EXPECT_GE(t["streams"]["scene_fragment"]["sent"].get<int>(), 3);  // 3000 B in 1422 B pieces
  EXPECT_GE(summary["steps"].get<int>(), 1);
}

TEST(RemoteNode, AgreesOnCompactToolStatesAndAnswersThemAsTheF64Ones) {
  const HapticScene scene = MakeBlockOnGearScene();
  const RemoteNodeConfig config = LocalNodeConfig(TestKey(31), "remote_node_compact_test.port");
  RunningNode node(config, scene);
  ASSERT_NE(node.port, 0);
  const SocketAddress remote = node.remote;
  UdpSocket socket(SocketAddress::Parse("127.0.0.1:0"));

  wire::HelloMessage hello;
  hello.client_nonce = 77;
  hello.codecs = wire::kCodecDracoMesh | wire::kCodecCompactToolState;
  socket.SendTo(wire::EncodeHello({wire::MessageType::kHello, 0, 1, 0}, hello, config.key).view(),
                remote);
  wire::Header h;
  wire::WelcomeMessage welcome;
  ASSERT_TRUE(Await(socket, config.key, wire::MessageType::kWelcome, h, [&](auto body) {
    return wire::DecodeWelcome(body, welcome) == wire::DecodeStatus::kOk;
  }));
  EXPECT_EQ(welcome.codecs, wire::kCodecDracoMesh | wire::kCodecCompactToolState);
  const std::uint32_t session = h.session_id;

  // The same press as the f64 test above, compact: the model answers it.
  const wire::ToolStateMessage state = PressedAtHome(scene);
  socket.SendTo(wire::EncodeCompactToolState({wire::MessageType::kCompactToolState, session, 1, 0},
                                             state, config.key)
                    .view(),
                remote);
  wire::ContactModelMessage model;
  ASSERT_TRUE(Await(socket, config.key, wire::MessageType::kContactModel, h, [&](auto body) {
    return wire::DecodeContactModel(body, model) == wire::DecodeStatus::kOk;
  }));
  EXPECT_EQ(model.model.tool_state_seq, 1u);
  ASSERT_EQ(model.model.num_contacts, 1);
  EXPECT_GT(model.model.contacts[0].depth_m, 0.0);
  EXPECT_GT(model.model.F_T_W_at_q0.force.z, 0.0);
  // The model is linearized where the compact state put the tool (within its position bound).
  EXPECT_LE(glm::length(model.model.X_WT0.translation - state.X_WT.translation), 1e-6);
  // A compact state with a NaN twist is authenticated, then refused as non-finite.
  wire::ToolStateMessage bad = state;
  bad.V_WT_W.angular.y = std::numeric_limits<double>::quiet_NaN();
  socket.SendTo(wire::EncodeCompactToolState({wire::MessageType::kCompactToolState, session, 2, 0},
                                             bad, config.key)
                    .view(),
                remote);
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  socket.SendTo(
      wire::EncodeGoodbye({wire::MessageType::kGoodbye, session, 1, 0}, config.key).view(), remote);
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  const nlohmann::json summary = node.Stop();
  const nlohmann::json& t = summary["transport"];
  EXPECT_EQ(t["rejected_by_reason"]["non_finite"].get<int>(), 1);
  EXPECT_EQ(t["streams"]["compact_tool_state"]["received"].get<int>(), 1);
  EXPECT_EQ(t["streams"]["compact_tool_state"]["rejected"].get<int>(), 1);
  EXPECT_EQ(t["streams"].value("tool_state", nlohmann::json::object()).value("received", 0), 0);
}

// Issue 33's thirty-fifth stop: the node sets the speculative floor from the round trip its
// operator's Ping reports (RemoteNodeConfig::speculative_speed_m_per_s × the round trip, at most
// max_speculative_floor_m), so that the model of a tool at rest 2 mm above the gear holds the gear
// (δ0 < 0) under a 200 ms round trip and nothing without a measured one.
TEST(RemoteNode, ModelsASurfaceARoundTripAwayFromTheRoundTripItsOperatorReports) {
  RemoteNodeConfig defaults;
  EXPECT_EQ(SpeculativeFloorForRoundTrip(defaults, 0), 0.0);
  EXPECT_NEAR(SpeculativeFloorForRoundTrip(defaults, 200'000'000), 5e-3, 1e-12);
  EXPECT_NEAR(SpeculativeFloorForRoundTrip(defaults, 1'000'000), 25e-6, 1e-12);
  EXPECT_EQ(SpeculativeFloorForRoundTrip(defaults, 2'000'000'000),
            defaults.max_speculative_floor_m);
  RemoteNodeConfig off;
  off.speculative_speed_m_per_s = 0.0;
  EXPECT_EQ(SpeculativeFloorForRoundTrip(off, 200'000'000), 0.0);
  const HapticScene scene = MakeBlockOnGearScene();
  int nonce = 0;
  for (const std::uint32_t rtt_us : {200'000u, 0u}) {
    SCOPED_TRACE(rtt_us);
    RemoteNodeConfig config = LocalNodeConfig(TestKey(42), "remote_node_floor_test.port");
    config.pipeline.speculative_lead_s = 0.0;  // at rest anyway: the floor alone
    RunningNode node(config, scene);
    ASSERT_NE(node.port, 0);
    const SocketAddress remote = node.remote;
    UdpSocket socket(SocketAddress::Parse("127.0.0.1:0"));
    wire::HelloMessage hello;
    hello.client_nonce = 191 + nonce++;
    hello.codecs = wire::kCodecDracoMesh | wire::kCodecCompactContactModel;
    wire::WelcomeMessage welcome;
    const std::uint32_t session = OpenSession(socket, remote, config.key, hello, welcome);
    ASSERT_NE(session, 0u);
    wire::Header h;
    std::uint32_t sequence = 1;
    if (rtt_us > 0) {
      ASSERT_TRUE(PingWithRoundTrip(socket, remote, config.key, session, sequence, rtt_us));
    }
    wire::ToolStateMessage state;
    state.X_WT = scene.X_WT_home;
    state.X_WT.translation.z += 2e-3;  // at rest, 2 mm above its home on the gear
    socket.SendTo(wire::EncodeToolState({wire::MessageType::kToolState, session, sequence++, 0},
                                        state, config.key)
                      .view(),
                  remote);
    wire::ContactModelMessage model;
    ASSERT_TRUE(
        Await(socket, config.key, wire::MessageType::kCompactContactModel, h, [&](auto body) {
          return wire::DecodeCompactContactModel(body, model, /*receive_time_ns=*/0) ==
                 wire::DecodeStatus::kOk;
        }));
    if (rtt_us > 0) {
      ASSERT_GE(model.model.num_contacts, 1);
      EXPECT_LT(model.model.contacts[0].depth_m, -1.5e-3);  // separated by about 2 mm
      EXPECT_GT(model.model.contacts[0].depth_m, -3e-3);
    } else {
      EXPECT_EQ(model.model.num_contacts, 0);
    }
    socket.SendTo(
        wire::EncodeGoodbye({wire::MessageType::kGoodbye, session, sequence++, 0}, config.key)
            .view(),
        remote);
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    const nlohmann::json summary = node.Stop();
    const nlohmann::json& f = summary["speculative_floor"];
    EXPECT_NEAR(f["last_mm"].get<double>(), rtt_us > 0 ? 5.0 : 0.0, 1e-9);
    EXPECT_NEAR(f["speed_mm_per_s"].get<double>(), 25.0, 1e-9);
  }
}

// The operator says Goodbye three times (a lost one would leave the node waiting for the peer
// timeout): the copies after the first belong to the session it closed and are counted as its
// copies, not as rejections (deploy/report draws rejections as faults). A Goodbye of a session
// that never was is still refused.
TEST(RemoteNode, TheCopiesOfTheOperatorsGoodbyeAreNoRejections) {
  const HapticScene scene = MakeBlockOnGearScene();
  RemoteNodeConfig config = LocalNodeConfig(TestKey(31), "remote_node_goodbye_test.port");
  RunningNode node(config, scene);
  ASSERT_NE(node.port, 0);
  UdpSocket socket(SocketAddress::Parse("127.0.0.1:0"));
  wire::HelloMessage hello;
  hello.client_nonce = 31;
  wire::WelcomeMessage welcome;
  const std::uint32_t session = OpenSession(socket, node.remote, config.key, hello, welcome);
  ASSERT_NE(session, 0u);
  for (std::uint32_t seq = 1; seq <= 3; ++seq) {
    socket.SendTo(
        wire::EncodeGoodbye({wire::MessageType::kGoodbye, session, seq, 0}, config.key).view(),
        node.remote);
  }
  socket.SendTo(
      wire::EncodeGoodbye({wire::MessageType::kGoodbye, session ^ 0x5a5a5a5au, 1, 0}, config.key)
          .view(),
      node.remote);
  // A new session: the node has handled every datagram sent before its Hello.
  hello.client_nonce = 32;
  ASSERT_NE(OpenSession(socket, node.remote, config.key, hello, welcome), 0u);
  const nlohmann::json summary = node.Stop();
  const nlohmann::json& t = summary["transport"];
  EXPECT_EQ(t["goodbyes"].get<int>(), 1);
  EXPECT_EQ(t["goodbye_copies"].get<int>(), 2);
  EXPECT_EQ(t["streams"]["goodbye"]["received"].get<int>(), 3);
  EXPECT_EQ(t["streams"]["goodbye"]["rejected"].get<int>(), 1);
  EXPECT_EQ(t["rejected_by_reason"].value("wrong_session", 0), 1);
  EXPECT_EQ(t["rejected_total"].get<int>(), 1);
}

// The header's sequence is a u32 (protocol version 8): a node whose streams near its end says
// Goodbye and closes the session (the operator then opens a new one), instead of sending numbers
// the operator would refuse as replays.
TEST(RemoteNode, EndsASessionWhoseSequenceNumbersRunLow) {
  const HapticScene scene = MakeBlockOnGearScene();
  RemoteNodeConfig config = LocalNodeConfig(TestKey(41), "remote_node_renew_test.port");
  config.start_sequences_at = wire::kSequenceRenewAt - 20;
  RunningNode node(config, scene);
  ASSERT_NE(node.port, 0);
  const SocketAddress remote = node.remote;
  UdpSocket socket(SocketAddress::Parse("127.0.0.1:0"));
  std::uint32_t sessions[2] = {0, 0};
  for (int attempt = 0; attempt < 2; ++attempt) {
    wire::HelloMessage hello;
    hello.client_nonce = 900 + static_cast<std::uint64_t>(attempt);
    wire::WelcomeMessage welcome;
    sessions[attempt] = OpenSession(socket, remote, config.key, hello, welcome);
    ASSERT_NE(sessions[attempt], 0u) << attempt;
    const std::uint32_t session = sessions[attempt];
    // Pressed tool states, a millisecond apart: contact models (and the scene) answer them, each
    // on its own stream, until one of them reaches kSequenceRenewAt.
    const wire::ToolStateMessage state = PressedAtHome(scene);
    bool goodbye = false;
    std::uint64_t highest = 0;
    std::array<std::uint8_t, wire::kMaxDatagramBytes> buf{};
    for (std::uint64_t seq = 1; seq <= 300 && !goodbye; ++seq) {
      socket.SendTo(wire::EncodeCompactToolState(
                        {wire::MessageType::kCompactToolState, session, seq, 0}, state, config.key)
                        .view(),
                    remote);
      socket.WaitReadable(1);
      SocketAddress from;
      while (auto n = socket.ReceiveFrom(buf, from)) {
        wire::Header got;
        std::span<const std::uint8_t> body;
        if (wire::OpenDatagram({buf.data(), *n}, config.key, got, body) !=
                wire::DecodeStatus::kOk ||
            got.session_id != session) {
          continue;
        }
        if (got.type == wire::MessageType::kGoodbye) goodbye = true;
        if (got.type != wire::MessageType::kGoodbye && got.type != wire::MessageType::kWelcome) {
          highest = std::max(highest, got.sequence);
        }
      }
    }
    EXPECT_TRUE(goodbye) << attempt;
    // Every stream stayed below its last number; the one that ended the session reached the mark.
    EXPECT_GE(highest, wire::kSequenceRenewAt) << attempt;
    EXPECT_LT(highest, wire::kMaxSequence) << attempt;
  }
  EXPECT_NE(sessions[0], sessions[1]);
  const nlohmann::json summary = node.Stop();
  EXPECT_EQ(summary["transport"]["sessions_renewed"].get<int>(), 2);
  EXPECT_EQ(summary["transport"]["sessions"].get<int>(), 2);
}

TEST(RemoteNode, RefusesAnOperatorOfAnotherVersionAndHoldsBackModelsThatSayNothingNew) {
  const HapticScene scene = MakeBlockOnGearScene();
  const RemoteNodeConfig config = LocalNodeConfig(TestKey(21), "remote_node_deadband_test.port");
  RunningNode node(config, scene);
  ASSERT_NE(node.port, 0);
  const SocketAddress remote = node.remote;
  UdpSocket socket(SocketAddress::Parse("127.0.0.1:0"));

  // 1. A version-3 operator's Hello (header version 3, the 32-byte v3 body) gets a Reject in
  // version 3 that it can read.
  wire::HelloMessage hello;
  hello.client_nonce = 4242;
  hello.min_version = hello.max_version = 3;
  const wire::Datagram own =
      wire::EncodeHello({wire::MessageType::kHello, 0, 1, 0}, hello, config.key);
  const wire::Datagram old = test::LegacyDatagram(3, wire::MessageType::kHello, 1,
                                                  test::BodyOf(own).first(32), config.key);
  ASSERT_TRUE(socket.SendTo(old.view(), remote));
  bool refused = false;
  std::array<std::uint8_t, wire::kMaxDatagramBytes> buf{};
  for (int i = 0; i < 300 && !refused; ++i) {
    socket.WaitReadable(10);
    SocketAddress from;
    while (auto n = socket.ReceiveFrom(buf, from)) {
      const std::span<const std::uint8_t> d(buf.data(), *n);
      const test::LegacyHeader header = test::ReadLegacyHeader(d);
      if (*n < wire::kLegacyHeaderBytes + wire::kRejectFixedBytes + wire::kLegacyMacBytes ||
          header.magic != wire::kLegacyMagic || header.version != 3 ||
          header.type != static_cast<std::uint8_t>(wire::MessageType::kReject)) {
        continue;
      }
      ASSERT_TRUE(test::LegacyMacVerifies(d, config.key));
      // The v3 Reject body: u64 nonce, u8 reason, u8 n, text.
      const std::uint8_t* b = buf.data() + wire::kLegacyHeaderBytes;
      std::uint64_t nonce = 0;
      for (int k = 7; k >= 0; --k) nonce = (nonce << 8) | b[k];
      EXPECT_EQ(nonce, 4242u);
      EXPECT_EQ(b[8], static_cast<std::uint8_t>(wire::RejectReason::kVersion));
      const std::string text(reinterpret_cast<const char*>(b + 10), b[9]);
      EXPECT_NE(text.find("operator speaks 3..3"), std::string::npos) << text;
      refused = true;
    }
  }
  ASSERT_TRUE(refused);

  // 1b. The previous version (this header and MAC: version 9, whose Ping was empty) gets a Reject
  // in this layout with its own version.
  {
    wire::HelloMessage previous;
    previous.client_nonce = 4299;
    previous.min_version = previous.max_version = wire::kProtocolVersion - 1;
    wire::Datagram d =
        wire::EncodeHello({wire::MessageType::kHello, 0, 1, 0}, previous, config.key);
    d.size -= wire::kMacBytes;
    d.bytes[wire::kHeaderVersionOffset] = static_cast<std::uint8_t>(wire::kProtocolVersion - 1);
    ComputeMac(d.view(), config.key,
               std::span<std::uint8_t, wire::kMacBytes>(d.bytes.data() + d.size, wire::kMacBytes));
    d.size += wire::kMacBytes;
    ASSERT_TRUE(socket.SendTo(d.view(), remote));
    bool refused_previous = false;
    for (int i = 0; i < 300 && !refused_previous; ++i) {
      socket.WaitReadable(10);
      SocketAddress from;
      while (auto n = socket.ReceiveFrom(buf, from)) {
        const std::span<const std::uint8_t> r(buf.data(), *n);
        if (*n < wire::kHeaderBytes + wire::kRejectFixedBytes + wire::kMacBytes ||
            r[wire::kHeaderVersionOffset] != wire::kProtocolVersion - 1 ||
            r[wire::kHeaderTypeOffset] != static_cast<std::uint8_t>(wire::MessageType::kReject)) {
          continue;
        }
        ASSERT_TRUE(VerifyMac(r, config.key));
        wire::RejectMessage reject;
        ASSERT_EQ(
            wire::DecodeReject(
                r.subspan(wire::kHeaderBytes, *n - wire::kHeaderBytes - wire::kMacBytes), reject),
            wire::DecodeStatus::kOk);
        EXPECT_EQ(reject.client_nonce, 4299u);
        EXPECT_EQ(reject.reason, wire::RejectReason::kVersion);
        const std::string speaks = "operator speaks " + std::to_string(wire::kProtocolVersion - 1);
        EXPECT_NE(std::string(reject.message()).find(speaks), std::string::npos)
            << reject.message();
        refused_previous = true;
      }
    }
    ASSERT_TRUE(refused_previous);
  }

  // 2. An operator of this version asks for a 10 % deadband on both streams and compact models.
  hello = {};
  hello.client_nonce = 4343;
  hello.codecs = wire::kCodecDracoMesh | wire::kCodecCompactContactModel;
  hello.deadband = {0.1f, 0.1f, 100, 100};
  socket.SendTo(wire::EncodeHello({wire::MessageType::kHello, 0, 2, 0}, hello, config.key).view(),
                remote);
  wire::Header h;
  wire::WelcomeMessage welcome;
  ASSERT_TRUE(Await(socket, config.key, wire::MessageType::kWelcome, h, [&](auto body) {
    return wire::DecodeWelcome(body, welcome) == wire::DecodeStatus::kOk;
  }));
  EXPECT_EQ(welcome.deadband.model_deadband, 0.1f);
  EXPECT_NE(welcome.codecs & wire::kCodecCompactContactModel, 0u);
  const std::uint32_t session = h.session_id;
  // One tool state, at rest and pressed on the ridges, then nothing: the node has nothing new to
  // compute, skips its steps and keeps the operator's model alive every 100 ms.
  const wire::ToolStateMessage state = PressedAtHome(scene);
  socket.SendTo(
      wire::EncodeToolState({wire::MessageType::kToolState, session, 1, 0}, state, config.key)
          .view(),
      remote);
  wire::ContactModelMessage first;
  ASSERT_TRUE(Await(socket, config.key, wire::MessageType::kCompactContactModel, h, [&](auto b) {
    return wire::DecodeCompactContactModel(b, first, /*receive_time_ns=*/0) ==
           wire::DecodeStatus::kOk;
  }));
  ASSERT_EQ(first.model.num_contacts, 1);
  // The same v3 Hello played again gets no second Reject.
  ASSERT_TRUE(socket.SendTo(old.view(), remote));
  // 450 ms with pings (the node's peer timeout is 500 ms): only keep-alives of that model come,
  // at most one per keep-alive period (not one per step), each with the same echo and a hold
  // that grows with its send time.
  std::vector<std::chrono::steady_clock::time_point> arrivals;
  std::vector<wire::ContactModelMessage> copies;
  const auto start = std::chrono::steady_clock::now();
  std::uint64_t ping_sequence = 1;
  auto next_ping = start;
  while (std::chrono::steady_clock::now() < start + std::chrono::milliseconds(450)) {
    if (std::chrono::steady_clock::now() >= next_ping) {
      socket.SendTo(
          wire::EncodePing({wire::MessageType::kPing, session, ping_sequence++, 0}, {}, config.key)
              .view(),
          remote);
      next_ping += std::chrono::milliseconds(100);
    }
    socket.WaitReadable(10);
    SocketAddress from;
    while (auto n = socket.ReceiveFrom(buf, from)) {
      std::span<const std::uint8_t> body;
      wire::ContactModelMessage m;
      if (wire::OpenDatagram({buf.data(), *n}, config.key, h, body) == wire::DecodeStatus::kOk &&
          h.type == wire::MessageType::kCompactContactModel &&
          wire::DecodeCompactContactModel(body, m, /*receive_time_ns=*/0) ==
              wire::DecodeStatus::kOk) {
        arrivals.push_back(std::chrono::steady_clock::now());
        copies.push_back(m);
      }
    }
  }
  ASSERT_GE(copies.size(), 2u);  // 100 ms keep-alives in 450 ms: about four
  for (std::size_t i = 0; i < copies.size(); ++i) {
    EXPECT_EQ(copies[i].model.contacts[0].depth_m, first.model.contacts[0].depth_m);
    EXPECT_EQ(copies[i].tool_state_send_time_ns, first.tool_state_send_time_ns);
    EXPECT_EQ(copies[i].model.tool_state_seq, first.model.tool_state_seq);
    const std::int64_t previous_hold = i == 0 ? first.hold_ns : copies[i - 1].hold_ns;
    EXPECT_GE(copies[i].hold_ns - previous_hold, 50'000'000) << i;  // ≥ 50 ms apart at the node
    if (i > 0) {
      EXPECT_GE(arrivals[i] - arrivals[i - 1], std::chrono::milliseconds(20)) << i;
    }
  }
  const nlohmann::json summary = node.Stop();
  const nlohmann::json& t = summary["transport"];
  EXPECT_EQ(t["foreign_version_hellos"].get<int>(), 2);  // version 3 and the previous one
  EXPECT_EQ(t["hello_replayed"].get<int>(), 1);
  EXPECT_EQ(t["rejects_sent"].get<int>(), 2);
  EXPECT_EQ(t["peers_lost"].get<int>(), 0);
  // The node waited instead of stepping: a pass that holds still waits up to 10 ms on the socket
  // (pings wake it), so 450 ms hold some tens of passes, each counted, and only a few steps.
  EXPECT_GT(t["deadband"]["steps_skipped"].get<int>(), 10);
  EXPECT_LT(summary["steps"].get<int>(), t["deadband"]["steps_skipped"].get<int>());
  EXPECT_EQ(t["deadband"]["keepalives_sent"].get<std::size_t>(), copies.size());
}

}  // namespace
}  // namespace ht
