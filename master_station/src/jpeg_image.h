#pragma once
// Private to master_station_display: JPEG decoding from memory (jpeg_image.cc), used by
// DecodeImage() (png_image.cc).

#include <cstdint>
#include <span>
#include <vector>

namespace ht::image_internal {

// Decodes JPEG bytes into RGBA8 (alpha 255), row 0 the top, as DecodeImage() documents; images
// wider or taller than `max_side` pixels are refused from the header. Throws std::runtime_error
// naming libjpeg's reason on corrupt or truncated data or an unsupported colour space.
std::vector<std::uint8_t> DecodeJpeg(std::span<const std::uint8_t> bytes, int max_side, int* width,
                                     int* height);

}  // namespace ht::image_internal
