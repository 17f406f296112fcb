#!/usr/bin/env python3
"""Along a frontier run made on a trace's poses (speed_error_frontier --trace SCENE=trace.csv):
the force of the pipeline truth and of each setting between consecutive poses (in pose order,
which is the trace's time order), how often it jumps and how often the count of patches or
contacts changes. Usage: trajectory_jumps.py FRONTIER_DIR (no numpy needed)."""
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


def total(rows, keys):
    return [sum(float(x[k]) for x in rows) for k in keys]


series = {"pipeline truth": ([total(P[i], ("fx_gt", "fy_gt", "fz_gt")) for i in ids],
                             [len(P[i]) for i in ids])}
for s in C:
    series[s] = ([total(C[s][i], ("fx", "fy", "fz")) for i in ids], [len(C[s][i]) for i in ids])
steps = sorted(math.dist(poses[ids[k + 1]], poses[ids[k]]) * 1e3 for k in range(len(ids) - 1))
print(f"{len(ids)} poses, median step between consecutive poses {steps[len(steps) // 2]:.3f} mm")
for name, (f, n) in series.items():
    jumps = sorted(math.dist(f[k + 1], f[k]) for k in range(len(f) - 1))
    changes = sum(1 for k in range(len(n) - 1) if n[k + 1] != n[k])
    print(f"{name:45s} mean |F| {sum(math.hypot(*x) for x in f) / len(f):.2f} N; |ΔF| between "
          f"poses p50 {jumps[len(jumps) // 2]:.2f}, p90 {jumps[int(0.9 * len(jumps))]:.2f}, "
          f"max {jumps[-1]:.2f} N, above 0.5 N on {sum(x > 0.5 for x in jumps)} of {len(jumps)}; "
          f"count changes {changes}")
