#!/usr/bin/python3
"""The pipeline truth's patches whose direction is tilted more than 30 degrees from W's z (the
striped blocks' faces are level): how many, how much of the truth's force they carry, and each
setting's force error against the truth with and without them. Also lists the truth's steps
above 0.4 N between consecutive poses (a --trace-from run) with the patches on either side.

Usage: tilted_patches.py FRONTIER_DIR   (patches.csv and contacts.csv of speed_error_frontier)
"""
import collections
import csv
import math
import sys

import numpy as np

d = sys.argv[1]
P = collections.defaultdict(list)
for r in csv.DictReader(open(f"{d}/patches.csv")):
    P[int(r["pose_id"])].append(r)
C = collections.defaultdict(lambda: collections.defaultdict(list))
for r in csv.DictReader(open(f"{d}/contacts.csv")):
    C[r["setting"]][int(r["pose_id"])].append(r)
ids = sorted(set(P) | set(C["default"]))


def tilted(r):
    return abs(float(r["window_nz"])) < math.cos(math.radians(30))


def truth(rows, keep=lambda r: True):
    return np.array([sum(float(r.get("share") or 1) * float(r[k]) for r in rows if keep(r))
                     for k in ("fx_gt", "fy_gt", "fz_gt")])


T = np.array([truth(P[i]) for i in ids])
Tf = np.array([truth(P[i], lambda r: not tilted(r)) for i in ids])
Tt = T - Tf
n_t = sum(1 for i in ids for r in P[i] if tilted(r))
print("tilted patches: %d of %d; poses with one: %d of %d" %
      (n_t, sum(len(P[i]) for i in ids), sum(any(tilted(r) for r in P[i]) for i in ids), len(ids)))
rms = lambda a: math.sqrt(np.mean(np.sum(a ** 2, 1)))
print("truth |F| RMS %.3f N, of it the tilted patches' %.3f N" % (rms(T), rms(Tt)))
for s in C:
    M = np.array([[sum(float(r[k]) for r in C[s][i]) for k in ("fx", "fy", "fz")] for i in ids])
    err = lambda ref: 100 * math.sqrt(np.mean(np.sum((M - ref) ** 2, 1)) / np.mean(np.sum(ref ** 2, 1)))
    print("%s: force error %.1f %% against the truth, %.1f %% without its tilted patches" %
          (s, err(T), err(Tf)))
print("truth steps > 0.4 N between consecutive poses (pose: delta, centre x,y mm, n):")
for a, b in zip(ids, ids[1:]):
    step = np.linalg.norm(truth(P[b]) - truth(P[a]))
    if step <= 0.4:
        continue
    def show(rows):
        return "; ".join("%.0f um at %.1f,%.1f n=(%.2f,%.2f,%.2f)" % (
            1e6 * float(r["delta_gt_m"]), 1e3 * float(r["window_cx"]), 1e3 * float(r["window_cy"]),
            float(r["window_nx"]), float(r["window_ny"]), float(r["window_nz"])) for r in rows)
    print("  %d -> %d: %.2f N | %s | -> %s" % (a, b, step, show(P[a]), show(P[b])))
