// The compact messages' quantization (compact_quantization.h).

#include "compact_quantization.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <concepts>
#include <cstring>
#include <limits>
#include <span>
#include <type_traits>

#include "haptic_core/byte_order.h"
#include "haptic_core/contact_assembly.h"
#include "message_checks.h"
#include "transport/messages.h"

namespace ht::wire::detail {

// infinite or out-of-range double is ever converted to an integer.

float F32(double v) noexcept { return static_cast<float>(v); }

/// round(steps) within ±kCompactI16Max (±∞ go to the ends); kCompactNotFinite for NaN.
std::int16_t RoundToI16(double steps) noexcept {
  if (std::isnan(steps)) return kCompactNotFinite;
  const double limit = kCompactI16Max;
  return static_cast<std::int16_t>(std::clamp(std::round(steps), -limit, limit));
}

/// `value` in units of `step`: kCompactNotFinite for a value that is not finite; 0 for a step that
/// is 0 (every finite value it steps is then 0) or infinite (the receiver rejects it).
std::int16_t QuantizeI16(double value, double step) noexcept {
  if (!std::isfinite(value)) return kCompactNotFinite;
  if (!(step > 0.0) || !std::isfinite(step)) return 0;
  return RoundToI16(value / step);
}

/// A time (µs) rounded within [0, kCompactMaxTimeUs]; kCompactTimeNotFinite when not finite.
std::uint16_t QuantizeTimeUs(float us) noexcept {
  if (!std::isfinite(us)) return kCompactTimeNotFinite;
  return static_cast<std::uint16_t>(
      std::round(std::clamp(static_cast<double>(us), 0.0, kCompactMaxTimeUs)));
}

double SignNotZero(double v) noexcept { return v < 0.0 ? -1.0 : 1.0; }

/// Octahedral (u, v)·kCompactI16Max of the direction of `n` (protocol.h); kCompactNotFinite twice
/// for a direction that is not finite or zero.
std::array<std::int16_t, 2> EncodeOctahedral(const glm::dvec3& n) noexcept {
  if (!Finite3(n)) return {kCompactNotFinite, kCompactNotFinite};
  const double largest = std::max({std::abs(n.x), std::abs(n.y), std::abs(n.z)});
  if (!(largest > 0.0)) return {kCompactNotFinite, kCompactNotFinite};
  const glm::dvec3 m = n / largest;  // so that the 1-norm neither overflows nor underflows
  const glm::dvec3 p = m / (std::abs(m.x) + std::abs(m.y) + std::abs(m.z));
  const bool upper = p.z >= 0.0;
  const double u = upper ? p.x : (1.0 - std::abs(p.y)) * SignNotZero(p.x);
  const double v = upper ? p.y : (1.0 - std::abs(p.x)) * SignNotZero(p.y);
  return {RoundToI16(u * kCompactI16Max), RoundToI16(v * kCompactI16Max)};
}

/// The unit direction of octahedral (u, v)·kCompactI16Max, each within ±kCompactI16Max.
glm::dvec3 DecodeOctahedral(const std::array<std::int16_t, 2>& uv) noexcept {
  const double u = uv[0] / static_cast<double>(kCompactI16Max);
  const double v = uv[1] / static_cast<double>(kCompactI16Max);
  glm::dvec3 p{u, v, 1.0 - std::abs(u) - std::abs(v)};
  if (p.z < 0.0) {
    p.x = (1.0 - std::abs(v)) * SignNotZero(u);
    p.y = (1.0 - std::abs(u)) * SignNotZero(v);
  }
  return glm::normalize(p);  // ‖p‖₁ = 1, so ‖p‖ ≥ 1/√3
}

/// Bit `at + i` of the 80-bit field (lo: bits 0–63, hi: bits 64–79) set from bit i of `value`,
/// for i < width.
void PutBits80(std::uint64_t& lo, std::uint16_t& hi, int at, int width,
               std::uint64_t value) noexcept {
  for (int i = 0; i < width; ++i) {
    if (((value >> i) & 1u) == 0) continue;
    const int bit = at + i;
    if (bit < 64) {
      lo |= std::uint64_t{1} << bit;
    } else {
      hi = static_cast<std::uint16_t>(hi | (1u << (bit - 64)));
    }
  }
}

/// Bits [at, at + width) of the 80-bit field, as an unsigned value.
std::uint64_t GetBits80(std::uint64_t lo, std::uint16_t hi, int at, int width) noexcept {
  std::uint64_t value = 0;
  for (int i = 0; i < width; ++i) {
    const int bit = at + i;
    const std::uint64_t b =
        bit < 64 ? (lo >> bit) & 1u : (static_cast<unsigned>(hi) >> (bit - 64)) & 1u;
    value |= b << i;
  }
  return value;
}

/// "Smallest three" of the unit quaternion `q_in` (finite, not zero; protocol.h), `bits` bits a
/// component: put(at, width, value) writes the index of the largest |component| (0 w, 1 x, 2 y,
/// 3 z, made positive) at bit 0 in 2 bits, then the other three in w, x, y, z order at bits 2,
/// 2 + bits, 2 + 2·bits as two's complement in units of `step` ((1/√2)/(2^(bits−1) − 1)).
/// CompactToolState's 20-bit u64 and CompactContactModel's 26-bit 80-bit field share it.
template <class Put>
void EncodeSmallestThreeBits(const glm::dquat& q_in, int bits, double step, Put&& put) noexcept {
  const glm::dquat q = glm::normalize(q_in);
  const std::array<double, 4> c{q.w, q.x, q.y, q.z};
  int largest = 0;
  for (int k = 1; k < 4; ++k) {
    if (std::abs(c[k]) > std::abs(c[largest])) largest = k;
  }
  const double flip = c[largest] < 0.0 ? -1.0 : 1.0;
  put(0, 2, static_cast<std::uint64_t>(largest));
  const auto max = static_cast<double>((std::int64_t{1} << (bits - 1)) - 1);
  int slot = 0;
  for (int k = 0; k < 4; ++k) {
    if (k == largest) continue;
    const double steps = std::clamp(std::round(flip * c[k] / step), -max, max);
    put(2 + bits * slot++, bits, static_cast<std::uint64_t>(static_cast<std::int64_t>(steps)));
  }
}

/// The unit quaternion of "smallest three" read through get(at, width) (the bits at [at, at +
/// width), unsigned), laid out as EncodeSmallestThreeBits writes it; false for bits no unit
/// quaternion encodes to (a component of −2^(bits−1), or squares summing above 1 + 1e-9).
template <class Get>
bool DecodeSmallestThreeBits(int bits, double step, Get&& get, glm::dquat& q) noexcept {
  const auto largest = static_cast<int>(get(0, 2));
  const std::int64_t half = std::int64_t{1} << (bits - 1);
  std::array<double, 4> c{};
  double sum2 = 0.0;
  int slot = 0;
  for (int k = 0; k < 4; ++k) {
    if (k == largest) continue;
    auto field = static_cast<std::int64_t>(get(2 + bits * slot++, bits));
    if (field >= half) field -= 2 * half;  // two's complement
    if (field < -(half - 1)) return false;
    c[k] = static_cast<double>(field) * step;
    sum2 += c[k] * c[k];
  }
  if (sum2 > 1.0 + 1e-9) return false;  // (rounding alone never takes a real one past 0.75)
  c[largest] = std::sqrt(std::max(0.0, 1.0 - sum2));
  q = glm::normalize(glm::dquat(c[0], c[1], c[2], c[3]));
  return true;
}

/// The contact model's rotation as its 80-bit "smallest three" (protocol.h, version 11).
void EncodeModelSmallestThree(const glm::dquat& q, std::uint64_t& lo, std::uint16_t& hi) noexcept {
  lo = 0;
  hi = 0;
  EncodeSmallestThreeBits(
      q, kCompactModelQuaternionBits, kCompactModelQuaternionStep,
      [&](int at, int width, std::uint64_t v) { PutBits80(lo, hi, at, width, v); });
}

bool DecodeModelSmallestThree(std::uint64_t lo, std::uint16_t hi, glm::dquat& q) noexcept {
  return DecodeSmallestThreeBits(
      kCompactModelQuaternionBits, kCompactModelQuaternionStep,
      [&](int at, int width) { return GetBits80(lo, hi, at, width); }, q);
}

/// Whole µs of `ns`, rounded to nearest (ties up), for any i64.
std::int64_t RoundToWholeUs(std::int64_t ns) noexcept {
  std::int64_t q = ns / 1000;
  std::int64_t r = ns % 1000;
  if (r < 0) {
    q -= 1;
    r += 1000;
  }
  return r >= 500 ? q + 1 : q;
}

CompactContactModelBody QuantizeContactModel(const ContactModelMessage& m) noexcept {
  const ContactModel& model = m.model;
  CompactContactModelBody b;
  // Low 32 bits: a tool state's sequence is a header sequence (u32); the receiver unwraps the echo
  // against its own clock and counts steps modulo 2³².
  b.tool_state_seq = static_cast<std::uint32_t>(model.tool_state_seq);
  b.tool_state_send_time_us = static_cast<std::uint32_t>(
      static_cast<std::uint64_t>(RoundToWholeUs(m.tool_state_send_time_ns)));
  b.hold_us = static_cast<std::uint32_t>(
      std::clamp<std::int64_t>(RoundToWholeUs(m.hold_ns), 0, 0xFFFF'FFFF));
  b.remote_step_count = static_cast<std::uint32_t>(m.remote_step_count);
  b.collision_us = QuantizeTimeUs(m.collision_us);
  b.texture_us = QuantizeTimeUs(m.texture_us);
  b.step_us = QuantizeTimeUs(m.step_us);
  const glm::dvec3& p_WT0 = model.X_WT0.translation;
  const double f32_max = std::numeric_limits<float>::max();
  bool pose_ok = CheckPose(model.X_WT0) == DecodeStatus::kOk;
  for (int k = 0; k < 3; ++k) {
    // Beyond f32 (or NaN) converting would be undefined: sent as NaN, the receiver rejects it.
    if (!(std::abs(p_WT0[k]) <= f32_max)) pose_ok = false;
    b.p_WT0[k] = pose_ok ? F32(p_WT0[k]) : 0.0f;
  }
  if (pose_ok) {
    EncodeModelSmallestThree(model.X_WT0.rotation, b.q_WT0_low, b.q_WT0_high);
  } else {
    b.p_WT0[0] = std::numeric_limits<float>::quiet_NaN();  // the receiver rejects it: kNonFinite
  }
  const int n = std::clamp(model.num_contacts, 0, kMaxWireContacts);
  b.num_contacts = n;
  for (int i = 0; i < n; ++i) {
    const ContactLinearization& c = model.contacts[i];
    CompactContact& w = b.contacts[i];
    w.depth_m = F32(c.depth_m);
    w.stiffness_n_per_m = F32(c.stiffness_n_per_m);
    for (int k = 0; k < 3; ++k) {
      w.d_translation[k] = F32(c.gradient.d_translation_W[k]);
      w.d_rotation[k] = F32(c.gradient.d_rotation_W[k]);
      // From p_WT0 as the receiver reads it (f32), so that the point's error is the offset's.
      w.point_offset[k] =
          QuantizeI16(c.point_W[k] - static_cast<double>(b.p_WT0[k]), kCompactPointStepM);
    }
    w.normal_oct = EncodeOctahedral(c.normal_W);
  }
  // The ids that fit the datagram (all of them for kMaxWireContacts compact contacts).
  b.num_field_ids = static_cast<int>(
      FlattenFieldIds(model, static_cast<std::size_t>(n),
                      std::span(b.field_ids)
                          .first(static_cast<std::size_t>(DepthFieldIdCapacity(
                              kCompactContactModelFixedBytes, kCompactContactBytes, n)))));
  return b;
}

bool HasMarker(const auto& values) {
  return std::ranges::any_of(values, [](std::int16_t v) { return v == kCompactNotFinite; });
}

bool AllFinite(const auto& values) {
  return std::ranges::all_of(values, [](float v) { return std::isfinite(v); });
}

DecodeStatus Check(const CompactContactModelBody& m) {
  for (int i = 0; i < m.num_contacts; ++i) {
    const CompactContact& c = m.contacts[i];
    if (!std::isfinite(c.depth_m) || !std::isfinite(c.stiffness_n_per_m) ||
        !AllFinite(c.d_translation) || !AllFinite(c.d_rotation) || HasMarker(c.point_offset) ||
        HasMarker(c.normal_oct)) {
      return DecodeStatus::kNonFinite;
    }
    if (c.stiffness_n_per_m < 0.0f) return DecodeStatus::kBadValue;
  }
  std::array<bool, kMaxWireContacts> has_field{};
  for (int j = 0; j < m.num_field_ids; ++j) {
    const WireFieldId& f = m.field_ids[static_cast<std::size_t>(j)];
    if (f.contact >= m.num_contacts || f.id == 0 || has_field[f.contact]) {
      return DecodeStatus::kBadValue;
    }
    has_field[f.contact] = true;
  }
  if (!AllFinite(m.p_WT0)) return DecodeStatus::kNonFinite;
  glm::dquat q;
  if (!DecodeModelSmallestThree(m.q_WT0_low, m.q_WT0_high, q)) return DecodeStatus::kBadValue;
  if (m.collision_us == kCompactTimeNotFinite || m.texture_us == kCompactTimeNotFinite ||
      m.step_us == kCompactTimeNotFinite) {
    return DecodeStatus::kNonFinite;
  }
  return DecodeStatus::kOk;
}

/// The model a CompactContactModel body stands for; `b` passed Check(). The echo is the time
/// within ±2³¹ µs of `receive_time_ns` (the receiver's clock) whose whole µs end in the bits sent.
ContactModelMessage DequantizeContactModel(const CompactContactModelBody& b,
                                           std::int64_t receive_time_ns) noexcept {
  ContactModelMessage m;
  ContactModel& model = m.model;
  model.tool_state_seq = b.tool_state_seq;
  const std::int64_t now_us = RoundToWholeUs(receive_time_ns);
  const auto ahead = static_cast<std::int32_t>(
      b.tool_state_send_time_us - static_cast<std::uint32_t>(static_cast<std::uint64_t>(now_us)));
  // Clamped so that ×1000 stays an i64 for any receive time (a steady clock never comes near).
  constexpr std::int64_t kMaxUs = std::numeric_limits<std::int64_t>::max() / 1000 - (1LL << 32);
  m.tool_state_send_time_ns = std::clamp<std::int64_t>(now_us + ahead, -kMaxUs, kMaxUs) * 1000;
  m.hold_ns = static_cast<std::int64_t>(b.hold_us) * 1000;
  m.remote_step_count = b.remote_step_count;
  m.collision_us = static_cast<float>(b.collision_us);
  m.texture_us = static_cast<float>(b.texture_us);
  m.step_us = static_cast<float>(b.step_us);
  model.X_WT0.translation = glm::dvec3(b.p_WT0[0], b.p_WT0[1], b.p_WT0[2]);
  DecodeModelSmallestThree(b.q_WT0_low, b.q_WT0_high, model.X_WT0.rotation);
  model.num_contacts = b.num_contacts;
  for (int i = 0; i < b.num_contacts; ++i) {
    const CompactContact& w = b.contacts[i];
    ContactLinearization& c = model.contacts[i];
    c.depth_m = w.depth_m;
    c.stiffness_n_per_m = w.stiffness_n_per_m;
    for (int k = 0; k < 3; ++k) {
      c.gradient.d_translation_W[k] = w.d_translation[k];
      c.gradient.d_rotation_W[k] = w.d_rotation[k];
      c.point_W[k] = b.p_WT0[k] + w.point_offset[k] * kCompactPointStepM;
    }
    c.normal_W = DecodeOctahedral(w.normal_oct);
  }
  // Check() found every field id's contact valid and once.
  DistributeFieldIds({b.field_ids.data(), static_cast<std::size_t>(b.num_field_ids)},
                     static_cast<std::size_t>(b.num_contacts), model);
  // Not on the wire (version 11): the sender summed it the same way (AssembleContactModel).
  model.F_T_W_at_q0 = ContactModelWrenchAtQ0(model);
  return m;
}

// CompactToolState (protocol.h).

/// `v` as IEEE-754 binary16 bits, rounded to nearest (ties to even); NaN stays NaN, ±∞ stays ±∞,
/// a finite value beyond ±kCompactTwistMax becomes ±kCompactTwistMax. (glm::packHalf1x16 goes
/// through float, rounding twice, and rounds ties up: not the bound protocol.h states.)
std::uint16_t ToBinary16(double v) noexcept {
  if (std::isnan(v)) return 0x7E00;
  const std::uint16_t sign = std::signbit(v) ? 0x8000 : 0x0000;
  if (std::isinf(v)) return sign | 0x7C00;
  const double a = std::min(std::abs(v), kCompactTwistMax);
  if (a == 0.0) return sign;
  int e = 0;
  std::frexp(a, &e);                          // a = m·2^e, m ∈ [0.5, 1)
  const int exponent = std::max(e - 1, -14);  // a = 1.f·2^exponent, or a subnormal below 2^-14
  // a in units of the binary16 step at this exponent (2^(exponent − 10)): exact, then rounded.
  double steps = std::nearbyint(std::ldexp(a, 10 - exponent));
  if (exponent == -14 && steps < 1024.0) return sign | static_cast<std::uint16_t>(steps);
  int biased = exponent + 15;
  if (steps >= 2048.0) {  // rounded up to the next power of two
    steps = 1024.0;
    ++biased;
  }
  return sign | static_cast<std::uint16_t>(biased << 10) |
         static_cast<std::uint16_t>(static_cast<int>(steps) - 1024);
}

/// The value of binary16 bits (NaN and ±∞ included).
double FromBinary16(std::uint16_t h) noexcept {
  const double sign = (h & 0x8000) ? -1.0 : 1.0;
  const int biased = (h >> 10) & 0x1F;
  const int fraction = h & 0x3FF;
  if (biased == 0x1F) {
    return fraction ? std::numeric_limits<double>::quiet_NaN()
                    : sign * std::numeric_limits<double>::infinity();
  }
  if (biased == 0) return sign * std::ldexp(fraction, -24);
  return sign * std::ldexp(1024 + fraction, biased - 25);
}

bool IsFiniteBinary16(std::uint16_t h) noexcept { return ((h >> 10) & 0x1F) != 0x1F; }

/// The unit quaternion `q` as CompactToolState's "smallest three" (20 bits a component, u64).
std::uint64_t EncodeSmallestThree(const glm::dquat& q) noexcept {
  std::uint64_t bits = 0;
  EncodeSmallestThreeBits(q, kCompactQuaternionBits, kCompactQuaternionStep,
                          [&](int at, int width, std::uint64_t v) {
                            bits |= (v & ((std::uint64_t{1} << width) - 1)) << at;
                          });
  return bits;
}

/// The unit quaternion of CompactToolState's "smallest three" bits; false for bits no unit
/// quaternion encodes to (bits 62–63 set among them).
bool DecodeSmallestThree(std::uint64_t bits, glm::dquat& q) noexcept {
  if (bits >> (2 + 3 * kCompactQuaternionBits)) return false;
  return DecodeSmallestThreeBits(
      kCompactQuaternionBits, kCompactQuaternionStep,
      [bits](int at, int width) { return (bits >> at) & ((std::uint64_t{1} << width) - 1); }, q);
}

CompactToolStateBody QuantizeToolState(const ToolStateMessage& m) noexcept {
  CompactToolStateBody b;
  const double f32_max = std::numeric_limits<float>::max();
  bool pose_ok = CheckPose(m.X_WT) == DecodeStatus::kOk;
  for (int k = 0; k < 3; ++k) {
    const double p = m.X_WT.translation[k];
    if (!(std::abs(p) <= f32_max)) {
      pose_ok = false;  // beyond f32 (or NaN): converting would be undefined
      b.p_WT[k] = 0.0f;
    } else {
      b.p_WT[k] = F32(p);
    }
  }
  if (pose_ok) {
    b.q_WT_smallest_three = EncodeSmallestThree(m.X_WT.rotation);
  } else {
    b.p_WT[0] = std::numeric_limits<float>::quiet_NaN();  // the receiver rejects it: kNonFinite
  }
  for (int k = 0; k < 3; ++k) {
    b.V_WT_W[k] = ToBinary16(m.V_WT_W.linear[k]);
    b.V_WT_W[3 + k] = ToBinary16(m.V_WT_W.angular[k]);
  }
  return b;
}

DecodeStatus Check(const CompactToolStateBody& m) {
  if (!AllFinite(m.p_WT) ||
      !std::ranges::all_of(m.V_WT_W, [](std::uint16_t h) { return IsFiniteBinary16(h); })) {
    return DecodeStatus::kNonFinite;
  }
  glm::dquat q;
  if (!DecodeSmallestThree(m.q_WT_smallest_three, q)) return DecodeStatus::kBadValue;
  return DecodeStatus::kOk;
}

/// The tool state a CompactToolState body stands for; `b` passed Check().
ToolStateMessage DequantizeToolState(const CompactToolStateBody& b) noexcept {
  ToolStateMessage m;
  m.X_WT.translation = glm::dvec3(b.p_WT[0], b.p_WT[1], b.p_WT[2]);
  DecodeSmallestThree(b.q_WT_smallest_three, m.X_WT.rotation);
  for (int k = 0; k < 3; ++k) {
    m.V_WT_W.linear[k] = FromBinary16(b.V_WT_W[k]);
    m.V_WT_W.angular[k] = FromBinary16(b.V_WT_W[3 + k]);
  }
  return m;
}

}  // namespace ht::wire::detail
