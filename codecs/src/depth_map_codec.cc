// The depth-map stream (depth_map_codec.h): quantization, prediction, zlib.

#include "codecs/depth_map_codec.h"

#include <zlib.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>

namespace ht {
namespace {

constexpr std::size_t kHeaderBytes = 1 + 2 + 2 + 4 + 4 + 4;
constexpr int kMaxCode = 65534;

void PutU16(std::vector<std::uint8_t>& out, std::uint16_t v) {
  out.push_back(static_cast<std::uint8_t>(v));
  out.push_back(static_cast<std::uint8_t>(v >> 8));
}
void PutU32(std::vector<std::uint8_t>& out, std::uint32_t v) {
  for (int b = 0; b < 4; ++b) out.push_back(static_cast<std::uint8_t>(v >> (8 * b)));
}
void PutF32(std::vector<std::uint8_t>& out, float f) {
  std::uint32_t v;
  std::memcpy(&v, &f, 4);
  PutU32(out, v);
}
std::uint32_t GetU32(const std::uint8_t* p) {
  return static_cast<std::uint32_t>(p[0]) | (static_cast<std::uint32_t>(p[1]) << 8) |
         (static_cast<std::uint32_t>(p[2]) << 16) | (static_cast<std::uint32_t>(p[3]) << 24);
}
float GetF32(const std::uint8_t* p) {
  const std::uint32_t v = GetU32(p);
  float f;
  std::memcpy(&f, &v, 4);
  return f;
}

/// The prediction of node (i, j)'s code from its coded neighbours (depth_map_codec.h).
inline int Predict(const std::vector<std::int32_t>& code, int nx, int i, int j, int previous) {
  const int k = j * nx + i;
  const int left = i > 0 ? code[static_cast<std::size_t>(k - 1)] : -1;
  const int up = j > 0 ? code[static_cast<std::size_t>(k - nx)] : -1;
  const int up_left = i > 0 && j > 0 ? code[static_cast<std::size_t>(k - nx - 1)] : -1;
  if (left >= 0 && up >= 0 && up_left >= 0) return std::clamp(left + up - up_left, 0, kMaxCode);
  if (left >= 0) return left;
  if (up >= 0) return up;
  return std::max(previous, 0);
}

inline std::uint16_t ZigZag(int residual) {
  const auto s = static_cast<std::int16_t>(static_cast<std::uint16_t>(residual & 0xFFFF));
  return static_cast<std::uint16_t>((static_cast<std::uint16_t>(s) << 1) ^
                                    static_cast<std::uint16_t>(s >> 15));
}
inline int UnZigZag(std::uint16_t z) {
  return static_cast<std::int16_t>(static_cast<std::uint16_t>((z >> 1) ^ (0u - (z & 1u))));
}

}  // namespace

std::vector<std::uint8_t> EncodeDepthMap(std::span<const float> heights_m, int nx, int ny,
                                         const DepthMapEncodeOptions& options) {
  if (nx < 1 || ny < 1 || nx > kDepthMapMaxSide || ny > kDepthMapMaxSide) {
    throw std::invalid_argument("EncodeDepthMap: a side of " + std::to_string(nx) + " x " +
                                std::to_string(ny) + " nodes is outside [1, " +
                                std::to_string(kDepthMapMaxSide) + "]");
  }
  const std::size_t n = static_cast<std::size_t>(nx) * static_cast<std::size_t>(ny);
  if (heights_m.size() != n) {
    throw std::invalid_argument("EncodeDepthMap: " + std::to_string(heights_m.size()) +
                                " heights for " + std::to_string(n) + " nodes");
  }
  if (!(options.step_m > 0.0) || !std::isfinite(options.step_m) || options.level < 1 ||
      options.level > 9) {
    throw std::invalid_argument("EncodeDepthMap: the step must be > 0 and finite, the level 1..9");
  }
  float lo = std::numeric_limits<float>::infinity(), hi = -lo;
  std::uint32_t present = 0;
  for (const float h : heights_m) {
    if (std::isnan(h)) continue;
    if (!(std::abs(h) <= 1e3f)) {
      throw std::invalid_argument("EncodeDepthMap: a height is infinite or beyond 1e3 m");
    }
    lo = std::min(lo, h);
    hi = std::max(hi, h);
    ++present;
  }
  if (present == 0) lo = hi = 0.0f;
  const double q = std::max(options.step_m, (static_cast<double>(hi) - lo) / kMaxCode);
  std::vector<std::int32_t> code(n, -1);
  std::vector<std::uint8_t> raw((n + 7) / 8 + 2 * static_cast<std::size_t>(present), 0);
  std::uint8_t* low = raw.data() + (n + 7) / 8;
  std::uint8_t* high = low + present;
  std::size_t r = 0;
  int previous = -1;
  for (int j = 0; j < ny; ++j) {
    for (int i = 0; i < nx; ++i) {
      const std::size_t k = static_cast<std::size_t>(j) * nx + i;
      const float h = heights_m[k];
      if (std::isnan(h)) continue;
      const int c = std::clamp(static_cast<int>(std::lround((h - lo) / q)), 0, kMaxCode);
      const int p = Predict(code, nx, i, j, previous);
      code[k] = c;
      previous = c;
      raw[k / 8] = static_cast<std::uint8_t>(raw[k / 8] | (1u << (k % 8)));
      const std::uint16_t z = ZigZag(c - p);
      low[r] = static_cast<std::uint8_t>(z);
      high[r] = static_cast<std::uint8_t>(z >> 8);
      ++r;
    }
  }
  std::vector<std::uint8_t> out;
  out.reserve(kHeaderBytes + compressBound(static_cast<uLong>(raw.size())));
  out.push_back(kDepthMapFormat);
  PutU16(out, static_cast<std::uint16_t>(nx));
  PutU16(out, static_cast<std::uint16_t>(ny));
  PutF32(out, static_cast<float>(q));
  PutF32(out, lo);
  PutU32(out, present);
  uLongf packed = compressBound(static_cast<uLong>(raw.size()));
  out.resize(kHeaderBytes + packed);
  const int z = compress2(out.data() + kHeaderBytes, &packed, raw.data(),
                          static_cast<uLong>(raw.size()), options.level);
  if (z != Z_OK)
    throw std::runtime_error("EncodeDepthMap: zlib compress2 failed (" + std::to_string(z) + ")");
  out.resize(kHeaderBytes + packed);
  return out;
}

bool DecodeDepthMap(std::span<const std::uint8_t> bytes, int max_side, DecodedDepthMap& out,
                    std::string& error) {
  max_side = std::clamp(max_side, 1, kDepthMapMaxSide);
  if (bytes.size() < kHeaderBytes) {
    error = "a depth map of " + std::to_string(bytes.size()) + " bytes is shorter than its header";
    return false;
  }
  const std::uint8_t* p = bytes.data();
  if (p[0] != kDepthMapFormat) {
    error =
        "depth-map format " + std::to_string(p[0]) + " is not " + std::to_string(kDepthMapFormat);
    return false;
  }
  const int nx = p[1] | (p[2] << 8), ny = p[3] | (p[4] << 8);
  const float q = GetF32(p + 5), origin = GetF32(p + 9);
  const std::uint32_t present = GetU32(p + 13);
  if (nx < 1 || ny < 1 || nx > max_side || ny > max_side) {
    error = "a depth map of " + std::to_string(nx) + " x " + std::to_string(ny) +
            " nodes is outside [1, " + std::to_string(max_side) + "]";
    return false;
  }
  if (!(q > 0.0f) || !std::isfinite(q) || !std::isfinite(origin)) {
    error = "a depth map's step or origin is not finite, or its step not positive";
    return false;
  }
  const std::size_t n = static_cast<std::size_t>(nx) * static_cast<std::size_t>(ny);
  if (present > n) {
    error = "a depth map declares " + std::to_string(present) + " present nodes of " +
            std::to_string(n);
    return false;
  }
  const std::size_t mask_bytes = (n + 7) / 8;
  std::vector<std::uint8_t> raw(mask_bytes + 2 * static_cast<std::size_t>(present));
  z_stream s{};
  if (inflateInit(&s) != Z_OK) {
    error = "zlib inflateInit failed";
    return false;
  }
  s.next_in = const_cast<Bytef*>(p + kHeaderBytes);
  s.avail_in = static_cast<uInt>(bytes.size() - kHeaderBytes);
  s.next_out = raw.data();
  s.avail_out = static_cast<uInt>(raw.size());
  const int z = inflate(&s, Z_FINISH);
  const bool whole = z == Z_STREAM_END && s.avail_out == 0 && s.avail_in == 0;
  inflateEnd(&s);
  if (!whole) {
    error = z == Z_STREAM_END
                ? "a depth map's zlib stream is not the declared length, or bytes follow it"
                : "a depth map's zlib stream is corrupt or shorter than declared";
    return false;
  }
  std::uint32_t counted = 0;
  for (std::size_t b = 0; b < mask_bytes; ++b)
    counted += static_cast<std::uint32_t>(std::popcount(raw[b]));
  // Bits past the last node must be clear.
  if (n % 8 != 0 && (raw[mask_bytes - 1] >> (n % 8)) != 0) ++counted;
  if (counted != present) {
    error = "a depth map's presence bitmap counts " + std::to_string(counted) + " nodes, not " +
            std::to_string(present);
    return false;
  }
  out.nx = nx;
  out.ny = ny;
  out.step_m = q;
  out.heights_m.assign(n, std::numeric_limits<float>::quiet_NaN());
  std::vector<std::int32_t> code(n, -1);
  const std::uint8_t* low = raw.data() + mask_bytes;
  const std::uint8_t* high = low + present;
  std::size_t r = 0;
  int previous = -1;
  for (int j = 0; j < ny; ++j) {
    for (int i = 0; i < nx; ++i) {
      const std::size_t k = static_cast<std::size_t>(j) * nx + i;
      if (((raw[k / 8] >> (k % 8)) & 1u) == 0) continue;
      const int pred = Predict(code, nx, i, j, previous);
      const auto zz = static_cast<std::uint16_t>(low[r] | (high[r] << 8));
      ++r;
      const int c = (pred + UnZigZag(zz)) & 0xFFFF;
      code[k] = c;
      previous = c;
      out.heights_m[k] = static_cast<float>(origin + static_cast<double>(c) * q);
    }
  }
  return true;
}

}  // namespace ht
