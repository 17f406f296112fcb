#!/usr/bin/env python3
"""Plots through_level.csv (the resting fig75 block tilted through level, torque about y at q0):
the pipeline truth with a 1 um tilt lift and with the default texel lift, and the method's
settings. Usage: through_level_plot.py through_level.csv OUT.png (matplotlib)."""
import csv
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

rows = list(csv.DictReader(open(sys.argv[1])))
th = [float(r["tilt_mrad"]) for r in rows]
fig, ax = plt.subplots(figsize=(9, 5))
ax.plot(th, [float(r["truth_ty_mNm"]) for r in rows], "k", lw=2.2,
        label="pipeline truth, tilt step 1 µm lift (0.05 mrad)")
ax.plot(th, [float(r["truth_texel_tilt_ty_mNm"]) for r in rows], "k--", lw=1.2,
        label="pipeline truth, default tilt step 0.1 mm lift (4.8 mrad)")
for c, st in [("default", "C0"), ("kink_hang_other_arm", "C1"), ("parallax", "C2")]:
    ax.plot(th, [float(r[c + "_ty_mNm"]) for r in rows], st, lw=1.1, label=c)
ax.axhline(0, color="gray", lw=0.5)
ax.set_xlabel("tool tilt r_y (mrad); the block 122 µm deep at level (fig75, deadband_lockstep row 1000)")
ax.set_ylabel("torque τ_y at q0 (mN·m)")
ax.set_title("Resting block through level: k·δ·r ≈ 21 mN·m on either arm")
ax.grid(alpha=0.3)
ax.legend(fontsize=8)
fig.tight_layout()
fig.savefig(sys.argv[2], dpi=110)
