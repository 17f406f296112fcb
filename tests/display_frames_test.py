#!/usr/bin/python3
"""The operator's headless display on the loopback fig75 run of ctest (HT_LOOPBACK_OUT; run by
deploy/run-loopback with --display headless, one frame per second), issue 17:
  - summary.json's display part: frames written, no error, the renderer named;
  - every frame is a PNG of the stated size and not blank;
  - the overlay (frame_overlay.h): a black box in the top-left corner with white text, whose
    pixels change from frame to frame (the time it prints does);
  - what the frames show: the gear's bronze and the tool's steel blue (the materials the scene
    graph gave), and, in a frame taken while the tool pressed on the gear, the force arrow's
    orange (master_station/scene_renderer.h kForceArrowColour) above the gear's top.
Usage: tests/display_frames_test.py   (HT_LOOPBACK_OUT names the run folder)
"""
import json
import os
import sys

import matplotlib.image as mpimg

from png_checks import check, failures, linear_rgb, png_size, tool_blue


def main():
    run = os.environ.get("HT_LOOPBACK_OUT")
    if not run or not os.path.exists(os.path.join(run, "summary.json")):
        print("display_frames_test: no loopback run (HT_LOOPBACK_OUT)", file=sys.stderr)
        return 1
    s = json.load(open(os.path.join(run, "summary.json")))
    d = s.get("display", {})
    check(d.get("mode") == "headless", f"the run's display is headless (got {d.get('mode')})")
    check(not d.get("error"), f"the display had no error (got {d.get('error')!r})")
    check(bool(d.get("renderer")), "the display names its renderer")
    check(d.get("frames", 0) >= 3, f"at least 3 frames in a 5 s run at 1/s (got {d.get('frames')})")
    frames_dir = os.path.join(run, "frames")
    frames = sorted(f for f in os.listdir(frames_dir) if f.endswith(".png")) \
        if os.path.isdir(frames_dir) else []
    check(len(frames) == d.get("frames"), f"{d.get('frames')} frame files (got {len(frames)})")
    w, h = d.get("size", [0, 0])
    arrow_frames = 0
    check(d.get("overlay") is True, f"the overlay is on by default (got {d.get('overlay')})")
    overlays = []
    for name in frames:
        path = os.path.join(frames_dir, name)
        check(png_size(path) == (w, h), f"{name} is a {w}x{h} PNG (got {png_size(path)})")
        img = mpimg.imread(path)
        check(float(img[..., :3].std()) > 0.02, f"{name} is not blank")
        # The overlay's box: rows 4..20, columns 4..200 hold only pure black and pure white, and
        # both (text on its box); no scene colour shows through.
        box = img[6:18, 6:200, :3]
        black = (box.max(axis=-1) == 0.0)
        white = (box.min(axis=-1) == 1.0)
        check(bool((black | white).all()), f"{name}: the overlay box is black and white only")
        check(white.sum() > 0.05 * box.shape[0] * box.shape[1] and black.sum() > 0.3 *
              box.shape[0] * box.shape[1], f"{name}: text on the overlay box "
              f"({int(white.sum())} white, {int(black.sum())} black pixels)")
        overlays.append(white)
        # The gear (bronze 0.72, 0.50, 0.26 times a shade in 0.3..1) and the tool (steel blue
        # 0.45, 0.55, 0.70 times a shade): both in view, the camera follows the tool.
        # The frames are sRGB images of linear colours: compare in linear terms.
        rgb = linear_rgb(img)
        bronze = int(((rgb[..., 0] > rgb[..., 1] + 0.05) & (rgb[..., 1] > rgb[..., 2] + 0.05) &
                      (rgb[..., 0] - rgb[..., 2] > 0.15) & (rgb[..., 0] < 0.85)).sum())
        blue = int(tool_blue(rgb).sum())
        check(bronze > 0.02 * w * h, f"{name} shows the gear ({bronze} bronze pixels)")
        check(blue > 0.01 * w * h, f"{name} shows the tool ({blue} blue pixels)")
        # The arrow: kForceArrowColour (1.0, 0.35, 0.05) times a shade in 0.7..1.
        orange = int(((rgb[..., 0] > 0.65) & (rgb[..., 1] > 0.2) & (rgb[..., 1] < 0.4) &
                      (rgb[..., 2] < 0.12)).sum())
        if orange > 50:
            arrow_frames += 1
    # The time printed changes from frame to frame, and so do the text's pixels.
    check(all((a != b).any() for a, b in zip(overlays, overlays[1:])),
          "each frame's overlay differs from the one before (the time moves on)")
    # The tool presses on the gear for most of fig75: at least one frame shows a force arrow.
    check(arrow_frames >= 1, f"a force arrow in at least one frame (got {arrow_frames})")
    print(f"display_frames_test: {len(frames)} frames, {arrow_frames} with a force arrow, "
          f"renderer {d.get('renderer')}")
    if failures:
        print(f"display_frames_test: {len(failures)} failure(s)")
        return 1
    print("display_frames_test: ok")
    return 0


if __name__ == "__main__":
    sys.exit(main())
