// Text on display frames (frame_overlay.h), with stb_easy_font's glyphs.
#include "master_station/frame_overlay.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <stdexcept>
#include <vector>

#if defined(__GNUC__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wunused-function"
#pragma GCC diagnostic ignored "-Wsign-compare"
#pragma GCC diagnostic ignored "-Wconversion"
#pragma GCC diagnostic ignored "-Wold-style-cast"
#endif
#include <stb_easy_font.h>
#if defined(__GNUC__)
#pragma GCC diagnostic pop
#endif

namespace ht::station {
namespace {

// stb_easy_font's vertex: x, y, z (float) and an RGBA8 colour; four per quad.
struct GlyphVertex {
  float x, y, z;
  unsigned char rgba[4];
};
static_assert(sizeof(GlyphVertex) == 16);

void FillRect(std::span<std::uint8_t> rgba, int width, int height, int x0, int y0, int x1, int y1,
              const std::uint8_t colour[4]) {
  x0 = std::max(x0, 0);
  y0 = std::max(y0, 0);
  x1 = std::min(x1, width);
  y1 = std::min(y1, height);
  for (int y = y0; y < y1; ++y) {
    std::uint8_t* row = rgba.data() + (static_cast<std::size_t>(y) * width) * 4;
    for (int x = x0; x < x1; ++x) std::memcpy(row + static_cast<std::size_t>(x) * 4, colour, 4);
  }
}

}  // namespace

std::string FormatFrameOverlay(const FrameOverlayText& text) {
  char buffer[160];
  std::string line;
  std::snprintf(buffer, sizeof(buffer), "t %.3f s", text.t_s);
  line += buffer;
  if (!text.phase.empty()) line += "  phase " + text.phase;
  std::snprintf(buffer, sizeof(buffer), "  |F| %.2f N  %d contact%s", text.force_n, text.contacts,
                text.contacts == 1 ? "" : "s");
  line += buffer;
  return line;
}

void DrawTextBox(std::span<std::uint8_t> rgba_top_down, int width, int height, int x0, int y0,
                 const std::string& line, int scale, const std::uint8_t colour[4],
                 const std::uint8_t box_colour[4], int* box_w, int* box_h) {
  if (width < 1 || height < 1) {
    throw std::invalid_argument("frame overlay: image size must be at least 1x1");
  }
  if (rgba_top_down.size() != static_cast<std::size_t>(width) * height * 4) {
    throw std::invalid_argument("frame overlay: the image has " +
                                std::to_string(rgba_top_down.size()) + " bytes, not " +
                                std::to_string(static_cast<std::size_t>(width) * height * 4));
  }
  if (scale < 1) throw std::invalid_argument("frame overlay: scale must be at least 1");
  // stb_easy_font takes a mutable char*; it reads only. Characters outside ASCII 32..126 draw
  // nothing but advance (its table starts at 32).
  std::vector<char> text(line.begin(), line.end());
  for (char& c : text) {
    if (static_cast<unsigned char>(c) < 32 || static_cast<unsigned char>(c) > 126) c = ' ';
  }
  text.push_back('\0');
  const int text_w = stb_easy_font_width(text.data());
  const int text_h = stb_easy_font_height(text.data());
  // A one-unit margin on every side.
  const int bw = (text_w + 2) * scale;
  const int bh = (text_h + 2) * scale;
  if (box_w != nullptr) *box_w = bw;
  if (box_h != nullptr) *box_h = bh;
  FillRect(rgba_top_down, width, height, x0, y0, x0 + bw, y0 + bh, box_colour);
  // ~270 bytes (17 quads) per character on average; the widest glyphs use fewer than 40 quads.
  std::vector<GlyphVertex> quads(text.size() * 40 * 4);
  const int n = stb_easy_font_print(1.0f, 1.0f, text.data(), nullptr, quads.data(),
                                    static_cast<int>(quads.size() * sizeof(GlyphVertex)));
  for (int q = 0; q < n; ++q) {
    const GlyphVertex* v = &quads[static_cast<std::size_t>(q) * 4];
    // Each quad is axis-aligned: vertices 0 and 2 are opposite corners.
    const float ax = std::min(v[0].x, v[2].x), bx = std::max(v[0].x, v[2].x);
    const float ay = std::min(v[0].y, v[2].y), by = std::max(v[0].y, v[2].y);
    FillRect(rgba_top_down, width, height,
             x0 + static_cast<int>(std::lround(ax * static_cast<float>(scale))),
             y0 + static_cast<int>(std::lround(ay * static_cast<float>(scale))),
             x0 + static_cast<int>(std::lround(bx * static_cast<float>(scale))),
             y0 + static_cast<int>(std::lround(by * static_cast<float>(scale))), colour);
  }
}

}  // namespace ht::station
