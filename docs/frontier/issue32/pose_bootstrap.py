#!/usr/bin/env python3
"""Paired bootstrap over poses of a frontier run: is setting B's pipeline force (and torque) error
against the pipeline truth different from setting A's beyond what the choice of 200 poses
explains? Each pose's method wrench is the sum over its contacts (contacts.csv), the truth's the
sum over its patches (patches.csv; a pose with no patch has a zero truth); the error is the
relative RMS over poses, sqrt(Σ|F − F_gt|² / Σ|F_gt|²), as the frontier's pipeline_force_rel_rms.
Poses are resampled with replacement (the same resample for both settings), 2,000 times; printed
per scene: each setting's error, B − A, and its 95 % interval.
Usage: pose_bootstrap.py FRONTIER_DIR SETTING_A SETTING_B [SCENE ...] (numpy)."""
import collections
import csv
import sys

import numpy as np


def main():
    d, sa, sb = sys.argv[1:4]
    scenes_wanted = set(sys.argv[4:])
    contacts = collections.defaultdict(lambda: np.zeros(6))
    poses = collections.defaultdict(set)
    for r in csv.DictReader(open(f"{d}/contacts.csv")):
        key = (r["scene"], r["setting"], int(r["pose_id"]))
        contacts[key] += [float(r[k]) for k in ("fx", "fy", "fz", "tx", "ty", "tz")]
        poses[r["scene"]].add(int(r["pose_id"]))
    truth = collections.defaultdict(lambda: np.zeros(6))
    for r in csv.DictReader(open(f"{d}/patches.csv")):
        # Each patch's share of a shared penalty (patches.csv's share column since issue 32's
        # fourteenth stop; older runs have none: 1).
        share = float(r.get("share") or 1.0)
        truth[(r["scene"], int(r["pose_id"]))] += [
            share * float(r[k]) for k in ("fx_gt", "fy_gt", "fz_gt", "tx_gt", "ty_gt", "tz_gt")]
        poses[r["scene"]].add(int(r["pose_id"]))
    rng = np.random.default_rng(1)
    for scene in sorted(poses):
        if scenes_wanted and scene not in scenes_wanted:
            continue
        ids = sorted(poses[scene])
        T = np.array([truth[(scene, p)] for p in ids])
        A = np.array([contacts[(scene, sa, p)] for p in ids])
        B = np.array([contacts[(scene, sb, p)] for p in ids])
        for name, sl in (("force", slice(0, 3)), ("torque", slice(3, 6))):
            ea = ((A[:, sl] - T[:, sl]) ** 2).sum(1)
            eb = ((B[:, sl] - T[:, sl]) ** 2).sum(1)
            t2 = (T[:, sl] ** 2).sum(1)
            full = (np.sqrt(eb.sum() / t2.sum()) - np.sqrt(ea.sum() / t2.sum())) * 100
            diffs = []
            for _ in range(2000):
                k = rng.integers(0, len(ids), len(ids))
                diffs.append(np.sqrt(eb[k].sum() / t2[k].sum()) - np.sqrt(ea[k].sum() / t2[k].sum()))
            lo, hi = np.percentile(np.array(diffs) * 100, [2.5, 97.5])
            print(f"{scene} {name}: {sa} {100 * np.sqrt(ea.sum() / t2.sum()):.1f} %, {sb} "
                  f"{100 * np.sqrt(eb.sum() / t2.sum()):.1f} %, B - A {full:+.1f} points "
                  f"(95 % interval {lo:+.1f} to {hi:+.1f}), {len(ids)} poses")


if __name__ == "__main__":
    main()
