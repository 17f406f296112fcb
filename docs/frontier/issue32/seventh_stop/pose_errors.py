#!/usr/bin/env python3
"""Per pose of a frontier run: the method's summed force against the pipeline truth's, each
pose's share of the squared error, and the shares by (method contacts, truth patches).
Usage: pose_errors.py FRONTIER_DIR SCENE [SETTING=default] [TOP=20] (no numpy needed)."""
import collections
import csv
import math
import sys

d, scene = sys.argv[1], sys.argv[2]
setting = sys.argv[3] if len(sys.argv) > 3 else "default"
top = int(sys.argv[4]) if len(sys.argv) > 4 else 20
C, P = collections.defaultdict(list), collections.defaultdict(list)
for r in csv.DictReader(open(f"{d}/contacts.csv")):
    if r["setting"] == setting and r["scene"] == scene:
        C[int(r["pose_id"])].append(r)
for r in csv.DictReader(open(f"{d}/patches.csv")):
    if r["scene"] == scene:
        P[int(r["pose_id"])].append(r)
rows, num, den = [], 0.0, 0.0
for p in sorted(set(C) | set(P)):
    fm = [sum(float(c[k]) for c in C[p]) for k in ("fx", "fy", "fz")]
    ft = [sum(float(c[k]) for c in P[p]) for k in ("fx_gt", "fy_gt", "fz_gt")]
    e = sum((a - b) ** 2 for a, b in zip(fm, ft))
    num += e
    den += sum(b * b for b in ft)
    rows.append((e, p, len(C[p]), len(P[p]), fm, ft,
                 [float(c["delta_m"]) * 1e6 for c in C[p]],
                 [float(c["delta_gt_m"]) * 1e6 for c in P[p]]))
print(f"{scene} {setting}: force rel rms {100 * math.sqrt(num / den):.1f} % over {len(rows)} poses")
rows.sort(reverse=True)
cum = 0.0
for e, p, nc, npt, fm, ft, dm, dt in rows[:top]:
    cum += e
    print(f"pose {p:3d} share {100 * e / num:4.1f} % (cum {100 * cum / num:4.1f} %) contacts {nc} "
          f"patches {npt} F {['%.2f' % x for x in fm]} truth {['%.2f' % x for x in ft]} "
          f"δ {['%.0f' % x for x in dm]} truth δ {['%.0f' % x for x in dt]} µm")
share = collections.Counter()
count = collections.Counter()
for e, p, nc, npt, *_ in rows:
    share[(nc, npt)] += e
    count[(nc, npt)] += 1
for k in sorted(count):
    print(f"contacts {k[0]}, patches {k[1]}: {count[k]} poses, {100 * share[k] / num:.1f} % of the squared error")
