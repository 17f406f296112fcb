#!/usr/bin/env python3
"""The torque about y at q0 of the resting fig75 block tilted through level, from speed_error_frontier
runs on a synthetic trace (through_level_trace.py): the pipeline truth (patches.csv) and each named
setting (contacts.csv). Usage: through_level.py OUT.png DIR:SETTING[:LABEL] [DIR:SETTING[:LABEL]...]
(numpy, matplotlib). Rows are 0.01 mrad apart from -0.6 mrad."""
import collections
import csv
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

out, runs = sys.argv[1], sys.argv[2:]
fig, ax = plt.subplots(figsize=(9, 5))
truth_done = False
for spec in runs:
    parts = spec.split(":")
    d, setting = parts[0], parts[1]
    label = parts[2] if len(parts) > 2 else setting
    C = collections.defaultdict(list)
    for r in csv.DictReader(open(f"{d}/contacts.csv")):
        if r["setting"] == setting:
            C[int(r["pose_id"])].append(r)
    ids = sorted(C)
    theta = [(i - 60) * 0.01 for i in ids]
    if not truth_done:
        P = collections.defaultdict(list)
        for r in csv.DictReader(open(f"{d}/patches.csv")):
            P[int(r["pose_id"])].append(r)
        ax.plot(theta, [1e3 * sum(float(r.get("share") or 1.0) * float(r["ty_gt"]) for r in P[i])
                        for i in ids], "k", lw=2, label="pipeline truth")
        truth_done = True
    ax.plot(theta, [1e3 * sum(float(r["ty"]) for r in C[i]) for i in ids], lw=1.2, label=label)
ax.set_xlabel("tool tilt r_y (mrad), block 122 µm deep at level")
ax.set_ylabel("torque τ_y at q0 (mN·m)")
ax.grid(alpha=0.3)
ax.legend(fontsize=8)
fig.tight_layout()
fig.savefig(out, dpi=110)
