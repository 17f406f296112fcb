#include "master_station/png_image.h"

#include <png.h>

#include <cstring>
#include <stdexcept>

#include "jpeg_image.h"

namespace ht {
namespace {

constexpr int kMaxPngSide = 16384;

// libpng's simplified API keeps its reason in image.message (never longer than 64 bytes).
std::string Reason(const png_image& image) {
  return std::string(image.message, strnlen(image.message, sizeof(image.message)));
}

}  // namespace

void WritePng(const std::string& path, int width, int height,
              std::span<const std::uint8_t> rgba_top_down) {
  if (width < 1 || height < 1 || width > kMaxPngSide || height > kMaxPngSide) {
    throw std::invalid_argument("WritePng: image size must be in [1, " +
                                std::to_string(kMaxPngSide) + "] each, got " +
                                std::to_string(width) + " x " + std::to_string(height));
  }
  const std::size_t expected =
      static_cast<std::size_t>(width) * static_cast<std::size_t>(height) * 4;
  if (rgba_top_down.size() != expected) {
    throw std::invalid_argument("WritePng: a " + std::to_string(width) + " x " +
                                std::to_string(height) + " RGBA8 image needs " +
                                std::to_string(expected) + " bytes, got " +
                                std::to_string(rgba_top_down.size()));
  }
  png_image image;
  std::memset(&image, 0, sizeof(image));
  image.version = PNG_IMAGE_VERSION;
  image.width = static_cast<png_uint_32>(width);
  image.height = static_cast<png_uint_32>(height);
  image.format = PNG_FORMAT_RGBA;
  // Row stride in components (positive: row 0 is the top).
  const png_int_32 stride = static_cast<png_int_32>(PNG_IMAGE_ROW_STRIDE(image));
  if (png_image_write_to_file(&image, path.c_str(), /*convert_to_8bit=*/0, rgba_top_down.data(),
                              stride, /*colormap=*/nullptr) == 0) {
    const std::string reason = Reason(image);
    png_image_free(&image);
    throw std::runtime_error("WritePng: cannot write " + path + ": " + reason);
  }
}

std::vector<std::uint8_t> ReadPng(const std::string& path, int* width, int* height) {
  if (width == nullptr || height == nullptr) {
    throw std::invalid_argument("ReadPng: width and height must not be null");
  }
  png_image image;
  std::memset(&image, 0, sizeof(image));
  image.version = PNG_IMAGE_VERSION;
  if (png_image_begin_read_from_file(&image, path.c_str()) == 0) {
    const std::string reason = Reason(image);
    png_image_free(&image);
    throw std::runtime_error("ReadPng: cannot read " + path + ": " + reason);
  }
  if (image.width < 1 || image.height < 1 || image.width > kMaxPngSide ||
      image.height > kMaxPngSide) {
    const std::string size = std::to_string(image.width) + " x " + std::to_string(image.height);
    png_image_free(&image);
    throw std::runtime_error("ReadPng: " + path + " is " + size + " pixels; at most " +
                             std::to_string(kMaxPngSide) + " a side is read");
  }
  image.format = PNG_FORMAT_RGBA;
  std::vector<std::uint8_t> rgba(PNG_IMAGE_SIZE(image));
  if (png_image_finish_read(&image, /*background=*/nullptr, rgba.data(),
                            static_cast<png_int_32>(PNG_IMAGE_ROW_STRIDE(image)),
                            /*colormap=*/nullptr) == 0) {
    const std::string reason = Reason(image);
    png_image_free(&image);
    throw std::runtime_error("ReadPng: cannot read " + path + ": " + reason);
  }
  *width = static_cast<int>(image.width);
  *height = static_cast<int>(image.height);
  return rgba;
}

std::vector<std::uint8_t> DecodeImage(std::span<const std::uint8_t> bytes, int* width,
                                      int* height) {
  if (width == nullptr || height == nullptr) {
    throw std::invalid_argument("DecodeImage: width and height must not be null");
  }
  const std::string size = std::to_string(bytes.size()) + " bytes";
  if (bytes.size() >= 3 && bytes[0] == 0xFF && bytes[1] == 0xD8 && bytes[2] == 0xFF) {
    return image_internal::DecodeJpeg(bytes, kMaxDecodedImageSide, width, height);
  }
  if (bytes.size() < 8 || png_sig_cmp(bytes.data(), 0, 8) != 0) {
    throw std::runtime_error("DecodeImage: " + size +
                             " are neither PNG nor JPEG (no PNG or JPEG signature)");
  }
  png_image image;
  std::memset(&image, 0, sizeof(image));
  image.version = PNG_IMAGE_VERSION;
  if (png_image_begin_read_from_memory(&image, bytes.data(), bytes.size()) == 0) {
    const std::string reason = Reason(image);
    png_image_free(&image);
    throw std::runtime_error("DecodeImage: PNG of " + size + ": " + reason);
  }
  if (image.width < 1 || image.height < 1 || image.width > kMaxDecodedImageSide ||
      image.height > kMaxDecodedImageSide) {
    const std::string dims = std::to_string(image.width) + " x " + std::to_string(image.height);
    png_image_free(&image);
    throw std::runtime_error("DecodeImage: PNG of " + size + " is " + dims + " pixels; at most " +
                             std::to_string(kMaxDecodedImageSide) + " a side is decoded");
  }
  image.format = PNG_FORMAT_RGBA;  // 8-bit sRGB, alpha 255 where the file has none
  std::vector<std::uint8_t> rgba;
  try {
    rgba.resize(PNG_IMAGE_SIZE(image));
  } catch (...) {
    png_image_free(&image);
    throw;
  }
  if (png_image_finish_read(&image, /*background=*/nullptr, rgba.data(),
                            static_cast<png_int_32>(PNG_IMAGE_ROW_STRIDE(image)),
                            /*colormap=*/nullptr) == 0) {
    const std::string reason = Reason(image);
    png_image_free(&image);
    throw std::runtime_error("DecodeImage: PNG of " + size + ": " + reason);
  }
  *width = static_cast<int>(image.width);
  *height = static_cast<int>(image.height);
  return rgba;
}

}  // namespace ht
