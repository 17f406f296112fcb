#pragma once

// Little-endian byte order, the one byte order of every format the project writes: datagrams
// (transport/messages.cc), the haptic-model cache (model_build/haptic_model_build.cc) and GLB
// containers (codecs). One definition each of the store, load and append helpers, used by all
// of them (docs/STYLE.md §7: field-by-field serialization, never a struct's memory image).
//
// The helpers shift bytes rather than copy memory, so they are correct on any host byte order,
// and the compiler turns them into one load or store on a little-endian host.

#include <bit>
#include <concepts>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace ht {

/// Writes `value` to out[0 .. sizeof(T)) least significant byte first. `out` must hold
/// sizeof(T) bytes (not checked: callers check the space once per field list).
template <std::unsigned_integral T>
constexpr void StoreLe(T value, std::uint8_t* out) noexcept {
  for (std::size_t i = 0; i < sizeof(T); ++i) {
    out[i] = static_cast<std::uint8_t>(value >> (8 * i));
  }
}

/// Reads a T stored least significant byte first from in[0 .. sizeof(T)) (not checked).
template <std::unsigned_integral T>
constexpr T LoadLe(const std::uint8_t* in) noexcept {
  T value = 0;
  for (std::size_t i = 0; i < sizeof(T); ++i)
    value |= static_cast<T>(static_cast<T>(in[i]) << (8 * i));
  return value;
}

/// Appends `value` to `out`, least significant byte first. Allocates as std::vector does.
template <std::unsigned_integral T>
void AppendLe(std::vector<std::uint8_t>& out, T value) {
  std::uint8_t bytes[sizeof(T)];
  StoreLe(value, bytes);
  out.insert(out.end(), bytes, bytes + sizeof(T));
}

/// Appends an IEEE-754 float or double as its bit pattern, least significant byte first.
inline void AppendLe(std::vector<std::uint8_t>& out, float value) {
  AppendLe(out, std::bit_cast<std::uint32_t>(value));
}
inline void AppendLe(std::vector<std::uint8_t>& out, double value) {
  AppendLe(out, std::bit_cast<std::uint64_t>(value));
}

}  // namespace ht
