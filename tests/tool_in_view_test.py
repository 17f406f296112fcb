#!/usr/bin/python3
"""The display keeps the tool in view (issue 35): on a run of a scene that has its own glTF
camera (the Duck), the default camera follows the tool, and the frames show the tool's steel blue
(the built-in probe, slave_sim/src/display_scene.cc kToolColour, times a shade) over at least
0.5 % of the frame in most frames. With the file's camera (the default before issue 35) the probe
was a few pixels.
Usage: tests/tool_in_view_test.py RUN_DIR
"""
import json
import os
import sys

import matplotlib.image as mpimg

from png_checks import linear_rgb, tool_blue


def main():
    run = sys.argv[1]
    if not os.path.exists(os.path.join(run, "summary.json")):
        print(f"skipped: no explore run in {run} (the team's ../shared/data is not here)")
        return 77
    s = json.load(open(os.path.join(run, "summary.json")))
    d = s.get("display", {})
    if d.get("camera") != "follow":
        print(f"tool_in_view_test: the display's camera is {d.get('camera')!r}, not 'follow'")
        return 1
    frames_dir = os.path.join(run, "frames")
    frames = sorted(f for f in os.listdir(frames_dir) if f.endswith(".png"))
    if len(frames) < 3:
        print(f"tool_in_view_test: {len(frames)} frames in {frames_dir}, want at least 3")
        return 1
    shares = []
    for name in frames:
        img = mpimg.imread(os.path.join(frames_dir, name))
        blue = tool_blue(linear_rgb(img)).sum()
        shares.append(float(blue) / (img.shape[0] * img.shape[1]))
    seen = sum(1 for x in shares if x >= 0.005)
    print("tool_in_view_test: tool's share of each frame: " +
          " ".join(f"{100 * x:.1f}%" for x in shares))
    if 2 * seen < len(shares):
        print(f"tool_in_view_test: the tool covers 0.5 % of the frame in {seen} of {len(shares)} "
              "frames; want most")
        return 1
    print(f"tool_in_view_test: ok ({seen} of {len(shares)} frames show the tool)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
