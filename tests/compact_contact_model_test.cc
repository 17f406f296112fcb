// The compact contact model (protocol.h, CompactContactModel): every field of random models comes
// back within the error bound protocol.h states; the wrench and stiffness the operator evaluates
// from it agree with those from the float encoding within the bound those field bounds give; the
// bytes sit where protocol.h says; it is smaller than the float encoding; truncated, lengthened,
// bit-flipped and marked bodies are refused (or decode to finite values) without crashing.
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <iostream>
#include <limits>
#include <random>
#include <span>
#include <string>
#include <vector>

#include "haptic_core/contact_assembly.h"
#include "haptic_core/contact_model.h"
#include "haptic_core/spatial.h"
#include "transport/link.h"
#include "transport/messages.h"

namespace ht::wire {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();
/// The f32 subnormal spacing protocol.h adds to the f32 and gradient bounds.
constexpr double kF32Tiny = 0x1p-150;
/// The receiver's clock when it decodes (ns; 58 days of uptime): RandomModel's echoes lie up to 2 s
/// before it, as a model's echo does (its tool state was sent a round trip earlier).
constexpr std::int64_t kNowNs = 5'000'000'000'000'000;

MacKey TestKey() {
  MacKey k;
  for (std::size_t i = 0; i < k.bytes.size(); ++i)
    k.bytes[i] = static_cast<std::uint8_t>(3 + 11 * i);
  return k;
}

double Uniform(std::mt19937& rng, double lo, double hi) {
  return std::uniform_real_distribution<double>(lo, hi)(rng);
}

glm::dvec3 RandomUnit(std::mt19937& rng) {
  std::normal_distribution<double> g;
  for (;;) {
    const glm::dvec3 v(g(rng), g(rng), g(rng));
    if (glm::length(v) > 1e-6) return glm::normalize(v);
  }
}

std::uint64_t Random64(std::mt19937& rng) { return (std::uint64_t{rng()} << 32) | rng(); }

/// Realistic magnitudes: depth ±5 mm, |∂δ/∂x| ≤ 1, |∂δ/∂θ| ≤ 0.2 m/rad, stiffness 100..20000 N/m,
/// points within 0.3 m of p_WT0, unit normals, a random rotation.
ContactModelMessage RandomModel(std::mt19937& rng, int contacts) {
  ContactModelMessage m;
  ContactModel& model = m.model;
  model.X_WT0.translation = {Uniform(rng, -0.5, 0.5), Uniform(rng, -0.5, 0.5),
                             Uniform(rng, -0.5, 0.5)};
  std::normal_distribution<double> g;
  model.X_WT0.rotation = glm::normalize(glm::dquat(g(rng), g(rng), g(rng), g(rng)));
  model.tool_state_seq = rng();  // a header sequence: u32
  model.num_contacts = contacts;
  for (int i = 0; i < contacts; ++i) {
    ContactLinearization& c = model.contacts[i];
    c.depth_m = Uniform(rng, -5e-3, 5e-3);
    c.gradient.d_translation_W = RandomUnit(rng) * Uniform(rng, 0.0, 1.0);
    c.gradient.d_rotation_W = RandomUnit(rng) * Uniform(rng, 0.0, 0.2);
    c.stiffness_n_per_m = Uniform(rng, 100.0, 20000.0);
    c.point_W = model.X_WT0.translation + RandomUnit(rng) * Uniform(rng, 0.0, 0.3);
    c.normal_W = RandomUnit(rng);
  }
  // As the sender assembles it (AssembleContactModel): the contacts' wrench at q0.
  model.F_T_W_at_q0 = ContactModelWrenchAtQ0(model);
  m.tool_state_send_time_ns = kNowNs - static_cast<std::int64_t>(Uniform(rng, 0.0, 2e9));
  m.hold_ns = static_cast<std::int64_t>(rng());
  m.remote_step_count = Random64(rng);
  m.collision_us = static_cast<float>(Uniform(rng, 0.0, 60000.0));
  m.texture_us = static_cast<float>(Uniform(rng, 0.0, 60000.0));
  m.step_us = static_cast<float>(Uniform(rng, 0.0, 60000.0));
  return m;
}

Header TestHeader() { return {MessageType::kCompactContactModel, 7, 3, 11}; }

std::span<const std::uint8_t> BodyOf(const Datagram& d) {
  return d.view().subspan(kHeaderBytes, d.size - kHeaderBytes - kMacBytes);
}

std::vector<std::uint8_t> CompactBody(const ContactModelMessage& m, const MacKey& key) {
  const Datagram d = EncodeCompactContactModel(TestHeader(), m, key);
  const auto body = BodyOf(d);
  return {body.begin(), body.end()};
}

/// Opens and decodes a compact datagram; checks that its header says so.
DecodeStatus OpenCompact(const Datagram& d, const MacKey& key, ContactModelMessage& out) {
  Header h;
  std::span<const std::uint8_t> body;
  if (const DecodeStatus s = OpenDatagram(d.view(), key, h, body); s != DecodeStatus::kOk) return s;
  EXPECT_EQ(h.type, MessageType::kCompactContactModel);
  return DecodeCompactContactModel(body, out, kNowNs);
}

DecodeStatus OpenFloat(const Datagram& d, const MacKey& key, ContactModelMessage& out) {
  Header h;
  std::span<const std::uint8_t> body;
  if (const DecodeStatus s = OpenDatagram(d.view(), key, h, body); s != DecodeStatus::kOk) return s;
  return DecodeContactModel(body, out);
}

// Little-endian access to a body at the offsets protocol.h's layout gives, written here
// independently of the codec.
template <class T>
T Get(std::span<const std::uint8_t> b, std::size_t at) {
  std::uint64_t u = 0;
  for (std::size_t i = 0; i < sizeof(T); ++i) u |= std::uint64_t{b[at + i]} << (8 * i);
  if constexpr (sizeof(T) == 1) return std::bit_cast<T>(static_cast<std::uint8_t>(u));
  if constexpr (sizeof(T) == 2) return std::bit_cast<T>(static_cast<std::uint16_t>(u));
  if constexpr (sizeof(T) == 4) return std::bit_cast<T>(static_cast<std::uint32_t>(u));
  if constexpr (sizeof(T) == 8) return std::bit_cast<T>(u);
}

template <class T>
void Put(std::vector<std::uint8_t>& b, std::size_t at, T value) {
  std::uint64_t u = 0;
  if constexpr (sizeof(T) == 1) u = std::bit_cast<std::uint8_t>(value);
  if constexpr (sizeof(T) == 2) u = std::bit_cast<std::uint16_t>(value);
  if constexpr (sizeof(T) == 4) u = std::bit_cast<std::uint32_t>(value);
  if constexpr (sizeof(T) == 8) u = std::bit_cast<std::uint64_t>(value);
  for (std::size_t i = 0; i < sizeof(T); ++i) b[at + i] = static_cast<std::uint8_t>(u >> (8 * i));
}

// Offsets in the body (protocol.h, CompactContactModel, version 11).
constexpr std::size_t kAtSeq = 0, kAtSendTime = 4, kAtHold = 8, kAtSteps = 12, kAtTimes = 16;
constexpr std::size_t kAtP = 22, kAtQ = 34;
constexpr std::size_t kAtCount = 44, kAtContacts = 45;

/// Bits [at, at + width) of the body's 80-bit quaternion field (10 bytes, little-endian), read
/// byte by byte.
std::uint64_t QuaternionBits(std::span<const std::uint8_t> b, int at, int width) {
  std::uint64_t v = 0;
  for (int i = 0; i < width; ++i) {
    const int bit = at + i;
    v |= std::uint64_t{(b[kAtQ + static_cast<std::size_t>(bit / 8)] >> (bit % 8)) & 1u} << i;
  }
  return v;
}
// Within a contact.
constexpr std::size_t kAtDepth = 0, kAtDx = 4, kAtDtheta = 16, kAtK = 28, kAtPoint = 32,
                      kAtNormal = 38;

double F32Bound(double v) { return kCompactF32RelativeError * std::abs(v) + kF32Tiny; }

/// Angle (rad) between two directions.
double Angle(const glm::dvec3& a, const glm::dvec3& b) {
  return std::atan2(glm::length(glm::cross(a, b)), glm::dot(a, b));
}

/// Angle (rad) of the rotation between two unit quaternions.
double RotationAngle(const glm::dquat& a, const glm::dquat& b) {
  const glm::dquat r = a * glm::conjugate(b);
  return 2.0 * std::atan2(glm::length(glm::dvec3(r.x, r.y, r.z)), std::abs(r.w));
}

/// Largest |component| of ∂δ/∂x (translation) or ∂δ/∂θ over a model's contacts.
double MaxComponent(const ContactModel& m, bool translation) {
  double largest = 0.0;
  for (int i = 0; i < m.num_contacts; ++i) {
    const glm::dvec3& g =
        translation ? m.contacts[i].gradient.d_translation_W : m.contacts[i].gradient.d_rotation_W;
    largest = std::max({largest, std::abs(g.x), std::abs(g.y), std::abs(g.z)});
  }
  return largest;
}

/// The worst error seen of one field, against its bound.
struct Worst {
  const char* name;
  double error = 0.0;
  double ratio = 0.0;  ///< largest error / bound
  void Add(double e, double bound) {
    error = std::max(error, e);
    ratio = std::max(ratio, e / bound);
  }
};

/// Every field of a decoded model is finite and what a model must be (for corrupted bodies).
void ExpectSane(const ContactModelMessage& m) {
  const ContactModel& model = m.model;
  ASSERT_GE(model.num_contacts, 0);
  ASSERT_LE(model.num_contacts, kMaxWireContacts);
  EXPECT_TRUE(IsFiniteRigidTransform(model.X_WT0));
  EXPECT_NEAR(glm::length(model.X_WT0.rotation), 1.0, 1e-12);
  EXPECT_TRUE(IsFinite(model.F_T_W_at_q0));
  EXPECT_TRUE(std::isfinite(m.collision_us) && std::isfinite(m.texture_us) &&
              std::isfinite(m.step_us));
  for (int i = 0; i < model.num_contacts; ++i) {
    const ContactLinearization& c = model.contacts[i];
    EXPECT_TRUE(std::isfinite(c.depth_m));
    EXPECT_TRUE(std::isfinite(c.stiffness_n_per_m) && c.stiffness_n_per_m >= 0.0);
    for (int k = 0; k < 3; ++k) {
      EXPECT_TRUE(std::isfinite(c.gradient.d_translation_W[k]));
      EXPECT_TRUE(std::isfinite(c.gradient.d_rotation_W[k]));
      EXPECT_TRUE(std::isfinite(c.point_W[k]));
    }
    EXPECT_NEAR(glm::length(c.normal_W), 1.0, 1e-12);
  }
  const ContactModelEvaluation e = EvaluateContactModel(model, model.X_WT0);
  EXPECT_TRUE(IsFinite(e.F_T_W));
  EXPECT_TRUE(e.K.allFinite());
}

TEST(CompactContactModel, RandomModelsComeBackWithinTheStatedBounds) {
  const MacKey key = TestKey();
  std::mt19937 rng(18);
  Worst time{"time_us"}, echo{"echo_and_hold_ns"}, position{"position_m"}, rotation{"rotation_rad"},
      wrench{"F_T_W_at_q0"}, depth{"depth_m"}, stiffness{"stiffness"}, d_x{"d_translation"},
      d_theta{"d_rotation"}, point{"point_m"}, normal{"normal_rad"};
  for (int trial = 0; trial < 2000; ++trial) {
    const int n = trial % (kMaxWireContacts + 1);
    const ContactModelMessage m = RandomModel(rng, n);
    const Datagram d = EncodeCompactContactModel(TestHeader(), m, key);
    ContactModelMessage out;
    ASSERT_EQ(OpenCompact(d, key, out), DecodeStatus::kOk) << trial;
    EXPECT_EQ(out.model.tool_state_seq, m.model.tool_state_seq);  // a u32, sent whole
    // Whole µs, within ±2³¹ µs of the receiver's clock (here 0–2 s before it).
    EXPECT_EQ(out.tool_state_send_time_ns % 1000, 0);
    EXPECT_EQ(out.hold_ns % 1000, 0);
    echo.Add(static_cast<double>(std::abs(out.tool_state_send_time_ns - m.tool_state_send_time_ns)),
             1e3 * kCompactTimeErrorUs);
    echo.Add(static_cast<double>(std::abs(out.hold_ns - m.hold_ns)), 1e3 * kCompactTimeErrorUs);
    EXPECT_EQ(out.remote_step_count, m.remote_step_count & 0xFFFF'FFFFu);
    for (const auto& [a, b] :
         {std::pair{out.collision_us, m.collision_us}, std::pair{out.texture_us, m.texture_us},
          std::pair{out.step_us, m.step_us}}) {
      time.Add(std::abs(double{a} - double{b}), kCompactTimeErrorUs);
    }
    for (int k = 0; k < 3; ++k) {
      const double p = m.model.X_WT0.translation[k];
      position.Add(std::abs(out.model.X_WT0.translation[k] - p),
                   kCompactModelPositionRelativeError * std::abs(p) + kF32Tiny);
    }
    rotation.Add(RotationAngle(out.model.X_WT0.rotation, m.model.X_WT0.rotation),
                 kCompactRotationErrorRad);
    EXPECT_NEAR(glm::length(out.model.X_WT0.rotation), 1.0, 1e-12);
    // Not sent: summed again from the decoded contacts. Each term k·δ·J has three f32 factors
    // (≤ 2⁻²⁴ each, so ≤ 4·2⁻²⁴ of the term with margin), against the sender's f64 sum.
    {
      Wrench scale{};
      for (int i = 0; i < n; ++i) {
        const ContactLinearization& c = m.model.contacts[i];
        const double kd = c.stiffness_n_per_m * std::max(c.depth_m, 0.0);
        scale.force += kd * glm::abs(c.gradient.d_translation_W);
        scale.torque += kd * glm::abs(c.gradient.d_rotation_W);
      }
      const Wrench& a = out.model.F_T_W_at_q0;
      const Wrench& b = m.model.F_T_W_at_q0;
      for (int k = 0; k < 3; ++k) {
        wrench.Add(std::abs(a.force[k] - b.force[k]),
                   4.0 * kCompactF32RelativeError * scale.force[k] + 1e-12);
        wrench.Add(std::abs(a.torque[k] - b.torque[k]),
                   4.0 * kCompactF32RelativeError * scale.torque[k] + 1e-12);
      }
    }
    ASSERT_EQ(out.model.num_contacts, n);
    for (int i = 0; i < n; ++i) {
      const ContactLinearization& a = out.model.contacts[i];
      const ContactLinearization& b = m.model.contacts[i];
      depth.Add(std::abs(a.depth_m - b.depth_m), F32Bound(b.depth_m));
      stiffness.Add(std::abs(a.stiffness_n_per_m - b.stiffness_n_per_m),
                    F32Bound(b.stiffness_n_per_m));
      for (int k = 0; k < 3; ++k) {
        d_x.Add(std::abs(a.gradient.d_translation_W[k] - b.gradient.d_translation_W[k]),
                F32Bound(b.gradient.d_translation_W[k]));
        d_theta.Add(std::abs(a.gradient.d_rotation_W[k] - b.gradient.d_rotation_W[k]),
                    F32Bound(b.gradient.d_rotation_W[k]));
        // Plus the double rounding of p_WT0 + offset (|p| < 1 m here).
        point.Add(std::abs(a.point_W[k] - b.point_W[k]), kCompactPointErrorM + 1e-12);
      }
      normal.Add(Angle(a.normal_W, b.normal_W), kCompactNormalErrorRad);
      EXPECT_NEAR(glm::length(a.normal_W), 1.0, 1e-12);
    }
  }
  for (const Worst& w :
       {time, echo, position, rotation, wrench, depth, stiffness, d_x, d_theta, point, normal}) {
    EXPECT_LE(w.ratio, 1.0) << w.name << ": largest error " << w.error;
    std::cout << "[ measured ] " << w.name << ": largest error " << w.error << " = " << w.ratio
              << " of its bound\n";
  }
}

TEST(CompactContactModel, NormalsOfManyDirectionsStayWithinTheBound) {
  const MacKey key = TestKey();
  std::mt19937 rng(5);
  std::vector<glm::dvec3> directions;
  // The axes, the octants' diagonals, the fold's edges and corners, just below the equator, and
  // directions that are finite but not unit (the encoder keeps only the direction).
  for (int a = 0; a < 3; ++a) {
    for (const double s : {1.0, -1.0}) {
      glm::dvec3 v(0.0);
      v[a] = s;
      directions.push_back(v);
    }
  }
  for (int octant = 0; octant < 8; ++octant) {
    const glm::dvec3 v((octant & 1) ? -1 : 1, (octant & 2) ? -1 : 1, (octant & 4) ? -1 : 1);
    directions.push_back(v / std::sqrt(3.0));
    directions.push_back(glm::dvec3(v.x, v.y, -1e-300));
    directions.push_back(glm::dvec3(v.x, 0.0, -1e-9));
    directions.push_back(glm::dvec3(0.0, v.y, v.z * 1e-12));
    directions.push_back(v * 1e300);
    directions.push_back(v * 1e-300);
  }
  while (directions.size() < 140000) directions.push_back(RandomUnit(rng));
  double worst = 0.0;
  ContactModelMessage m = RandomModel(rng, kMaxWireContacts);
  for (std::size_t first = 0; first < directions.size(); first += kMaxWireContacts) {
    const int n =
        static_cast<int>(std::min<std::size_t>(kMaxWireContacts, directions.size() - first));
    m.model.num_contacts = n;
    for (int i = 0; i < n; ++i) m.model.contacts[i].normal_W = directions[first + i];
    ContactModelMessage out;
    ASSERT_EQ(OpenCompact(EncodeCompactContactModel(TestHeader(), m, key), key, out),
              DecodeStatus::kOk);
    for (int i = 0; i < n; ++i) {
      const glm::dvec3& v = directions[first + i];
      const glm::dvec3 unit =
          glm::normalize(v / std::max({std::abs(v.x), std::abs(v.y), std::abs(v.z)}));
      const double angle = Angle(out.model.contacts[i].normal_W, unit);
      worst = std::max(worst, angle);
      EXPECT_LE(angle, kCompactNormalErrorRad) << first + i;
      EXPECT_NEAR(glm::length(out.model.contacts[i].normal_W), 1.0, 1e-12);
    }
  }
  std::cout << "[ measured ] largest normal error over " << directions.size()
            << " directions: " << worst << " rad (bound " << kCompactNormalErrorRad << ")\n";
}

// A second route to the same numbers: what the operator computes from a model (its wrench and
// stiffness at poses near q0) agrees between the float encoding (exact for every field that enters
// the wrench) and the compact one, within the bound that protocol.h's field bounds give.
TEST(CompactContactModel, EvaluatedWrenchAndStiffnessAgreeWithTheFloatEncoding) {
  const MacKey key = TestKey();
  std::mt19937 rng(77);
  const double sqrt3 = std::sqrt(3.0);
  double worst_force = 0.0, worst_torque = 0.0, worst_K = 0.0;  // as fractions of their bounds
  double largest_force_n = 0.0;
  int active = 0, compared = 0;
  for (int trial = 0; trial < 600; ++trial) {
    const ContactModelMessage m = RandomModel(rng, 1 + trial % kMaxWireContacts);
    ContactModelMessage ref, cmp;
    ASSERT_EQ(
        OpenFloat(EncodeContactModel({MessageType::kContactModel, 7, 3, 11}, m, key), key, ref),
        DecodeStatus::kOk);
    ASSERT_EQ(OpenCompact(EncodeCompactContactModel(TestHeader(), m, key), key, cmp),
              DecodeStatus::kOk);
    // Per component |error| ≤ 2⁻²⁴·|component|, bounded here by the largest component.
    const double e_x = kCompactF32RelativeError * MaxComponent(ref.model, true) + kF32Tiny;
    const double e_theta = kCompactF32RelativeError * MaxComponent(ref.model, false) + kF32Tiny;
    const double e_J = std::sqrt(3.0 * (e_x * e_x + e_theta * e_theta));  // |J' − J| (6-vector)
    for (int pose = 0; pose < 4; ++pose) {
      const Twist step{
          {Uniform(rng, -2e-3, 2e-3), Uniform(rng, -2e-3, 2e-3), Uniform(rng, -2e-3, 2e-3)},
          {Uniform(rng, -0.02, 0.02), Uniform(rng, -0.02, 0.02), Uniform(rng, -0.02, 0.02)}};
      const RigidTransform X_WT = Displace(ref.model.X_WT0, step);
      const ContactModelEvaluation a = EvaluateContactModel(ref.model, X_WT);
      const ContactModelEvaluation b = EvaluateContactModel(cmp.model, X_WT);
      // q ⊖ q0: the translation moves by p_WT0's f32 rounding (e_p, a length); the rotation
      // vector by at most about the rotation error of X_WT0 (twice it, for margin).
      const Twist dq = PoseDifference(X_WT, ref.model.X_WT0);
      const glm::dvec3& p0 = ref.model.X_WT0.translation;
      const double e_p = sqrt3 * (kCompactModelPositionRelativeError *
                                      std::max({std::abs(p0.x), std::abs(p0.y), std::abs(p0.z)}) +
                                  kF32Tiny);
      const double dx = glm::length(dq.linear);
      const double dtheta = glm::length(dq.angular) + 2.0 * kCompactRotationErrorRad;
      double bound_force = 0.0, bound_torque = 0.0, bound_K = 0.0, scale_F = 0.0, scale_K = 0.0;
      bool ambiguous = false;
      for (int i = 0; i < ref.model.num_contacts; ++i) {
        const ContactLinearization& c = ref.model.contacts[i];
        const double k = c.stiffness_n_per_m, dk = F32Bound(k);
        const double jx = glm::length(c.gradient.d_translation_W);
        const double jr = glm::length(c.gradient.d_rotation_W);
        const double j = std::sqrt(jx * jx + jr * jr);
        const double jx_c = jx + sqrt3 * e_x, jr_c = jr + sqrt3 * e_theta, j_c = j + e_J;
        const double delta = c.depth_m + c.gradient.Dot(dq);
        // |δ' − δ|: δ0 as f32, J' − J times q ⊖ q0, J times the moved rotation vector.
        const double e_delta = F32Bound(c.depth_m) + sqrt3 * e_x * dx + sqrt3 * e_theta * dtheta +
                               jr * 2.0 * kCompactRotationErrorRad + jx_c * e_p;
        const double d = std::max(delta, 0.0);  // max(·, 0) moves by at most e_delta
        // k'd'J' − kdJ = (k' − k)d'J' + k(d' − d)J' + kd(J' − J).
        bound_force += dk * (d + e_delta) * jx_c + k * e_delta * jx_c + k * d * sqrt3 * e_x;
        bound_torque += dk * (d + e_delta) * jr_c + k * e_delta * jr_c + k * d * sqrt3 * e_theta;
        scale_F += k * (d + e_delta) * j_c;
        if (std::abs(delta) <= e_delta) {
          ambiguous = true;  // one side may count it and the other not
          bound_K += (k + dk) * j_c * j_c;
        } else if (delta > 0.0) {
          bound_K += dk * j_c * j_c + k * (j + j_c) * e_J;  // k'J'J'ᵀ − kJJᵀ
        }
        scale_K += (k + dk) * j_c * j_c;
      }
      // The double rounding of both evaluations.
      const double slack_F = 1e-12 * (1.0 + scale_F), slack_K = 1e-12 * (1.0 + scale_K);
      const double err_force = glm::length(b.F_T_W.force - a.F_T_W.force);
      const double err_torque = glm::length(b.F_T_W.torque - a.F_T_W.torque);
      const double err_K = (b.K - a.K).norm();
      EXPECT_LE(err_force, bound_force + slack_F) << trial << " " << pose;
      EXPECT_LE(err_torque, bound_torque + slack_F) << trial << " " << pose;
      EXPECT_LE(err_K, bound_K + slack_K) << trial << " " << pose;
      if (!ambiguous) {
        EXPECT_EQ(a.active_contacts, b.active_contacts);
      }
      worst_force = std::max(worst_force, err_force / (bound_force + slack_F));
      worst_torque = std::max(worst_torque, err_torque / (bound_torque + slack_F));
      worst_K = std::max(worst_K, err_K / (bound_K + slack_K));
      largest_force_n = std::max(largest_force_n, err_force);
      active += a.active_contacts;
      ++compared;
    }
  }
  EXPECT_GT(active, compared);  // the poses do press: on average more than one contact active
  std::cout << "[ measured ] over " << compared << " poses: force error up to " << largest_force_n
            << " N; worst fraction of the bound: force " << worst_force << ", torque "
            << worst_torque << ", stiffness " << worst_K << "\n";
}

TEST(CompactContactModel, BytesSitWhereProtocolHSaysAndAreFewerThanTheFloatEncoding) {
  const MacKey key = TestKey();
  std::mt19937 rng(3);
  // protocol.h's layout counted by hand.
  EXPECT_EQ(kCompactContactModelFixedBytes, std::size_t{4 + 4 + 4 + 4 + 3 * 2 + 3 * 4 + 10 + 1});
  EXPECT_EQ(kCompactContactBytes, std::size_t{4 + 3 * 4 + 3 * 4 + 4 + 3 * 2 + 2 * 2});
  EXPECT_EQ(kAtContacts, kCompactContactModelFixedBytes);
  std::string sizes;
  for (int n = 0; n <= kMaxWireContacts; ++n) {
    const ContactModelMessage m = RandomModel(rng, n);
    const Datagram compact = EncodeCompactContactModel(TestHeader(), m, key);
    const Datagram full = EncodeContactModel({MessageType::kContactModel, 7, 3, 11}, m, key);
    EXPECT_EQ(compact.size, kHeaderBytes + kCompactContactModelFixedBytes +
                                n * kCompactContactBytes + kDepthFieldIdCountBytes + kMacBytes);
    EXPECT_LE(compact.size, kMaxDatagramBytes);
    if (n >= 1) {
      EXPECT_LT(compact.size, full.size) << n;
    }
    sizes += " " + std::to_string(n) + ":" + std::to_string(compact.size) + "/" +
             std::to_string(full.size);

    // The fields at their offsets.
    const auto b = BodyOf(compact);
    EXPECT_EQ(compact.bytes[kHeaderTypeOffset], 12);  // the type
    EXPECT_EQ(Get<std::uint32_t>(b, kAtSeq), m.model.tool_state_seq);
    // The echo's and hold's whole µs (rounded to nearest), the echo's low 32 bits.
    EXPECT_EQ(Get<std::uint32_t>(b, kAtSendTime),
              static_cast<std::uint32_t>((m.tool_state_send_time_ns + 500) / 1000));
    EXPECT_EQ(Get<std::uint32_t>(b, kAtHold), static_cast<std::uint32_t>((m.hold_ns + 500) / 1000));
    EXPECT_EQ(Get<std::uint32_t>(b, kAtSteps), static_cast<std::uint32_t>(m.remote_step_count));
    EXPECT_EQ(Get<std::uint16_t>(b, kAtTimes + 4), std::lround(m.step_us));
    EXPECT_EQ(Get<float>(b, kAtP + 8), static_cast<float>(m.model.X_WT0.translation.z));
    // Smallest three: the index of the largest |component| (w, x, y, z), then the other three in
    // 26-bit two's complement, each the component (sign of the largest made +) over the step.
    const glm::dquat& q = m.model.X_WT0.rotation;
    const std::array<double, 4> qc{q.w, q.x, q.y, q.z};
    const auto largest = static_cast<std::size_t>(QuaternionBits(b, 0, 2));
    for (std::size_t k = 0; k < 4; ++k) EXPECT_GE(std::abs(qc[largest]), std::abs(qc[k]));
    int slot = 0;
    for (std::size_t k = 0; k < 4; ++k) {
      if (k == largest) continue;
      auto field = static_cast<std::int64_t>(QuaternionBits(b, 2 + 26 * slot++, 26));
      if (field >= (std::int64_t{1} << 25)) field -= std::int64_t{1} << 26;
      const double expected = std::copysign(1.0, qc[largest]) * qc[k] / kCompactModelQuaternionStep;
      EXPECT_LE(std::abs(static_cast<double>(field) - expected), 0.5 + 1e-6) << k;
    }
    EXPECT_EQ(Get<std::uint8_t>(b, kAtCount), n);
    for (int i = 0; i < n; ++i) {
      const ContactLinearization& c = m.model.contacts[i];
      const std::size_t at = kAtContacts + i * kCompactContactBytes;
      EXPECT_EQ(Get<float>(b, at + kAtDepth), static_cast<float>(c.depth_m));
      EXPECT_EQ(Get<float>(b, at + kAtK), static_cast<float>(c.stiffness_n_per_m));
      EXPECT_EQ(Get<float>(b, at + kAtDx + 4), static_cast<float>(c.gradient.d_translation_W.y));
      EXPECT_EQ(Get<float>(b, at + kAtDtheta + 8), static_cast<float>(c.gradient.d_rotation_W.z));
      // From p_WT0 as the receiver reads it (f32).
      const double p0x = static_cast<float>(m.model.X_WT0.translation.x);
      EXPECT_EQ(Get<std::int16_t>(b, at + kAtPoint),
                std::lround((c.point_W.x - p0x) / kCompactPointStepM));
      // The octahedral u of an upper-hemisphere normal is x/‖n‖₁.
      if (c.normal_W.z >= 0.0) {
        const double l1 = std::abs(c.normal_W.x) + std::abs(c.normal_W.y) + c.normal_W.z;
        EXPECT_EQ(Get<std::int16_t>(b, at + kAtNormal), std::lround(c.normal_W.x / l1 * 32767));
      }
    }
  }
  std::cout << "[ measured ] datagram bytes n:compact/float" << sizes << "\n";
}

TEST(CompactContactModel, EveryTruncationAndWrongLengthOrCountIsRefused) {
  const MacKey key = TestKey();
  std::mt19937 rng(9);
  for (const int n : {0, 3, kMaxWireContacts}) {
    const std::vector<std::uint8_t> body = CompactBody(RandomModel(rng, n), key);
    ContactModelMessage out;
    ASSERT_EQ(DecodeCompactContactModel(body, out, kNowNs), DecodeStatus::kOk);
    out.hold_ns = -12345;  // must stay as it is whenever decoding fails
    for (std::size_t len = 0; len < body.size(); ++len) {
      EXPECT_EQ(DecodeCompactContactModel(std::span(body).first(len), out, kNowNs),
                DecodeStatus::kTooShort)
          << n << " " << len;
    }
    std::vector<std::uint8_t> longer = body;
    longer.push_back(0);
    EXPECT_EQ(DecodeCompactContactModel(longer, out, kNowNs), DecodeStatus::kTooLong);
    // A count above kMaxWireContacts, with the bytes it would need or without.
    std::vector<std::uint8_t> over = body;
    over[kAtCount] = kMaxWireContacts + 1;
    over.resize(kCompactContactModelFixedBytes + (kMaxWireContacts + 1) * kCompactContactBytes);
    EXPECT_EQ(DecodeCompactContactModel(over, out, kNowNs), DecodeStatus::kBadCount);
    over[kAtCount] = 255;
    EXPECT_EQ(DecodeCompactContactModel(over, out, kNowNs), DecodeStatus::kBadCount);
    // A count that disagrees with the length.
    if (n > 0 && n < kMaxWireContacts) {
      std::vector<std::uint8_t> wrong = body;
      wrong[kAtCount] = static_cast<std::uint8_t>(n + 1);
      EXPECT_EQ(DecodeCompactContactModel(wrong, out, kNowNs), DecodeStatus::kTooShort);
      // One fewer: the depth-field section then starts inside the last contact, and its count,
      // length or values refuse it.
      wrong[kAtCount] = static_cast<std::uint8_t>(n - 1);
      EXPECT_NE(DecodeCompactContactModel(wrong, out, kNowNs), DecodeStatus::kOk);
    }
    EXPECT_EQ(out.hold_ns, -12345);
  }
}

TEST(CompactContactModel, TinyGradientComponentsBesideTheNormalSurvive) {
  // The case that sank a per-message i16 step: a gradient's in-plane components many orders
  // below its normal component (a tool resting on a ridge crest, where rounding noise is what
  // breaks the symmetry). Each must come back to 2⁻²⁴ of itself, not be zeroed.
  const MacKey key = TestKey();
  std::mt19937 rng(7);
  ContactModelMessage m = RandomModel(rng, 2);
  m.model.contacts[0].gradient.d_translation_W = {3e-9, -2e-7, -1.0};
  m.model.contacts[0].gradient.d_rotation_W = {1e-10, 0.0149, -4e-8};
  m.model.contacts[1].gradient.d_translation_W = {0.9, 1e-12, -0.4};
  ContactModelMessage out;
  ASSERT_EQ(OpenCompact(EncodeCompactContactModel(TestHeader(), m, key), key, out),
            DecodeStatus::kOk);
  for (int i = 0; i < 2; ++i) {
    for (int k = 0; k < 3; ++k) {
      const double a = m.model.contacts[i].gradient.d_translation_W[k];
      const double b = m.model.contacts[i].gradient.d_rotation_W[k];
      EXPECT_LE(std::abs(out.model.contacts[i].gradient.d_translation_W[k] - a), F32Bound(a));
      EXPECT_LE(std::abs(out.model.contacts[i].gradient.d_rotation_W[k] - b), F32Bound(b));
      if (a != 0.0) EXPECT_NE(out.model.contacts[i].gradient.d_translation_W[k], 0.0);
    }
  }
}

TEST(CompactContactModel, MarkedAndImpossibleValuesAreRefused) {
  const MacKey key = TestKey();
  std::mt19937 rng(4);
  const std::vector<std::uint8_t> body = CompactBody(RandomModel(rng, 3), key);
  const std::size_t c1 = kAtContacts + kCompactContactBytes;  // the second contact
  struct Case {
    const char* what;
    std::size_t at;
    enum { kI16, kF32, kU16 } kind;
    double value;
    DecodeStatus expected;
  };
  const float big = std::numeric_limits<float>::infinity();
  for (const Case& t : std::initializer_list<Case>{
           {"d_translation NaN", c1 + kAtDx + 4, Case::kF32, kNaN, DecodeStatus::kNonFinite},
           {"d_rotation inf", c1 + kAtDtheta, Case::kF32, big, DecodeStatus::kNonFinite},
           {"point marker", c1 + kAtPoint + 4, Case::kI16, kCompactNotFinite,
            DecodeStatus::kNonFinite},
           {"normal marker", c1 + kAtNormal + 2, Case::kI16, kCompactNotFinite,
            DecodeStatus::kNonFinite},
           {"depth NaN", c1 + kAtDepth, Case::kF32, kNaN, DecodeStatus::kNonFinite},
           {"stiffness inf", c1 + kAtK, Case::kF32, big, DecodeStatus::kNonFinite},
           {"stiffness negative", c1 + kAtK, Case::kF32, -1.0, DecodeStatus::kBadValue},
           {"p_WT0 NaN", kAtP, Case::kF32, kNaN, DecodeStatus::kNonFinite},
           {"p_WT0 inf", kAtP + 8, Case::kF32, -big, DecodeStatus::kNonFinite},
           {"time marker", kAtTimes + 2, Case::kU16, kCompactTimeNotFinite,
            DecodeStatus::kNonFinite},
       }) {
    std::vector<std::uint8_t> bad = body;
    if (t.kind == Case::kI16) Put(bad, t.at, static_cast<std::int16_t>(t.value));
    if (t.kind == Case::kU16) Put(bad, t.at, static_cast<std::uint16_t>(t.value));
    if (t.kind == Case::kF32) Put(bad, t.at, static_cast<float>(t.value));
    ContactModelMessage out;
    EXPECT_EQ(DecodeCompactContactModel(bad, out, kNowNs), t.expected) << t.what;
  }
  // Quaternion bits no unit quaternion encodes to: a component of −2²⁵ (the one 26-bit value
  // outside ±(2²⁵ − 1)), or three components whose squares sum above 1 (each 0.7, 0.7, 0.7).
  // Three components of ±(2²⁵ − 1)·step = ±1/√2 with the largest restored as 0 are a value.
  const auto quaternion = [&](int largest, std::int64_t c0, std::int64_t c1, std::int64_t c2) {
    std::vector<std::uint8_t> q = body;
    std::array<std::uint8_t, 10> field{};
    const auto put = [&](int at, int width, std::uint64_t v) {
      for (int i = 0; i < width; ++i) {
        if ((v >> i) & 1u) field[static_cast<std::size_t>((at + i) / 8)] |= 1u << ((at + i) % 8);
      }
    };
    put(0, 2, static_cast<std::uint64_t>(largest));
    put(2, 26, static_cast<std::uint64_t>(c0));
    put(28, 26, static_cast<std::uint64_t>(c1));
    put(54, 26, static_cast<std::uint64_t>(c2));
    std::copy(field.begin(), field.end(), q.begin() + kAtQ);
    return q;
  };
  ContactModelMessage out;
  const std::int64_t max = kCompactModelQuaternionMax;
  const auto seven_tenths = static_cast<std::int64_t>(0.7 / kCompactModelQuaternionStep);
  EXPECT_EQ(DecodeCompactContactModel(quaternion(0, -max - 1, 0, 0), out, kNowNs),
            DecodeStatus::kBadValue);
  EXPECT_EQ(DecodeCompactContactModel(quaternion(3, seven_tenths, seven_tenths, -seven_tenths), out,
                                      kNowNs),
            DecodeStatus::kBadValue);
  ASSERT_EQ(DecodeCompactContactModel(quaternion(2, max, -max, 0), out, kNowNs), DecodeStatus::kOk);
  EXPECT_NEAR(glm::length(out.model.X_WT0.rotation), 1.0, 1e-12);
  EXPECT_NEAR(std::abs(out.model.X_WT0.rotation.w), std::sqrt(0.5), 1e-7);
  EXPECT_NEAR(std::abs(out.model.X_WT0.rotation.x), std::sqrt(0.5), 1e-7);
  // The extreme i16 values other than the marker are values: ±32767 steps.
  std::vector<std::uint8_t> edge = body;
  Put(edge, c1 + kAtPoint, std::int16_t{-32767});
  Put(edge, c1 + kAtNormal, std::int16_t{32767});
  Put(edge, c1 + kAtNormal + 2, std::int16_t{-32767});
  ASSERT_EQ(DecodeCompactContactModel(edge, out, kNowNs), DecodeStatus::kOk);
  EXPECT_NEAR(out.model.contacts[1].point_W.x - out.model.X_WT0.translation.x, -kCompactPointRangeM,
              1e-12);
  EXPECT_NEAR(glm::length(out.model.contacts[1].normal_W), 1.0, 1e-12);
}

// The encoder's side: a non-finite field (which the float encoding sends as it is, for the
// receiver to refuse) is marked, so that the receiver refuses the compact datagram the same way;
// out-of-range finite values are clamped as protocol.h says.
TEST(CompactContactModel, NonFiniteFieldsAreRefusedAtTheReceiverAndFarValuesClamped) {
  const MacKey key = TestKey();
  std::mt19937 rng(12);
  const ContactModelMessage base = RandomModel(rng, 4);
  using Mutate = void (*)(ContactModelMessage&);
  struct Case {
    const char* what;
    Mutate mutate;
    bool float_refuses;  // the float encoding refuses it too
  };
  for (const Case& t : std::initializer_list<Case>{
           {"depth NaN", [](ContactModelMessage& m) { m.model.contacts[1].depth_m = kNaN; }, true},
           {"depth -inf", [](ContactModelMessage& m) { m.model.contacts[0].depth_m = -kInf; },
            true},
           {"stiffness inf",
            [](ContactModelMessage& m) { m.model.contacts[2].stiffness_n_per_m = kInf; }, true},
           {"d_translation NaN",
            [](ContactModelMessage& m) { m.model.contacts[1].gradient.d_translation_W.y = kNaN; },
            true},
           {"d_rotation inf",
            [](ContactModelMessage& m) { m.model.contacts[3].gradient.d_rotation_W.z = -kInf; },
            true},
           {"point NaN", [](ContactModelMessage& m) { m.model.contacts[0].point_W.x = kNaN; },
            true},
           {"normal NaN", [](ContactModelMessage& m) { m.model.contacts[2].normal_W.z = kNaN; },
            true},
           {"normal inf", [](ContactModelMessage& m) { m.model.contacts[2].normal_W.x = kInf; },
            true},
           {"normal zero",
            [](ContactModelMessage& m) { m.model.contacts[2].normal_W = glm::dvec3(0.0); }, false},
           {"p_WT0 NaN", [](ContactModelMessage& m) { m.model.X_WT0.translation.y = kNaN; }, true},
           {"rotation NaN", [](ContactModelMessage& m) { m.model.X_WT0.rotation.x = kNaN; }, true},
           // Finite, but beyond f32's range (the float encoding carries it as f64).
           {"p_WT0 1e300", [](ContactModelMessage& m) { m.model.X_WT0.translation.z = 1e300; },
            false},
           {"collision_us NaN",
            [](ContactModelMessage& m) {
              m.collision_us = std::numeric_limits<float>::quiet_NaN();
            },
            true},
           {"step_us inf",
            [](ContactModelMessage& m) { m.step_us = std::numeric_limits<float>::infinity(); },
            true},
           // Finite, but the step it needs is beyond f32's range (sent infinite).
           {"gradient 1e300",
            [](ContactModelMessage& m) { m.model.contacts[1].gradient.d_translation_W.x = 1e300; },
            false},
       }) {
    ContactModelMessage m = base;
    t.mutate(m);
    ContactModelMessage out;
    EXPECT_EQ(OpenCompact(EncodeCompactContactModel(TestHeader(), m, key), key, out),
              DecodeStatus::kNonFinite)
        << t.what;
    if (t.float_refuses) {
      EXPECT_EQ(
          OpenFloat(EncodeContactModel({MessageType::kContactModel, 7, 3, 11}, m, key), key, out),
          DecodeStatus::kNonFinite)
          << t.what;
    }
  }

  // Far points are clamped per axis, times saturate, the step count is sent whole, all-zero
  // gradients come back as zeros, and a count above the wire's limit is cut.
  ContactModelMessage m = base;
  m.model.contacts[0].point_W = m.model.X_WT0.translation + glm::dvec3(2.0, -0.1, -7.0);
  m.collision_us = 1e7f;
  m.texture_us = -5.0f;
  m.step_us = 65534.4f;
  m.remote_step_count = std::numeric_limits<std::uint64_t>::max() - 6;
  m.hold_ns = std::int64_t{1} << 50;  // beyond the u32 µs: sent as 2³² − 1 µs
  for (int i = 0; i < m.model.num_contacts; ++i) m.model.contacts[i].gradient = {};
  ContactModelMessage out;
  ASSERT_EQ(OpenCompact(EncodeCompactContactModel(TestHeader(), m, key), key, out),
            DecodeStatus::kOk);
  const glm::dvec3 offset = out.model.contacts[0].point_W - out.model.X_WT0.translation;
  EXPECT_NEAR(offset.x, kCompactPointRangeM, 1e-12);
  EXPECT_NEAR(offset.y, -0.1, kCompactPointErrorM + 1e-12);
  EXPECT_NEAR(offset.z, -kCompactPointRangeM, 1e-12);
  EXPECT_EQ(out.collision_us, static_cast<float>(kCompactMaxTimeUs));
  EXPECT_EQ(out.texture_us, 0.0f);
  EXPECT_EQ(out.step_us, 65534.0f);
  EXPECT_EQ(out.remote_step_count, 0xFFFF'FFFFu - 6);  // its low 32 bits
  EXPECT_EQ(out.hold_ns, std::int64_t{0xFFFF'FFFF} * 1000);
  for (int i = 0; i < out.model.num_contacts; ++i) {
    EXPECT_EQ(out.model.contacts[i].gradient.d_translation_W, glm::dvec3(0.0));
    EXPECT_EQ(out.model.contacts[i].gradient.d_rotation_W, glm::dvec3(0.0));
  }
  ContactModelMessage many = RandomModel(rng, kMaxWireContacts);
  many.model.num_contacts = kMaxWireContacts + 5;
  ASSERT_EQ(OpenCompact(EncodeCompactContactModel(TestHeader(), many, key), key, out),
            DecodeStatus::kOk);
  EXPECT_EQ(out.model.num_contacts, kMaxWireContacts);
}

TEST(CompactContactModel, BitFlipsAndRandomBodiesNeverCrashNorDecodeToNonFiniteValues) {
  const MacKey key = TestKey();
  std::mt19937 rng(21);
  int accepted = 0, refused = 0;
  for (int trial = 0; trial < 20000; ++trial) {
    std::vector<std::uint8_t> body =
        CompactBody(RandomModel(rng, trial % (kMaxWireContacts + 1)), key);
    const int flips = 1 + static_cast<int>(rng() % 4);
    for (int f = 0; f < flips; ++f) {
      const std::size_t bit = rng() % (8 * body.size());
      body[bit / 8] = static_cast<std::uint8_t>(body[bit / 8] ^ (1u << (bit % 8)));
    }
    ContactModelMessage out;
    if (DecodeCompactContactModel(body, out, kNowNs) == DecodeStatus::kOk) {
      ++accepted;
      ExpectSane(out);
      if (::testing::Test::HasFailure()) return;
    } else {
      ++refused;
    }
  }
  std::vector<std::uint8_t> noise;
  for (int trial = 0; trial < 20000; ++trial) {
    noise.resize(rng() % 700);
    for (auto& byte : noise) byte = static_cast<std::uint8_t>(rng());
    if (noise.size() > kAtCount && trial % 2 == 0) {  // a plausible count and length
      const std::size_t n = rng() % (kMaxWireContacts + 1);
      noise.resize(kCompactContactModelFixedBytes + n * kCompactContactBytes);
      noise[kAtCount] = static_cast<std::uint8_t>(n);
    }
    ContactModelMessage out;
    if (DecodeCompactContactModel(noise, out, kNowNs) == DecodeStatus::kOk) {
      ++accepted;
      ExpectSane(out);
      if (::testing::Test::HasFailure()) return;
    } else {
      ++refused;
    }
  }
  std::cout << "[ measured ] corrupted bodies: " << accepted << " decoded (all finite), " << refused
            << " refused\n";
}

// Version 11 sends the echo as the low 32 bits of its whole µs: the receiver takes the time
// within ±2³¹ µs of its own clock, so a model's echo comes back right across the wrap of those
// bits, a round trip or 35 minutes old, and even a little ahead of the receiver's clock.
TEST(CompactContactModel, TheEchoComesBackAcrossTheWrapOfItsLow32Bits) {
  const MacKey key = TestKey();
  std::mt19937 rng(33);
  const ContactModelMessage base = RandomModel(rng, 2);
  const std::int64_t wrap_us = std::int64_t{1} << 32;
  for (const std::int64_t wraps : {std::int64_t{1}, std::int64_t{1000}, std::int64_t{2000000}}) {
    for (const std::int64_t echo_offset_ns :
         {-3'000'000'000LL, -1'499LL, -500LL, -499LL, 0LL, 499LL, 2'000'000'000LL}) {
      for (const std::int64_t age_ns :
           {150'000'000LL, 1LL, 35LL * 60 * 1'000'000'000, -1'000'000'000LL}) {
        ContactModelMessage m = base;
        m.tool_state_send_time_ns = wraps * wrap_us * 1000 + echo_offset_ns;
        const std::vector<std::uint8_t> body = CompactBody(m, key);
        ContactModelMessage out;
        ASSERT_EQ(DecodeCompactContactModel(body, out, m.tool_state_send_time_ns + age_ns),
                  DecodeStatus::kOk);
        EXPECT_LE(std::abs(out.tool_state_send_time_ns - m.tool_state_send_time_ns), 500)
            << wraps << " " << echo_offset_ns << " " << age_ns;
        EXPECT_EQ(out.tool_state_send_time_ns % 1000, 0);
      }
    }
  }
  // Older than 2³¹ µs (35.8 min) the bits name a time 2³² µs later: the bound is stated, not
  // stretched.
  ContactModelMessage m = base;
  m.tool_state_send_time_ns = kNowNs;
  ContactModelMessage out;
  ASSERT_EQ(DecodeCompactContactModel(CompactBody(m, key), out,
                                      kNowNs + (wrap_us / 2 + 1'000'000) * 1000),
            DecodeStatus::kOk);
  EXPECT_EQ(out.tool_state_send_time_ns, kNowNs + wrap_us * 1000);
}

// Version 11 does not send the wrench at q0: the receiver sums it from the contacts as the
// sender's AssembleContactModel did. Two routes: the assembly's incremental sum over the
// linearizations at the sender, and the receiver's sum over what it decoded.
TEST(CompactContactModel, TheWrenchAtQ0IsTheSendersAssemblyOfTheContactsItCarries) {
  const MacKey key = TestKey();
  std::mt19937 rng(41);
  int pressed = 0;
  for (int trial = 0; trial < 300; ++trial) {
    const ContactModelMessage shape = RandomModel(rng, 1 + trial % kMaxWireContacts);
    std::vector<ContactLinearization> lins(shape.model.contacts.begin(),
                                           shape.model.contacts.begin() + shape.model.num_contacts);
    ContactModelMessage m = shape;
    m.model.num_contacts = 0;
    m.model.F_T_W_at_q0 = {};
    ASSERT_EQ(AssembleContactModel(lins, m.model), static_cast<int>(lins.size()));
    ContactModelMessage out;
    ASSERT_EQ(OpenCompact(EncodeCompactContactModel(TestHeader(), m, key), key, out),
              DecodeStatus::kOk);
    // Each term is k·δ·J of f32 factors (≤ 2⁻²⁴ each; 8·2⁻²⁴ of the term with margin).
    double bound = 1e-12;
    for (const ContactLinearization& c : lins) {
      const double kd = c.stiffness_n_per_m * std::max(c.depth_m, 0.0);
      bound += 8.0 * kCompactF32RelativeError * kd *
               (glm::length(c.gradient.d_translation_W) + glm::length(c.gradient.d_rotation_W));
    }
    const Wrench& a = out.model.F_T_W_at_q0;
    const Wrench& b = m.model.F_T_W_at_q0;
    EXPECT_LE(glm::length(a.force - b.force), bound) << trial;
    EXPECT_LE(glm::length(a.torque - b.torque), bound) << trial;
    if (glm::length(b.force) > 0.0) ++pressed;
  }
  EXPECT_GT(pressed, 100);  // most models press (half the depths are positive)
}

// The operator counts the remote node's steps from the low 32 bits a compact model carries:
// across the wrap of those bits, and from 0 again behind a restarted node.
TEST(CompactContactModel, RemoteStepsAreCountedAcrossTheWrapAndARestart) {
  EXPECT_EQ(RemoteStepsBetween(100, 250), 150u);
  EXPECT_EQ(RemoteStepsBetween(0xFFFF'FFF0u, 0x10u), 0x20u);  // the count's low bits wrapped
  EXPECT_EQ(RemoteStepsBetween(7, 7), 0u);
  EXPECT_EQ(RemoteStepsBetween(5'000'000, 1'200), 1'200u);  // a restarted node: its own count
  // Summed over a stream of models whose full count passes 2³² twice, the sum is the count's.
  std::uint64_t count = 0xFFFF'0000u, total = 0;
  std::uint32_t last = static_cast<std::uint32_t>(count);
  const std::uint64_t first = count;
  for (int k = 0; k < 20000; ++k) {
    count += 1 + static_cast<std::uint64_t>(k % 7) * 60'000'000;  // up to 3.6e8 steps between
    const auto low = static_cast<std::uint32_t>(count);
    total += RemoteStepsBetween(last, low);
    last = low;
  }
  ASSERT_GT(count - first, 2 * (std::uint64_t{1} << 32));
  EXPECT_EQ(total, count - first);
}

TEST(CompactContactModel, IsATypeOfItsOwnThatTheOperatorAccepts) {
  const MacKey key = TestKey();
  std::mt19937 rng(1);
  const Datagram d = EncodeCompactContactModel(TestHeader(), RandomModel(rng, 2), key);
  Header h;
  ASSERT_EQ(PeekHeader(d.view(), h), DecodeStatus::kOk);
  EXPECT_EQ(h.type, MessageType::kCompactContactModel);
  EXPECT_EQ(h.sequence, 3u);
  EXPECT_STREQ(ToString(MessageType::kCompactContactModel), "compact_contact_model");
  EXPECT_TRUE(Accepts(LinkRole::kOperator, MessageType::kCompactContactModel));
  EXPECT_FALSE(Accepts(LinkRole::kRemote, MessageType::kCompactContactModel));
  EXPECT_EQ(kCodecCompactContactModel & kCodecDracoMesh, 0u);
}

}  // namespace
}  // namespace ht::wire
