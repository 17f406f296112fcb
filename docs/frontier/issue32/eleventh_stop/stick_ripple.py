#!/usr/bin/env python3
"""One phase of deploy/run-loopback runs (default y, the fig75 slide; rotate for fig76): the device
and contact force's high-passed RMS (minus a centred 11-tick mean) outside the slips (ticks within
15 of a device one-tick change above 0.08 N), and the slips' count and each one's whole drop.
Usage: stick_ripple.py [--phase NAME] RUN_DIR...  (needs numpy)"""
import csv, math, sys
import numpy as np
args = sys.argv[1:]
phase = "y"
if "--phase" in args:
    i = args.index("--phase")
    phase = args[i + 1]
    args = args[:i] + args[i + 2:]
for run in args:
    rows = [r for r in csv.DictReader(open(f"{run}/trace.csv")) if r["phase"] == phase]
    D = np.array([[float(r[k]) for k in ("device_fx", "device_fy", "device_fz")] for r in rows])
    C = np.array([[float(r[k]) for k in ("fx", "fy", "fz")] for r in rows])
    step = np.linalg.norm(np.diff(D, axis=0), axis=1)
    bad = np.zeros(len(D), bool)
    ev = np.where(step > 0.08)[0]
    for i in ev: bad[max(0, i - 15):i + 16] = True
    ker = np.ones(11) / 11
    def hp(F): return F - np.stack([np.convolve(F[:, j], ker, mode="same") for j in range(3)], 1)
    keep = ~bad; keep[:6] = keep[-6:] = False
    hd = np.sqrt((hp(D)[keep] ** 2).sum(1).mean()); hc = np.sqrt((hp(C)[keep] ** 2).sum(1).mean())
    # group events into slips (ticks within 5 of each other)
    slips = []
    for i in ev:
        if slips and i - slips[-1][-1] <= 5: slips[-1].append(i)
        else: slips.append([i])
    drops = [np.linalg.norm(D[min(s[-1] + 2, len(D) - 1)] - D[max(s[0] - 1, 0)]) for s in slips]
    print(f"{run}: sticking ticks {keep.sum()}, device hp RMS {hd*1e3:.1f} mN, contact hp RMS {hc*1e3:.0f} mN; "
          f"slips {len(slips)}, drop per slip {', '.join(f'{d:.2f}' for d in drops)} N")
