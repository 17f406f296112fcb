// libFuzzer target for the datagram decoder (transport/messages.h) and the scene reassembler.
// Each input is tried three ways:
//   1. as a received datagram, through OpenDatagram and the body decoder of its type, under a fixed
//      key (the MAC refuses almost everything: this covers the header and size checks);
//   2. sealed with that key first (the input is taken as header + body and the MAC appended), so
//      that every body decoder sees arbitrary bytes behind a valid MAC;
//   3. every decoded scene fragment / manifest / NACK is fed to a SceneReassembler / SceneSender,
//      whose memory must stay within its limits, and every decoded NodePoses to a SceneNodePoses;
//      every depth-field fragment / NACK to a DepthFieldReassembler / DepthFieldSender, and every
//      field it completes to the depth-field decoder (codecs/depth_field_codec.h);
//   4. as the bytes of a scene-graph object (transport/scene_graph.h): a graph it decodes to must
//      encode back to the same bytes and compose (every object the reassembler completes is tried
//      the same way).
// Build and run: tests/fuzz/run-fuzz (CI runs it for a bounded time).
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string>
#include <vector>

#include "codecs/depth_field_codec.h"
#include "transport/depth_field_stream.h"
#include "transport/messages.h"
#include "transport/scene_graph.h"
#include "transport/scene_stream.h"

