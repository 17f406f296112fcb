#!/usr/bin/env python3
"""Each setting's force and torque error (relative RMS over the poses) against the pipeline truth
with its patches' shares (contact_patch_truth.h step 4a; must equal frontier.csv's
pipeline_force_rel_rms) and without them (every share 1: the truth before issue 32's fourteenth
stop), from one frontier run's contacts.csv and patches.csv. Usage: truth_compare.py FRONTIER_DIR."""
import collections
import csv
import math
import sys

d = sys.argv[1]
K6 = ("fx", "fy", "fz", "tx", "ty", "tz")
method = collections.defaultdict(lambda: [0.0] * 6)
settings = collections.defaultdict(set)
for r in csv.DictReader(open(f"{d}/contacts.csv")):
    key = (r["scene"], r["setting"], int(r["pose_id"]))
    settings[r["scene"]].add(r["setting"])
    for i, k in enumerate(K6):
        method[key][i] += float(r[k])
shared = collections.defaultdict(lambda: [0.0] * 6)
unshared = collections.defaultdict(lambda: [0.0] * 6)
patches = collections.Counter()
sharing = collections.Counter()
poses = collections.defaultdict(set)
for r in csv.DictReader(open(f"{d}/patches.csv")):
    key = (r["scene"], int(r["pose_id"]))
    s = float(r.get("share") or 1.0)
    patches[r["scene"]] += 1
    sharing[r["scene"]] += s < 1.0
    poses[r["scene"]].add(int(r["pose_id"]))
    for i, k in enumerate(K6):
        v = float(r[k + "_gt"])
        shared[key][i] += s * v
        unshared[key][i] += v
frontier = {(r["scene"], r["setting"]): r for r in csv.DictReader(open(f"{d}/frontier.csv"))}


def err(scene, setting, truth, lo, hi):
    num = den = 0.0
    for p in poses[scene]:
        m = method.get((scene, setting, p), [0.0] * 6)
        g = truth[(scene, p)]
        num += sum((m[i] - g[i]) ** 2 for i in range(lo, hi))
        den += sum(g[i] ** 2 for i in range(lo, hi))
    return 100 * math.sqrt(num / den) if den > 0 else float("nan")


print("| scene | patches (sharing) | setting | force err: shared truth / unshared | torque err: "
      "shared / unshared | frontier.csv force err |")
print("|---|---|---|---|---|---|")
for scene in sorted(settings):
    for s in sorted(settings[scene], key=lambda x: (x != "default", x)):
        fr = frontier.get((scene, s), {}).get("pipeline_force_rel_rms", "nan")
        print(f"| {scene} | {patches[scene]} ({sharing[scene]}) | {s} | "
              f"{err(scene, s, shared, 0, 3):.1f} / {err(scene, s, unshared, 0, 3):.1f} % | "
              f"{err(scene, s, shared, 3, 6):.1f} / {err(scene, s, unshared, 3, 6):.1f} % | "
              f"{100 * float(fr):.1f} % |")
