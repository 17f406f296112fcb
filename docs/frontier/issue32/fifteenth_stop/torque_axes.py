#!/usr/bin/python3
"""Per scene of a speed_error_frontier output (contacts.csv, patches.csv): the pose-summed torque of
the method (SETTING, default "default") against the pipeline truth (each patch weighed by its share),
per axis: RMS of each, the RMS error, correlation and least-squares slope (method on truth), and the
poses carrying the most squared error.

Usage: torque_axes.py FRONTIER_DIR [SETTING]"""
import collections
import csv
import os
import sys

import numpy as np

SCENES = ("fig75", "fig76", "fig77", "hammer_torus")
METHOD = ("fx", "fy", "fz", "tx", "ty", "tz")
TRUTH = ("fx_gt", "fy_gt", "fz_gt", "tx_gt", "ty_gt", "tz_gt")


def pose_sums(rows, keys, weight):
    """{pose_id: the 6-vector Σ weight(row)·row[keys]} and {pose_id: rows}."""
    sums = collections.defaultdict(lambda: np.zeros(6))
    count = collections.Counter()
    for r in rows:
        sums[r["pose_id"]] += weight(r) * np.array([float(r[k]) for k in keys])
        count[r["pose_id"]] += 1
    return sums, count


def rel_rms(a, b):
    return np.sqrt(((a - b) ** 2).sum() / (b ** 2).sum())


def main(argv):
    if not argv:
        print(__doc__.strip())
        return 2
    folder = argv[0]
    setting = argv[1] if len(argv) > 1 else "default"
    contacts = list(csv.DictReader(open(os.path.join(folder, "contacts.csv"))))
    patches = list(csv.DictReader(open(os.path.join(folder, "patches.csv"))))
    for scene in SCENES:
        m, n_contacts = pose_sums(
            (r for r in contacts if r["scene"] == scene and r["setting"] == setting), METHOD,
            lambda r: 1.0)
        g, n_patches = pose_sums((r for r in patches if r["scene"] == scene), TRUTH,
                                 lambda r: float(r["share"]))
        ids = sorted(set(m) | set(g))
        if not ids:
            continue
        M = np.array([m[i] for i in ids])
        G = np.array([g[i] for i in ids])
        F, Fg, T, Tg = M[:, :3], G[:, :3], M[:, 3:], G[:, 3:]
        print(scene, "poses", len(ids),
              "force err %.3f torque err %.3f" % (rel_rms(F, Fg), rel_rms(T, Tg)))
        for i, axis in enumerate("xyz"):
            print("  t" + axis,
                  "rms gt %.4f rms m %.4f rms err %.4f corr %.3f slope %.3f" % (
                      np.sqrt((Tg[:, i] ** 2).mean()), np.sqrt((T[:, i] ** 2).mean()),
                      np.sqrt(((T - Tg)[:, i] ** 2).mean()), np.corrcoef(T[:, i], Tg[:, i])[0, 1],
                      (T[:, i] * Tg[:, i]).sum() / (Tg[:, i] ** 2).sum()))
        e = ((T - Tg) ** 2).sum(1)
        order = np.argsort(-e)
        print("  top10 share %.2f top30 %.2f" % (e[order[:10]].sum() / e.sum(),
                                                 e[order[:30]].sum() / e.sum()))
        for k in order[:5]:
            print("   pose", ids[k], "T", np.round(T[k], 4), "Tg", np.round(Tg[k], 4), "F",
                  np.round(F[k], 2), "Fg", np.round(Fg[k], 2), "ncont", n_contacts[ids[k]],
                  "npatch", n_patches[ids[k]])
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
