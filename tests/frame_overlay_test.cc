// The display frames' text overlay (master_station/frame_overlay.h): what it says, where it draws,
// and what it leaves alone.
#include "master_station/frame_overlay.h"

#include <gtest/gtest.h>

#include <cstdint>
#include <stdexcept>
#include <vector>

namespace ht::station {
namespace {

constexpr std::uint8_t kWhite[4] = {255, 255, 255, 255};
constexpr std::uint8_t kBlack[4] = {0, 0, 0, 255};
constexpr std::uint8_t kGrey[4] = {90, 100, 110, 255};

std::vector<std::uint8_t> Filled(int w, int h, const std::uint8_t c[4]) {
  std::vector<std::uint8_t> img(static_cast<std::size_t>(w) * h * 4);
  for (std::size_t i = 0; i < img.size(); i += 4) {
    for (int k = 0; k < 4; ++k) img[i + k] = c[k];
  }
  return img;
}

bool Is(const std::vector<std::uint8_t>& img, int w, int x, int y, const std::uint8_t c[4]) {
  const std::size_t i = (static_cast<std::size_t>(y) * w + x) * 4;
  return img[i] == c[0] && img[i + 1] == c[1] && img[i + 2] == c[2] && img[i + 3] == c[3];
}

TEST(FrameOverlay, SaysTimePhaseForceAndContacts) {
  EXPECT_EQ(FormatFrameOverlay({1.2345, "press", 0.8412, 3}),
            "t 1.234 s  phase press  |F| 0.84 N  3 contacts");
  EXPECT_EQ(FormatFrameOverlay({0.0, "", 0.0, 1}), "t 0.000 s  |F| 0.00 N  1 contact");
}

TEST(FrameOverlay, DrawsTextInsideItsBoxAndNothingOutside) {
  const int w = 320, h = 120;
  std::vector<std::uint8_t> img = Filled(w, h, kGrey);
  int bw = 0, bh = 0;
  DrawTextBox(img, w, h, 10, 20, "t 1.5 s |F| 0.84 N", 2, kWhite, kBlack, &bw, &bh);
  ASSERT_GT(bw, 0);
  ASSERT_GT(bh, 0);
  ASSERT_LE(10 + bw, w);
  ASSERT_LE(20 + bh, h);
  int white = 0, black = 0, other = 0;
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const bool inside = x >= 10 && x < 10 + bw && y >= 20 && y < 20 + bh;
      if (!inside) {
        EXPECT_TRUE(Is(img, w, x, y, kGrey)) << "pixel (" << x << ", " << y << ") outside the box";
        continue;
      }
      if (Is(img, w, x, y, kWhite)) {
        ++white;
      } else if (Is(img, w, x, y, kBlack)) {
        ++black;
      } else {
        ++other;
      }
    }
  }
  EXPECT_EQ(other, 0);
  // Glyph strokes cover a fair part of the box, not all of it.
  EXPECT_GT(white, bw * bh / 20);
  EXPECT_GT(black, bw * bh / 2);
  // The box's one-unit margin (2 pixels at scale 2) holds no glyph pixel.
  for (int x = 10; x < 10 + bw; ++x) {
    EXPECT_TRUE(Is(img, w, x, 20, kBlack));
    EXPECT_TRUE(Is(img, w, x, 20 + bh - 1, kBlack));
  }
}

TEST(FrameOverlay, LongerTextAndLargerScaleMakeALargerBox) {
  std::vector<std::uint8_t> img = Filled(800, 200, kGrey);
  int w1 = 0, h1 = 0, w2 = 0, h2 = 0, w3 = 0, h3 = 0;
  DrawTextBox(img, 800, 200, 0, 0, "t 1 s", 2, kWhite, kBlack, &w1, &h1);
  DrawTextBox(img, 800, 200, 0, 0, "t 1 s  |F| 2.00 N", 2, kWhite, kBlack, &w2, &h2);
  DrawTextBox(img, 800, 200, 0, 0, "t 1 s", 3, kWhite, kBlack, &w3, &h3);
  EXPECT_GT(w2, w1);
  EXPECT_EQ(h2, h1);
  EXPECT_EQ(w3 * 2, w1 * 3);
  EXPECT_EQ(h3 * 2, h1 * 3);
}

TEST(FrameOverlay, DifferentTextDrawsDifferentPixels) {
  const int w = 200, h = 40;
  std::vector<std::uint8_t> a = Filled(w, h, kGrey), b = Filled(w, h, kGrey);
  DrawTextBox(a, w, h, 0, 0, "|F| 0.10 N", 2, kWhite, kBlack);
  DrawTextBox(b, w, h, 0, 0, "|F| 0.18 N", 2, kWhite, kBlack);
  EXPECT_NE(a, b);
}

TEST(FrameOverlay, ClipsAtTheImageEdgeAndRefusesBadImages) {
  const int w = 40, h = 10;
  std::vector<std::uint8_t> img = Filled(w, h, kGrey);
  // Far wider and taller than the image, and partly left of and above it: clipped, no fault.
  EXPECT_NO_THROW(
      DrawTextBox(img, w, h, -5, -3, "a long line of text that overflows", 3, kWhite, kBlack));
  EXPECT_NO_THROW(DrawTextBox(img, w, h, 100, 100, "off the image", 2, kWhite, kBlack));
  // Bytes outside printable ASCII draw nothing (and do not crash).
  EXPECT_NO_THROW(DrawTextBox(img, w, h, 0, 0, std::string("\x01\xff\n\t", 4), 1, kWhite, kBlack));
  std::vector<std::uint8_t> short_image(10);
  EXPECT_THROW(DrawTextBox(short_image, w, h, 0, 0, "x", 1, kWhite, kBlack), std::invalid_argument);
  EXPECT_THROW(DrawTextBox(img, 0, h, 0, 0, "x", 1, kWhite, kBlack), std::invalid_argument);
  EXPECT_THROW(DrawTextBox(img, w, h, 0, 0, "x", 0, kWhite, kBlack), std::invalid_argument);
}

}  // namespace
}  // namespace ht::station
