// The remote node on a real UDP socket: it answers tool states with contact models and drops
// malformed datagrams, counting them.
#include "slave_sim/remote_node.h"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <thread>

#include "transport/messages.h"

namespace ht {
namespace {

TEST(RemoteNode, AnswersToolStatesAndCountsGarbage) {
  const HapticScene scene = MakeBlockOnGearScene();
  RemoteNodeConfig config;
  config.listen_address = SocketAddress::Parse("127.0.0.1:0");
  config.progress_period_s = 0.0;
  const std::string port_file = ::testing::TempDir() + "/remote_node_test.port";
  std::remove(port_file.c_str());
  config.port_file = port_file;
  std::atomic<bool> stop{false};
  nlohmann::json summary;
  std::thread node([&] { summary = RunRemoteNode(config, scene, stop); });

  std::uint16_t port = 0;
  for (int i = 0; i < 400 && port == 0; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
    if (FILE* f = std::fopen(port_file.c_str(), "r")) {
      unsigned p = 0;
      if (std::fscanf(f, "%u", &p) == 1) port = static_cast<std::uint16_t>(p);
      std::fclose(f);
    }
  }
  ASSERT_NE(port, 0);
  const SocketAddress remote = SocketAddress::Parse("127.0.0.1:" + std::to_string(port));
  UdpSocket socket(SocketAddress::Parse("127.0.0.1:0"));

  const std::uint8_t garbage[] = {1,  2,  3,  4,  5,  6,  7,  8,  9,  10, 11, 12, 13, 14, 15,
                                  16, 17, 18, 19, 20, 21, 22, 23, 24, 25, 26, 27, 28, 29, 30};
  for (int i = 0; i < 5; ++i) socket.SendTo(garbage, remote);
  wire::ToolStateMessage state;
  state.X_WT = scene.X_WT_home;
  state.X_WT.translation.z -= 0.5e-3;  // pressed onto the ridges
  const wire::Datagram d = wire::EncodeToolState({wire::MessageType::kToolState, 5, 1, 0}, state);
  ASSERT_TRUE(socket.SendTo(d.view(), remote));

  std::array<std::uint8_t, wire::kMaxDatagramBytes> buf{};
  wire::ContactModelMessage model;
  bool got = false;
  for (int i = 0; i < 500 && !got; ++i) {
    socket.WaitReadable(10);
    SocketAddress from;
    while (auto n = socket.ReceiveFrom(buf, from)) {
      wire::Header h;
      if (wire::DecodeContactModel({buf.data(), *n}, h, model) == wire::DecodeStatus::kOk) {
        EXPECT_EQ(h.session_id, 5u);
        got = true;
      }
    }
  }
  ASSERT_TRUE(got);
  EXPECT_EQ(model.model.tool_state_seq, 1u);
  ASSERT_EQ(model.model.num_contacts, 1);
  EXPECT_GT(model.model.contacts[0].depth_m, 0.0);
  EXPECT_GT(model.model.F_T_W_at_q0.force.z, 0.0);  // pushes the block up, away from the gear

  const wire::Datagram bye = wire::EncodeGoodbye({wire::MessageType::kGoodbye, 5, 2, 0});
  socket.SendTo(bye.view(), remote);
  for (int i = 0; i < 200 && !summary.is_object(); ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  stop = true;
  node.join();
  EXPECT_EQ(summary["datagrams"]["tool_state"]["dropped_malformed"].get<int>(), 5);
  EXPECT_EQ(summary["datagrams"]["tool_state"]["accepted"].get<int>(), 1);
  EXPECT_GE(summary["steps"].get<int>(), 1);
}

}  // namespace
}  // namespace ht
