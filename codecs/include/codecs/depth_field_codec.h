#pragma once
// A contact's depth field (haptic_core/depth_field.h) as bytes, for the wire from the remote node
// to the operator: its frames, grid and lattice place in full, its two maps as depth-map streams
// (codecs/depth_map_codec.h).
//
// Layout (all little-endian, f64/f32 IEEE-754):
//   u8  format (kDepthFieldFormat)
//   u32 id (≠ 0)   u32 lattice_id   i32 lattice_i0, lattice_j0, tool_lattice_i0, tool_lattice_j0
//   f64 cell_m     u16 nx, u16 ny   f64 tool_offset_u_m, tool_offset_v_m
//   X_WF: 3×f64 translation (m), 4×f64 rotation w, x, y, z   X_WT0: the same
//   f64 travel_margin_m   f64 smooth_max_m   u8 force_law (ForceLaw: 0 seed, 1 pressure)
//   f64 pressure_area_m2   u8 stride_hint
//   u32 n, n bytes: the environment's map (nx × ny)   u32 n, n bytes: the tool's map (nx × ny)
// and nothing after. The decoded field is the encoded one but for its maps, each height within
// half its stream's step (DepthMapEncodeOptions::step_m, 0.25 µm by default).

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "codecs/depth_map_codec.h"
#include "haptic_core/depth_field.h"

namespace ht {

inline constexpr std::uint8_t kDepthFieldFormat = 2;
/// Bytes of the layout besides the two maps' streams.
inline constexpr std::size_t kDepthFieldFixedBytes = 199;

/// Encodes `field` (prepared or not: only what Prepare derives is left out). Throws
/// std::invalid_argument when its sides are outside [1, kMaxDepthFieldSide] or its maps are not
/// nx·ny, or a map cannot be encoded (EncodeDepthMap).
std::vector<std::uint8_t> EncodeDepthField(const DepthField& field,
                                           const DepthMapEncodeOptions& options = {});

/// Decodes `bytes` into `out` and prepares it (DepthField::Prepare; out's buffers reused, and
/// `scratch` for the maps' decoding). Returns false with `error` saying what is wrong for a
/// stream that is short, has another format byte or bytes after its end, a map that does not
/// decode (DecodeDepthMap) or whose sides are not the field's, or a field that Prepare refuses
/// (a zero id, a frame that is not finite, sides outside [4, kMaxDepthFieldSide], an unknown
/// law, ...).
bool DecodeDepthField(std::span<const std::uint8_t> bytes, DepthField& out,
                      DecodedDepthMap& scratch, std::string& error);

}  // namespace ht
