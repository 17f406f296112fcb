#!/usr/bin/env python3
"""Along a frontier run on a trace's consecutive poses (speed_error_frontier --trace ... --trace-from):
the summed force's change between consecutive poses for the pipeline truth and each setting,
outside and inside an event window of pose ids (where the truth itself jumps), and the changes of
the count of contacts with δ > 0 (contacts.csv also lists speculative contacts, δ <= 0, which push
with nothing). Usage: trajectory_ripple.py FRONTIER_DIR [FIRST LAST] (event pose ids; numpy)."""
import collections
import csv
import sys

import numpy as np

d = sys.argv[1]
lo, hi = (int(sys.argv[2]), int(sys.argv[3])) if len(sys.argv) > 3 else (-1, -1)
C = collections.defaultdict(lambda: collections.defaultdict(list))
for r in csv.DictReader(open(f"{d}/contacts.csv")):
    C[r["setting"]][int(r["pose_id"])].append(r)
P = collections.defaultdict(list)
for r in csv.DictReader(open(f"{d}/patches.csv")):
    P[int(r["pose_id"])].append(r)
ids = sorted(set().union(*[set(v) for v in C.values()]) | set(P))


def steps(get):
    F = np.array([get(i) for i in ids])
    return np.linalg.norm(np.diff(F, axis=0), axis=1)


# Each patch's share (patches.csv's share column since issue 32's fourteenth stop; else 1).
series = {"pipeline truth": steps(lambda i: [sum(float(r.get("share") or 1.0) * float(r[k]) for r in P[i])
                                             for k in ("fx_gt", "fy_gt", "fz_gt")])}
counts = {"pipeline truth": [len(P[i]) for i in ids]}
for s in C:
    series[s] = steps(lambda i, s=s: [sum(float(r[k]) for r in C[s][i]) for k in ("fx", "fy", "fz")])
    counts[s] = [sum(1 for r in C[s][i] if float(r["delta_m"]) > 0) for i in ids]
outside = np.array([not (lo <= ids[k] <= hi) for k in range(1, len(ids))])
for name, v in series.items():
    changes = sum(1 for k in range(1, len(ids)) if counts[name][k] != counts[name][k - 1])
    print(f"{name}: outside poses {lo}-{hi}: |dF| p50 {np.percentile(v[outside], 50):.3f}, "
          f"p90 {np.percentile(v[outside], 90):.3f}, p99 {np.percentile(v[outside], 99):.3f}, "
          f"max {v[outside].max():.2f} N, > 0.2 N on {(v[outside] > 0.2).sum()}; inside: > 0.5 N on "
          f"{(v[~outside] > 0.5).sum()}; count of contacts with delta > 0 (truth: patches) changes {changes}")
