#!/usr/bin/python3
"""Per run of several deploy/deadband-table outputs (arms), against ONE reference table's first 0 %
run: contact models sent per second (the remote node's deadband decisions other than not_sent,
over the run's duration_s) and the RMS error of the device force and of the device torque
(trace.csv device_fx..fz, device_tx..tz; rows paired on the nearest t_s), in percent of the
reference's RMS. One reference for every arm, so that arms made without a 0 % run of their own
(--master-args "--model-deadband N" changes the 0 % runs too) are judged alike.

Usage: arm_errors.py REFERENCE_TABLE_DIR ARM_DIR [ARM_DIR ...]
"""
import csv
import glob
import json
import os
import sys

import numpy as np


def load(run_dir):
    rows = list(csv.DictReader(open(os.path.join(run_dir, "trace.csv"))))
    t = np.array([float(r["t_s"]) for r in rows])
    force = np.array([[float(r[k]) for k in ("device_fx", "device_fy", "device_fz")] for r in rows])
    torque = np.array([[float(r[k]) for k in ("device_tx", "device_ty", "device_tz")] for r in rows])
    return t, force, torque


def rms_error_pct(ref, run):
    t0, f0, m0 = ref
    t1, f1, m1 = run
    i = np.clip(np.searchsorted(t1, t0), 0, len(t1) - 1)
    def pct(a, b):
        return 100 * np.sqrt(((b[i] - a) ** 2).sum(1).mean() / (a ** 2).sum(1).mean())
    return pct(f0, f1), pct(m0, m1)


def main(argv):
    if len(argv) < 2:
        print(__doc__.strip())
        return 2
    ref_dir = argv[0]
    for name in ("fig75", "kinesthetic"):
        ref_run = os.path.join(ref_dir, "runs", f"{name}_db0_r0")
        if not os.path.isdir(ref_run):
            continue
        ref = load(ref_run)
        for arm in argv[1:]:
            cells = []
            for d in sorted(glob.glob(os.path.join(arm, "runs", f"{name}_db*_r*"))):
                if d.endswith(".log") or f"{name}_db0_" in d:
                    continue
                s = json.load(open(os.path.join(d, "summary.json")))
                decisions = s["remote"]["transport"]["deadband"]["model_decisions"]
                sent = sum(v for k, v in decisions.items() if k != "not_sent")
                fe, te = rms_error_pct(ref, load(d))
                cells.append(f"{sent / s['duration_s']:.0f}/s F {fe:.1f} % T {te:.1f} %")
            print(f"{name:12s} {os.path.basename(arm.rstrip('/')):24s} " + " | ".join(cells))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
