#!/usr/bin/env python3
"""The summed force |F| along a frontier run on a trace's consecutive rows (speed_error_frontier
--trace ... --trace-from), for the pipeline truth and each setting named, and the first contact's
δ against the texture-stage truth on its own window: what the operator's loop would be given.
Usage: stretch_force.py FRONTIER_DIR OUT.png SETTING [SETTING...] (numpy, matplotlib)."""
import collections
import csv
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

d, out, settings = sys.argv[1], sys.argv[2], sys.argv[3:]
C = collections.defaultdict(lambda: collections.defaultdict(list))
for r in csv.DictReader(open(f"{d}/contacts.csv")):
    C[r["setting"]][int(r["pose_id"])].append(r)
P = collections.defaultdict(list)
for r in csv.DictReader(open(f"{d}/patches.csv")):
    P[int(r["pose_id"])].append(r)
ids = sorted(P)
fig, (a, b) = plt.subplots(2, 1, figsize=(10, 7), sharex=True)
truth = [np.linalg.norm([sum(float(r.get("share") or 1.0) * float(r[k]) for r in P[i])
                         for k in ("fx_gt", "fy_gt", "fz_gt")]) for i in ids]
a.plot(ids, truth, "k", lw=2, label="pipeline truth")
for s in settings:
    F = [np.linalg.norm([sum(float(r[k]) for r in C[s][i]) for k in ("fx", "fy", "fz")]) for i in ids]
    a.plot(ids, F, lw=1, label=s)
    first = [C[s][i][0] if C[s][i] else None for i in ids]
    b.plot(ids, [float(r["delta_m"]) * 1e6 if r else np.nan for r in first], lw=1, label=f"{s} δ")
gt = [C[settings[0]][i][0] if C[settings[0]][i] else None for i in ids]
# The texture-stage truth on the method's window; where it reads the window's whole box (a
# grazing window, 20 mm) it is left out.
b.plot(ids, [float(r["delta_gt_m"]) * 1e6 if r and float(r["delta_gt_m"]) < 2e-3 else np.nan
             for r in gt], "k:", lw=1, label="truth on the first window (< 2 mm)")
a.set_ylabel("|F| (N)")
b.set_ylabel("first contact δ (µm)")
b.set_xlabel("trace row (1 ms apart)")
mine = [float(r["delta_m"]) * 1e6 for r in gt if r and float(r["delta_m"]) > -1.0]
b.set_ylim(-50.0, np.percentile(mine, 99) * 1.3)  # separated (δ < 0) rows cut off
a.legend(fontsize=8)
b.legend(fontsize=8)
fig.tight_layout()
fig.savefig(out, dpi=110)
