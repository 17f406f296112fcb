#pragma once
// PNG files of RGBA8 images (libpng's simplified API): display frames written by the operator
// station and read back by tests; and PNG or JPEG images decoded from memory (a glTF material's
// base-colour texture as the remote node streams it).

#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace ht {

/// Writes a width x height RGBA8 image (row 0 the top; rgba_top_down has width·height·4 bytes)
/// to `path` as an 8-bit RGBA PNG, replacing any file there. Throws std::invalid_argument for
/// width or height < 1 or a buffer of another size, and std::runtime_error naming the path and
/// libpng's reason when the file cannot be written.
void WritePng(const std::string& path, int width, int height,
              std::span<const std::uint8_t> rgba_top_down);

/// Reads the PNG at `path` as RGBA8, row 0 the top: returns width·height·4 bytes and sets *width
/// and *height (pixels). Any PNG colour type and bit depth is converted (grey → r = g = b, no
/// alpha → 255, 16-bit → 8-bit). Throws std::runtime_error naming the path and the reason for a
/// missing, truncated or corrupt file, or one wider or taller than 16384 pixels;
/// std::invalid_argument for null width/height pointers.
std::vector<std::uint8_t> ReadPng(const std::string& path, int* width, int* height);

/// Largest width and height (pixels) DecodeImage() accepts: 8192² RGBA8 is 256 MiB.
inline constexpr int kMaxDecodedImageSide = 8192;

/// Decodes a PNG or JPEG image held in memory (told apart by its first bytes, not by a MIME type)
/// into RGBA8, row 0 the top: returns width·height·4 bytes and sets *width and *height (pixels).
/// The colour values are the file's, 8-bit sRGB-encoded for ordinary images (a PNG with another
/// gamma is converted to sRGB by libpng; a JPEG is taken as sRGB, embedded ICC profiles are
/// ignored); they are not converted to linear. PNG: any colour type and bit depth (grey →
/// r = g = b, no alpha → 255, 16-bit → 8-bit), through libpng's simplified API. JPEG: baseline or
/// progressive, grey or YCbCr (alpha 255), through libjpeg(-turbo), whose error manager is
/// replaced so that a corrupt stream is reported rather than ending the process; corrupt-data
/// warnings (a premature end, bad Huffman codes, ...) are errors here.
///
/// Throws std::runtime_error, saying what is wrong, for bytes that are neither PNG nor JPEG,
/// truncated or corrupt data, an unsupported JPEG colour space (CMYK), or an image wider or
/// taller than kMaxDecodedImageSide (refused from its header, before the pixels are
/// allocated); std::invalid_argument for null width/height pointers. Never crashes or exits on
/// garbage.
std::vector<std::uint8_t> DecodeImage(std::span<const std::uint8_t> bytes, int* width, int* height);

}  // namespace ht
