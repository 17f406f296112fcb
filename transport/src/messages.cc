#include "transport/messages.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <concepts>
#include <cstring>
#include <limits>
#include <type_traits>

#include "haptic_core/byte_order.h"
#include "haptic_core/contact_assembly.h"

namespace ht::wire {
namespace {

// Every body's wire layout is written once, as a Fields(archive, message) function that the
// Writer (encoding) and the Reader (decoding) both walk. The Reader checks structure as it goes
// (the body's length, and every count against its capacity and the bytes left before any element
// is read); what the values must satisfy is each message's Check(), run only on decode.

/// What an archive carries as itself: integers, enums (their underlying integer) and IEEE-754
/// floats, all little-endian.
template <class T>
concept Scalar =
    (std::integral<T> && !std::same_as<T, bool>) || std::is_enum_v<T> || std::floating_point<T>;

/// The unsigned integer whose bytes a scalar of N bytes is sent as.
template <std::size_t N>
using Bits = std::conditional_t<
    N == 1, std::uint8_t,
    std::conditional_t<N == 2, std::uint16_t,
                       std::conditional_t<N == 4, std::uint32_t, std::uint64_t>>>;

/// `M` is `T` or `const T`: Fields() get the message const from the Writer, mutable from the
/// Reader.
template <class M, class T>
concept Of = std::same_as<std::remove_const_t<M>, T>;

/// Encodes into a Datagram. Space is not checked per field: protocol.h's static_asserts bound every
/// body; only byte payloads are cut to what fits before the MAC.
class Writer {
 public:
  explicit Writer(Datagram& d) : d_(d) { d_.size = 0; }
  template <Scalar T>
  void operator()(T value) {
    StoreLe(std::bit_cast<Bits<sizeof(T)>>(value), d_.bytes.data() + d_.size);
    d_.size += sizeof(T);
  }
  /// A double sent as an f32.
  void F32(double v) { (*this)(static_cast<float>(v)); }
  /// The count of the elements that follow, as a `Wire` integer: `n` clamped to [0, capacity].
  /// Returns how many elements follow.
  template <std::unsigned_integral Wire, class N>
  std::size_t Count(const N& n, std::size_t capacity, std::size_t /*element_bytes*/) {
    const auto count = static_cast<std::size_t>(
        std::clamp<std::int64_t>(n, 0, static_cast<std::int64_t>(capacity)));
    (*this)(static_cast<Wire>(count));
    return count;
  }
  /// As Count, for a count whose elements are followed by further fields.
  template <std::unsigned_integral Wire, class N>
  std::size_t CountBefore(const N& n, std::size_t capacity, std::size_t element_bytes,
                          std::size_t /*min_bytes_after*/) {
    return Count<Wire>(n, capacity, element_bytes);
  }
  /// The first `n` bytes of `bytes`.
  template <class T, std::size_t N>
  void Bytes(const std::array<T, N>& bytes, std::size_t n) {
    static_assert(sizeof(T) == 1);
    Payload({reinterpret_cast<const std::uint8_t*>(bytes.data()), std::min(n, N)});
  }
  /// u8 length, then the text's first `length` bytes zero padded to N bytes.
  template <std::size_t N>
  void Text(std::uint8_t length, const std::array<char, N>& text) {
    const std::size_t n = std::min<std::size_t>(length, N);
    (*this)(static_cast<std::uint8_t>(n));
    Bytes(text, n);
    for (std::size_t i = n; i < N; ++i) (*this)(std::uint8_t{0});
  }
  /// The bytes, cut to what fits before the MAC.
  void Payload(std::span<const std::uint8_t> b) {
    const std::size_t n = std::min(b.size(), d_.bytes.size() - kMacBytes - d_.size);
    std::memcpy(d_.bytes.data() + d_.size, b.data(), n);
    d_.size += n;
  }
  void Seal(const MacKey& key) {
    ComputeMac({d_.bytes.data(), d_.size}, key,
               std::span<std::uint8_t, kMacBytes>(d_.bytes.data() + d_.size, kMacBytes));
    d_.size += kMacBytes;
  }
  /// Seal with the whole 32-byte MAC of versions 2 to 7.
  void SealFull(const MacKey& key) {
    ComputeFullMac(
        {d_.bytes.data(), d_.size}, key,
        std::span<std::uint8_t, kFullMacBytes>(d_.bytes.data() + d_.size, kFullMacBytes));
    d_.size += kFullMacBytes;
  }

 private:
  Datagram& d_;
};

/// Decodes a body. The first problem met is kept (kTooShort past the end, kBadCount, kTooLong)
/// and every later field is skipped.
class Reader {
 public:
  explicit Reader(std::span<const std::uint8_t> b) : b_(b) {}
  template <Scalar T>
  void operator()(T& value) {
    if (!Need(sizeof(T))) return;
    value = std::bit_cast<T>(LoadLe<Bits<sizeof(T)>>(b_.data() + pos_));
    pos_ += sizeof(T);
  }
  void F32(double& v) {
    float f = 0.0f;
    (*this)(f);
    v = f;
  }
  /// Reads the count, then, before any element: kBadCount above `capacity`, kTooShort or kTooLong
  /// unless exactly count · element_bytes bytes are left. Returns the count (0 on a problem).
  template <std::unsigned_integral Wire, class N>
  std::size_t Count(N& n, std::size_t capacity, std::size_t element_bytes) {
    Wire count = 0;
    (*this)(count);
    if (status_ != DecodeStatus::kOk) return 0;
    if (count > capacity) return Fail(DecodeStatus::kBadCount);
    const std::size_t expected = element_bytes * count;
    if (remaining() < expected) return Fail(DecodeStatus::kTooShort);
    if (remaining() > expected) return Fail(DecodeStatus::kTooLong);
    n = static_cast<N>(count);
    return count;
  }
  /// As Count, for elements followed by further fields: kTooShort unless at least count ·
  /// element_bytes + min_bytes_after bytes are left (the last count checks the exact length).
  template <std::unsigned_integral Wire, class N>
  std::size_t CountBefore(N& n, std::size_t capacity, std::size_t element_bytes,
                          std::size_t min_bytes_after) {
    Wire count = 0;
    (*this)(count);
    if (status_ != DecodeStatus::kOk) return 0;
    if (count > capacity) return Fail(DecodeStatus::kBadCount);
    if (remaining() < element_bytes * count + min_bytes_after) return Fail(DecodeStatus::kTooShort);
    n = static_cast<N>(count);
    return count;
  }
  /// A value the field list found invalid while reading (e.g. an index out of range): `s` is kept
  /// unless an earlier problem was.
  void Reject(DecodeStatus s) { Fail(s); }
  bool ok() const { return status_ == DecodeStatus::kOk; }
  template <class T, std::size_t N>
  void Bytes(std::array<T, N>& bytes, std::size_t n) {
    static_assert(sizeof(T) == 1);
    if (n > N) Fail(DecodeStatus::kBadCount);
    if (!Need(n)) return;
    std::memcpy(bytes.data(), b_.data() + pos_, n);
    pos_ += n;
  }
  /// The length as sent (checked by the message's Check()), then all N bytes.
  template <std::size_t N>
  void Text(std::uint8_t& length, std::array<char, N>& text) {
    (*this)(length);
    Bytes(text, N);
  }
  /// The rest of the body, at least one byte; points into the body.
  void Payload(std::span<const std::uint8_t>& b) {
    if (!Need(std::max<std::size_t>(remaining(), 1))) return;
    b = b_.subspan(pos_);
    pos_ = b_.size();
  }
  /// kOk when every field was read and no byte is left over.
  DecodeStatus Finish() {
    if (status_ == DecodeStatus::kOk && remaining() > 0) status_ = DecodeStatus::kTooLong;
    return status_;
  }

