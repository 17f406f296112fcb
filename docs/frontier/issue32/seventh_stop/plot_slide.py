#!/usr/bin/env python3
"""The y phase (the slide across the ridges) of deploy/run-loopback runs: the contact force on
the simulated tool (fy, fz), the device force (device_fy) and the tool's y.
Usage: plot_slide.py OUT.png LABEL=RUN_DIR [LABEL=RUN_DIR...] (needs matplotlib)."""
import csv
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

out = sys.argv[1]
fig, ax = plt.subplots(4, 1, figsize=(12, 11), sharex=True)
for arg in sys.argv[2:]:
    label, run = arg.split("=", 1)
    rows = [r for r in csv.DictReader(open(f"{run}/trace.csv")) if r["phase"] == "y"]
    t = [float(r["t_s"]) for r in rows]
    for a, key, scale, what in ((ax[0], "fy", 1, "contact fy (N)"), (ax[1], "device_fy", 1, "device fy (N)"),
                                (ax[2], "fz", 1, "contact fz (N)"), (ax[3], "tool_y", 1e3, "tool y (mm)")):
        a.plot(t, [float(r[key]) * scale for r in rows], lw=0.6, label=f"{label}: {what}")
for a in ax:
    a.legend(fontsize=8)
    a.grid(alpha=0.3)
ax[3].set_xlabel("t (s)")
fig.suptitle("fig75 loopback, y phase: cell secant against texel-scale gradient")
plt.savefig(out, dpi=80)
