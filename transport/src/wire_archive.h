#pragma once
// The archives that walk a message's fields (internal to the wire format's files): Writer
// (encoding), Reader (decoding, with the structural checks) and Sizer (the layout's size, for
// protocol.h's static_asserts), and the field helpers every message's Fields() uses.

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
#include "transport/messages.h"

namespace ht::wire::detail {

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

}  // namespace ht::wire::detail
