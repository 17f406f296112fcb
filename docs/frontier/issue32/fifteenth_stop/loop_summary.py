#!/usr/bin/python3
"""Per run of deploy/run-loopback and per phase of its trace.csv, what the operator's loop did:
ticks whose contact force (fx..fz) or device force (device_fx..fz) changed by more than 0.2 N in one
tick, the largest device step, the tool's tilt ripple (tool_rx and tool_ry less their 50-tick
trailing mean, RMS, mrad: the resting face rocking between its edges), the contact torque's
one-tick change (median, mN·m) and the device torque (RMS, mN·m); then the run's passivity figures
from summary.json (force scaled and damped away over the device force's impulse, and the energy
the model switches created).

Usage: loop_summary.py RUN_DIR [RUN_DIR ...]"""
import csv
import json
import os
import sys

import numpy as np


def main(runs):
    if not runs:
        print(__doc__.strip())
        return 2
    for run in runs:
        rows = list(csv.DictReader(open(os.path.join(run, "trace.csv"))))
        col = lambda k: np.array([float(r[k]) for r in rows])
        phase = np.array([r["phase"] for r in rows])
        F = np.stack([col("fx"), col("fy"), col("fz")], 1)
        D = np.stack([col("device_fx"), col("device_fy"), col("device_fz")], 1)
        T = np.stack([col("tx"), col("ty"), col("tz")], 1)
        DT = np.stack([col("device_tx"), col("device_ty"), col("device_tz")], 1)
        tilt = np.stack([col("tool_rx"), col("tool_ry")], 1)
        out = []
        for ph in dict.fromkeys(phase):
            m = phase == ph
            if m.sum() < 60:
                continue
            f, d, t, dt, a = F[m], D[m], T[m], DT[m], tilt[m]
            fs = np.linalg.norm(np.diff(f, axis=0), axis=1)
            ds = np.linalg.norm(np.diff(d, axis=0), axis=1)
            ts = np.linalg.norm(np.diff(t, axis=0), axis=1)
            kernel = np.ones(50) / 50
            trend = np.stack([np.convolve(a[:, i], kernel, mode="valid") for i in range(2)], 1)
            ripple = a[49:] - trend
            out.append(f"{ph}: contact>0.2N {int((fs > 0.2).sum())}, device>0.2N "
                       f"{int((ds > 0.2).sum())} (max {ds.max():.3f} N), tilt ripple "
                       f"{1e3 * np.sqrt((ripple ** 2).sum(1).mean()):.3f} mrad, dT p50 "
                       f"{1e3 * np.median(ts):.2f} mN·m, device T rms "
                       f"{1e3 * np.sqrt((dt ** 2).sum(1).mean()):.2f} mN·m")
        s = json.load(open(os.path.join(run, "summary.json")))
        p = s.get("passivity", {})
        impulse = np.linalg.norm(D, axis=1).sum() * 1e-3
        away = p.get("force_scaled_away_Ns", 0.0) + p.get("force_damped_away_Ns", 0.0)
        created = p.get("attribution", {}).get("switch_energy_created_J", float("nan"))
        print(f"{os.path.basename(run.rstrip('/'))}: passivity scaled + damped away "
              f"{100 * away / (away + impulse):.1f} % of the device impulse, model switches "
              f"created {1e3 * created:.1f} mJ")
        for line in out:
            print("   " + line)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
