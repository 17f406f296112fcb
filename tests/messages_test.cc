#include "transport/messages.h"

#include <gtest/gtest.h>

#include <random>

namespace ht::wire {
namespace {

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

TEST(Messages, ToolStateRoundTrips) {
  Header h{MessageType::kToolState, 0xabcdef01u, 99, -5};
  ToolStateMessage m;
  m.X_WT.translation = {1, 2, 3};
  m.X_WT.rotation = QuaternionFromRotationVector({0.1, 0.2, 0.3});
  m.V_WT_W = {{0.4, 0.5, 0.6}, {-0.7, 0.8, -0.9}};
  const Datagram d = EncodeToolState(h, m);
  ASSERT_EQ(d.size, kHeaderBytes + kToolStateBodyBytes);
  Header h2;
  ToolStateMessage m2;
  ASSERT_EQ(DecodeToolState(d.view(), h2, m2), DecodeStatus::kOk);
  EXPECT_EQ(h2.session_id, h.session_id);
  EXPECT_EQ(h2.sequence, 99u);
  EXPECT_EQ(h2.send_time_ns, -5);
  EXPECT_EQ(m2.X_WT.translation, m.X_WT.translation);
  EXPECT_EQ(m2.X_WT.rotation, m.X_WT.rotation);
  EXPECT_EQ(m2.V_WT_W.angular, m.V_WT_W.angular);
}

TEST(Messages, ContactModelRoundTripsWithEveryCount) {
  for (int n : {0, 1, 7, kMaxWireContacts}) {
    const ContactModelMessage m = SampleModel(n);
    const Datagram d = EncodeContactModel({MessageType::kContactModel, 7, 3, 11}, m);
    ASSERT_EQ(d.size, kHeaderBytes + kContactModelFixedBytes + n * kContactBytes);
    ASSERT_LE(d.size, kMaxDatagramBytes);
    Header h;
    ContactModelMessage out;
    ASSERT_EQ(DecodeContactModel(d.view(), h, out), DecodeStatus::kOk) << n;
    EXPECT_EQ(out.model.num_contacts, n);
    EXPECT_EQ(out.model.tool_state_seq, 42u);
    EXPECT_EQ(out.hold_ns, 1500);
    for (int i = 0; i < n; ++i) {
      EXPECT_EQ(out.model.contacts[i].depth_m, m.model.contacts[i].depth_m);
      EXPECT_EQ(out.model.contacts[i].gradient.d_rotation_W,
                m.model.contacts[i].gradient.d_rotation_W);
    }
  }
}

TEST(Messages, EveryTruncationAndExtensionIsRejected) {
  const Datagram d = EncodeContactModel({MessageType::kContactModel, 7, 3, 11}, SampleModel(3));
  Header h;
  ContactModelMessage out;
  for (std::size_t len = 0; len < d.size; ++len) {
    EXPECT_NE(DecodeContactModel({d.bytes.data(), len}, h, out), DecodeStatus::kOk) << len;
  }
  std::array<std::uint8_t, kMaxDatagramBytes> longer{};
  std::copy(d.bytes.begin(), d.bytes.begin() + d.size, longer.begin());
  EXPECT_EQ(DecodeContactModel({longer.data(), d.size + 1}, h, out), DecodeStatus::kTooLong);
}

TEST(Messages, HeaderFieldsAreChecked) {
  const Datagram good = EncodeToolState({MessageType::kToolState, 1, 1, 0}, ToolStateMessage{});
  Header h;
  ToolStateMessage out;
  auto mutate = [&](std::size_t offset, std::uint8_t value) {
    Datagram d = good;
    d.bytes[offset] = value;
    return DecodeToolState(d.view(), h, out);
  };
  EXPECT_EQ(mutate(0, 0x00), DecodeStatus::kBadMagic);
  EXPECT_EQ(mutate(4, 0x09), DecodeStatus::kBadVersion);
  EXPECT_EQ(mutate(6, 0x7f), DecodeStatus::kUnknownType);
  EXPECT_EQ(mutate(7, 0x01), DecodeStatus::kBadFlags);
}

TEST(Messages, NonFiniteAndImpossibleValuesAreRejected) {
  ToolStateMessage m;
  m.X_WT.translation.x = NAN;
  Header h;
  ToolStateMessage out;
  EXPECT_EQ(DecodeToolState(EncodeToolState({}, m).view(), h, out), DecodeStatus::kNonFinite);
  m = {};
  m.X_WT.rotation = glm::dquat(3.0, 0, 0, 0);
  EXPECT_EQ(DecodeToolState(EncodeToolState({}, m).view(), h, out), DecodeStatus::kBadValue);
  ContactModelMessage cm = SampleModel(2);
  cm.model.contacts[1].gradient.d_translation_W.y = INFINITY;
  ContactModelMessage cout;
  EXPECT_EQ(DecodeContactModel(EncodeContactModel({}, cm).view(), h, cout),
            DecodeStatus::kNonFinite);
  cm = SampleModel(2);
  cm.model.contacts[0].stiffness_n_per_m = -1;
  EXPECT_EQ(DecodeContactModel(EncodeContactModel({}, cm).view(), h, cout),
            DecodeStatus::kBadValue);
  Datagram d = EncodeContactModel({}, SampleModel(0));
  d.bytes[kHeaderBytes + kContactModelFixedBytes - 1] = kMaxWireContacts + 1;  // count byte
  EXPECT_EQ(DecodeContactModel(d.view(), h, cout), DecodeStatus::kBadCount);
}

TEST(Messages, RandomBytesNeverDecodeOrCrash) {
  std::mt19937 rng(1);
  std::array<std::uint8_t, kMaxDatagramBytes> buf{};
  Header h;
  ContactModelMessage cm;
  ToolStateMessage ts;
  int accepted = 0;
  for (int i = 0; i < 20000; ++i) {
    const std::size_t len = rng() % buf.size();
    for (std::size_t k = 0; k < len; ++k) buf[k] = static_cast<std::uint8_t>(rng());
    accepted += DecodeContactModel({buf.data(), len}, h, cm) == DecodeStatus::kOk;
    accepted += DecodeToolState({buf.data(), len}, h, ts) == DecodeStatus::kOk;
  }
  EXPECT_EQ(accepted, 0);
}

}  // namespace
}  // namespace ht::wire
