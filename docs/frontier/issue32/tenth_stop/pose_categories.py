#!/usr/bin/env python3
"""Per pose of a frontier run: the method's positive contacts against the pipeline truth's
patches, and whether the summed force is over (> 1.3x), under (< 0.7x) or about the truth's;
each class's poses and share of the squared force error.
Usage: pose_categories.py FRONTIER_DIR SCENE [SETTING=default] (no numpy needed)."""
import csv, collections, math, sys
d, scene = sys.argv[1], sys.argv[2]
setting = sys.argv[3] if len(sys.argv) > 3 else "default"
C, P = collections.defaultdict(list), collections.defaultdict(list)
for r in csv.DictReader(open(f"{d}/contacts.csv")):
    if r["setting"] == setting and r["scene"] == scene: C[int(r["pose_id"])].append(r)
for r in csv.DictReader(open(f"{d}/patches.csv")):
    if r["scene"] == scene: P[int(r["pose_id"])].append(r)
num = den = 0
share = collections.Counter(); cnt = collections.Counter()
for p in sorted(set(C) | set(P)):
    pos = [c for c in C[p] if math.isfinite(float(c["delta_m"])) and float(c["delta_m"]) > 0]
    fm = [sum(float(c[k]) for c in C[p]) for k in ("fx", "fy", "fz")]
    ft = [sum(float(c[k]) for c in P[p]) for k in ("fx_gt", "fy_gt", "fz_gt")]
    e = sum((a - b) ** 2 for a, b in zip(fm, ft)); num += e; den += sum(b*b for b in ft)
    fmn = math.sqrt(sum(x*x for x in fm)); ftn = math.sqrt(sum(x*x for x in ft))
    ratio = fmn / ftn if ftn > 0 else float('inf')
    k = (min(len(pos), 3), min(len(P[p]), 3), 'over' if ratio > 1.3 else ('under' if ratio < 0.7 else 'ok'))
    share[k] += e; cnt[k] += 1
for k in sorted(cnt): print(f"pos contacts {k[0]} patches {k[1]} {k[2]:5s}: {cnt[k]:3d} poses {100*share[k]/num:5.1f} % of sq err")
print("total rel", 100*math.sqrt(num/den))
