#!/usr/bin/env python3
"""Plots through_level.csv: the torque about y at q0 of the resting fig75 block tilted through
level (0.01 mrad steps), the pipeline truth and each setting's column.
Usage: through_level.py through_level.csv OUT.png [COLUMN...] (numpy, matplotlib); without
columns: the default, the hung other arm and parallax before this stop."""
import csv
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

rows = list(csv.DictReader(open(sys.argv[1])))
columns = sys.argv[3:] or ["default", "kink_hang_other_arm", "parallax_before_95bdf74"]
theta = [float(r["tilt_mrad"]) for r in rows]
fig, ax = plt.subplots(figsize=(9, 5))
ax.plot(theta, [float(r["truth_ty_mNm"]) for r in rows], "k", lw=2, label="pipeline truth")
for c in columns:
    ax.plot(theta, [float(r[c + "_ty_mNm"]) for r in rows], lw=1.2, label=c)
ax.set_xlabel("tool tilt r_y (mrad); the block 122 µm deep at level")
ax.set_ylabel("torque τ_y at q0 (mN·m)")
ax.grid(alpha=0.3)
ax.legend(fontsize=8)
fig.tight_layout()
fig.savefig(sys.argv[2], dpi=110)
