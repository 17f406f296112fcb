// The compact tool state (protocol.h, CompactToolState): every field of random states comes back
// within the error bound protocol.h states; the binary16 conversion matches the values the format
// defines (exact values, ties to even, subnormals, the clamp); the bytes sit where protocol.h says;
// the datagram is smaller than the f64 one; the sender's own prediction of what the receiver
// decodes equals the decode; truncated, lengthened, non-finite and impossible bodies are refused,
// and random bodies decode to a unit rotation or are refused, without crashing.
#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <cstdint>
#include <iostream>
#include <limits>
#include <random>
#include <span>
#include <vector>

#include "haptic_core/byte_order.h"
#include "haptic_core/spatial.h"
#include "transport/messages.h"

namespace ht::wire {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

MacKey TestKey() {
  MacKey k;
  for (std::size_t i = 0; i < k.bytes.size(); ++i)
    k.bytes[i] = static_cast<std::uint8_t>(5 + 7 * i);
  return k;
}

double Uniform(std::mt19937& rng, double lo, double hi) {
  return std::uniform_real_distribution<double>(lo, hi)(rng);
}

/// A uniformly random rotation (normalized Gaussian quaternion).
glm::dquat RandomRotation(std::mt19937& rng) {
  std::normal_distribution<double> g;
  for (;;) {
    const glm::dquat q(g(rng), g(rng), g(rng), g(rng));
    const double n = std::sqrt(q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z);
    if (n > 1e-6) return q / n;
  }
}

/// A twist component whose magnitude spans 1e-9 .. 30 (log-uniform), either sign.
double RandomTwistComponent(std::mt19937& rng) {
  const double magnitude = std::pow(10.0, Uniform(rng, -9.0, std::log10(30.0)));
  return rng() % 2 ? magnitude : -magnitude;
}

/// The rotation angle (rad) between two unit quaternions.
double AngleBetween(const glm::dquat& a, const glm::dquat& b) {
  const double d = std::abs(a.w * b.w + a.x * b.x + a.y * b.y + a.z * b.z);
  return 2.0 * std::acos(std::min(1.0, d));
}

/// Encodes `m` as a CompactToolState and decodes it through OpenDatagram.
DecodeStatus RoundTrip(const ToolStateMessage& m, ToolStateMessage& out) {
  const MacKey key = TestKey();
  const Datagram d = EncodeCompactToolState({MessageType::kCompactToolState, 3, 1, 0}, m, key);
  Header h;
  std::span<const std::uint8_t> body;
  if (const DecodeStatus s = OpenDatagram(d.view(), key, h, body); s != DecodeStatus::kOk) {
    return s;
  }
  EXPECT_EQ(h.type, MessageType::kCompactToolState);
  return DecodeCompactToolState(body, out);
}

/// The body (32 bytes) of a CompactToolState datagram of `m`.
std::vector<std::uint8_t> Body(const ToolStateMessage& m) {
  const Datagram d = EncodeCompactToolState({}, m, TestKey());
  return {d.bytes.begin() + kHeaderBytes,
          d.bytes.begin() + kHeaderBytes + kCompactToolStateBodyBytes};
}

/// Decodes the twist's linear x from a state whose only non-zero twist component is `v`.
double Binary16RoundTrip(double v) {
  ToolStateMessage m;
  m.V_WT_W.linear.x = v;
  ToolStateMessage out;
  EXPECT_EQ(RoundTrip(m, out), DecodeStatus::kOk) << v;
  return out.V_WT_W.linear.x;
}

TEST(CompactToolState, RandomStatesComeBackWithinTheStatedBounds) {
  std::mt19937 rng(20261125);
  double worst_angle = 0.0, worst_position = 0.0, worst_twist = 0.0;
  for (int i = 0; i < 200000; ++i) {
    ToolStateMessage m;
    m.X_WT.translation = {Uniform(rng, -2.0, 2.0), Uniform(rng, -2.0, 2.0),
                          Uniform(rng, -2.0, 2.0)};
    m.X_WT.rotation = RandomRotation(rng);
    for (int k = 0; k < 3; ++k) {
      m.V_WT_W.linear[k] = RandomTwistComponent(rng);
      m.V_WT_W.angular[k] = RandomTwistComponent(rng);
    }
    ToolStateMessage out;
    ASSERT_EQ(RoundTrip(m, out), DecodeStatus::kOk) << i;
    ASSERT_TRUE(IsFiniteRigidTransform(out.X_WT));
    for (int k = 0; k < 3; ++k) {
      const double p = m.X_WT.translation[k];
      const double e = std::abs(out.X_WT.translation[k] - p);
      ASSERT_LE(e, kCompactToolStatePositionRelativeError * std::abs(p) + 0x1p-150) << i;
      worst_position = std::max(worst_position, e / std::abs(p));
      for (const auto& [sent, got] : {std::pair{m.V_WT_W.linear[k], out.V_WT_W.linear[k]},
                                      std::pair{m.V_WT_W.angular[k], out.V_WT_W.angular[k]}}) {
        const double bound =
            kCompactTwistRelativeError * std::abs(sent) + kCompactTwistAbsoluteError;
        ASSERT_LE(std::abs(got - sent), bound) << i << " " << sent;
        worst_twist = std::max(worst_twist, std::abs(got - sent) / bound);
      }
    }
    const double angle = AngleBetween(out.X_WT.rotation, m.X_WT.rotation);
    ASSERT_LE(angle, kCompactToolStateRotationErrorRad) << i;
    worst_angle = std::max(worst_angle, angle);
    // The sender's prediction is the receiver's decode, bit for bit.
    const ToolStateMessage predicted = CompactToolStateAsReceived(m);
    ASSERT_EQ(predicted.X_WT.translation, out.X_WT.translation);
    ASSERT_EQ(predicted.X_WT.rotation, out.X_WT.rotation);
    ASSERT_EQ(predicted.V_WT_W.linear, out.V_WT_W.linear);
    ASSERT_EQ(predicted.V_WT_W.angular, out.V_WT_W.angular);
  }
  std::cout << "[ compact tool state ] largest rotation error " << worst_angle << " rad (bound "
            << kCompactToolStateRotationErrorRad << "), position " << worst_position
            << " of |p|, twist " << worst_twist << " of its bound\n";
  // The bound is a bound, not a wild over-estimate: random rotations reach a fair part of it.
  EXPECT_GT(worst_angle, 0.1 * kCompactToolStateRotationErrorRad);
}

TEST(CompactToolState, TheSenderEncodesTheStateNotItsPrediction) {
  // A 120° turn about (1, 1, 1): all four components tie at ½. Each is sent as 370727 steps
  // (½ + 1.4e-7); the receiver restores the largest (w) as ½ − 4.3e-7, now below the others, so
  // encoding the prediction again would leave out x instead and decode 1.6e-6 rad away. The
  // network worker therefore encodes the state and predicts from CompactToolStateAsReceived.
  ToolStateMessage m;
  m.X_WT.rotation = glm::dquat(0.5, 0.5, 0.5, 0.5);
  const ToolStateMessage predicted = CompactToolStateAsReceived(m);
  ToolStateMessage sent, sent_twice;
  ASSERT_EQ(RoundTrip(m, sent), DecodeStatus::kOk);
  ASSERT_EQ(RoundTrip(predicted, sent_twice), DecodeStatus::kOk);
  EXPECT_EQ(sent.X_WT.rotation, predicted.X_WT.rotation);
  EXPECT_NE(sent_twice.X_WT.rotation, predicted.X_WT.rotation);
  EXPECT_LT(AngleBetween(sent_twice.X_WT.rotation, predicted.X_WT.rotation), 1e-5);
  EXPECT_LT(predicted.X_WT.rotation.w, predicted.X_WT.rotation.x);
}

TEST(CompactToolState, QAndMinusQAreOneRotationAndTheIdentityIsExact) {
  std::mt19937 rng(7);
  for (int i = 0; i < 1000; ++i) {
    ToolStateMessage a;
    a.X_WT.rotation = RandomRotation(rng);
    ToolStateMessage b = a;
    b.X_WT.rotation = -a.X_WT.rotation;
    ToolStateMessage out_a, out_b;
    ASSERT_EQ(RoundTrip(a, out_a), DecodeStatus::kOk);
    ASSERT_EQ(RoundTrip(b, out_b), DecodeStatus::kOk);
    EXPECT_EQ(out_a.X_WT.rotation, out_b.X_WT.rotation);
    EXPECT_EQ(Body(a), Body(b));  // the sender made the largest component positive
  }
  ToolStateMessage identity;
  ToolStateMessage out;
  ASSERT_EQ(RoundTrip(identity, out), DecodeStatus::kOk);
  EXPECT_EQ(out.X_WT.rotation, glm::dquat(1.0, 0.0, 0.0, 0.0));
  EXPECT_EQ(out.X_WT.translation, glm::dvec3(0.0));
  EXPECT_EQ(out.V_WT_W.linear, glm::dvec3(0.0));
}

TEST(CompactToolState, Binary16GivesTheFormatsOwnValues) {
  // Exactly representable values come back exactly.
  for (const double v : {0.0, 1.0, -1.0, 0.5, 1.5, -3.25, 65504.0, -65504.0, 0x1p-14, 0x1p-24,
                         -0x1p-24, 1023.0 * 0x1p-24, 1.0 + 0x1p-10, 2047.0}) {
    EXPECT_EQ(Binary16RoundTrip(v), v) << v;
  }
  // Ties go to the even significand: 1 + 2⁻¹¹ lies between 1 and 1 + 2⁻¹⁰ (odd), 1 + 3·2⁻¹¹
  // between 1 + 2⁻¹⁰ (odd) and 1 + 2⁻⁹ (even).
  EXPECT_EQ(Binary16RoundTrip(1.0 + 0x1p-11), 1.0);
  EXPECT_EQ(Binary16RoundTrip(1.0 + 3 * 0x1p-11), 1.0 + 0x1p-9);
  // Just above a tie rounds up; the largest value below 2 that rounds up carries into 2.
  EXPECT_EQ(Binary16RoundTrip(1.0 + 0x1p-11 + 0x1p-30), 1.0 + 0x1p-10);
  EXPECT_EQ(Binary16RoundTrip(2.0 - 0x1p-12), 2.0);
  // Subnormals: half the smallest one is a tie to 0, a little more rounds to it; the largest
  // subnormal rounds up into the smallest normal.
  EXPECT_EQ(Binary16RoundTrip(0x1p-25), 0.0);
  EXPECT_EQ(Binary16RoundTrip(0x1p-25 + 0x1p-40), 0x1p-24);
  EXPECT_EQ(Binary16RoundTrip(0x1p-14 - 0x1p-26), 0x1p-14);
  // Beyond the format's range the sender clamps.
  EXPECT_EQ(Binary16RoundTrip(1e6), 65504.0);
  EXPECT_EQ(Binary16RoundTrip(-70000.0), -65504.0);
  // A second route to the same numbers: a dense sweep is monotonic and within half a step.
  double previous = -kInf;
  for (double v = 0x1p-26; v < 70000.0; v *= 1.0 + 1.0 / 4096.0) {
    const double got = Binary16RoundTrip(v);
    ASSERT_GE(got, previous) << v;
    ASSERT_LE(std::abs(got - std::min(v, 65504.0)),
              kCompactTwistRelativeError * std::min(v, 65504.0) + kCompactTwistAbsoluteError)
        << v;
    previous = got;
  }
}

TEST(CompactToolState, BytesSitWhereProtocolHSays) {
  ToolStateMessage m;
  m.X_WT.translation = {0.25, -1.5, 3.0};
  m.V_WT_W.linear = {1.0, -2.0, 0.5};
  m.V_WT_W.angular = {0.0, 65504.0, -0x1p-24};
  const Datagram d = EncodeCompactToolState({}, m, TestKey());
  EXPECT_EQ(d.size, kHeaderBytes + kCompactToolStateBodyBytes + kMacBytes);
  EXPECT_EQ(d.size, 66u);  // protocol version 8: 18 + 32 + 16
  EXPECT_LT(d.size, EncodeToolState({}, m, TestKey()).size);
  const std::uint8_t* b = d.bytes.data() + kHeaderBytes;
  EXPECT_EQ(std::bit_cast<float>(LoadLe<std::uint32_t>(b + 0)), 0.25f);
  EXPECT_EQ(std::bit_cast<float>(LoadLe<std::uint32_t>(b + 4)), -1.5f);
  EXPECT_EQ(std::bit_cast<float>(LoadLe<std::uint32_t>(b + 8)), 3.0f);
  // The identity: w is the largest (index 0) and x, y, z are 0.
  EXPECT_EQ(LoadLe<std::uint64_t>(b + 12), 0u);
  const std::uint16_t twist[6] = {0x3C00, 0xC000, 0x3800, 0x0000, 0x7BFF, 0x8001};
  for (int k = 0; k < 6; ++k) EXPECT_EQ(LoadLe<std::uint16_t>(b + 20 + 2 * k), twist[k]) << k;
  // A half turn about z: z is the largest (index 3), the others 0.
  m.X_WT.rotation = glm::dquat(0.0, 0.0, 0.0, -1.0);
  const Datagram turned = EncodeCompactToolState({}, m, TestKey());
  EXPECT_EQ(LoadLe<std::uint64_t>(turned.bytes.data() + kHeaderBytes + 12), 3u);
  EXPECT_STREQ(ToString(MessageType::kCompactToolState), "compact_tool_state");
}

TEST(CompactToolState, NonFiniteAndImpossibleBodiesAreRefused) {
  ToolStateMessage m;
  m.X_WT.translation = {0.1, 0.2, 0.3};
  m.X_WT.rotation = QuaternionFromRotationVector({0.3, -0.2, 0.1});
  m.V_WT_W = {{0.01, 0.02, 0.03}, {0.1, 0.2, 0.3}};
  ToolStateMessage out;
  // What the sender could not encode reaches the receiver as non-finite.
  for (int field = 0; field < 4; ++field) {
    ToolStateMessage bad = m;
    if (field == 0) bad.X_WT.translation.y = kNaN;
    if (field == 1) bad.X_WT.rotation.x = kNaN;
    if (field == 2) bad.V_WT_W.linear.z = kInf;
    if (field == 3) bad.V_WT_W.angular.x = kNaN;
    EXPECT_EQ(RoundTrip(bad, out), DecodeStatus::kNonFinite) << field;
    // The sender's prediction of such a state is the state itself (never sent as is).
    EXPECT_EQ(CompactToolStateAsReceived(bad).X_WT.translation.x, 0.1);
  }
  // A coordinate beyond f32's range (the f64 encoding carries it) is refused, not undefined.
  ToolStateMessage far = m;
  far.X_WT.translation.z = 1e39;
  EXPECT_EQ(RoundTrip(far, out), DecodeStatus::kNonFinite);
  ToolStateMessage zero_rotation = m;
  zero_rotation.X_WT.rotation = glm::dquat(0.0, 0.0, 0.0, 0.0);
  EXPECT_NE(RoundTrip(zero_rotation, out), DecodeStatus::kOk);

  const std::vector<std::uint8_t> good = Body(m);
  ASSERT_EQ(DecodeCompactToolState(good, out), DecodeStatus::kOk);
  // Lengths other than 32.
  EXPECT_EQ(DecodeCompactToolState({good.data(), good.size() - 1}, out), DecodeStatus::kTooShort);
  std::vector<std::uint8_t> longer = good;
  longer.push_back(0);
  EXPECT_EQ(DecodeCompactToolState(longer, out), DecodeStatus::kTooLong);
  EXPECT_EQ(DecodeCompactToolState({}, out), DecodeStatus::kTooShort);
  const auto with_quaternion = [&](std::uint64_t bits) {
    std::vector<std::uint8_t> b = good;
    StoreLe(bits, b.data() + 12);
    return DecodeCompactToolState(b, out);
  };
  const std::uint64_t mask = (std::uint64_t{1} << kCompactQuaternionBits) - 1;
  EXPECT_EQ(with_quaternion(0), DecodeStatus::kOk);
  // Bits 62–63 set.
  EXPECT_EQ(with_quaternion(std::uint64_t{1} << 62), DecodeStatus::kBadValue);
  EXPECT_EQ(with_quaternion(std::uint64_t{1} << 63), DecodeStatus::kBadValue);
  // A component of −2¹⁹ (beyond −kCompactQuaternionMax).
  EXPECT_EQ(with_quaternion((std::uint64_t{1} << (kCompactQuaternionBits - 1)) << 2),
            DecodeStatus::kBadValue);
  // Three components of 1/√2: their squares sum to 1.5.
  const std::uint64_t max = static_cast<std::uint64_t>(kCompactQuaternionMax) & mask;
  EXPECT_EQ(with_quaternion(max << 2 | max << 22 | max << 42), DecodeStatus::kBadValue);
  // Two of 1/√2: the largest is restored as 0, still a unit quaternion.
  EXPECT_EQ(with_quaternion(max << 2 | max << 22), DecodeStatus::kOk);
  EXPECT_LE(AngleBetween(out.X_WT.rotation, glm::normalize(glm::dquat(0.0, 1.0, 1.0, 0.0))),
            kCompactToolStateRotationErrorRad);
  // Non-finite f32 position and binary16 twist.
  for (const std::size_t at : {std::size_t{0}, std::size_t{8}}) {
    std::vector<std::uint8_t> b = good;
    StoreLe(std::bit_cast<std::uint32_t>(std::numeric_limits<float>::infinity()), b.data() + at);
    EXPECT_EQ(DecodeCompactToolState(b, out), DecodeStatus::kNonFinite) << at;
  }
  for (const std::uint16_t h : {std::uint16_t{0x7C00}, std::uint16_t{0xFC00}, std::uint16_t{0x7E00},
                                std::uint16_t{0x7C01}}) {
    std::vector<std::uint8_t> b = good;
    StoreLe(h, b.data() + 30);
    EXPECT_EQ(DecodeCompactToolState(b, out), DecodeStatus::kNonFinite) << h;
  }
}

TEST(CompactToolState, RandomBodiesDecodeToAUnitRotationOrAreRefused) {
  std::mt19937 rng(99);
  int accepted = 0;
  for (int i = 0; i < 100000; ++i) {
    std::vector<std::uint8_t> b(kCompactToolStateBodyBytes);
    for (auto& byte : b) byte = static_cast<std::uint8_t>(rng());
    if (i % 2) b[19] &= 0x3F;  // half of them with bits 62–63 clear
    ToolStateMessage out;
    const DecodeStatus s = DecodeCompactToolState(b, out);
    if (s != DecodeStatus::kOk) continue;
    ++accepted;
    ASSERT_TRUE(IsFiniteRigidTransform(out.X_WT));
    ASSERT_TRUE(IsFinite(out.V_WT_W));
    const glm::dquat& q = out.X_WT.rotation;
    ASSERT_NEAR(q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z, 1.0, 1e-12);
  }
  EXPECT_GT(accepted, 0);
}

}  // namespace
}  // namespace ht::wire
