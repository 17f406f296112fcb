#pragma once
// Compression of one map of a contact's depth field (haptic_core/depth_field.h: the environment's
// heights b or the tool's heights a on a grid, NaN where the surface is absent) for the wire from
// the remote node to the operator: heights quantized on a uniform step, predicted from their
// neighbours, deflated with zlib (https://zlib.net).
//
// Stream (all little-endian):
//   u8  format (kDepthMapFormat)      u16 nx, u16 ny (1..kDepthMapMaxSide)
//   f32 step_m q (> 0, finite)        f32 origin_m o (finite): node k's height is o + code_k·q
//   u32 present (nodes with a surface, ≤ nx·ny)
//   then one zlib stream of ceil(nx·ny/8) + 2·present bytes: the presence bitmap (bit k % 8 of
//   byte k / 8 for node k = j·nx + i), then the present nodes' residuals in row order as zigzag
//   16-bit integers, their low bytes first, then their high bytes. A code is its residual plus
//   its prediction, modulo 2¹⁶: the prediction is left + up − up-left where all three are present
//   (the plane through them, clamped to [0, 65534]), else the left, else the up, else the previous
//   present code in row order, else 0.
// Each decoded height lies within q/2 of the encoded one, plus float32 rounding (6e-8 of its
// magnitude): q is the requested step, or the map's range over 65534 where that is coarser.

#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace ht {

/// The stream's format byte.
inline constexpr std::uint8_t kDepthMapFormat = 1;
/// Largest side (nodes) a stream may declare; haptic_core's kMaxDepthFieldSide is below it.
inline constexpr int kDepthMapMaxSide = 1024;

/// Options of EncodeDepthMap().
struct DepthMapEncodeOptions {
  /// Quantization step q (m, > 0): the decoded heights are within q/2 of the map's. 0.25 µm is
  /// an eighth of the depth field's smooth-maximum width (kDepthFieldSmoothMaxM, 2 µm).
  double step_m = 0.25e-6;
  /// zlib's level, 1 (fastest) to 9 (smallest).
  int level = 6;
};

/// Encodes `heights_m` (nx·ny heights in m, row-major j·nx + i; NaN: no surface there). Throws
/// std::invalid_argument when nx or ny is outside [1, kDepthMapMaxSide], the span's size is not
/// nx·ny, a height is infinite or beyond ±1e3 m, or an option is out of range;
/// std::runtime_error when zlib fails.
std::vector<std::uint8_t> EncodeDepthMap(std::span<const float> heights_m, int nx, int ny,
                                         const DepthMapEncodeOptions& options = {});

/// A decoded map.
struct DecodedDepthMap {
  int nx = 0, ny = 0;
  double step_m = 0.0;           ///< the stream's q (m): the bound on each height's error is q/2
  std::vector<float> heights_m;  ///< nx·ny, row-major, NaN where absent
};

/// Decodes a stream written by EncodeDepthMap into `out` (its vector reused). Returns false with
/// `error` saying what is wrong (and `out` unspecified) for a stream that is short, has another
/// format byte, declares a side outside [1, max_side] (max_side ≤ kDepthMapMaxSide), a step or
/// origin that is not finite or a step ≤ 0, more present nodes than nodes, a zlib stream that does
/// not inflate to exactly the declared length, a bitmap whose count disagrees with `present`, or
/// bytes after the zlib stream. Never reads or allocates beyond what the header bounds
/// (at most max_side² nodes).
bool DecodeDepthMap(std::span<const std::uint8_t> bytes, int max_side, DecodedDepthMap& out,
                    std::string& error);

}  // namespace ht
