#!/usr/bin/env python3
"""Per-pose share of the frontier's pipeline force (torque) error: which poses make the RMS."""
import collections, csv, sys
import numpy as np
d, setting = sys.argv[1:3]
scenes_wanted = set(sys.argv[3:])
contacts = collections.defaultdict(lambda: np.zeros(6)); ncont = collections.Counter()
poses = collections.defaultdict(set)
for r in csv.DictReader(open(f"{d}/contacts.csv")):
    if r["setting"] != setting: continue
    key = (r["scene"], int(r["pose_id"]))
    contacts[key] += [float(r[k]) for k in ("fx","fy","fz","tx","ty","tz")]; ncont[key] += 1
    poses[r["scene"]].add(int(r["pose_id"]))
truth = collections.defaultdict(lambda: np.zeros(6)); npatch = collections.Counter()
for r in csv.DictReader(open(f"{d}/patches.csv")):
    share = float(r.get("share") or 1.0)
    key = (r["scene"], int(r["pose_id"]))
    truth[key] += [share*float(r[k]) for k in ("fx_gt","fy_gt","fz_gt","tx_gt","ty_gt","tz_gt")]; npatch[key] += 1
    poses[r["scene"]].add(int(r["pose_id"]))
for scene in sorted(poses):
    if scenes_wanted and scene not in scenes_wanted: continue
    ids = sorted(poses[scene])
    for name, sl in (("force", slice(0,3)), ("torque", slice(3,6))):
        T = np.array([truth[(scene,p)][sl] for p in ids]); A = np.array([contacts[(scene,p)][sl] for p in ids])
        e = ((A-T)**2).sum(1); t2 = (T**2).sum(1)
        tot = np.sqrt(e.sum()/t2.sum())
        order = np.argsort(-e)
        print(f"{scene} {name}: {100*tot:.1f} %; top poses' share of sum|dF|^2:")
        cum = 0
        for i in order[:12]:
            cum += e[i]
            p = ids[i]
            print(f"  pose {p:3d}: |T|={np.sqrt(t2[i]):8.4f} |A|={np.linalg.norm(A[i]):8.4f} |dF|={np.sqrt(e[i]):8.4f} share {100*e[i]/e.sum():5.1f} % cum {100*cum/e.sum():5.1f} % contacts {ncont[(scene,p)]} patches {npatch[(scene,p)]}  T={np.round(T[i],4)} A={np.round(A[i],4)}")
        for k in (5,10,20):
            keep = order[k:]
            print(f"  without top {k}: {100*np.sqrt(e[keep].sum()/t2[keep].sum()):.1f} %")
