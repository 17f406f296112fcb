#!/usr/bin/env python3
"""Along a frontier run made on a trace's poses (speed_error_frontier --trace SCENE=trace.csv):
the force of the pipeline truth, with its patches' shares (contact_patch_truth.h step 4a) and
without them (every share 1: the truth before issue 32's fourteenth stop), and of each setting,
between consecutive poses (pose order = the trace's time order): how often it jumps, how often the
count of patches or contacts changes, and the force error of each setting against both truths.
Usage: trajectory_jumps.py FRONTIER_DIR (no numpy needed)."""
import collections
import csv
import math
import sys

d = sys.argv[1]
C = collections.defaultdict(lambda: collections.defaultdict(list))
P = collections.defaultdict(list)
poses = {}
for r in csv.DictReader(open(f"{d}/contacts.csv")):
    C[r["setting"]][int(r["pose_id"])].append(r)
    poses[int(r["pose_id"])] = (float(r["tool_px"]), float(r["tool_py"]), float(r["tool_pz"]))
for r in csv.DictReader(open(f"{d}/patches.csv")):
    P[int(r["pose_id"])].append(r)
ids = sorted(poses)


def total(rows, keys, weight=lambda r: 1.0):
    return [sum(weight(x) * float(x[k]) for x in rows) for k in keys]


def share(r):
    return float(r.get("share") or 1.0)


G = ("fx_gt", "fy_gt", "fz_gt")
truths = {"pipeline truth, shared (4a)": [total(P[i], G, share) for i in ids],
          "pipeline truth, unshared": [total(P[i], G) for i in ids]}
series = {k: (v, [len(P[i]) for i in ids]) for k, v in truths.items()}
for s in C:
    series[s] = ([total(C[s][i], ("fx", "fy", "fz")) for i in ids],
                 [sum(1 for x in C[s][i] if float(x["delta_m"]) > 0) for i in ids])
steps = sorted(math.dist(poses[ids[k + 1]], poses[ids[k]]) * 1e3 for k in range(len(ids) - 1))
print(f"{len(ids)} poses, median step between consecutive poses {steps[len(steps) // 2]:.3f} mm")
print(f"patches sharing: {sum(1 for i in ids for r in P[i] if share(r) < 1)} of "
      f"{sum(len(P[i]) for i in ids)}")
print("| series | mean abs F (N) | abs dF p50 / p90 / max (N) | abs dF > 0.5 N | count changes |")
print("|---|---|---|---|---|")
for name, (f, n) in series.items():
    jumps = sorted(math.dist(f[k + 1], f[k]) for k in range(len(f) - 1))
    changes = sum(1 for k in range(len(n) - 1) if n[k + 1] != n[k])
    print(f"| {name} | {sum(math.hypot(*x) for x in f) / len(f):.2f} | "
          f"{jumps[len(jumps) // 2]:.3f} / {jumps[int(0.9 * len(jumps))]:.3f} / {jumps[-1]:.2f} | "
          f"{sum(x > 0.5 for x in jumps)} of {len(jumps)} | {changes} |")
print()
print("| setting | force err vs shared truth | vs unshared truth |")
print("|---|---|---|")
for s in C:
    f = series[s][0]
    row = []
    for t in truths.values():
        num = sum(math.dist(a, b) ** 2 for a, b in zip(f, t))
        den = sum(math.hypot(*b) ** 2 for b in t)
        row.append(f"{100 * math.sqrt(num / den):.1f} %")
    print(f"| {s} | {row[0]} | {row[1]} |")
