#!/usr/bin/env python3
"""The resting block's rocking in deadband_lockstep traces: per arm, the tool's r_y and r_x (mrad)
over the x slide (0.4-2.0 s by default): RMS, peak to peak, sign changes. Usage: rocking.py DIR [lo hi]."""
import csv, glob, os, sys
import numpy as np
d = sys.argv[1]; lo, hi = (float(sys.argv[2]), float(sys.argv[3])) if len(sys.argv) > 3 else (0.4, 2.0)
for f in sorted(glob.glob(f"{d}/*.csv")):
    R = [r for r in csv.DictReader(open(f)) if lo <= float(r["t_s"]) <= hi]
    out = [os.path.basename(f)[:-4]]
    for k in ("tool_ry", "tool_rx"):
        v = np.array([float(r[k]) for r in R]) * 1e3
        out.append(f"{k} rms {np.sqrt(np.mean(v**2)):.3f} p-p {np.ptp(v):.3f} flips {int(np.sum(np.diff(np.sign(v)) != 0))}")
    print(" | ".join(out))