 private:
  std::size_t remaining() const { return b_.size() - pos_; }
  bool Need(std::size_t n) {
    if (status_ == DecodeStatus::kOk && remaining() < n) status_ = DecodeStatus::kTooShort;
    return status_ == DecodeStatus::kOk;
  }
  std::size_t Fail(DecodeStatus s) {
    if (status_ == DecodeStatus::kOk) status_ = s;
    return 0;
  }
  std::span<const std::uint8_t> b_;
  std::size_t pos_ = 0;
  DecodeStatus status_ = DecodeStatus::kOk;
};

/// Counts the bytes of a field list at compile time, each count followed by one element, so that
/// static_asserts below tie every Fields() to the sizes in protocol.h.
class Sizer {
 public:
  template <Scalar T>
  constexpr void operator()(const T&) {
    bytes += sizeof(T);
  }
  constexpr void F32(double) { bytes += 4; }
  template <std::unsigned_integral Wire, class N>
  constexpr std::size_t Count(const N&, std::size_t, std::size_t element_bytes) {
    bytes += sizeof(Wire);
    counted_bytes += element_bytes;
    return 1;
  }
  template <std::unsigned_integral Wire, class N>
  constexpr std::size_t CountBefore(const N& n, std::size_t capacity, std::size_t element_bytes,
                                    std::size_t) {
    return Count<Wire>(n, capacity, element_bytes);
  }
  template <class T, std::size_t N>
  constexpr void Bytes(const std::array<T, N>&, std::size_t n) {
    bytes += n;
  }
  template <std::size_t N>
  constexpr void Text(std::uint8_t, const std::array<char, N>&) {
    bytes += 1 + N;
  }
  constexpr void Payload(std::span<const std::uint8_t>) {}
  std::size_t bytes = 0;          ///< fixed part and one element per count
  std::size_t counted_bytes = 0;  ///< element sizes the counts declare
};

/// Wire layout of a count: the count as `Wire`, then that many elements of element_bytes each.
/// Returns the number of elements the caller's Fields() then walks.
template <std::unsigned_integral Wire>
constexpr std::size_t Count(auto& a, auto& n, std::size_t capacity, std::size_t element_bytes) {
  return a.template Count<Wire>(n, capacity, element_bytes);
}
/// The same for a count whose elements are followed by at least `min_bytes_after` more bytes.
template <std::unsigned_integral Wire>
constexpr std::size_t CountBefore(auto& a, auto& n, std::size_t capacity, std::size_t element_bytes,
                                  std::size_t min_bytes_after) {
  return a.template CountBefore<Wire>(n, capacity, element_bytes, min_bytes_after);
}

// 3×f64.
constexpr void Vec(auto& a, Of<glm::dvec3> auto& v) {
  a(v.x);
  a(v.y);
  a(v.z);
}

// 3×f32 (a dvec3 rounded to float).
constexpr void Vec32(auto& a, Of<glm::dvec3> auto& v) {
  a.F32(v.x);
  a.F32(v.y);
  a.F32(v.z);
}

// Translation 3×f64, then the quaternion w, x, y, z as f64.
constexpr void Pose(auto& a, Of<RigidTransform> auto& X) {
  Vec(a, X.translation);
  a(X.rotation.w);
  a(X.rotation.x);
  a(X.rotation.y);
  a(X.rotation.z);
}

/// The header as it is on the wire (protocol.h); the u48 send time as its low 32 and high 16 bits
/// (the same little-endian bytes).
struct WireHeader {
  std::uint16_t magic = kMagic;
  std::uint8_t version = static_cast<std::uint8_t>(kProtocolVersion);
  std::uint8_t type = 0;
  std::uint32_t session_id = 0;
  std::uint32_t sequence = 0;
  std::uint32_t send_time_us_low = 0;
  std::uint16_t send_time_us_high = 0;
};

/// The header of versions 2 to 7 (protocol.h), read from an older operator's Hello and written in
/// the Reject that answers it.
struct LegacyWireHeader {
  std::uint32_t magic = kLegacyMagic;
  std::uint16_t version = 0;
  std::uint8_t type = 0;
  std::uint8_t flags = 0;
  std::uint32_t session_id = 0;
  std::uint64_t sequence = 0;
  std::int64_t send_time_ns = 0;
};

/// The header of `type` for `header`: the sequence saturated at 2³² − 1 (the stream's last) and
/// the send time as whole µs, clamped to [0, kMaxSendTimeUs].
WireHeader ToWire(const Header& header, MessageType type) noexcept {
  const std::int64_t us = std::clamp<std::int64_t>(header.send_time_ns / 1000, 0, kMaxSendTimeUs);
  return {.type = static_cast<std::uint8_t>(type),
          .session_id = header.session_id,
          .sequence = static_cast<std::uint32_t>(std::min(header.sequence, kMaxSequence)),
          .send_time_us_low = static_cast<std::uint32_t>(us),
          .send_time_us_high = static_cast<std::uint16_t>(us >> 32)};
}

/// The body of Goodbye.
struct EmptyBody {};

constexpr void Fields(auto& a, Of<WireHeader> auto& h) {
  a(h.magic);
  a(h.version);
  a(h.type);
  a(h.session_id);
  a(h.sequence);
  a(h.send_time_us_low);
  a(h.send_time_us_high);
}

constexpr void Fields(auto& a, Of<LegacyWireHeader> auto& h) {
  a(h.magic);
  a(h.version);
  a(h.type);
  a(h.flags);
  a(h.session_id);
  a(h.sequence);
  a(h.send_time_ns);
}

constexpr void Fields(auto&, Of<EmptyBody> auto&) {}

constexpr void Fields(auto& a, Of<ToolStateMessage> auto& m) {
  Pose(a, m.X_WT);
  Vec(a, m.V_WT_W.linear);
  Vec(a, m.V_WT_W.angular);
}

constexpr void Fields(auto& a, Of<ContactLinearization> auto& c) {
  a(c.depth_m);
  Vec(a, c.gradient.d_translation_W);
  Vec(a, c.gradient.d_rotation_W);
  a(c.stiffness_n_per_m);
  Vec32(a, c.point_W);
  Vec32(a, c.normal_W);
}

static_assert(kMaxKinkPlanesPerContact == kMaxKinkPlanes);

/// One kink plane as it is on the wire (protocol.h).
struct WireKinkPlane {
  std::uint8_t contact = 0;
  float depth_m = 0.0f;
  std::array<float, 3> d_rotation{};            ///< ∂δ_m/∂θ (m/rad)
  std::array<float, 3> d_translation_offset{};  ///< ∂δ_m/∂x less the contact's ∂δ/∂x
};

constexpr void Fields(auto& a, Of<WireKinkPlane> auto& p) {
  a(p.contact);
  a(p.depth_m);
  for (auto& v : p.d_rotation) a(v);
  for (auto& v : p.d_translation_offset) a(v);
}

/// The kink planes of contacts [0, n) of `model` in wire order (contact by contact), at most
/// `capacity` of them, into `out`; returns how many.
constexpr std::size_t FlattenKinkPlanes(const ContactModel& model, std::size_t n, int capacity,
                                        std::span<WireKinkPlane> out) noexcept {
  std::size_t k = 0;
  const std::size_t cap = std::min(out.size(), static_cast<std::size_t>(std::max(capacity, 0)));
  for (std::size_t i = 0; i < n && k < cap; ++i) {
    const ContactLinearization& c = model.contacts[i];
    const int planes = std::clamp(c.num_kink_planes, 0, kMaxKinkPlanes);
    for (int p = 0; p < planes && k < cap; ++p) {
      const KinkPlane& kp = c.kink_planes[static_cast<std::size_t>(p)];
      out[k++] = {static_cast<std::uint8_t>(i),
                  static_cast<float>(kp.depth_m),
                  {static_cast<float>(kp.d_rotation_W.x), static_cast<float>(kp.d_rotation_W.y),
                   static_cast<float>(kp.d_rotation_W.z)},
                  {static_cast<float>(kp.d_translation_offset_W.x),
                   static_cast<float>(kp.d_translation_offset_W.y),
                   static_cast<float>(kp.d_translation_offset_W.z)}};
    }
  }
  return k;
}

/// Gives each wire plane to its contact of `model` (whose first `n` contacts were read); false
/// when one names a contact ≥ n or a contact's (kMaxKinkPlanes + 1)-th plane.
bool DistributeKinkPlanes(std::span<const WireKinkPlane> planes, std::size_t n,
                          ContactModel& model) noexcept {
  for (std::size_t i = 0; i < n; ++i) model.contacts[i].num_kink_planes = 0;
  for (const WireKinkPlane& w : planes) {
    if (w.contact >= n) return false;
    ContactLinearization& c = model.contacts[w.contact];
    if (c.num_kink_planes >= kMaxKinkPlanes) return false;
    c.kink_planes[static_cast<std::size_t>(c.num_kink_planes++)] = {
        w.depth_m, glm::dvec3(w.d_rotation[0], w.d_rotation[1], w.d_rotation[2]),
        glm::dvec3(w.d_translation_offset[0], w.d_translation_offset[1],
                   w.d_translation_offset[2])};
  }
  return true;
}

/// The kink-plane section after the contacts (protocol.h): the Writer and the Sizer flatten the
/// model's planes, the Reader reads them and gives them to their contacts.
constexpr std::size_t KinkPlanes(auto& a, auto& model, std::size_t n, int capacity) {
  std::array<WireKinkPlane, kMaxWireKinkPlanes> planes{};
  std::size_t k = 0;
  if constexpr (!requires { a.Reject(DecodeStatus::kOk); }) {
    k = FlattenKinkPlanes(model, n, capacity, planes);
    const std::size_t sent = CountBefore<std::uint8_t>(
        a, k, static_cast<std::size_t>(capacity), kKinkPlaneBytes, kTranslationPatchCountBytes);
    for (std::size_t j = 0; j < std::min(sent, k); ++j) Fields(a, planes[j]);
    return std::min(sent, k);
  } else {
    k = CountBefore<std::uint8_t>(a, k, static_cast<std::size_t>(std::max(capacity, 0)),
                                  kKinkPlaneBytes, kTranslationPatchCountBytes);
    for (std::size_t j = 0; j < k; ++j) Fields(a, planes[j]);
    if (a.ok() && !DistributeKinkPlanes({planes.data(), k}, n, model)) {
      a.Reject(DecodeStatus::kBadValue);
    }
    return k;
  }
}

/// One translation patch as it is on the wire (protocol.h, version 9).
struct WirePatch {
  std::uint8_t contact = 0;
  float step_m = 0.0f;
  std::array<std::int16_t, 3> axis_u{};  ///< unit vector · kCompactI16Max
  std::array<std::int16_t, 3> axis_v{};
  float scale_m = 0.0f;  ///< m per node unit
  std::array<std::int16_t, kTranslationPatchNodes> nodes{};
  std::array<std::int16_t, 3> lever{};  ///< units of kCompactPointStepM; zero: translations only
};

constexpr void Fields(auto& a, Of<WirePatch> auto& p) {
  a(p.contact);
  a(p.step_m);
  for (auto& v : p.axis_u) a(v);
  for (auto& v : p.axis_v) a(v);
  a(p.scale_m);
  for (auto& v : p.nodes) a(v);
  for (auto& v : p.lever) a(v);
}

static_assert(kTranslationPatchNodes + 1 == kTranslationPatchSide * kTranslationPatchSide);

/// The patch's index of wire node k (the centre left out).
constexpr std::size_t PatchIndexOfWireNode(int k) noexcept {
  constexpr int centre = (kTranslationPatchSide * kTranslationPatchSide) / 2;
  return static_cast<std::size_t>(k < centre ? k : k + 1);
}

/// round(v) within ±kCompactI16Max; constexpr-friendly (no std::round).
constexpr std::int16_t PatchI16(double v) noexcept {
  const double limit = kCompactI16Max;
  const double c = v < -limit ? -limit : (v > limit ? limit : v);
  return static_cast<std::int16_t>(c < 0.0 ? c - 0.5 : c + 0.5);
}

/// `p` as it goes on the wire for contact `contact`; false (nothing to send) for no patch or a
/// non-finite one.
constexpr bool QuantizePatch(const TranslationPatch& p, std::uint8_t contact,
                             WirePatch& out) noexcept {
  const auto finite = [](double v) { return v == v && v - v == 0.0; };
  if (!(p.step_m > 0.0) || !finite(p.step_m)) return false;
  double largest = 0.0;
  for (const float v : p.depth_m) {
    if (!finite(v)) return false;
    largest = std::max(largest, v < 0.0f ? -static_cast<double>(v) : static_cast<double>(v));
  }
  for (int k = 0; k < 3; ++k) {
    if (!finite(p.axis_u_W[k]) || !finite(p.axis_v_W[k]) || !finite(p.lever_W[k])) return false;
  }
  out = {};
  out.contact = contact;
  out.step_m = static_cast<float>(p.step_m);
  for (int k = 0; k < 3; ++k) {
    out.axis_u[static_cast<std::size_t>(k)] = PatchI16(p.axis_u_W[k] * kCompactI16Max);
    out.axis_v[static_cast<std::size_t>(k)] = PatchI16(p.axis_v_W[k] * kCompactI16Max);
    out.lever[static_cast<std::size_t>(k)] = PatchI16(p.lever_W[k] / kCompactPointStepM);
  }
  out.scale_m = static_cast<float>(largest / kCompactI16Max);
  const double scale = static_cast<double>(out.scale_m);
  for (int k = 0; k < kTranslationPatchNodes; ++k) {
    const double v = p.depth_m[PatchIndexOfWireNode(k)];
    out.nodes[static_cast<std::size_t>(k)] = scale > 0.0 ? PatchI16(v / scale) : 0;
  }
  return true;
}

/// The patches of contacts [0, n) of `model` in wire order (contact by contact, those that have
/// one), at most `capacity`, into `out`; returns how many.
constexpr std::size_t FlattenPatches(const ContactModel& model, std::size_t n, int capacity,
                                     std::span<WirePatch> out) noexcept {
  std::size_t k = 0;
  const std::size_t cap = std::min(out.size(), static_cast<std::size_t>(std::max(capacity, 0)));
  for (std::size_t i = 0; i < n && k < cap; ++i) {
    if (QuantizePatch(model.contacts[i].patch, static_cast<std::uint8_t>(i), out[k])) ++k;
  }
  return k;
}

/// A wire patch's values: kOk, kNonFinite (a marked node or axis, a non-finite step or scale) or
/// kBadValue (a step or scale out of range, an axis shorter than 0.5).
DecodeStatus CheckPatch(const WirePatch& p) noexcept {
  const auto marked = [](const auto& values) {
    for (const std::int16_t v : values) {
      if (v == kCompactNotFinite) return true;
    }
    return false;
  };
  if (!std::isfinite(p.step_m) || !std::isfinite(p.scale_m) || marked(p.axis_u) ||
      marked(p.axis_v) || marked(p.nodes) || marked(p.lever)) {
    return DecodeStatus::kNonFinite;
  }
  if (!(p.step_m > 0.0f) || p.step_m > kMaxTranslationPatchStepM || p.scale_m < 0.0f) {
    return DecodeStatus::kBadValue;
  }
  for (const auto* axis : {&p.axis_u, &p.axis_v}) {
    double norm2 = 0.0;
    for (const std::int16_t v : *axis) norm2 += static_cast<double>(v) * v;
    if (!(std::sqrt(norm2) >= 0.5 * kCompactI16Max)) return DecodeStatus::kBadValue;
  }
  return DecodeStatus::kOk;
}

/// Gives each wire patch (values checked by CheckPatch) to its contact of `model` (whose first `n`
/// contacts were read); false when one names a contact ≥ n or a contact's second patch.
bool DistributePatches(std::span<const WirePatch> patches, std::size_t n,
                       ContactModel& model) noexcept {
  for (std::size_t i = 0; i < n; ++i) model.contacts[i].patch = TranslationPatch{};
  for (const WirePatch& w : patches) {
    if (w.contact >= n) return false;
    TranslationPatch& p = model.contacts[w.contact].patch;
    if (p.step_m > 0.0) return false;
    const auto axis = [](const std::array<std::int16_t, 3>& a) {
      return glm::normalize(glm::dvec3(a[0], a[1], a[2]));
    };
    p.step_m = w.step_m;
    p.axis_u_W = axis(w.axis_u);
    p.axis_v_W = axis(w.axis_v);
    p.lever_W = kCompactPointStepM * glm::dvec3(w.lever[0], w.lever[1], w.lever[2]);
    p.depth_m.fill(0.0f);
    for (int k = 0; k < kTranslationPatchNodes; ++k) {
      p.depth_m[PatchIndexOfWireNode(k)] =
          static_cast<float>(static_cast<double>(w.nodes[static_cast<std::size_t>(k)]) * w.scale_m);
    }
  }
  return true;
}

/// The translation-patch section after the kink planes (protocol.h, version 9), as KinkPlanes.
constexpr void TranslationPatches(auto& a, auto& model, std::size_t n, int capacity) {
  std::array<WirePatch, kMaxWireContacts> patches{};
  std::size_t k = 0;
  if constexpr (!requires { a.Reject(DecodeStatus::kOk); }) {
    k = FlattenPatches(model, n, capacity, patches);
    const std::size_t sent =
        Count<std::uint8_t>(a, k, static_cast<std::size_t>(capacity), kTranslationPatchBytes);
    for (std::size_t j = 0; j < std::min(sent, k); ++j) Fields(a, patches[j]);
  } else {
    k = Count<std::uint8_t>(a, k, static_cast<std::size_t>(std::max(capacity, 0)),
                            kTranslationPatchBytes);
    for (std::size_t j = 0; j < k; ++j) Fields(a, patches[j]);
    if (!a.ok()) return;
    for (std::size_t j = 0; j < k; ++j) {
      if (const DecodeStatus s = CheckPatch(patches[j]); s != DecodeStatus::kOk) {
        a.Reject(s);
        return;
      }
    }
    if (!DistributePatches({patches.data(), k}, n, model)) a.Reject(DecodeStatus::kBadValue);
  }
}

constexpr void Fields(auto& a, Of<ContactModelMessage> auto& m) {
  a(m.model.tool_state_seq);
  a(m.tool_state_send_time_ns);
  a(m.hold_ns);
  a(m.remote_step_count);
  a(m.collision_us);
  a(m.texture_us);
  a(m.step_us);
  Pose(a, m.model.X_WT0);
  Vec(a, m.model.F_T_W_at_q0.force);
  Vec(a, m.model.F_T_W_at_q0.torque);
  const std::size_t n =
      CountBefore<std::uint8_t>(a, m.model.num_contacts, kMaxWireContacts, kContactBytes,
                                kKinkPlaneCountBytes + kTranslationPatchCountBytes);
  for (std::size_t i = 0; i < n; ++i) Fields(a, m.model.contacts[i]);
  const std::size_t planes =
      KinkPlanes(a, m.model, n,
                 KinkPlaneCapacity(kContactModelFixedBytes, kContactBytes, static_cast<int>(n)));
  TranslationPatches(a, m.model, n,
                     TranslationPatchCapacity(kContactModelFixedBytes, kContactBytes,
                                              static_cast<int>(n), static_cast<int>(planes)));
}

/// One contact of a CompactContactModel as it is on the wire (protocol.h).
struct CompactContact {
  float depth_m = 0.0f;
  std::array<float, 3> d_translation{};  ///< ∂δ/∂x
  std::array<float, 3> d_rotation{};     ///< ∂δ/∂θ (m/rad)
  float stiffness_n_per_m = 0.0f;
  std::array<std::int16_t, 3> point_offset{};  ///< point_W − p_WT0 in units of kCompactPointStepM
  std::array<std::int16_t, 2> normal_oct{};    ///< octahedral (u, v)·kCompactI16Max
};

/// A kink plane of CompactContactModel (protocol.h, version 11): WireKinkPlane's fields, the
/// translation slope's offset on the wire only when bit kCompactKinkPlaneOwnSlope of `contact`
/// says the plane has one (the rotation arms share the contact's: 17 bytes instead of 29).
struct CompactWireKinkPlane {
  std::uint8_t contact = 0;  ///< the contact's index | kCompactKinkPlaneOwnSlope
  float depth_m = 0.0f;
  std::array<float, 3> d_rotation{};            ///< ∂δ_m/∂θ (m/rad)
  std::array<float, 3> d_translation_offset{};  ///< ∂δ_m/∂x less the contact's ∂δ/∂x
};

/// A CompactContactModel body as it is on the wire: what QuantizeContactModel() makes of a
/// ContactModelMessage and DequantizeContactModel() turns back into one.
struct CompactContactModelBody {
  std::uint32_t tool_state_seq = 0;
  std::uint32_t tool_state_send_time_us = 0;  ///< the echo's whole µs, low 32 bits
  std::uint32_t hold_us = 0;
  std::uint32_t remote_step_count = 0;  ///< low 32 bits
  std::uint16_t collision_us = 0;
  std::uint16_t texture_us = 0;
  std::uint16_t step_us = 0;
  std::array<float, 3> p_WT0{};
  std::uint64_t q_WT0_low = 0;   ///< bits 0–63 of the 80-bit "smallest three"
  std::uint16_t q_WT0_high = 0;  ///< bits 64–79
  int num_contacts = 0;
  std::array<CompactContact, kMaxWireContacts> contacts{};
  int num_kink_planes = 0;
  std::array<CompactWireKinkPlane, kMaxWireKinkPlanes> kink_planes{};
  int num_patches = 0;
  std::array<WirePatch, kMaxWireContacts> patches{};
};

// Every element of an array of scalars, in order.
constexpr void Each(auto& a, auto& values) {
  for (auto& v : values) a(v);
}

constexpr void Fields(auto& a, Of<CompactContact> auto& c) {
  a(c.depth_m);
  Each(a, c.d_translation);
  Each(a, c.d_rotation);
  a(c.stiffness_n_per_m);
  Each(a, c.point_offset);
  Each(a, c.normal_oct);
}

constexpr void Fields(auto& a, Of<CompactWireKinkPlane> auto& p) {
  a(p.contact);  // read first: the Reader knows from it whether the offset follows
  a(p.depth_m);
  Each(a, p.d_rotation);
  if ((p.contact & kCompactKinkPlaneOwnSlope) != 0) Each(a, p.d_translation_offset);
}

constexpr void Fields(auto& a, Of<CompactContactModelBody> auto& m) {
  a(m.tool_state_seq);
  a(m.tool_state_send_time_us);
  a(m.hold_us);
  a(m.remote_step_count);
  a(m.collision_us);
  a(m.texture_us);
  a(m.step_us);
  Each(a, m.p_WT0);
  a(m.q_WT0_low);
  a(m.q_WT0_high);
  const std::size_t n =
      CountBefore<std::uint8_t>(a, m.num_contacts, kMaxWireContacts, kCompactContactBytes,
                                kKinkPlaneCountBytes + kTranslationPatchCountBytes);
  for (std::size_t i = 0; i < n; ++i) Fields(a, m.contacts[i]);
  const int capacity =
      KinkPlaneCapacity(kCompactContactModelFixedBytes, kCompactContactBytes, static_cast<int>(n));
  // Counted as if each plane were kKinkPlaneBytes (as ContactModel's): the bound on the count is
  // the same whatever the planes carry; the bytes left are checked against the shortest plane.
  const std::size_t k =
      CountBefore<std::uint8_t>(a, m.num_kink_planes, static_cast<std::size_t>(capacity),
                                kCompactKinkPlaneBytes, kTranslationPatchCountBytes);
  for (std::size_t j = 0; j < k; ++j) Fields(a, m.kink_planes[j]);
  const int patch_capacity = TranslationPatchCapacity(
      kCompactContactModelFixedBytes, kCompactContactBytes, static_cast<int>(n), m.num_kink_planes);
  const std::size_t np = Count<std::uint8_t>(
      a, m.num_patches, static_cast<std::size_t>(patch_capacity), kTranslationPatchBytes);
  for (std::size_t j = 0; j < np; ++j) Fields(a, m.patches[j]);
}

/// A CompactToolState body as it is on the wire (protocol.h).
struct CompactToolStateBody {
  std::array<float, 3> p_WT{};            ///< m
  std::uint64_t q_WT_smallest_three = 0;  ///< index and three 20-bit components
  std::array<std::uint16_t, 6> V_WT_W{};  ///< binary16: linear (m/s), then angular (rad/s)
};

constexpr void Fields(auto& a, Of<CompactToolStateBody> auto& m) {
  Each(a, m.p_WT);
  a(m.q_WT_smallest_three);
  Each(a, m.V_WT_W);
}

constexpr void Fields(auto& a, Of<DeadbandTerms> auto& d) {
  a(d.tool_state_deadband);
  a(d.model_deadband);
  a(d.tool_state_keepalive_ms);
  a(d.model_keepalive_ms);
}

constexpr void Fields(auto& a, Of<HelloMessage> auto& m) {
  a(m.min_version);
  a(m.max_version);
  a(m.client_nonce);
  a(m.tool_state_rate_hz);
  a(m.max_model_rate_hz);
  a(m.max_grid);
  a(m.mtu);
  a(m.codecs);
  a(m.heartbeat_ms);
  a(m.peer_timeout_ms);
  Fields(a, m.deadband);
}

constexpr void Fields(auto& a, Of<WelcomeTarget> auto& t) {
  Vec32(a, t.box_min_W);
  Vec32(a, t.box_max_W);
  Vec32(a, t.top_W);
  a.F32(t.approach_m);
}

constexpr void Fields(auto& a, Of<WelcomeMessage> auto& m) {
  a(m.client_nonce);
  a(m.version);
  a(m.tool_state_rate_hz);
  a(m.model_rate_hz);
  a(m.grid);
  a(m.window_m);
  a(m.mtu);
  a(m.codecs);
  a(m.heartbeat_ms);
  a(m.peer_timeout_ms);
  Fields(a, m.deadband);
  a(m.scene_objects);
  a.Text(m.scene_name_length, m.scene_name);
  auto& l = m.layout;
  Pose(a, l.X_WT_home);
  a.F32(l.tool_mass_kg);
  Vec32(a, l.tool_inertia_diagonal_T);
  a.F32(l.tool_extent_down_m);
  const std::size_t n =
      Count<std::uint8_t>(a, l.num_targets, kMaxWelcomeTargets, kWelcomeTargetBytes);
  for (std::size_t i = 0; i < n; ++i) Fields(a, l.targets[i]);
}

constexpr void Fields(auto& a, Of<RejectMessage> auto& m) {
  a(m.client_nonce);
  a(m.reason);
  const std::size_t n = Count<std::uint8_t>(a, m.text_length, kMaxRejectText, 1);
  a.Bytes(m.text, n);
}

constexpr void Fields(auto& a, Of<PingMessage> auto& m) { a(m.operator_rtt_us); }

constexpr void Fields(auto& a, Of<PongMessage> auto& m) {
  a(m.ping_sequence);
  a(m.t1_ns);
  a(m.t2_ns);
}

constexpr void Fields(auto& a, Of<SceneFragmentMessage> auto& m) {
  a(m.object_id);
  a(m.version);
  a(m.object_bytes);
  a(m.fragment_index);
  a(m.fragment_count);
  a.Payload(m.payload);
}

constexpr void Fields(auto& a, Of<ManifestEntry> auto& e) {
  a(e.object_id);
  a(e.version);
  a(e.object_bytes);
  a(e.fragment_count);
  a(e.kind);
  a.Bytes(e.digest, kSceneDigestBytes);
}

constexpr void Fields(auto& a, Of<SceneManifestMessage> auto& m) {
  a(m.total_objects);
  a(m.first_index);
  const std::size_t n = Count<std::uint8_t>(a, m.count, kMaxManifestEntries, kManifestEntryBytes);
  for (std::size_t i = 0; i < n; ++i) Fields(a, m.entries[i]);
}

constexpr void Fields(auto& a, Of<SceneNackMessage> auto& m) {
  a(m.object_id);
  a(m.version);
  const std::size_t n = Count<std::uint16_t>(a, m.count, kMaxNackIndices, 2);
  for (std::size_t i = 0; i < n; ++i) a(m.missing[i]);
}

constexpr void Fields(auto& a, Of<NodePose> auto& p) {
  a(p.node);
  a(p.translation.x);
  a(p.translation.y);
  a(p.translation.z);
  a(p.rotation.w);
  a(p.rotation.x);
  a(p.rotation.y);
  a(p.rotation.z);
  a(p.scale.x);
  a(p.scale.y);
  a(p.scale.z);
}

constexpr void Fields(auto& a, Of<NodePosesMessage> auto& m) {
  a(m.graph_version);
  a(m.scene_time_s);
  const std::size_t n = Count<std::uint8_t>(a, m.count, kMaxNodePosesPerDatagram, kNodePoseBytes);
  for (std::size_t i = 0; i < n; ++i) Fields(a, m.poses[i]);
}

/// Msg's field list measured: bytes with one element per count, and the bytes the counts declare
/// their elements take.
template <class Msg>
constexpr Sizer SizeOf() {
  Sizer s;
  Msg m;
  Fields(s, m);
  return s;
}

static_assert(SizeOf<WireHeader>().bytes == kHeaderBytes);
static_assert(SizeOf<LegacyWireHeader>().bytes == kLegacyHeaderBytes);
static_assert(SizeOf<ToolStateMessage>().bytes == kToolStateBodyBytes);
static_assert(SizeOf<ContactModelMessage>().bytes == kContactModelFixedBytes + kContactBytes +
                                                         kKinkPlaneCountBytes +
                                                         kTranslationPatchCountBytes);
static_assert(SizeOf<ContactModelMessage>().counted_bytes ==
              kContactBytes + kKinkPlaneBytes + kTranslationPatchBytes);
static_assert(SizeOf<CompactContactModelBody>().bytes ==
              kCompactContactModelFixedBytes + kCompactContactBytes + kKinkPlaneCountBytes +
                  kCompactKinkPlaneBytes + kTranslationPatchCountBytes + kTranslationPatchBytes);
static_assert(SizeOf<CompactContactModelBody>().counted_bytes ==
              kCompactContactBytes + kCompactKinkPlaneBytes + kTranslationPatchBytes);
static_assert(SizeOf<CompactWireKinkPlane>().bytes == kCompactKinkPlaneBytes);
static_assert(SizeOf<WirePatch>().bytes == kTranslationPatchBytes);
static_assert(SizeOf<CompactToolStateBody>().bytes == kCompactToolStateBodyBytes);
static_assert(SizeOf<HelloMessage>().bytes == kHelloBodyBytes);
static_assert(SizeOf<WelcomeMessage>().bytes == kWelcomeFixedBytes + kWelcomeTargetBytes);
static_assert(SizeOf<WelcomeMessage>().counted_bytes == kWelcomeTargetBytes);
static_assert(SizeOf<RejectMessage>().bytes == kRejectFixedBytes + 1);
static_assert(SizeOf<PingMessage>().bytes == kPingBodyBytes);
static_assert(SizeOf<PongMessage>().bytes == kPongBodyBytes);
static_assert(SizeOf<SceneFragmentMessage>().bytes == kSceneFragmentFixedBytes);
static_assert(SizeOf<SceneManifestMessage>().bytes ==
              kSceneManifestFixedBytes + kManifestEntryBytes);
static_assert(SizeOf<SceneManifestMessage>().counted_bytes == kManifestEntryBytes);
static_assert(SizeOf<SceneNackMessage>().bytes == kSceneNackFixedBytes + 2);
static_assert(SizeOf<NodePosesMessage>().bytes == kNodePosesFixedBytes + kNodePoseBytes);
static_assert(SizeOf<NodePosesMessage>().counted_bytes == kNodePoseBytes);

bool Finite3(const glm::dvec3& v) {
  return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}

DecodeStatus CheckPose(const RigidTransform& X) {
  const glm::dquat& q = X.rotation;
  if (!Finite3(X.translation) || !std::isfinite(q.w) || !std::isfinite(q.x) ||
      !std::isfinite(q.y) || !std::isfinite(q.z)) {
    return DecodeStatus::kNonFinite;
  }
  return IsFiniteRigidTransform(X) ? DecodeStatus::kOk : DecodeStatus::kBadValue;
}

bool FinitePositive(float v) { return std::isfinite(v) && v >= 0.0f; }

// Checks of the values, in the order they apply, run once a body's fields were read.

DecodeStatus Check(const EmptyBody&) { return DecodeStatus::kOk; }

DecodeStatus Check(const ToolStateMessage& m) {
  if (const DecodeStatus s = CheckPose(m.X_WT); s != DecodeStatus::kOk) return s;
  if (!IsFinite(m.V_WT_W)) return DecodeStatus::kNonFinite;
  return DecodeStatus::kOk;
}

DecodeStatus Check(const ContactModelMessage& m) {
  for (int i = 0; i < m.model.num_contacts; ++i) {
    const ContactLinearization& c = m.model.contacts[i];
    if (!std::isfinite(c.depth_m) || !Finite3(c.gradient.d_translation_W) ||
        !Finite3(c.gradient.d_rotation_W) || !std::isfinite(c.stiffness_n_per_m) ||
        !Finite3(c.point_W) || !Finite3(c.normal_W)) {
      return DecodeStatus::kNonFinite;
    }
    if (c.stiffness_n_per_m < 0.0) return DecodeStatus::kBadValue;
    for (int p = 0; p < std::clamp(c.num_kink_planes, 0, kMaxKinkPlanes); ++p) {
      const KinkPlane& kp = c.kink_planes[static_cast<std::size_t>(p)];
      if (!std::isfinite(kp.depth_m) || !Finite3(kp.d_rotation_W) ||
          !Finite3(kp.d_translation_offset_W)) {
        return DecodeStatus::kNonFinite;
      }
    }
  }
  if (const DecodeStatus s = CheckPose(m.model.X_WT0); s != DecodeStatus::kOk) return s;
  if (!IsFinite(m.model.F_T_W_at_q0) || !std::isfinite(m.collision_us) ||
      !std::isfinite(m.texture_us) || !std::isfinite(m.step_us)) {
    return DecodeStatus::kNonFinite;
  }
  return DecodeStatus::kOk;
}

// CompactContactModel (protocol.h): the sender's quantization and the receiver's way back. No NaN,
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
  std::array<WireKinkPlane, kMaxWireKinkPlanes> planes{};
  b.num_kink_planes = static_cast<int>(FlattenKinkPlanes(
      model, static_cast<std::size_t>(n),
      KinkPlaneCapacity(kCompactContactModelFixedBytes, kCompactContactBytes, n), planes));
  for (int j = 0; j < b.num_kink_planes; ++j) {
    const WireKinkPlane& w = planes[static_cast<std::size_t>(j)];
    // A plane with its own translation slope says so; one that shares the contact's (every
    // rotation arm) leaves the zero offset off the wire. A non-finite offset goes, for the
    // receiver to refuse.
    const bool own = std::ranges::any_of(w.d_translation_offset, [](float v) { return v != 0.0f; });
    b.kink_planes[static_cast<std::size_t>(j)] = {
        static_cast<std::uint8_t>(w.contact | (own ? kCompactKinkPlaneOwnSlope : 0u)), w.depth_m,
        w.d_rotation, w.d_translation_offset};
  }
  b.num_patches = static_cast<int>(
      FlattenPatches(model, static_cast<std::size_t>(n),
                     TranslationPatchCapacity(kCompactContactModelFixedBytes, kCompactContactBytes,
                                              n, b.num_kink_planes),
                     b.patches));
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
  std::array<int, kMaxWireContacts> planes_of{};
  for (int j = 0; j < m.num_kink_planes; ++j) {
    const CompactWireKinkPlane& p = m.kink_planes[static_cast<std::size_t>(j)];
    if (!std::isfinite(p.depth_m) || !AllFinite(p.d_rotation) ||
        !AllFinite(p.d_translation_offset)) {
      return DecodeStatus::kNonFinite;
    }
    const int contact = p.contact & ~kCompactKinkPlaneOwnSlope;
    if (contact >= m.num_contacts ||
        ++planes_of[static_cast<std::size_t>(contact)] > kMaxKinkPlanes) {
      return DecodeStatus::kBadValue;
    }
  }
  std::array<bool, kMaxWireContacts> patched{};
  for (int j = 0; j < m.num_patches; ++j) {
    const WirePatch& p = m.patches[static_cast<std::size_t>(j)];
    if (const DecodeStatus s = CheckPatch(p); s != DecodeStatus::kOk) return s;
    if (p.contact >= m.num_contacts || patched[p.contact]) return DecodeStatus::kBadValue;
    patched[p.contact] = true;
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
  // Check() found every plane's contact and count valid.
  std::array<WireKinkPlane, kMaxWireKinkPlanes> planes{};
  for (int j = 0; j < b.num_kink_planes; ++j) {
    const CompactWireKinkPlane& p = b.kink_planes[static_cast<std::size_t>(j)];
    planes[static_cast<std::size_t>(j)] = {
        static_cast<std::uint8_t>(p.contact & ~kCompactKinkPlaneOwnSlope), p.depth_m, p.d_rotation,
        p.d_translation_offset};  // zero unless it was sent
  }
  DistributeKinkPlanes({planes.data(), static_cast<std::size_t>(b.num_kink_planes)},
                       static_cast<std::size_t>(b.num_contacts), model);
  // Check() found every patch's values, contact and count valid.
  DistributePatches({b.patches.data(), static_cast<std::size_t>(b.num_patches)},
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

DecodeStatus Check(const DeadbandTerms& d) {
  if (!std::isfinite(d.tool_state_deadband) || !std::isfinite(d.model_deadband)) {
    return DecodeStatus::kNonFinite;
  }
  if (!(d.tool_state_deadband >= 0.0f && d.tool_state_deadband < 1.0f) ||
      !(d.model_deadband >= 0.0f && d.model_deadband < 1.0f) || d.tool_state_keepalive_ms == 0 ||
      d.model_keepalive_ms == 0) {
    return DecodeStatus::kBadValue;
  }
  return DecodeStatus::kOk;
}

DecodeStatus Check(const HelloMessage& m) {
  if (!std::isfinite(m.tool_state_rate_hz) || !std::isfinite(m.max_model_rate_hz)) {
    return DecodeStatus::kNonFinite;
  }
  if (const DecodeStatus s = Check(m.deadband); s != DecodeStatus::kOk) return s;
  if (m.min_version > m.max_version || !(m.tool_state_rate_hz > 0.0f) ||
      !FinitePositive(m.max_model_rate_hz) || m.mtu < kMinMtuBytes || m.mtu > kMaxDatagramBytes ||
      m.heartbeat_ms == 0 || m.peer_timeout_ms <= m.heartbeat_ms) {
    return DecodeStatus::kBadValue;
  }
  return DecodeStatus::kOk;
}

DecodeStatus Check(const WelcomeMessage& m) {
  if (const DecodeStatus s = Check(m.deadband); s != DecodeStatus::kOk) return s;
  const SceneLayout& l = m.layout;
  for (int i = 0; i < l.num_targets; ++i) {
    const WelcomeTarget& t = l.targets[i];
    if (!Finite3(t.box_min_W) || !Finite3(t.box_max_W) || !Finite3(t.top_W) ||
        !std::isfinite(t.approach_m)) {
      return DecodeStatus::kNonFinite;
    }
    if (t.box_min_W.x > t.box_max_W.x || t.box_min_W.y > t.box_max_W.y ||
        t.box_min_W.z > t.box_max_W.z || t.approach_m < 0.0) {
      return DecodeStatus::kBadValue;
    }
  }
  if (const DecodeStatus s = CheckPose(l.X_WT_home); s != DecodeStatus::kOk) return s;
  if (!std::isfinite(l.tool_mass_kg) || !Finite3(l.tool_inertia_diagonal_T) ||
      !std::isfinite(l.tool_extent_down_m)) {
    return DecodeStatus::kNonFinite;
  }
  if (l.tool_mass_kg < 0.0 || l.tool_extent_down_m < 0.0 ||
      (l.tool_mass_kg > 0.0 &&
       !(l.tool_inertia_diagonal_T.x > 0.0 && l.tool_inertia_diagonal_T.y > 0.0 &&
         l.tool_inertia_diagonal_T.z > 0.0))) {
    return DecodeStatus::kBadValue;
  }
  if (!std::isfinite(m.tool_state_rate_hz) || !std::isfinite(m.model_rate_hz) ||
      !std::isfinite(m.window_m)) {
    return DecodeStatus::kNonFinite;
  }
  if (m.scene_name_length > kSceneNameBytes || !(m.tool_state_rate_hz > 0.0f) ||
      !FinitePositive(m.model_rate_hz) || !(m.window_m > 0.0f) || m.grid < 2 ||
      m.mtu < kMinMtuBytes || m.mtu > kMaxDatagramBytes || m.heartbeat_ms == 0 ||
      m.peer_timeout_ms <= m.heartbeat_ms) {
    return DecodeStatus::kBadValue;
  }
  return DecodeStatus::kOk;
}

DecodeStatus Check(const RejectMessage& m) {
  const auto reason = static_cast<std::uint8_t>(m.reason);
  return reason < 1 || reason > 3 ? DecodeStatus::kBadValue : DecodeStatus::kOk;
}

DecodeStatus Check(const PingMessage&) { return DecodeStatus::kOk; }

DecodeStatus Check(const PongMessage& m) {
  return m.ping_sequence == 0 ? DecodeStatus::kBadValue : DecodeStatus::kOk;
}

DecodeStatus Check(const SceneFragmentMessage& m) {
  if (m.object_bytes == 0 || m.object_bytes > kMaxSceneObjectBytes || m.fragment_count == 0 ||
      m.fragment_index >= m.fragment_count || m.payload.size() > m.object_bytes) {
    return DecodeStatus::kBadValue;
  }
  return DecodeStatus::kOk;
}

DecodeStatus Check(const SceneManifestMessage& m) {
  if (static_cast<std::size_t>(m.first_index) + m.count > m.total_objects) {
    return DecodeStatus::kBadValue;
  }
  for (int i = 0; i < m.count; ++i) {
    const ManifestEntry& e = m.entries[static_cast<std::size_t>(i)];
    const auto kind = static_cast<int>(e.kind);
    if (kind < 1 || kind > kMaxSceneObjectKind || e.object_bytes == 0 ||
        e.object_bytes > kMaxSceneObjectBytes || e.fragment_count == 0) {
      return DecodeStatus::kBadValue;
    }
  }
  return DecodeStatus::kOk;
}

DecodeStatus Check(const SceneNackMessage&) { return DecodeStatus::kOk; }

/// Squared norm of a NodePose rotation, in double (an f32 sum of squares could underflow).
double Norm2(const glm::quat& q) {
  return static_cast<double>(q.w) * q.w + static_cast<double>(q.x) * q.x +
         static_cast<double>(q.y) * q.y + static_cast<double>(q.z) * q.z;
}

DecodeStatus Check(const NodePosesMessage& m) {
  if (!std::isfinite(m.scene_time_s)) return DecodeStatus::kNonFinite;
  for (int i = 0; i < m.count; ++i) {
    const NodePose& p = m.poses[static_cast<std::size_t>(i)];
    const glm::quat& q = p.rotation;
    if (!std::isfinite(p.translation.x) || !std::isfinite(p.translation.y) ||
        !std::isfinite(p.translation.z) || !std::isfinite(q.w) || !std::isfinite(q.x) ||
        !std::isfinite(q.y) || !std::isfinite(q.z) || !std::isfinite(p.scale.x) ||
        !std::isfinite(p.scale.y) || !std::isfinite(p.scale.z)) {
      return DecodeStatus::kNonFinite;
    }
    if (!(Norm2(q) >= kMinNodePoseQuaternionNorm * kMinNodePoseQuaternionNorm)) {
      return DecodeStatus::kBadValue;
    }
  }
  return DecodeStatus::kOk;
}

/// Header, body and MAC: the one encoder of every message type; `version` goes in the header
/// (another than kProtocolVersion only for a Reject to an older operator of this layout).
template <class Body>
Datagram Encode(const Header& header, MessageType type, const Body& body, const MacKey& key,
                std::uint16_t version = kProtocolVersion) noexcept {
  Datagram d;
  Writer w(d);
  WireHeader h = ToWire(header, type);
  h.version = static_cast<std::uint8_t>(version);
  Fields(w, h);
  Fields(w, body);
  w.Seal(key);
  return d;
}

/// Reads `body` into a new Msg (structure checked as it is read), then Check(); `m` is written
/// only on kOk.
template <class Msg>
DecodeStatus Decode(std::span<const std::uint8_t> body, Msg& m) noexcept {
  Reader r(body);
  Msg out;
  Fields(r, out);
  if (const DecodeStatus s = r.Finish(); s != DecodeStatus::kOk) return s;
  if (const DecodeStatus s = Check(out); s != DecodeStatus::kOk) return s;
  m = out;
  return DecodeStatus::kOk;
}

/// Reads a quantized body (`Wire`, its structure and values checked), then the message it stands
/// for, checked as the full-precision decoder checks it (finite by construction once the body
/// passed); `m` is written only on kOk.
template <class Wire, class Msg, class Dequantize>
DecodeStatus DecodeQuantized(std::span<const std::uint8_t> body, Msg& m,
                             Dequantize&& dequantize) noexcept {
  Wire wire;
  if (const DecodeStatus s = Decode(body, wire); s != DecodeStatus::kOk) return s;
  const Msg out = dequantize(wire);
  if (const DecodeStatus s = Check(out); s != DecodeStatus::kOk) return s;
  m = out;
  return DecodeStatus::kOk;
}

}  // namespace

const char* ToString(DecodeStatus s) noexcept {
  switch (s) {
    case DecodeStatus::kOk:
      return "ok";
    case DecodeStatus::kTooShort:
      return "too_short";
    case DecodeStatus::kTooLong:
      return "too_long";
    case DecodeStatus::kBadMagic:
      return "bad_magic";
    case DecodeStatus::kBadVersion:
      return "bad_version";
    case DecodeStatus::kBadFlags:
      return "bad_flags";
    case DecodeStatus::kUnknownType:
      return "unknown_type";
    case DecodeStatus::kBadCount:
      return "bad_count";
    case DecodeStatus::kNonFinite:
      return "non_finite";
    case DecodeStatus::kBadValue:
      return "bad_value";
    case DecodeStatus::kBadMac:
      return "bad_mac";
    case DecodeStatus::kReplayed:
      return "replayed";
    case DecodeStatus::kWrongSession:
      return "wrong_session";
    case DecodeStatus::kUnexpected:
      return "unexpected";
  }
  return "unknown";
}

const char* ToString(MessageType t) noexcept {
  switch (t) {
    case MessageType::kToolState:
      return "tool_state";
    case MessageType::kContactModel:
      return "contact_model";
    case MessageType::kGoodbye:
      return "goodbye";
    case MessageType::kHello:
      return "hello";
    case MessageType::kWelcome:
      return "welcome";
    case MessageType::kReject:
      return "reject";
    case MessageType::kPing:
      return "ping";
    case MessageType::kPong:
      return "pong";
    case MessageType::kSceneFragment:
      return "scene_fragment";
    case MessageType::kSceneNack:
      return "scene_nack";
    case MessageType::kSceneManifest:
      return "scene_manifest";
    case MessageType::kCompactContactModel:
      return "compact_contact_model";
    case MessageType::kNodePoses:
      return "node_poses";
    case MessageType::kCompactToolState:
      return "compact_tool_state";
  }
  return "unknown";
}

Datagram EncodeToolState(const Header& header, const ToolStateMessage& m,
                         const MacKey& key) noexcept {
  return Encode(header, MessageType::kToolState, m, key);
}

Datagram EncodeCompactToolState(const Header& header, const ToolStateMessage& m,
                                const MacKey& key) noexcept {
  return Encode(header, MessageType::kCompactToolState, QuantizeToolState(m), key);
}

ToolStateMessage CompactToolStateAsReceived(const ToolStateMessage& m) noexcept {
  const CompactToolStateBody b = QuantizeToolState(m);
  if (Check(b) != DecodeStatus::kOk) return m;
  const ToolStateMessage out = DequantizeToolState(b);
  return Check(out) == DecodeStatus::kOk ? out : m;
}

Datagram EncodeContactModel(const Header& header, const ContactModelMessage& m,
                            const MacKey& key) noexcept {
  return Encode(header, MessageType::kContactModel, m, key);
}

Datagram EncodeCompactContactModel(const Header& header, const ContactModelMessage& m,
                                   const MacKey& key) noexcept {
  return Encode(header, MessageType::kCompactContactModel, QuantizeContactModel(m), key);
}

Datagram EncodeGoodbye(const Header& header, const MacKey& key) noexcept {
  return Encode(header, MessageType::kGoodbye, EmptyBody{}, key);
}

Datagram EncodePing(const Header& header, const PingMessage& m, const MacKey& key) noexcept {
  return Encode(header, MessageType::kPing, m, key);
}

Datagram EncodeHello(const Header& header, const HelloMessage& m, const MacKey& key) noexcept {
  return Encode(header, MessageType::kHello, m, key);
}

Datagram EncodeWelcome(const Header& header, const WelcomeMessage& m, const MacKey& key) noexcept {
  return Encode(header, MessageType::kWelcome, m, key);
}

Datagram EncodeReject(const Header& header, const RejectMessage& m, const MacKey& key) noexcept {
  return Encode(header, MessageType::kReject, m, key);
}

Datagram EncodeReject(const Header& header, const RejectMessage& m, const MacKey& key,
                      std::uint16_t version) noexcept {
  // An older version in this layout (8 to kProtocolVersion − 1): this layout with its number.
  if (version >= kFirstShortHeaderVersion && version < kProtocolVersion) {
    return Encode(header, MessageType::kReject, m, key, version);
  }
  // This version, or one whose layout is unknown here (the caller only asks for versions a
  // foreign Hello had: 2 to kProtocolVersion − 1), in this version's layout.
  if (version < 2 || version > kLastLegacyVersion) return EncodeReject(header, m, key);
  Datagram d;
  Writer w(d);
  const LegacyWireHeader h{.version = version,
                           .type = static_cast<std::uint8_t>(MessageType::kReject),
                           .session_id = header.session_id,
                           .sequence = header.sequence,
                           .send_time_ns = header.send_time_ns};
  Fields(w, h);
  Fields(w, m);
  w.SealFull(key);
  return d;
}

/// The header of layout `H` (`header_bytes`) and the Hello's first fields, which versions 2 to 9
/// lay out alike: u16 min_version, u16 max_version, u64 client_nonce. kTooShort unless `bytes`
/// holds them and a MAC of `mac_bytes`.
template <class H>
DecodeStatus ReadHelloStart(std::span<const std::uint8_t> bytes, std::size_t header_bytes,
                            std::size_t mac_bytes, H& h, ForeignHello& hello) noexcept {
  if (bytes.size() < header_bytes + 12 + mac_bytes) return DecodeStatus::kTooShort;
  Reader r(bytes.first(header_bytes + 12));
  Fields(r, h);
  r(hello.min_version);
  r(hello.max_version);
  r(hello.client_nonce);
  hello.header_version = h.version;
  return DecodeStatus::kOk;
}

DecodeStatus OpenForeignHello(std::span<const std::uint8_t> bytes, const MacKey& key,
                              ForeignHello& hello) noexcept {
  if (bytes.size() > kMaxDatagramBytes) return DecodeStatus::kTooLong;
  if (bytes.size() < 4) return DecodeStatus::kTooShort;
  constexpr auto kHello = static_cast<std::uint8_t>(MessageType::kHello);
  ForeignHello read;
  // This version's layout: this version (open it with OpenDatagram) or a newer one, whose
  // layout is unknown here (dropped: a newer operator falls back to this version itself), are
  // kBadVersion; an older one (kFirstShortHeaderVersion to kProtocolVersion − 1: the same header
  // and MAC) is read as far as the Hello's first fields.
  if (LoadLe<std::uint32_t>(bytes.data()) != kLegacyMagic) {
    if (LoadLe<std::uint16_t>(bytes.data()) != kMagic) return DecodeStatus::kBadMagic;
    const std::uint8_t version = bytes[kHeaderVersionOffset];
    if (version < kFirstShortHeaderVersion || version >= kProtocolVersion) {
      return DecodeStatus::kBadVersion;
    }
    WireHeader w;
    if (const DecodeStatus s = ReadHelloStart(bytes, kHeaderBytes, kMacBytes, w, read);
        s != DecodeStatus::kOk) {
      return s;
    }
    if (w.type != kHello) return DecodeStatus::kUnexpected;
    if (!VerifyMac(bytes, key)) return DecodeStatus::kBadMac;
    hello = read;
    return DecodeStatus::kOk;
  }
  LegacyWireHeader w;
  if (const DecodeStatus s = ReadHelloStart(bytes, kLegacyHeaderBytes, kLegacyMacBytes, w, read);
      s != DecodeStatus::kOk) {
    return s;
  }
  // Versions 2 to 7 share this header and the Hello's and Reject's first fields.
  if (w.version < 2 || w.version > kLastLegacyVersion) return DecodeStatus::kBadVersion;
  if (w.flags != 0) return DecodeStatus::kBadFlags;
  if (w.type != kHello) return DecodeStatus::kUnexpected;
  if (!VerifyFullMac(bytes, key)) return DecodeStatus::kBadMac;
  hello = read;
  return DecodeStatus::kOk;
}

Datagram EncodePong(const Header& header, const PongMessage& m, const MacKey& key) noexcept {
  return Encode(header, MessageType::kPong, m, key);
}

Datagram EncodeSceneFragment(const Header& header, const SceneFragmentMessage& m,
                             const MacKey& key) noexcept {
  return Encode(header, MessageType::kSceneFragment, m, key);
}

Datagram EncodeSceneManifest(const Header& header, const SceneManifestMessage& m,
                             const MacKey& key) noexcept {
  return Encode(header, MessageType::kSceneManifest, m, key);
}

Datagram EncodeSceneNack(const Header& header, const SceneNackMessage& m,
                         const MacKey& key) noexcept {
  return Encode(header, MessageType::kSceneNack, m, key);
}

Datagram EncodeNodePoses(const Header& header, const NodePosesMessage& m,
                         const MacKey& key) noexcept {
  return Encode(header, MessageType::kNodePoses, m, key);
}

DecodeStatus PeekHeader(std::span<const std::uint8_t> bytes, Header& h) noexcept {
  if (bytes.size() < kHeaderBytes) return DecodeStatus::kTooShort;
  if (bytes.size() > kMaxDatagramBytes) return DecodeStatus::kTooLong;
  Reader r(bytes.first(kHeaderBytes));
  WireHeader w;
  Fields(r, w);
  if (w.magic != kMagic) return DecodeStatus::kBadMagic;
  if (w.version != kProtocolVersion) return DecodeStatus::kBadVersion;
  if (w.type < 1 || w.type > kMaxMessageType) return DecodeStatus::kUnknownType;
  h.type = static_cast<MessageType>(w.type);
  h.session_id = w.session_id;
  h.sequence = w.sequence;
  h.send_time_ns =
      1000 * (static_cast<std::int64_t>(w.send_time_us_high) << 32 | w.send_time_us_low);
  return DecodeStatus::kOk;
}

int DatagramType(std::span<const std::uint8_t> bytes) noexcept {
  if (bytes.size() > kHeaderTypeOffset && LoadLe<std::uint16_t>(bytes.data()) == kMagic &&
      bytes[kHeaderVersionOffset] == kProtocolVersion) {
    return bytes[kHeaderTypeOffset];
  }
  if (bytes.size() > 6 && LoadLe<std::uint32_t>(bytes.data()) == kLegacyMagic) return bytes[6];
  return 0;
}

DecodeStatus OpenDatagram(std::span<const std::uint8_t> bytes, const MacKey& key, Header& h,
                          std::span<const std::uint8_t>& body) noexcept {
  if (bytes.size() > kMaxDatagramBytes) return DecodeStatus::kTooLong;
  if (bytes.size() < kHeaderBytes + kMacBytes) return DecodeStatus::kTooShort;
  Header header;
  if (const DecodeStatus s = PeekHeader(bytes, header); s != DecodeStatus::kOk) return s;
  if (!VerifyMac(bytes, key)) return DecodeStatus::kBadMac;
  h = header;
  body = bytes.subspan(kHeaderBytes, bytes.size() - kHeaderBytes - kMacBytes);
  return DecodeStatus::kOk;
}

DecodeStatus DecodeEmpty(std::span<const std::uint8_t> body) noexcept {
  EmptyBody m;
  return Decode(body, m);
}

DecodeStatus DecodePing(std::span<const std::uint8_t> body, PingMessage& m) noexcept {
  return Decode(body, m);
}

DecodeStatus DecodeToolState(std::span<const std::uint8_t> body, ToolStateMessage& m) noexcept {
  return Decode(body, m);
}

DecodeStatus DecodeCompactToolState(std::span<const std::uint8_t> body,
                                    ToolStateMessage& m) noexcept {
  return DecodeQuantized<CompactToolStateBody>(body, m, DequantizeToolState);
}

DecodeStatus DecodeContactModel(std::span<const std::uint8_t> body,
                                ContactModelMessage& m) noexcept {
  return Decode(body, m);
}

DecodeStatus DecodeCompactContactModel(std::span<const std::uint8_t> body, ContactModelMessage& m,
                                       std::int64_t receive_time_ns) noexcept {
  return DecodeQuantized<CompactContactModelBody>(
      body, m, [receive_time_ns](const CompactContactModelBody& b) {
        return DequantizeContactModel(b, receive_time_ns);
      });
}

DecodeStatus DecodeHello(std::span<const std::uint8_t> body, HelloMessage& m) noexcept {
  return Decode(body, m);
}

DecodeStatus DecodeWelcome(std::span<const std::uint8_t> body, WelcomeMessage& m) noexcept {
  return Decode(body, m);
}

DecodeStatus DecodeReject(std::span<const std::uint8_t> body, RejectMessage& m) noexcept {
  return Decode(body, m);
}

DecodeStatus DecodePong(std::span<const std::uint8_t> body, PongMessage& m) noexcept {
  return Decode(body, m);
}

DecodeStatus DecodeSceneFragment(std::span<const std::uint8_t> body,
                                 SceneFragmentMessage& m) noexcept {
  return Decode(body, m);
}

DecodeStatus DecodeSceneManifest(std::span<const std::uint8_t> body,
                                 SceneManifestMessage& m) noexcept {
  return Decode(body, m);
}

DecodeStatus DecodeSceneNack(std::span<const std::uint8_t> body, SceneNackMessage& m) noexcept {
  return Decode(body, m);
}

DecodeStatus DecodeNodePoses(std::span<const std::uint8_t> body, NodePosesMessage& m) noexcept {
  NodePosesMessage out;
  if (const DecodeStatus s = Decode(body, out); s != DecodeStatus::kOk) return s;
  for (int i = 0; i < out.count; ++i) {
    glm::quat& q = out.poses[static_cast<std::size_t>(i)].rotation;
    const double inverse = 1.0 / std::sqrt(Norm2(q));  // Check(): norm ≥ 1e-6, finite
    q = glm::quat(static_cast<float>(q.w * inverse), static_cast<float>(q.x * inverse),
                  static_cast<float>(q.y * inverse), static_cast<float>(q.z * inverse));
  }
  m = out;
  return DecodeStatus::kOk;
}

}  // namespace ht::wire
