#!/usr/bin/env python3
"""The force on the device (|F|, N) and the contact depth along fig77's scrape for loopback runs
(deploy/run-loopback --scene file-on-cad-part --experiment fig77), one panel per run, with a
zoom on one second: what the operator feels with and without parallax.
Usage: scrape_force.py OUT.png LABEL=RUN_DIR [LABEL=RUN_DIR ...]  (needs numpy and matplotlib)"""
import csv, sys
import numpy as np
import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt

out, runs = sys.argv[1], [a.split("=", 1) for a in sys.argv[2:]]
fig, axes = plt.subplots(len(runs), 2, figsize=(13, 3.2 * len(runs)), squeeze=False)
for row, (label, d) in enumerate(runs):
    t, f, depth = [], [], []
    for r in csv.DictReader(open(f"{d}/trace.csv")):
        if r["phase"] != "scrape":
            continue
        t.append(float(r["t_s"]))
        f.append(np.hypot(np.hypot(float(r["device_fx"]), float(r["device_fy"])), float(r["device_fz"])))
        depth.append(float(r["depth_m"]) * 1e6 if r["depth_m"] not in ("", "nan") else np.nan)
    t, f, depth = np.array(t), np.array(f), np.array(depth)
    steps = np.abs(np.diff(f))
    for col, (t0, t1) in enumerate([(t[0], t[-1]), (t[0] + 4.0, t[0] + 5.0)]):
        ax = axes[row][col]
        m = (t >= t0) & (t <= t1)
        ax.plot(t[m], f[m], lw=0.6, color="C0")
        ax.set_ylabel("|F| device (N)", color="C0")
        ax2 = ax.twinx()
        ax2.plot(t[m], depth[m], lw=0.5, color="C1", alpha=0.7)
        ax2.set_ylabel("depth (µm)", color="C1")
        ax.set_title(f"{label}: one-tick changes of |F| > 0.1 N {int((steps > 0.1).sum())}, "
                     f"> 0.2 N {int((steps > 0.2).sum())}" if col == 0 else f"{label}: one second")
        ax.set_xlabel("t (s)")
fig.tight_layout()
fig.savefig(out, dpi=110)
print("wrote", out)
