#!/usr/bin/env python3
"""Poses where the pipeline truth has a force and a setting gives none (every contact's δ ≤ 0),
from a speed_error_frontier output folder: per scene and setting, their count and pose ids, and
for each such pose its contacts' δ against the texture-stage truth on the same window (µm).
Usage: poses_without_force.py FRONTIER_DIR [SETTING...] (standard library only)."""
import collections
import csv
import sys

d = sys.argv[1]
want = set(sys.argv[2:])
C = collections.defaultdict(list)
for r in csv.DictReader(open(f"{d}/contacts.csv")):
    if not want or r["setting"] in want:
        C[(r["scene"], r["setting"])].append(r)
P = collections.defaultdict(lambda: collections.defaultdict(list))
for r in csv.DictReader(open(f"{d}/patches.csv")):
    P[r["scene"]][int(r["pose_id"])].append(r)


def magnitude(r, keys):
    return sum(float(r[k]) ** 2 for k in keys) ** 0.5


for (scene, setting), rows in sorted(C.items()):
    by_pose = collections.defaultdict(list)
    for r in rows:
        by_pose[int(r["pose_id"])].append(r)
    missed = []
    for pose, patches in sorted(P[scene].items()):
        truth = sum(float(p["share"] or 1.0) * magnitude(p, ("fx_gt", "fy_gt", "fz_gt")) for p in patches)
        method = sum(max(0.0, float(r["delta_m"])) for r in by_pose.get(pose, []))
        if truth > 0.0 and method <= 0.0:
            missed.append(pose)
    print(f"{scene} {setting}: {len(missed)} poses without force {missed}")
    for pose in missed:
        pairs = [f"{float(r['delta_m']) * 1e6:.0f}/{float(r['delta_gt_m']) * 1e6:.0f}" for r in by_pose.get(pose, [])]
        print(f"  pose {pose}: contacts δ/δ_truth(window) µm {' '.join(pairs)}")
