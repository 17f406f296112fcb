// JPEG decoding from memory with libjpeg(-turbo) (https://libjpeg-turbo.org, libjpeg.txt
// "Error handling"): libjpeg's default error_exit() prints and calls exit(), so the error manager
// is replaced by one that longjmps back to the decoding function, which then destroys the
// decompressor and reports libjpeg's message. As libjpeg-turbo's example.c and TurboJPEG do, the
// function that calls setjmp() holds only plain C data (no C++ object with a destructor lives
// across the longjmp), allocates the pixels with malloc, and the C++ wrapper copies them into a
// vector afterwards. Corrupt-data warnings (emit_message with level -1) are made fatal too, as
// TurboJPEG's TJFLAG_STOPONWARNING does, so that a truncated file is refused rather than padded
// with grey.

#include "jpeg_image.h"

// clang-format off
#include <cstdio>  // jpeglib.h needs FILE and size_t first
#include <jpeglib.h>
#include <jerror.h>
// clang-format on

#include <csetjmp>
#include <cstdlib>
#include <cstring>
#include <stdexcept>
#include <string>

namespace ht::image_internal {
namespace {

struct ErrorManager {
  jpeg_error_mgr pub;  // first: libjpeg sees a jpeg_error_mgr*
  std::jmp_buf jump;
  char message[JMSG_LENGTH_MAX];
};

[[noreturn]] void ErrorExit(j_common_ptr cinfo) {
  ErrorManager* const err = reinterpret_cast<ErrorManager*>(cinfo->err);
  (*cinfo->err->format_message)(cinfo, err->message);
  std::longjmp(err->jump, 1);
}

// Level -1 is a warning: fatal unless it is one that says nothing about the pixels' integrity.
// Levels >= 0 are trace messages: ignored.
void EmitMessage(j_common_ptr cinfo, int msg_level) {
  if (msg_level >= 0) return;
  const int code = cinfo->err->msg_code;
  if (code == JWRN_JFIF_MAJOR || code == JWRN_ADOBE_XFORM || code == JWRN_BOGUS_ICC) return;
  ErrorExit(cinfo);
}

void OutputMessage(j_common_ptr) {}  // nothing is printed

// Decodes `data` into a malloc'd RGBA8 buffer (*pixels, the caller frees it). Returns true, or
// false with `message` (JMSG_LENGTH_MAX bytes) set. Only plain C data lives in this frame.
bool DecodeJpegC(const unsigned char* data, unsigned long size, int max_side,
                 unsigned char** pixels, int* width, int* height, char* message) {
  jpeg_decompress_struct cinfo;
  ErrorManager err;
  std::memset(&cinfo, 0, sizeof cinfo);   // jpeg_destroy_decompress is safe on it at any point
  unsigned char* volatile out = nullptr;  // written after setjmp, read after the longjmp
  cinfo.err = jpeg_std_error(&err.pub);
  err.pub.error_exit = ErrorExit;
  err.pub.emit_message = EmitMessage;
  err.pub.output_message = OutputMessage;
  err.message[0] = '\0';
  if (setjmp(err.jump) != 0) {
    jpeg_destroy_decompress(&cinfo);
    std::free(out);
    std::memcpy(message, err.message, JMSG_LENGTH_MAX);
    message[JMSG_LENGTH_MAX - 1] = '\0';
    return false;
  }
  jpeg_create_decompress(&cinfo);
  jpeg_mem_src(&cinfo, data, size);
  jpeg_read_header(&cinfo, TRUE);
  if (cinfo.image_width < 1 || cinfo.image_height < 1 ||
      cinfo.image_width > static_cast<JDIMENSION>(max_side) ||
      cinfo.image_height > static_cast<JDIMENSION>(max_side)) {
    std::snprintf(message, JMSG_LENGTH_MAX, "the image is %u x %u pixels; at most %d a side",
                  static_cast<unsigned>(cinfo.image_width),
                  static_cast<unsigned>(cinfo.image_height), max_side);
    jpeg_destroy_decompress(&cinfo);
    return false;
  }
  cinfo.out_color_space = JCS_EXT_RGBA;  // libjpeg-turbo: grey and YCbCr to RGBA, alpha 255
  jpeg_start_decompress(&cinfo);
  if (cinfo.output_components != 4) {
    std::snprintf(message, JMSG_LENGTH_MAX, "decoded to %d components, expected 4",
                  cinfo.output_components);
    jpeg_destroy_decompress(&cinfo);
    return false;
  }
  const std::size_t row = static_cast<std::size_t>(cinfo.output_width) * 4;
  out = static_cast<unsigned char*>(std::malloc(row * cinfo.output_height));
  if (out == nullptr) {
    std::snprintf(message, JMSG_LENGTH_MAX, "out of memory for %u x %u pixels",
                  static_cast<unsigned>(cinfo.output_width),
                  static_cast<unsigned>(cinfo.output_height));
    jpeg_destroy_decompress(&cinfo);
    return false;
  }
  while (cinfo.output_scanline < cinfo.output_height) {
    JSAMPROW r = out + row * cinfo.output_scanline;
    if (jpeg_read_scanlines(&cinfo, &r, 1) != 1) {
      std::snprintf(message, JMSG_LENGTH_MAX, "no scanline read at row %u",
                    static_cast<unsigned>(cinfo.output_scanline));
      jpeg_destroy_decompress(&cinfo);
      std::free(out);
      return false;
    }
  }
  jpeg_finish_decompress(&cinfo);
  *width = static_cast<int>(cinfo.output_width);
  *height = static_cast<int>(cinfo.output_height);
  *pixels = out;
  jpeg_destroy_decompress(&cinfo);
  return true;
}

}  // namespace

std::vector<std::uint8_t> DecodeJpeg(std::span<const std::uint8_t> bytes, int max_side, int* width,
                                     int* height) {
  char message[JMSG_LENGTH_MAX] = {};
  unsigned char* pixels = nullptr;
  int w = 0, h = 0;
  if (!DecodeJpegC(bytes.data(), static_cast<unsigned long>(bytes.size()), max_side, &pixels, &w,
                   &h, message)) {
    throw std::runtime_error(std::string("DecodeImage: JPEG of ") + std::to_string(bytes.size()) +
                             " bytes: " + message);
  }
  std::vector<std::uint8_t> rgba;
  try {
    rgba.assign(pixels, pixels + static_cast<std::size_t>(w) * static_cast<std::size_t>(h) * 4);
  } catch (...) {
    std::free(pixels);
    throw;
  }
  std::free(pixels);
  *width = w;
  *height = h;
  return rgba;
}

}  // namespace ht::image_internal
