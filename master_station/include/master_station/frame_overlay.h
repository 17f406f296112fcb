#pragma once
// Text drawn onto a display frame: the run's time, the experiment's phase and the contact force
// the operator feels, in the frame's top-left corner. The glyphs are stb_easy_font's
// (Sean Barrett, public domain; Debian's libstb-dev): each character is a few axis-aligned quads,
// filled here into the RGBA8 image after it was read back, so the renderer draws no text.

#include <cstdint>
#include <span>
#include <string>

namespace ht::station {

/// What the overlay says about one frame.
struct FrameOverlayText {
  double t_s = 0.0;      ///< run time of the tick the frame shows (s)
  std::string phase;     ///< the experiment's phase ("" = none: not printed)
  double force_n = 0.0;  ///< |F| of the contact force on the tool (N)
  int contacts = 0;      ///< contacts in the force
};

/// The overlay's line for `text`: "t 1.234 s  phase press  |F| 0.84 N  3 contacts" (the phase left
/// out when empty; "1 contact" in the singular). Non-finite numbers print as "nan"/"inf".
std::string FormatFrameOverlay(const FrameOverlayText& text);

/// Draws `line` (ASCII; other bytes are drawn as nothing) into the width × height RGBA8 image
/// `rgba_top_down` (row 0 the top, as SceneRenderer::Render returns it) at pixel (x0, y0), its
/// glyphs `scale` pixels per font unit (stb_easy_font's glyphs are about 5×7 units), in opaque
/// `colour` on an opaque box of `box_colour` one unit wider on every side. Whatever falls outside
/// the image is clipped; pixels outside the box are left as they were. Returns the box's size in
/// pixels (before clipping) through *box_w, *box_h when they are not null. Throws
/// std::invalid_argument for width or height < 1, an image of another size than width·height·4
/// bytes, or scale < 1.
void DrawTextBox(std::span<std::uint8_t> rgba_top_down, int width, int height, int x0, int y0,
                 const std::string& line, int scale, const std::uint8_t colour[4],
                 const std::uint8_t box_colour[4], int* box_w = nullptr, int* box_h = nullptr);

}  // namespace ht::station
