// The wire format: every message round-trips, every malformed case is rejected with its reason,
// and no single bit flip of an authenticated datagram gets through.
#include "transport/messages.h"

#include <gtest/gtest.h>
#include <sodium.h>

#include <algorithm>
#include <cstring>
#include <limits>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include "haptic_core/byte_order.h"
#include "haptic_core/contact_model.h"
#include "legacy_datagram.h"

namespace ht::wire {
namespace {

MacKey TestKey(std::uint8_t seed = 7) {
  MacKey k;
  for (std::size_t i = 0; i < k.bytes.size(); ++i)
    k.bytes[i] = static_cast<std::uint8_t>(seed + 13 * i);
  return k;
}

ContactModelMessage SampleModel(int contacts) {
  ContactModelMessage m;
  m.model.X_WT0.translation = {0.01, -0.02, 0.035};
  m.model.X_WT0.rotation = QuaternionFromRotationVector({0.01, 0.02, -0.03});
  m.model.tool_state_seq = 42;
  m.model.num_contacts = contacts;
  for (int i = 0; i < contacts; ++i) {
    m.model.contacts[i].depth_m = 1e-4 * i;
    m.model.contacts[i].gradient = {{0.1 * i, -0.2, -1.0}, {0.001, 0.002 * i, -0.003}};
    m.model.contacts[i].stiffness_n_per_m = 8000;
    m.model.contacts[i].point_W = {0.001 * i, 0.0, 0.025};
    m.model.contacts[i].normal_W = {0, 0, 1};
  }
  m.model.F_T_W_at_q0 = {{0.1, 0.2, 1.5}, {0.001, -0.002, 0.0}};
  m.tool_state_send_time_ns = 123456789;
  m.hold_ns = 1500;
  m.remote_step_count = 77;
  m.step_us = 900.5f;
  return m;
}

/// `d` with `edit` applied to all its bytes before the MAC, header included (it may change
/// d.size), sealed again with `key` (Resealed below edits the body alone): a datagram whose MAC
/// verifies, so that what the edit made is what a receiver checks.
template <class Edit>
Datagram EditedAndSealed(Datagram d, const MacKey& key, Edit&& edit) {
  d.size -= kMacBytes;
  edit(d);
  ComputeMac(d.view(), key, std::span<std::uint8_t, kMacBytes>(d.bytes.data() + d.size, kMacBytes));
  d.size += kMacBytes;
  return d;
}

/// Opens with `key` and decodes the body as the header's type says; kOk only if both pass.
DecodeStatus OpenAndDecode(std::span<const std::uint8_t> bytes, const MacKey& key) {
  Header h;
  std::span<const std::uint8_t> body;
  if (const DecodeStatus s = OpenDatagram(bytes, key, h, body); s != DecodeStatus::kOk) return s;
  switch (h.type) {
    case MessageType::kToolState: {
      ToolStateMessage m;
      return DecodeToolState(body, m);
    }
    case MessageType::kContactModel: {
      ContactModelMessage m;
      return DecodeContactModel(body, m);
    }
    case MessageType::kCompactToolState: {
      ToolStateMessage m;
      return DecodeCompactToolState(body, m);
    }
    case MessageType::kCompactContactModel: {
      ContactModelMessage m;
      return DecodeCompactContactModel(body, m, /*receive_time_ns=*/0);
    }
    case MessageType::kGoodbye:
      return DecodeEmpty(body);
    case MessageType::kPing: {
      PingMessage m;
      return DecodePing(body, m);
    }
    case MessageType::kHello: {
      HelloMessage m;
      return DecodeHello(body, m);
    }
    case MessageType::kWelcome: {
      WelcomeMessage m;
      return DecodeWelcome(body, m);
    }
    case MessageType::kReject: {
      RejectMessage m;
      return DecodeReject(body, m);
    }
    case MessageType::kPong: {
      PongMessage m;
      return DecodePong(body, m);
    }
    case MessageType::kSceneFragment: {
      SceneFragmentMessage m;
      return DecodeSceneFragment(body, m);
    }
    case MessageType::kSceneManifest: {
      SceneManifestMessage m;
      return DecodeSceneManifest(body, m);
    }
    case MessageType::kSceneNack: {
      SceneNackMessage m;
      return DecodeSceneNack(body, m);
    }
    case MessageType::kNodePoses: {
      NodePosesMessage m;
      return DecodeNodePoses(body, m);
    }
    case MessageType::kDepthFieldFragment: {
      SceneFragmentMessage m;
      return DecodeDepthFieldFragment(body, m);
    }
    case MessageType::kDepthFieldNack: {
      SceneNackMessage m;
      return DecodeDepthFieldNack(body, m);
    }
  }
  return DecodeStatus::kUnknownType;
}

WelcomeMessage SampleWelcome() {
  WelcomeMessage w;
  w.client_nonce = 0x1122334455667788ull;
  w.grid = 50;
  w.window_m = 0.02f;
  w.codecs = kCodecDracoMesh;
  w.scene_objects = 2;
  const std::string name = "block_on_gear";
  std::copy(name.begin(), name.end(), w.scene_name.begin());
  w.scene_name_length = static_cast<std::uint8_t>(name.size());
  SceneLayout& l = w.layout;
  l.X_WT_home.translation = {0.01, -0.02, 0.0215};
  l.X_WT_home.rotation = QuaternionFromRotationVector({-std::numbers::pi / 2, 0.0, 0.0});
  l.tool_mass_kg = 0.25;
  l.tool_inertia_diagonal_T = {1e-5, 2e-5, 3e-5};
  l.tool_extent_down_m = 0.0075;
  l.num_targets = kMaxWelcomeTargets;  // a full Welcome must fit the smallest MTU
  for (int i = 0; i < kMaxWelcomeTargets; ++i) {
    WelcomeTarget& t = l.targets[static_cast<std::size_t>(i)];
    t.box_min_W = {-0.06 - i, -0.05, -0.02};
    t.box_max_W = {0.06, 0.05 + i, 0.01};
    t.top_W = {0.001 * i, 0.0, 0.01};
    t.approach_m = 0.0125 + i;
  }
  return w;
}

/// NodePoses of `count` entries with distinct, exactly representable values.
NodePosesMessage SamplePoses(int count) {
  NodePosesMessage m;
  m.graph_version = 3;
  m.scene_time_s = 12.345678901234;
  m.count = static_cast<std::uint8_t>(count);
  for (int i = 0; i < count; ++i) {
    NodePose& p = m.poses[static_cast<std::size_t>(i)];
    const float f = static_cast<float>(i);
    p.node = static_cast<std::uint16_t>(1000 + 7 * i);
    p.translation = {0.25f * f, -0.5f, 0.125f + f};
    const float c = std::cos(0.1f * f), s = std::sin(0.1f * f);
    p.rotation = glm::quat(c, 0.0f, 0.0f, s);  // about z by 0.2·i rad
    p.scale = {1.0f, 2.0f + f, 0.5f};
  }
  return m;
}

/// One valid datagram of every message type.
std::vector<Datagram> OneOfEach(const MacKey& key) {
  static const std::vector<std::uint8_t> object(3000, 0x5a);
  std::vector<Datagram> out;
  Header h{MessageType::kToolState, 0xabcdef01u, 99, -5};
  ToolStateMessage ts;
  ts.X_WT.rotation = QuaternionFromRotationVector({0.1, 0.2, 0.3});
  out.push_back(EncodeToolState(h, ts, key));
  out.push_back(EncodeContactModel(h, SampleModel(kMaxWireContacts), key));
  out.push_back(EncodeGoodbye(h, key));
  HelloMessage hello;
  hello.client_nonce = 5;
  out.push_back(EncodeHello({MessageType::kHello, 0, 1, 3}, hello, key));
  out.push_back(EncodeWelcome(h, SampleWelcome(), key));
  RejectMessage r;
  r.reason = RejectReason::kCapabilities;
  r.text_length = 5;
  std::copy_n("grid!", 5, r.text.begin());
  out.push_back(EncodeReject(h, r, key));
  out.push_back(EncodePing(h, {123456}, key));
  out.push_back(EncodePong(h, {9, 100, 200}, key));
  SceneFragmentMessage f{7, 2, 3000,
                         1, 3, std::span<const std::uint8_t>(object).subspan(1396, 1396)};
  out.push_back(EncodeSceneFragment(h, f, key));
  SceneManifestMessage m;
  m.total_objects = 2;
  m.count = 2;
  m.entries[0] = {1, 1, 100, 1, SceneObjectKind::kDracoMesh, {}};
  m.entries[1] = {2, 4, 5000, 4, SceneObjectKind::kDracoMesh, {1, 2, 3}};
  out.push_back(EncodeSceneManifest(h, m, key));
  SceneNackMessage n;
  n.object_id = 7;
  n.version = 2;
  n.count = 3;
  n.missing[0] = 0;
  n.missing[1] = 5;
  n.missing[2] = 9;
  out.push_back(EncodeSceneNack(h, n, key));
  out.push_back(EncodeCompactContactModel(h, SampleModel(kMaxWireContacts), key));
  out.push_back(EncodeNodePoses(h, SamplePoses(kMaxNodePosesPerDatagram), key));
  ToolStateMessage tool;
  tool.X_WT.translation = {0.1, -0.2, 0.3};
  tool.V_WT_W = {{0.01, 0.0, -0.02}, {0.5, 0.0, 0.0}};
  out.push_back(EncodeCompactToolState(h, tool, key));
  SceneFragmentMessage ff{9,    kDepthFieldVersion,
                          3000, 2,
                          3,    std::span<const std::uint8_t>(object).subspan(2 * 1396, 208)};
  out.push_back(EncodeDepthFieldFragment(h, ff, key));
  SceneNackMessage fn = n;
  fn.object_id = 9;
  fn.version = kDepthFieldVersion;
  out.push_back(EncodeDepthFieldNack(h, fn, key));
  return out;
}

TEST(Messages, EveryTypeRoundTripsThroughOpen) {
  const MacKey key = TestKey();
  const auto all = OneOfEach(key);
  ASSERT_EQ(all.size(), static_cast<std::size_t>(kMaxMessageType));
  for (const Datagram& d : all) {
    EXPECT_LE(d.size, kMaxDatagramBytes);
    EXPECT_EQ(OpenAndDecode(d.view(), key), DecodeStatus::kOk) << DatagramType(d.view());
  }
}

TEST(Messages, FieldsSurviveTheRoundTrip) {
  const MacKey key = TestKey();
  Header h;
  std::span<const std::uint8_t> body;
  ToolStateMessage m;
  m.X_WT.translation = {1, 2, 3};
  m.X_WT.rotation = QuaternionFromRotationVector({0.1, 0.2, 0.3});
  m.V_WT_W = {{0.4, 0.5, 0.6}, {-0.7, 0.8, -0.9}};
  const Datagram d =
      EncodeToolState({MessageType::kToolState, 0xabcdef01u, 99, 1234567891234}, m, key);
  ASSERT_EQ(d.size, kHeaderBytes + kToolStateBodyBytes + kMacBytes);
  ASSERT_EQ(OpenDatagram(d.view(), key, h, body), DecodeStatus::kOk);
  EXPECT_EQ(h.session_id, 0xabcdef01u);
  EXPECT_EQ(h.sequence, 99u);
  EXPECT_EQ(h.send_time_ns, 1234567891000);  // whole µs on the wire
  ToolStateMessage m2;
  ASSERT_EQ(DecodeToolState(body, m2), DecodeStatus::kOk);
  EXPECT_EQ(m2.X_WT.translation, m.X_WT.translation);
  EXPECT_EQ(m2.X_WT.rotation, m.X_WT.rotation);
  EXPECT_EQ(m2.V_WT_W.angular, m.V_WT_W.angular);

  for (int n : {0, 1, 7, kMaxWireContacts}) {
    const ContactModelMessage cm = SampleModel(n);
    const Datagram dc = EncodeContactModel({MessageType::kContactModel, 7, 3, 11}, cm, key);
    ASSERT_EQ(dc.size, kHeaderBytes + kContactModelFixedBytes + n * kContactBytes +
                           kDepthFieldIdCountBytes + kMacBytes);
    ASSERT_EQ(OpenDatagram(dc.view(), key, h, body), DecodeStatus::kOk);
    ContactModelMessage out;
    ASSERT_EQ(DecodeContactModel(body, out), DecodeStatus::kOk) << n;
    EXPECT_EQ(out.model.num_contacts, n);
    EXPECT_EQ(out.model.tool_state_seq, 42u);
    EXPECT_EQ(out.hold_ns, 1500);
    for (int i = 0; i < n; ++i) {
      EXPECT_EQ(out.model.contacts[i].depth_m, cm.model.contacts[i].depth_m);
      EXPECT_EQ(out.model.contacts[i].gradient.d_rotation_W,
                cm.model.contacts[i].gradient.d_rotation_W);
    }
  }

  const Datagram dw = EncodeWelcome({MessageType::kWelcome, 5, 1, 0}, SampleWelcome(), key);
  ASSERT_EQ(OpenDatagram(dw.view(), key, h, body), DecodeStatus::kOk);
  WelcomeMessage w;
  ASSERT_EQ(DecodeWelcome(body, w), DecodeStatus::kOk);
  EXPECT_EQ(w.name(), "block_on_gear");
  EXPECT_EQ(w.client_nonce, 0x1122334455667788ull);
  EXPECT_EQ(w.scene_objects, 2);
  // The layout: the pose in f64 exactly, the rest in f32.
  const SceneLayout& sent = SampleWelcome().layout;
  EXPECT_EQ(w.layout.X_WT_home.translation, sent.X_WT_home.translation);
  EXPECT_EQ(w.layout.X_WT_home.rotation, sent.X_WT_home.rotation);
  EXPECT_FLOAT_EQ(static_cast<float>(w.layout.tool_mass_kg), 0.25f);
  EXPECT_FLOAT_EQ(static_cast<float>(w.layout.tool_inertia_diagonal_T.z), 3e-5f);
  EXPECT_FLOAT_EQ(static_cast<float>(w.layout.tool_extent_down_m), 0.0075f);
  ASSERT_EQ(w.layout.num_targets, kMaxWelcomeTargets);
  for (int i = 0; i < kMaxWelcomeTargets; ++i) {
    const WelcomeTarget& a = w.layout.targets[static_cast<std::size_t>(i)];
    const WelcomeTarget& b = sent.targets[static_cast<std::size_t>(i)];
    EXPECT_FLOAT_EQ(static_cast<float>(a.box_min_W.x), static_cast<float>(b.box_min_W.x));
    EXPECT_FLOAT_EQ(static_cast<float>(a.box_max_W.y), static_cast<float>(b.box_max_W.y));
    EXPECT_FLOAT_EQ(static_cast<float>(a.top_W.x), static_cast<float>(b.top_W.x));
    EXPECT_FLOAT_EQ(static_cast<float>(a.approach_m), static_cast<float>(b.approach_m));
  }
  EXPECT_LE(dw.size, kMinMtuBytes);

  const auto all = OneOfEach(key);
  ASSERT_EQ(OpenDatagram(all[8].view(), key, h, body), DecodeStatus::kOk);
  SceneFragmentMessage f;
  ASSERT_EQ(DecodeSceneFragment(body, f), DecodeStatus::kOk);
  EXPECT_EQ(f.object_id, 7u);
  EXPECT_EQ(f.fragment_index, 1);
  EXPECT_EQ(f.payload.size(), 1396u);
  ASSERT_EQ(OpenDatagram(all[10].view(), key, h, body), DecodeStatus::kOk);
  SceneNackMessage n;
  ASSERT_EQ(DecodeSceneNack(body, n), DecodeStatus::kOk);
  EXPECT_EQ(n.count, 3);
  EXPECT_EQ(n.missing[2], 9);
}

TEST(Messages, EveryTruncationAndExtensionIsRejected) {
  const MacKey key = TestKey();
  for (const Datagram& d : OneOfEach(key)) {
    for (std::size_t len = 0; len < d.size; ++len) {
      EXPECT_NE(OpenAndDecode({d.bytes.data(), len}, key), DecodeStatus::kOk) << len;
    }
    std::array<std::uint8_t, kMaxDatagramBytes + 1> longer{};
    std::copy(d.bytes.begin(), d.bytes.begin() + d.size, longer.begin());
    EXPECT_NE(OpenAndDecode({longer.data(), d.size + 1}, key), DecodeStatus::kOk);
    EXPECT_EQ(OpenAndDecode({longer.data(), kMaxDatagramBytes + 1}, key), DecodeStatus::kTooLong);
  }
}

TEST(Messages, TruncatedBodiesThatStillCarryAValidMacAreRejected) {
  // The MAC is recomputed over the cut datagram: only the body decoders' length checks remain.
  const MacKey key = TestKey();
  for (const Datagram& d : OneOfEach(key)) {
    const std::size_t body = d.size - kHeaderBytes - kMacBytes;
    const int type = DatagramType(d.view());
    for (std::size_t cut = 1; cut <= body; ++cut) {
      // A fragment with a shorter payload is still a fragment (its reassembler checks the
      // payload against its field's cut).
      const bool fragment =
          type == int(MessageType::kSceneFragment) || type == int(MessageType::kDepthFieldFragment);
      if (fragment && cut < body) continue;
      Datagram t;
      std::copy(d.bytes.begin(), d.bytes.begin() + static_cast<long>(d.size - kMacBytes - cut),
                t.bytes.begin());
      t.size = d.size - kMacBytes - cut;
      ComputeMac(t.view(), key,
                 std::span<std::uint8_t, kMacBytes>(t.bytes.data() + t.size, kMacBytes));
      t.size += kMacBytes;
      const DecodeStatus s = OpenAndDecode(t.view(), key);
      EXPECT_NE(s, DecodeStatus::kOk) << "type " << type << " cut " << cut;
    }
  }
}

TEST(Messages, AnySingleBitFlipIsRejected) {
  const MacKey key = TestKey();
  std::size_t flips = 0;
  for (const Datagram& d : OneOfEach(key)) {
    for (std::size_t bit = 0; bit < d.size * 8; ++bit) {
      Datagram f = d;
      f.bytes[bit / 8] ^= static_cast<std::uint8_t>(1u << (bit % 8));
      ASSERT_NE(OpenAndDecode(f.view(), key), DecodeStatus::kOk)
          << "type " << DatagramType(d.view()) << " bit " << bit;
      ++flips;
    }
  }
  EXPECT_GT(flips, 30000u);  // every bit of one datagram of each of the 13 types
}

TEST(Messages, AnotherKeyIsRejectedAsBadMac) {
  const MacKey key = TestKey(1), other = TestKey(2);
  for (const Datagram& d : OneOfEach(key)) {
    EXPECT_EQ(OpenAndDecode(d.view(), other), DecodeStatus::kBadMac);
  }
}

TEST(Messages, HeaderFieldsAreCheckedBeforeTheMac) {
  const MacKey key = TestKey();
  const Datagram good =
      EncodeToolState({MessageType::kToolState, 1, 1, 0}, ToolStateMessage{}, key);
  auto mutate = [&](std::size_t offset, std::uint8_t value) {
    Datagram d = good;
    d.bytes[offset] = value;
    return OpenAndDecode(d.view(), key);
  };
  EXPECT_EQ(mutate(0, 0x00), DecodeStatus::kBadMagic);
  EXPECT_EQ(mutate(1, 0x00), DecodeStatus::kBadMagic);
  EXPECT_EQ(mutate(kHeaderVersionOffset, 0x07), DecodeStatus::kBadVersion);  // 7 no longer
  EXPECT_EQ(mutate(kHeaderVersionOffset, 0x08), DecodeStatus::kBadVersion);  // nor 8
  EXPECT_EQ(mutate(kHeaderVersionOffset, 0x09), DecodeStatus::kBadVersion);  // nor 9
  EXPECT_EQ(mutate(kHeaderVersionOffset, 0x0a), DecodeStatus::kBadVersion);  // nor 10
  EXPECT_EQ(mutate(kHeaderVersionOffset, 0x0b), DecodeStatus::kBadVersion);  // nor 11
  EXPECT_EQ(mutate(kHeaderVersionOffset, 0x0c), DecodeStatus::kBadVersion);  // nor 12
  EXPECT_EQ(mutate(kHeaderVersionOffset, 0x0d), DecodeStatus::kBadVersion);  // nor 13
  EXPECT_EQ(mutate(kHeaderVersionOffset, 0x0e), DecodeStatus::kBadVersion);  // nor 14
  EXPECT_EQ(mutate(kHeaderVersionOffset, 0x10), DecodeStatus::kBadVersion);
  EXPECT_EQ(mutate(kHeaderTypeOffset, 0x7f), DecodeStatus::kUnknownType);
  EXPECT_EQ(mutate(kHeaderTypeOffset, 0x00), DecodeStatus::kUnknownType);
  EXPECT_EQ(mutate(5, 0x01), DecodeStatus::kBadMac);   // session id changed
  EXPECT_EQ(mutate(9, 0x01), DecodeStatus::kBadMac);   // sequence changed
  EXPECT_EQ(mutate(13, 0x01), DecodeStatus::kBadMac);  // send time changed
  EXPECT_EQ(mutate(good.size - 1, good.bytes[good.size - 1] ^ 1), DecodeStatus::kBadMac);
}

/// Encodes with a valid MAC, so that the body checks are what rejects.
template <typename Encode>
DecodeStatus Sealed(Encode&& encode) {
  const MacKey key = TestKey();
  return OpenAndDecode(encode(key).view(), key);
}

TEST(Messages, NonFiniteAndImpossibleValuesAreRejectedEvenWithAValidMac) {
  ToolStateMessage m;
  m.X_WT.translation.x = NAN;
  EXPECT_EQ(Sealed([&](const MacKey& k) { return EncodeToolState({}, m, k); }),
            DecodeStatus::kNonFinite);
  m = {};
  m.X_WT.rotation = glm::dquat(3.0, 0, 0, 0);
  EXPECT_EQ(Sealed([&](const MacKey& k) { return EncodeToolState({}, m, k); }),
            DecodeStatus::kBadValue);
  ContactModelMessage cm = SampleModel(2);
  cm.model.contacts[1].gradient.d_translation_W.y = INFINITY;
  EXPECT_EQ(Sealed([&](const MacKey& k) { return EncodeContactModel({}, cm, k); }),
            DecodeStatus::kNonFinite);
  cm = SampleModel(2);
  cm.model.contacts[0].stiffness_n_per_m = -1;
  EXPECT_EQ(Sealed([&](const MacKey& k) { return EncodeContactModel({}, cm, k); }),
            DecodeStatus::kBadValue);
  EXPECT_EQ(Sealed([&](const MacKey& k) {
              Datagram d = EncodeContactModel({}, SampleModel(0), k);
              d.size -= kMacBytes;
              d.bytes[kHeaderBytes + kContactModelFixedBytes - 1] = kMaxWireContacts + 1;
              ComputeMac(d.view(), k,
                         std::span<std::uint8_t, kMacBytes>(d.bytes.data() + d.size, kMacBytes));
              d.size += kMacBytes;
              return d;
            }),
            DecodeStatus::kBadCount);
  HelloMessage hello;
  hello.mtu = 100;  // below the smallest MTU
  EXPECT_EQ(Sealed([&](const MacKey& k) { return EncodeHello({}, hello, k); }),
            DecodeStatus::kBadValue);
  hello = {};
  hello.min_version = 5;
  hello.max_version = 3;
  EXPECT_EQ(Sealed([&](const MacKey& k) { return EncodeHello({}, hello, k); }),
            DecodeStatus::kBadValue);
  hello = {};
  hello.tool_state_rate_hz = NAN;
  EXPECT_EQ(Sealed([&](const MacKey& k) { return EncodeHello({}, hello, k); }),
            DecodeStatus::kNonFinite);
  WelcomeMessage w = SampleWelcome();
  w.scene_name_length = 40;
  EXPECT_EQ(Sealed([&](const MacKey& k) {
              Datagram d = EncodeWelcome({}, SampleWelcome(), k);
              d.size -= kMacBytes;
              d.bytes[kHeaderBytes + 36 + kDeadbandTermsBytes] =
                  40;  // name length beyond its field
              ComputeMac(d.view(), k,
                         std::span<std::uint8_t, kMacBytes>(d.bytes.data() + d.size, kMacBytes));
              d.size += kMacBytes;
              return d;
            }),
            DecodeStatus::kBadValue);
  static const std::vector<std::uint8_t> bytes(10, 1);
  SceneFragmentMessage f{1, 1, 10, 3, 3, bytes};  // index >= count
  EXPECT_EQ(Sealed([&](const MacKey& k) { return EncodeSceneFragment({}, f, k); }),
            DecodeStatus::kBadValue);
  f = {1, 1, 5, 0, 1, bytes};  // payload longer than the object
  EXPECT_EQ(Sealed([&](const MacKey& k) { return EncodeSceneFragment({}, f, k); }),
            DecodeStatus::kBadValue);
  f = {1, 1, kMaxSceneObjectBytes + 1, 0, 60000, bytes};
  EXPECT_EQ(Sealed([&](const MacKey& k) { return EncodeSceneFragment({}, f, k); }),
            DecodeStatus::kBadValue);
  SceneManifestMessage man;
  man.total_objects = 1;
  man.first_index = 1;
  man.count = 1;
  man.entries[0] = {1, 1, 10, 1, SceneObjectKind::kDracoMesh, {}};
  EXPECT_EQ(Sealed([&](const MacKey& k) { return EncodeSceneManifest({}, man, k); }),
            DecodeStatus::kBadValue);
  EXPECT_EQ(Sealed([&](const MacKey& k) {
              return EncodePong({}, {0, 1, 2}, k);
            }),
            DecodeStatus::kBadValue);
}

TEST(Messages, ImpossibleSceneLayoutsAreRejected) {
  const auto status = [](const WelcomeMessage& w) {
    return Sealed([&](const MacKey& k) { return EncodeWelcome({}, w, k); });
  };
  ASSERT_EQ(status(SampleWelcome()), DecodeStatus::kOk);
  WelcomeMessage w = SampleWelcome();
  w.layout.X_WT_home.translation.y = NAN;
  EXPECT_EQ(status(w), DecodeStatus::kNonFinite);
  w = SampleWelcome();
  w.layout.X_WT_home.rotation = glm::dquat(2.0, 0.0, 0.0, 0.0);
  EXPECT_EQ(status(w), DecodeStatus::kBadValue);
  w = SampleWelcome();
  w.layout.tool_mass_kg = -1.0;
  EXPECT_EQ(status(w), DecodeStatus::kBadValue);
  w = SampleWelcome();
  w.layout.tool_inertia_diagonal_T.y = 0.0;  // a mass without an inertia
  EXPECT_EQ(status(w), DecodeStatus::kBadValue);
  w = SampleWelcome();
  w.layout.tool_extent_down_m = INFINITY;
  EXPECT_EQ(status(w), DecodeStatus::kNonFinite);
  w = SampleWelcome();
  w.layout.targets[3].box_min_W.z = 1.0;  // min above max
  EXPECT_EQ(status(w), DecodeStatus::kBadValue);
  w = SampleWelcome();
  w.layout.targets[7].top_W.x = NAN;
  EXPECT_EQ(status(w), DecodeStatus::kNonFinite);
  w = SampleWelcome();
  w.layout.targets[0].approach_m = -0.01;
  EXPECT_EQ(status(w), DecodeStatus::kBadValue);
  // A count beyond the limit, and a count that does not match the bytes.
  const MacKey key = TestKey();
  const auto reseal = [&](Datagram d, std::size_t offset, std::uint8_t value) {
    d.size -= kMacBytes;
    d.bytes[offset] = value;
    ComputeMac(d.view(), key,
               std::span<std::uint8_t, kMacBytes>(d.bytes.data() + d.size, kMacBytes));
    d.size += kMacBytes;
    return OpenAndDecode(d.view(), key);
  };
  const std::size_t count_at = kHeaderBytes + kWelcomeFixedBytes - 1;
  w = SampleWelcome();
  w.layout.num_targets = 2;
  const Datagram two = EncodeWelcome({}, w, key);
  EXPECT_EQ(OpenAndDecode(two.view(), key), DecodeStatus::kOk);
  EXPECT_EQ(reseal(two, count_at, 9), DecodeStatus::kBadCount);
  EXPECT_EQ(reseal(two, count_at, 3), DecodeStatus::kTooShort);
  EXPECT_EQ(reseal(two, count_at, 1), DecodeStatus::kTooLong);
  // A Welcome without targets is valid (a scene with nothing touchable).
  w.layout.num_targets = 0;
  EXPECT_EQ(status(w), DecodeStatus::kOk);
}

TEST(Messages, RandomBytesNeverOpenOrCrash) {
  const MacKey key = TestKey();
  std::mt19937 rng(1);
  std::array<std::uint8_t, kMaxDatagramBytes + 1> buf{};
  int accepted = 0;
  for (int i = 0; i < 20000; ++i) {
    const std::size_t len = rng() % buf.size();
    for (std::size_t k = 0; k < len; ++k) buf[k] = static_cast<std::uint8_t>(rng());
    if (len >= 4 && i % 2 == 0) {  // a valid-looking header, so that the MAC is what refuses it
      buf[0] = 'H';
      buf[1] = 'T';
      buf[kHeaderVersionOffset] = kProtocolVersion;
      buf[kHeaderTypeOffset] = static_cast<std::uint8_t>(1 + rng() % kMaxMessageType);
    }
    accepted += OpenAndDecode({buf.data(), len}, key) == DecodeStatus::kOk;
  }
  EXPECT_EQ(accepted, 0);
}

/// `d` with its body edited by `edit` (bytes after the header) and a new MAC.
template <typename Edit>
Datagram Resealed(Datagram d, const MacKey& key, Edit&& edit) {
  std::vector<std::uint8_t> body(d.bytes.begin() + kHeaderBytes,
                                 d.bytes.begin() + static_cast<long>(d.size - kMacBytes));
  edit(body);
  std::copy(body.begin(), body.end(), d.bytes.begin() + kHeaderBytes);
  d.size = kHeaderBytes + body.size();
  ComputeMac(d.view(), key, std::span<std::uint8_t, kMacBytes>(d.bytes.data() + d.size, kMacBytes));
  d.size += kMacBytes;
  return d;
}

TEST(NodePoses, AFullDatagramRoundTripsAndFitsTheSmallestMtu) {
  const MacKey key = TestKey();
  const NodePosesMessage sent = SamplePoses(kMaxNodePosesPerDatagram);
  const Datagram d = EncodeNodePoses({MessageType::kToolState, 9, 4, 77}, sent, key);
  EXPECT_EQ(d.size, kHeaderBytes + kNodePosesFixedBytes +
                        kMaxNodePosesPerDatagram * kNodePoseBytes + kMacBytes);
  EXPECT_EQ(kNodePoseBytes, 42u);  // u16 + 10 × f32
  EXPECT_LE(d.size, kMinMtuBytes);
  EXPECT_GT(d.size + kNodePoseBytes, kMinMtuBytes);  // one more would not fit
  Header h;
  std::span<const std::uint8_t> body;
  ASSERT_EQ(OpenDatagram(d.view(), key, h, body), DecodeStatus::kOk);
  EXPECT_EQ(h.type, MessageType::kNodePoses);  // the encoder sets the type
  EXPECT_EQ(h.session_id, 9u);
  NodePosesMessage got;
  ASSERT_EQ(DecodeNodePoses(body, got), DecodeStatus::kOk);
  EXPECT_EQ(got.graph_version, 3u);
  EXPECT_EQ(got.scene_time_s, sent.scene_time_s);  // f64
  ASSERT_EQ(got.count, kMaxNodePosesPerDatagram);
  for (int i = 0; i < kMaxNodePosesPerDatagram; ++i) {
    const NodePose &a = got.poses[static_cast<std::size_t>(i)],
                   &b = sent.poses[static_cast<std::size_t>(i)];
    EXPECT_EQ(a.node, b.node);
    EXPECT_EQ(a.translation, b.translation);
    EXPECT_EQ(a.scale, b.scale);
    // Unit within f32 rounding: the decoder normalizes what it receives.
    EXPECT_NEAR(a.rotation.w, b.rotation.w, 1e-6f) << i;
    EXPECT_NEAR(a.rotation.z, b.rotation.z, 1e-6f) << i;
    EXPECT_NEAR(glm::length(a.rotation), 1.0f, 1e-6f);
  }
  // The entry layout: u16 node, then translation, rotation w x y z, scale as f32.
  const std::size_t first = kHeaderBytes + kNodePosesFixedBytes;
  EXPECT_EQ(d.bytes[first] | d.bytes[first + 1] << 8, 1000);
  float w = 0.0f;
  std::memcpy(&w, &d.bytes[first + 2 + 12], 4);  // the test host is little-endian
  EXPECT_EQ(w, 1.0f);
  // Fewer entries, and none, are fine too; a non-unit rotation arrives normalized.
  NodePosesMessage few = SamplePoses(2);
  few.poses[1].rotation = glm::quat(0.0f, 0.0f, 3.0f, 4.0f);
  const Datagram few_datagram = EncodeNodePoses({}, few, key);  // the body points into it
  ASSERT_EQ(OpenDatagram(few_datagram.view(), key, h, body), DecodeStatus::kOk);
  ASSERT_EQ(DecodeNodePoses(body, got), DecodeStatus::kOk);
  EXPECT_EQ(got.count, 2);
  EXPECT_FLOAT_EQ(got.poses[1].rotation.y, 0.6f);
  EXPECT_FLOAT_EQ(got.poses[1].rotation.z, 0.8f);
  const Datagram none = EncodeNodePoses({}, SamplePoses(0), key);
  EXPECT_EQ(none.size, kHeaderBytes + kNodePosesFixedBytes + kMacBytes);
  EXPECT_EQ(OpenAndDecode(none.view(), key), DecodeStatus::kOk);
  EXPECT_STREQ(ToString(MessageType::kNodePoses), "node_poses");
  EXPECT_EQ(static_cast<int>(MessageType::kDepthFieldNack), kMaxMessageType);
}

TEST(NodePoses, BadCountsSizesValuesAndMacsAreRejected) {
  const MacKey key = TestKey();
  const Datagram good = EncodeNodePoses({}, SamplePoses(3), key);
  ASSERT_EQ(OpenAndDecode(good.view(), key), DecodeStatus::kOk);
  const std::size_t count_at = kNodePosesFixedBytes - 1;  // within the body
  // A count above the limit, with the bytes of that many entries.
  const Datagram over = Resealed(EncodeNodePoses({}, SamplePoses(kMaxNodePosesPerDatagram), key),
                                 key, [&](std::vector<std::uint8_t>& b) {
                                   b[count_at] = kMaxNodePosesPerDatagram + 1;
                                   b.resize(b.size() + kNodePoseBytes, 0);
                                 });
  EXPECT_EQ(OpenAndDecode(over.view(), key), DecodeStatus::kBadCount);
  // The encoder never sends more than the limit, whatever the count says.
  NodePosesMessage too_many = SamplePoses(kMaxNodePosesPerDatagram);
  too_many.count = 200;
  const Datagram clamped = EncodeNodePoses({}, too_many, key);
  EXPECT_LE(clamped.size, kMinMtuBytes);
  EXPECT_EQ(OpenAndDecode(clamped.view(), key), DecodeStatus::kOk);
  // Sizes other than exactly `count` entries.
  const auto resized = [&](long delta) {
    return OpenAndDecode(
        Resealed(good, key,
                 [&](std::vector<std::uint8_t>& b) {
                   b.resize(static_cast<std::size_t>(static_cast<long>(b.size()) + delta));
                 })
            .view(),
        key);
  };
  EXPECT_EQ(resized(-1), DecodeStatus::kTooShort);
  EXPECT_EQ(resized(-static_cast<long>(kNodePoseBytes)), DecodeStatus::kTooShort);
  EXPECT_EQ(resized(+1), DecodeStatus::kTooLong);
  EXPECT_EQ(resized(+static_cast<long>(kNodePoseBytes)), DecodeStatus::kTooLong);
  EXPECT_EQ(resized(-static_cast<long>(good.size - kHeaderBytes - kMacBytes) + 5),
            DecodeStatus::kTooShort);
  // Non-finite fields: NaN or ∞ in the time, a translation, a rotation, a scale.
  const auto status = [&](const NodePosesMessage& m) {
    return OpenAndDecode(EncodeNodePoses({}, m, key).view(), key);
  };
  const float nan = std::numeric_limits<float>::quiet_NaN();
  NodePosesMessage m = SamplePoses(3);
  m.scene_time_s = std::numeric_limits<double>::quiet_NaN();
  EXPECT_EQ(status(m), DecodeStatus::kNonFinite);
  m = SamplePoses(3);
  m.poses[2].translation.y = nan;
  EXPECT_EQ(status(m), DecodeStatus::kNonFinite);
  m = SamplePoses(3);
  m.poses[0].rotation.x = nan;
  EXPECT_EQ(status(m), DecodeStatus::kNonFinite);
  m = SamplePoses(3);
  m.poses[1].scale.z = std::numeric_limits<float>::infinity();
  EXPECT_EQ(status(m), DecodeStatus::kNonFinite);
  // A zero rotation (and one too short to normalize).
  m = SamplePoses(3);
  m.poses[1].rotation = glm::quat(0.0f, 0.0f, 0.0f, 0.0f);
  EXPECT_EQ(status(m), DecodeStatus::kBadValue);
  m.poses[1].rotation = glm::quat(1e-7f, 0.0f, 0.0f, 0.0f);
  EXPECT_EQ(status(m), DecodeStatus::kBadValue);
  m.poses[1].rotation = glm::quat(0.0f, 0.0f, -1e-5f, 0.0f);  // small but not zero: accepted
  EXPECT_EQ(status(m), DecodeStatus::kOk);
  // Entries past the count are not read: a NaN there is not seen.
  m = SamplePoses(3);
  m.poses[5].translation.x = nan;
  EXPECT_EQ(status(m), DecodeStatus::kOk);
  // The MAC: a flipped body byte, a flipped MAC byte, another key.
  Datagram bad = good;
  bad.bytes[kHeaderBytes + 20] ^= 0x10;
  EXPECT_EQ(OpenAndDecode(bad.view(), key), DecodeStatus::kBadMac);
  bad = good;
  bad.bytes[good.size - 3] ^= 0x01;
  EXPECT_EQ(OpenAndDecode(bad.view(), key), DecodeStatus::kBadMac);
  EXPECT_EQ(OpenAndDecode(good.view(), TestKey(99)), DecodeStatus::kBadMac);
  // A decoder failure leaves the message as it was.
  NodePosesMessage kept;
  kept.graph_version = 42;
  Header h;
  std::span<const std::uint8_t> body;
  m = SamplePoses(3);
  m.poses[1].rotation = glm::quat(0.0f, 0.0f, 0.0f, 0.0f);
  const Datagram zero = EncodeNodePoses({}, m, key);
  ASSERT_EQ(OpenDatagram(zero.view(), key, h, body), DecodeStatus::kOk);
  EXPECT_EQ(DecodeNodePoses(body, kept), DecodeStatus::kBadValue);
  EXPECT_EQ(kept.graph_version, 42u);
}

TEST(Messages, TheManifestCarriesEverySceneObjectKindAndNoOther) {
  const MacKey key = TestKey();
  SceneManifestMessage m;
  m.total_objects = 3;
  m.count = 3;
  m.entries[0] = {1, 1, 100, 1, SceneObjectKind::kDracoMesh, {}};
  m.entries[1] = {2, 1, 100, 1, SceneObjectKind::kSceneGraph, {}};
  m.entries[2] = {3, 1, 100, 1, SceneObjectKind::kImage, {}};
  Header h;
  std::span<const std::uint8_t> body;
  const Datagram d = EncodeSceneManifest({}, m, key);  // the body points into it
  ASSERT_EQ(OpenDatagram(d.view(), key, h, body), DecodeStatus::kOk);
  SceneManifestMessage got;
  ASSERT_EQ(DecodeSceneManifest(body, got), DecodeStatus::kOk);
  EXPECT_EQ(got.entries[1].kind, SceneObjectKind::kSceneGraph);
  EXPECT_EQ(got.entries[2].kind, SceneObjectKind::kImage);
  for (const int kind : {0, kMaxSceneObjectKind + 1, 255}) {
    m.entries[2].kind = static_cast<SceneObjectKind>(kind);
    EXPECT_EQ(OpenAndDecode(EncodeSceneManifest({}, m, key).view(), key), DecodeStatus::kBadValue)
        << kind;
  }
}

TEST(Messages, AnOlderOperatorsHelloIsOpenedForARejectInItsOwnVersion) {
  // Versions 4 to 15 changed neither the Hello body nor the Reject body; version 3's Hello body is
  // the first 32 bytes (no deadband terms). Versions 2 to 7 had the 28-byte header and the whole
  // 32-byte MAC (test::LegacyDatagram writes them byte by byte).
  EXPECT_EQ(kProtocolVersion, 15);
  EXPECT_EQ(kMinProtocolVersion, 15);
  const MacKey key = TestKey();
  for (const std::uint16_t version : {std::uint16_t{7}, std::uint16_t{6}, std::uint16_t{5},
                                      std::uint16_t{4}, std::uint16_t{3}, std::uint16_t{2}}) {
    HelloMessage hello;
    hello.client_nonce = 0xfeedu + version;
    hello.min_version = hello.max_version = version;
    const Datagram own = EncodeHello({MessageType::kHello, 0, 1, 0}, hello, key);
    std::span<const std::uint8_t> hello_body = test::BodyOf(own);
    if (version < 4) hello_body = hello_body.first(32);
    const Datagram d = test::LegacyDatagram(version, MessageType::kHello, 1, hello_body, key);
    Header h;
    std::span<const std::uint8_t> body;
    EXPECT_EQ(OpenDatagram(d.view(), key, h, body), DecodeStatus::kBadVersion) << version;
    ForeignHello foreign;
    ASSERT_EQ(OpenForeignHello(d.view(), key, foreign), DecodeStatus::kOk) << version;
    EXPECT_EQ(foreign.header_version, version);
    EXPECT_EQ(foreign.min_version, version);
    EXPECT_EQ(foreign.max_version, version);
    EXPECT_EQ(foreign.client_nonce, 0xfeedu + version);
    EXPECT_EQ(OpenForeignHello(d.view(), TestKey(3), foreign), DecodeStatus::kBadMac);
    // Cut before its nonce, or with its MAC truncated as this version's: refused.
    EXPECT_EQ(
        OpenForeignHello(d.view().first(kLegacyHeaderBytes + 11 + kLegacyMacBytes), key, foreign),
        DecodeStatus::kTooShort);
    EXPECT_EQ(
        OpenForeignHello(d.view().first(d.size - (kLegacyMacBytes - kMacBytes)), key, foreign),
        DecodeStatus::kBadMac);
    // The Reject in that version: the old header with the version in it, the body every version
    // since 2 shares, the whole MAC.
    RejectMessage reject;
    reject.client_nonce = foreign.client_nonce;
    reject.reason = RejectReason::kVersion;
    reject.text_length = 4;
    std::copy_n("v5!!", 4, reject.text.begin());
    const Datagram r = EncodeReject({MessageType::kReject, 0, 1, 0}, reject, key, version);
    const test::LegacyHeader rh = test::ReadLegacyHeader(r.view());
    EXPECT_EQ(rh.magic, kLegacyMagic);
    EXPECT_EQ(rh.version, version);
    EXPECT_EQ(rh.type, static_cast<std::uint8_t>(MessageType::kReject));
    EXPECT_EQ(rh.flags, 0);
    EXPECT_EQ(r.size, kLegacyHeaderBytes + kRejectFixedBytes + 4 + kLegacyMacBytes);
    EXPECT_TRUE(test::LegacyMacVerifies(r.view(), key));
    EXPECT_FALSE(VerifyMac(r.view(), key));  // not this version's MAC
    RejectMessage back;
    ASSERT_EQ(DecodeReject(r.view().subspan(kLegacyHeaderBytes,
                                            r.size - kLegacyHeaderBytes - kLegacyMacBytes),
                           back),
              DecodeStatus::kOk);
    EXPECT_EQ(back.client_nonce, 0xfeedu + version);
    EXPECT_EQ(back.message(), "v5!!");
  }
  // Neither this version's own Hello, nor a newer one, nor an old-layout one older than 2 is
  // foreign; a Reject asked in this version is this version's.
  ForeignHello foreign;
  const Datagram own = EncodeHello({MessageType::kHello, 0, 1, 0}, HelloMessage{}, key);
  EXPECT_EQ(OpenForeignHello(own.view(), key, foreign), DecodeStatus::kBadVersion);
  const Datagram newer = EditedAndSealed(
      own, key, [](Datagram& d) { d.bytes[kHeaderVersionOffset] = kProtocolVersion + 1; });
  EXPECT_EQ(OpenForeignHello(newer.view(), key, foreign), DecodeStatus::kBadVersion);
  for (const std::uint16_t version : {std::uint16_t{1}, std::uint16_t{8}, std::uint16_t{9},
                                      std::uint16_t{10}, std::uint16_t{11}, std::uint16_t{12}}) {
    const Datagram d =
        test::LegacyDatagram(version, MessageType::kHello, 1, test::BodyOf(own), key);
    EXPECT_EQ(OpenForeignHello(d.view(), key, foreign), DecodeStatus::kBadVersion) << version;
  }
  // Versions 8 (this header and MAC, no translation patches), 9 (an empty Ping) and 10 (the
  // 103-byte compact model): its Hello is this version's with that version byte and its own MAC;
  // it gets a Reject in this layout with that version.
  for (const std::uint8_t old : {std::uint8_t{8}, std::uint8_t{9}, std::uint8_t{10}}) {
    HelloMessage hello;
    hello.client_nonce = 0xbeef00u + old;
    hello.min_version = hello.max_version = old;
    const Datagram v8 =
        EditedAndSealed(EncodeHello({MessageType::kHello, 0, 1, 0}, hello, key), key,
                        [old](Datagram& d) { d.bytes[kHeaderVersionOffset] = old; });
    Header h8;
    std::span<const std::uint8_t> body8;
    EXPECT_EQ(OpenDatagram(v8.view(), key, h8, body8), DecodeStatus::kBadVersion);
    ASSERT_EQ(OpenForeignHello(v8.view(), key, foreign), DecodeStatus::kOk);
    EXPECT_EQ(foreign.header_version, old);
    EXPECT_EQ(foreign.max_version, old);
    EXPECT_EQ(foreign.client_nonce, 0xbeef00u + old);
    EXPECT_EQ(OpenForeignHello(v8.view(), TestKey(3), foreign), DecodeStatus::kBadMac);
    EXPECT_EQ(OpenForeignHello(v8.view().first(kHeaderBytes + 11 + kMacBytes), key, foreign),
              DecodeStatus::kTooShort);
    RejectMessage reject;
    reject.client_nonce = 0xbeef00u + old;
    reject.reason = RejectReason::kVersion;
    const Datagram r8 = EncodeReject({MessageType::kReject, 0, 1, 0}, reject, key, old);
    EXPECT_EQ(LoadLe<std::uint16_t>(r8.bytes.data()), kMagic);
    EXPECT_EQ(r8.bytes[kHeaderVersionOffset], old);
    EXPECT_EQ(r8.bytes[kHeaderTypeOffset], static_cast<std::uint8_t>(MessageType::kReject));
    EXPECT_TRUE(VerifyMac(r8.view(), key));
    RejectMessage back;
    ASSERT_EQ(
        DecodeReject(r8.view().subspan(kHeaderBytes, r8.size - kHeaderBytes - kMacBytes), back),
        DecodeStatus::kOk);
    EXPECT_EQ(back.client_nonce, 0xbeef00u + old);
  }
  const Datagram r =
      EncodeReject({MessageType::kReject, 0, 1, 0}, RejectMessage{}, key, kProtocolVersion);
  Header h;
  std::span<const std::uint8_t> body;
  EXPECT_EQ(OpenDatagram(r.view(), key, h, body), DecodeStatus::kOk);
}

// RFC 4231 test case 2 (HMAC-SHA-256, key "Jefe", data "what do ya want for nothing?"): a key
// shorter than the hash's block is padded with zeros, so the 32-byte key "Jefe" + 28 zeros gives
// the published value, of which the wire MAC is the first 16 bytes (RFC 4868's HMAC-SHA-256-128).
TEST(Messages, TheMacIsHmacSha256TruncatedTo128Bits) {
  MacKey key;
  std::copy_n("Jefe", 4, key.bytes.begin());
  const std::string data = "what do ya want for nothing?";
  std::array<std::uint8_t, kMacBytes> mac{};
  ComputeMac({reinterpret_cast<const std::uint8_t*>(data.data()), data.size()}, key, mac);
  const std::array<std::uint8_t, 16> expected = {0x5b, 0xdc, 0xc1, 0x46, 0xbf, 0x60, 0x75, 0x4e,
                                                 0x6a, 0x04, 0x24, 0x26, 0x08, 0x95, 0x75, 0xc7};
  EXPECT_EQ(mac, expected);
  std::vector<std::uint8_t> datagram(data.begin(), data.end());
  datagram.insert(datagram.end(), mac.begin(), mac.end());
  EXPECT_TRUE(VerifyMac(datagram, key));
  datagram[3] ^= 1;
  EXPECT_FALSE(VerifyMac(datagram, key));
  EXPECT_FALSE(VerifyMac(std::span(datagram).first(kMacBytes - 1), key));
  // RFC 4231 test case 5, the truncation case: key 0x0c × 20, "Test With Truncation", HMAC-SHA-256
  // truncated to 128 bits.
  MacKey key5;
  std::fill_n(key5.bytes.begin(), 20, std::uint8_t{0x0c});
  const std::string data5 = "Test With Truncation";
  ComputeMac({reinterpret_cast<const std::uint8_t*>(data5.data()), data5.size()}, key5, mac);
  const std::array<std::uint8_t, 16> expected5 = {0xa3, 0xb6, 0x16, 0x74, 0x73, 0x10, 0x0e, 0xe0,
                                                  0x6e, 0x0c, 0x79, 0x6c, 0x29, 0x55, 0x55, 0x2b};
  EXPECT_EQ(mac, expected5);
}

// Protocol version 10: a Ping carries the operator's round trip as a u32 of µs (the remote node
// sizes its depth fields' margin and speculative floor from it); its body is exactly that.
TEST(Messages, APingCarriesTheOperatorsRoundTrip) {
  const MacKey key = TestKey();
  for (const std::uint32_t rtt_us : {0u, 1u, 10'000u, 0xFFFF'FFFFu}) {
    const Datagram d = EncodePing({MessageType::kPing, 3, 4, 5000}, {rtt_us}, key);
    ASSERT_EQ(d.size, kHeaderBytes + kPingBodyBytes + kMacBytes);
    EXPECT_EQ(LoadLe<std::uint32_t>(d.bytes.data() + kHeaderBytes), rtt_us);
    Header h;
    std::span<const std::uint8_t> body;
    ASSERT_EQ(OpenDatagram(d.view(), key, h, body), DecodeStatus::kOk);
    PingMessage back;
    ASSERT_EQ(DecodePing(body, back), DecodeStatus::kOk);
    EXPECT_EQ(back.operator_rtt_us, rtt_us);
    EXPECT_EQ(DecodePing(body.first(3), back), DecodeStatus::kTooShort);
    // An empty body (version 9's Ping, were it opened as this version's) is refused, not read as
    // a zero round trip.
    EXPECT_EQ(DecodePing(body.first(0), back), DecodeStatus::kTooShort);
    std::array<std::uint8_t, kPingBodyBytes + 1> longer{};
    EXPECT_EQ(DecodePing(longer, back), DecodeStatus::kTooLong);
  }
}

// Version 8's header: the sequence as u32 and the send time as whole µs in 48 bits, each written
// at its offset (protocol.h); the MAC is HMAC-SHA-256-128.
TEST(Messages, TheHeaderCarriesSequenceAndTimeInItsOwnWidths) {
  const MacKey key = TestKey();
  const std::int64_t big_ns = 0x0000'ABCD'1234'5678LL * 1000 + 999;  // 48 bits of µs, 999 ns more
  const Datagram d = EncodePing({MessageType::kPing, 0x01020304u, 0xA1B2C3D4u, big_ns}, {}, key);
  ASSERT_EQ(d.size, kHeaderBytes + kPingBodyBytes + kMacBytes);
  EXPECT_EQ(LoadLe<std::uint16_t>(d.bytes.data()), kMagic);
  EXPECT_EQ(d.bytes[kHeaderVersionOffset], kProtocolVersion);
  EXPECT_EQ(d.bytes[kHeaderTypeOffset], static_cast<std::uint8_t>(MessageType::kPing));
  EXPECT_EQ(LoadLe<std::uint32_t>(d.bytes.data() + 4), 0x01020304u);
  EXPECT_EQ(LoadLe<std::uint32_t>(d.bytes.data() + 8), 0xA1B2C3D4u);
  EXPECT_EQ(LoadLe<std::uint32_t>(d.bytes.data() + 12), 0x12345678u);
  EXPECT_EQ(LoadLe<std::uint16_t>(d.bytes.data() + 16), 0xABCDu);
  Header h;
  std::span<const std::uint8_t> body;
  ASSERT_EQ(OpenDatagram(d.view(), key, h, body), DecodeStatus::kOk);
  EXPECT_EQ(h.send_time_ns, big_ns - 999);
  EXPECT_EQ(h.sequence, 0xA1B2C3D4u);
  // Past the widths: the sequence saturates at the stream's last number, the time clamps.
  const Datagram past = EncodePing(
      {MessageType::kPing, 1, std::uint64_t{1} << 40, kMaxSendTimeUs * 1000 + 5000}, {}, key);
  ASSERT_EQ(OpenDatagram(past.view(), key, h, body), DecodeStatus::kOk);
  EXPECT_EQ(h.sequence, 0xFFFFFFFFu);
  EXPECT_EQ(h.send_time_ns, kMaxSendTimeUs * 1000);
  const Datagram before = EncodePing({MessageType::kPing, 1, 1, -5}, {}, key);
  ASSERT_EQ(OpenDatagram(before.view(), key, h, body), DecodeStatus::kOk);
  EXPECT_EQ(h.send_time_ns, 0);
  // The MAC is the first 16 bytes of HMAC-SHA-256 over header and body, built here from SHA-256
  // by RFC 2104's formula H((K ⊕ opad) ‖ H((K ⊕ ipad) ‖ m)), not by libsodium's HMAC.
  std::array<std::uint8_t, 64> inner_key{}, outer_key{};
  for (std::size_t i = 0; i < 64; ++i) {
    const std::uint8_t k = i < key.bytes.size() ? key.bytes[i] : 0;
    inner_key[i] = k ^ 0x36;
    outer_key[i] = k ^ 0x5c;
  }
  std::vector<std::uint8_t> inner(inner_key.begin(), inner_key.end());
  inner.insert(inner.end(), d.bytes.begin(), d.bytes.begin() + kHeaderBytes + kPingBodyBytes);
  std::array<std::uint8_t, crypto_hash_sha256_BYTES> inner_hash{}, hmac{};
  crypto_hash_sha256(inner_hash.data(), inner.data(), inner.size());
  std::vector<std::uint8_t> outer(outer_key.begin(), outer_key.end());
  outer.insert(outer.end(), inner_hash.begin(), inner_hash.end());
  crypto_hash_sha256(hmac.data(), outer.data(), outer.size());
  const std::size_t mac_at = kHeaderBytes + kPingBodyBytes;
  EXPECT_TRUE(std::equal(hmac.begin(), hmac.begin() + kMacBytes, d.bytes.begin() + mac_at));
  // Every one of the 16 MAC bytes counts.
  for (std::size_t i = 0; i < kMacBytes; ++i) {
    Datagram f = d;
    f.bytes[mac_at + i] ^= 0x80;
    EXPECT_EQ(OpenDatagram(f.view(), key, h, body), DecodeStatus::kBadMac) << i;
  }
}

// Each contact's depth-field id comes back with it, both encodings; the section ends the body. A
// float model of more contacts with fields than fit its datagram sends the first ids that fit
// (DepthFieldIdCapacity), and the datagram stays within kMaxDatagramBytes.
TEST(Messages, DepthFieldIdsTravelWithTheirContactsAndBadSectionsAreRejected) {
  const MacKey key = TestKey();
  for (const bool compact : {false, true}) {
    for (const int n : {1, 3, 7, kMaxWireContacts}) {
      ContactModelMessage m = SampleModel(n);
      int with_field = 0;
      for (int i = 0; i < n; ++i) {  // every other contact has a field
        m.model.contacts[i].depth_field_id = i % 2 == 0 ? 1000u + 17u * i : 0u;
        with_field += i % 2 == 0 ? 1 : 0;
      }
      const Datagram d =
          compact ? EncodeCompactContactModel({}, m, key) : EncodeContactModel({}, m, key);
      ASSERT_LE(d.size, kMaxDatagramBytes);
      const std::size_t fixed = compact ? kCompactContactModelFixedBytes : kContactModelFixedBytes;
      const std::size_t contact = compact ? kCompactContactBytes : kContactBytes;
      EXPECT_EQ(d.size, kHeaderBytes + fixed + n * contact + DepthFieldIdSectionBytes(with_field) +
                            kMacBytes);
      const auto decode = [&](const Datagram& datagram, ContactModelMessage& out) {
        Header h;
        std::span<const std::uint8_t> body;
        const DecodeStatus open = OpenDatagram(datagram.view(), key, h, body);
        if (open != DecodeStatus::kOk) return open;
        return compact ? DecodeCompactContactModel(body, out, /*receive_time_ns=*/0)
                       : DecodeContactModel(body, out);
      };
      ContactModelMessage out;
      // A message reused from an earlier model: its contacts' ids are overwritten, not kept.
      for (auto& c : out.model.contacts) c.depth_field_id = 55;
      ASSERT_EQ(decode(d, out), DecodeStatus::kOk) << compact << " " << n;
      for (int i = 0; i < n; ++i) {
        EXPECT_EQ(out.model.contacts[i].depth_field_id, m.model.contacts[i].depth_field_id)
            << compact << " " << i;
      }
      // The section's entries, edited behind a valid MAC: a contact out of range, a contact
      // named twice, an id 0.
      const std::size_t at = fixed + n * contact;  // the count, in the body
      const auto edited = [&](auto&& edit) {
        return Resealed(d, key, [&](std::vector<std::uint8_t>& b) {
          ASSERT_EQ(b[at], with_field);
          edit(b);
        });
      };
      ContactModelMessage bad;
      EXPECT_EQ(decode(edited([&](std::vector<std::uint8_t>& b) { b[at + 1] = 0xE0; }), bad),
                DecodeStatus::kBadValue);
      EXPECT_EQ(decode(edited([&](std::vector<std::uint8_t>& b) {
                         std::fill_n(b.begin() + static_cast<long>(at + 2), 4, 0);
                       }),
                       bad),
                DecodeStatus::kBadValue);
      if (with_field >= 2) {
        EXPECT_EQ(decode(edited([&](std::vector<std::uint8_t>& b) {
                           b[at + 1 + kDepthFieldIdBytes] = b[at + 1];
                         }),
                         bad),
                  DecodeStatus::kBadValue);
      }
      // A count above the contacts.
      EXPECT_NE(decode(edited([&](std::vector<std::uint8_t>& b) { b[at] = n + 1; }), bad),
                DecodeStatus::kOk);
    }
  }
  // Every contact with a field: the compact model carries all 14 ids; the float model the 11
  // that fit, those of its first contacts, and the others come without a field.
  const int float_fit =
      DepthFieldIdCapacity(kContactModelFixedBytes, kContactBytes, kMaxWireContacts);
  EXPECT_EQ(float_fit,
            static_cast<int>((kMaxDatagramBytes - kHeaderBytes - kContactModelFixedBytes -
                              kMaxWireContacts * kContactBytes - 1 - kMacBytes) /
                             kDepthFieldIdBytes));
  EXPECT_EQ(float_fit, 11);
  for (const bool compact : {false, true}) {
    ContactModelMessage m = SampleModel(kMaxWireContacts);
    for (int i = 0; i < kMaxWireContacts; ++i) m.model.contacts[i].depth_field_id = 500u + i;
    const Datagram d =
        compact ? EncodeCompactContactModel({}, m, key) : EncodeContactModel({}, m, key);
    ASSERT_LE(d.size, kMaxDatagramBytes);
    Header h;
    std::span<const std::uint8_t> body;
    ASSERT_EQ(OpenDatagram(d.view(), key, h, body), DecodeStatus::kOk);
    ContactModelMessage out;
    ASSERT_EQ(compact ? DecodeCompactContactModel(body, out, 0) : DecodeContactModel(body, out),
              DecodeStatus::kOk);
    const int sent = compact ? kMaxWireContacts : float_fit;
    for (int i = 0; i < kMaxWireContacts; ++i) {
      EXPECT_EQ(out.model.contacts[i].depth_field_id, i < sent ? 500u + i : 0u) << compact << i;
    }
    // A count above what fits is refused before any entry is read.
    if (!compact) {
      const Datagram over = Resealed(d, key, [&](std::vector<std::uint8_t>& b) {
        b[kContactModelFixedBytes + kMaxWireContacts * kContactBytes] = float_fit + 1;
      });
      ContactModelMessage bad;
      ASSERT_EQ(OpenDatagram(over.view(), key, h, body), DecodeStatus::kOk);
      EXPECT_EQ(DecodeContactModel(body, bad), DecodeStatus::kBadCount);
    }
  }
}

TEST(Messages, DepthFieldFragmentsAndNacksRefuseWhatNoFieldCanBe) {
  const MacKey key = TestKey();
  static const std::vector<std::uint8_t> bytes(3000, 0x33);
  const SceneFragmentMessage good{
      4, kDepthFieldVersion, 3000, 0, 3, std::span<const std::uint8_t>(bytes).first(1396)};
  const auto open = [&](const Datagram& d, SceneFragmentMessage& out) {
    Header h;
    std::span<const std::uint8_t> body;
    const DecodeStatus s = OpenDatagram(d.view(), key, h, body);
    if (s != DecodeStatus::kOk) return s;
    EXPECT_EQ(h.type, MessageType::kDepthFieldFragment);
    return DecodeDepthFieldFragment(body, out);
  };
  SceneFragmentMessage out;
  ASSERT_EQ(open(EncodeDepthFieldFragment({}, good, key), out), DecodeStatus::kOk);
  EXPECT_EQ(out.object_id, 4u);
  EXPECT_EQ(out.payload.size(), 1396u);
  SceneFragmentMessage f = good;
  f.object_id = 0;
  EXPECT_EQ(open(EncodeDepthFieldFragment({}, f, key), out), DecodeStatus::kBadValue);
  f = good;
  f.version = 2;
  EXPECT_EQ(open(EncodeDepthFieldFragment({}, f, key), out), DecodeStatus::kBadValue);
  f = good;
  f.object_bytes = kMaxDepthFieldBytes + 1;
  EXPECT_EQ(open(EncodeDepthFieldFragment({}, f, key), out), DecodeStatus::kBadValue);
  f = good;
  f.fragment_index = 3;  // ≥ count: as a scene fragment
  EXPECT_EQ(open(EncodeDepthFieldFragment({}, f, key), out), DecodeStatus::kBadValue);
  SceneNackMessage nack;
  nack.object_id = 4;
  nack.version = kDepthFieldVersion;
  nack.count = 1;
  nack.missing[0] = 2;
  const auto open_nack = [&](const SceneNackMessage& n) {
    Header h;
    std::span<const std::uint8_t> body;
    SceneNackMessage got;
    const Datagram d = EncodeDepthFieldNack({}, n, key);
    EXPECT_EQ(OpenDatagram(d.view(), key, h, body), DecodeStatus::kOk);
    EXPECT_EQ(h.type, MessageType::kDepthFieldNack);
    return DecodeDepthFieldNack(body, got);
  };
  EXPECT_EQ(open_nack(nack), DecodeStatus::kOk);
  nack.object_id = 0;
  EXPECT_EQ(open_nack(nack), DecodeStatus::kBadValue);
  nack.object_id = 4;
  nack.version = 7;
  EXPECT_EQ(open_nack(nack), DecodeStatus::kBadValue);
  EXPECT_STREQ(ToString(MessageType::kDepthFieldFragment), "depth_field_fragment");
  EXPECT_STREQ(ToString(MessageType::kDepthFieldNack), "depth_field_nack");
}

}  // namespace
}  // namespace ht::wire
