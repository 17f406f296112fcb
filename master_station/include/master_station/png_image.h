#pragma once
// PNG files of RGBA8 images (libpng's simplified API): display frames written by the operator
// station and read back by tests.

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

}  // namespace ht