namespace {

const ht::MacKey& Key() {
  static const ht::MacKey key = [] {
    ht::MacKey k;
    for (std::size_t i = 0; i < k.bytes.size(); ++i)
      k.bytes[i] = static_cast<std::uint8_t>(i * 7 + 1);
    return k;
  }();
  return key;
}

void Check(bool ok) {
  if (!ok) std::abort();
}

/// Decodes `bytes` as a scene-graph object; a graph it accepts must be one the encoder writes as
/// exactly these bytes, and its poses must compose.
void DecodeGraph(std::span<const std::uint8_t> bytes) {
  ht::SceneGraphDescription graph;
  std::string error;
  if (!ht::DecodeSceneGraph(bytes, &graph, &error)) {
    Check(!error.empty());
    return;
  }
  const std::vector<std::uint8_t> again = ht::EncodeSceneGraph(graph);
  Check(again.size() == bytes.size() && std::equal(again.begin(), again.end(), bytes.begin()));
  Check(ht::ComposeWorldPoses(graph).size() == graph.nodes.size());
}

void DecodeBody(const ht::wire::Header& h, std::span<const std::uint8_t> body) {
  using namespace ht::wire;
  static ht::SceneReassembler reassembler(kMinMtuBytes, [] {
    ht::ReassemblyLimits l;
    l.max_object_bytes = 1 << 20;
    l.max_total_bytes = 2 << 20;
    l.max_objects = 16;
    return l;
  }());
  static ht::SceneSender sender = [] {
    ht::SceneSender s(kMinMtuBytes);
    s.Update(1, std::vector<std::uint8_t>(5000, 1));
    return s;
  }();
  static ht::SceneNodePoses node_poses = [] {
    ht::SceneGraphDescription g;
    g.nodes.resize(40);
    return ht::SceneNodePoses(g, 1);
  }();
  static ht::DepthFieldReassembler field_reassembler(kMinMtuBytes, 4);
  static ht::DepthFieldSender field_sender = [] {
    ht::DepthFieldSender s(kMinMtuBytes, 2);
    s.Add(7, std::vector<std::uint8_t>(3000, 2));
    return s;
  }();
  static ht::DepthField field;
  static ht::DecodedDepthMap field_scratch;
  static std::int64_t now = 0;
  now += 1000000;
  switch (h.type) {
    case MessageType::kToolState: {
      ToolStateMessage m;
      if (DecodeToolState(body, m) == DecodeStatus::kOk) Check(ht::IsFiniteRigidTransform(m.X_WT));
      break;
    }
    case MessageType::kCompactToolState: {
      ToolStateMessage m;
      if (DecodeCompactToolState(body, m) == DecodeStatus::kOk) {
        Check(ht::IsFiniteRigidTransform(m.X_WT) && ht::IsFinite(m.V_WT_W));
      }
      break;
    }
    case MessageType::kContactModel: {
      ContactModelMessage m;
      if (DecodeContactModel(body, m) == DecodeStatus::kOk)
        Check(m.model.num_contacts <= kMaxWireContacts);
      break;
    }
    case MessageType::kCompactContactModel: {
      ContactModelMessage m;
      // The receiver's clock from the fuzzed header: near 0, or near the i64 limits (the echo's
      // unwrap must stay defined for any clock).
      const auto t = static_cast<std::int64_t>(h.send_time_ns);
      const std::int64_t receive_ns = (h.sequence % 3 == 0)   ? t
                                      : (h.sequence % 3 == 1) ? INT64_MAX - t
                                                              : INT64_MIN + t;
      if (DecodeCompactContactModel(body, m, receive_ns) == DecodeStatus::kOk)
        Check(m.model.num_contacts <= kMaxWireContacts &&
              ht::IsFiniteRigidTransform(m.model.X_WT0));
      break;
    }
    case MessageType::kGoodbye:
      (void)DecodeEmpty(body);
      break;
    case MessageType::kPing: {
      PingMessage m;
      (void)DecodePing(body, m);
      break;
    }
    case MessageType::kHello: {
      HelloMessage m;
      if (DecodeHello(body, m) == DecodeStatus::kOk) Check(m.mtu >= kMinMtuBytes);
      break;
    }
    case MessageType::kWelcome: {
      WelcomeMessage m;
      if (DecodeWelcome(body, m) == DecodeStatus::kOk) {
        Check(m.name().size() <= kSceneNameBytes);
        Check(m.layout.num_targets <= kMaxWelcomeTargets && m.layout.tool_mass_kg >= 0.0);
      }
      break;
    }
    case MessageType::kReject: {
      RejectMessage m;
      if (DecodeReject(body, m) == DecodeStatus::kOk) Check(m.message().size() <= kMaxRejectText);
      break;
    }
    case MessageType::kPong: {
      PongMessage m;
      (void)DecodePong(body, m);
      break;
    }
    case MessageType::kSceneFragment: {
      SceneFragmentMessage m;
      if (DecodeSceneFragment(body, m) == DecodeStatus::kOk) {
        if (reassembler.Add(m, now) == ht::SceneReassembler::Outcome::kCompleted)
          DecodeGraph(reassembler.CompletedBytes(m.object_id));
        Check(reassembler.bytes_held() <= (2u << 20));
      }
      break;
    }
    case MessageType::kSceneManifest: {
      SceneManifestMessage m;
      if (DecodeSceneManifest(body, m) == DecodeStatus::kOk) {
        reassembler.OnManifest(m, now);
        Check(reassembler.manifest_objects() <= 16);
        reassembler.CollectNacks(
            now, ht::SceneReassembler::RepairTiming{0, 0},
            [](const SceneNackMessage& n) { Check(n.count <= kMaxNackIndices); });
      }
      break;
    }
    case MessageType::kNodePoses: {
      NodePosesMessage m;
      if (DecodeNodePoses(body, m) == DecodeStatus::kOk) {
        Check(m.count <= kMaxNodePosesPerDatagram && std::isfinite(m.scene_time_s));
        for (int i = 0; i < m.count; ++i) {
          const glm::quat& q = m.poses[static_cast<std::size_t>(i)].rotation;
          Check(std::abs(glm::length(q) - 1.0f) < 1e-5f);
        }
        Check(node_poses.Apply(m) <= m.count);
      }
      break;
    }
    case MessageType::kDepthFieldFragment: {
      SceneFragmentMessage m;
      if (DecodeDepthFieldFragment(body, m) == DecodeStatus::kOk) {
        Check(m.object_id != 0 && m.object_bytes <= kMaxDepthFieldBytes);
        field_reassembler.Wanted(m.object_id + 1, now);
        if (field_reassembler.Add(m, now) == ht::DepthFieldReassembler::Outcome::kCompleted) {
          Check(field_reassembler.completed().size() == m.object_bytes);
          std::string error;
          if (ht::DecodeDepthField(field_reassembler.completed(), field, field_scratch, error)) {
            Check(field.prepared);
            field_reassembler.Held(field_reassembler.completed_id());
          } else {
            Check(!error.empty());
          }
        }
        field_reassembler.CollectNacks(now, {0, 0}, [](const SceneNackMessage& n) {
          Check(n.object_id != 0 && n.count <= kMaxNackIndices);
        });
      }
      break;
    }
    case MessageType::kDepthFieldNack: {
      SceneNackMessage m;
      if (DecodeDepthFieldNack(body, m) == DecodeStatus::kOk) {
        field_sender.OnNack(m);
        SceneFragmentMessage f;
        for (int i = 0; i < 20 && field_sender.Next(f); ++i) {
          Check(f.payload.size() <= f.object_bytes && f.object_id == 7);
        }
      }
      break;
    }
    case MessageType::kSceneNack: {
      SceneNackMessage m;
      if (DecodeSceneNack(body, m) == DecodeStatus::kOk) {
        sender.OnNack(m);
        SceneFragmentMessage f;
        for (int i = 0; i < 20 && sender.Next(f); ++i) Check(f.payload.size() <= f.object_bytes);
      }
      break;
    }
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace ht::wire;
  const std::span<const std::uint8_t> input(data, size);
  Header h;
  std::span<const std::uint8_t> body;
  if (OpenDatagram(input, Key(), h, body) == DecodeStatus::kOk) DecodeBody(h, body);
  ForeignHello foreign;
  (void)OpenForeignHello(input, Key(), foreign);
  (void)DatagramType(input);
  DecodeGraph(input);
  // Sealed: the same bytes behind a valid MAC.
  if (size >= kHeaderBytes && size + kMacBytes <= kMaxDatagramBytes) {
    Datagram d;
    std::copy(data, data + size, d.bytes.begin());
    d.size = size;
    ht::ComputeMac(d.view(), Key(),
                   std::span<std::uint8_t, kMacBytes>(d.bytes.data() + size, kMacBytes));
    d.size += kMacBytes;
    if (OpenDatagram(d.view(), Key(), h, body) == DecodeStatus::kOk) {
      Check(body.size() == size - kHeaderBytes);
      DecodeBody(h, body);
    }
  }
  return 0;
}
