#!/usr/bin/python3
"""Device-force RMS error (%) of every run of several deadband tables against ONE reference run
(REF_TABLE's <input>_db0_r0), rows paired on the nearest t_s, as deploy/deadband-table does.
Usage: cross_errors.py REF_TABLE TABLE [TABLE ...]"""
import csv, glob, os, sys
import numpy as np

def load(d):
    rows = list(csv.DictReader(open(os.path.join(d, "trace.csv"))))
    t = np.array([float(r["t_s"]) for r in rows])
    f = np.array([[float(r[k]) for k in ("device_fx", "device_fy", "device_fz")] for r in rows])
    return t, f

def err(ref, run):
    (t0, f0), (t1, f1) = ref, run
    i = np.clip(np.searchsorted(t1, t0), 0, len(t1) - 1)
    return 100 * np.sqrt(((f1[i] - f0) ** 2).sum(1).mean() / (f0 ** 2).sum(1).mean())

ref_table, tables = sys.argv[1], sys.argv[2:]
for name in ("fig75", "kinesthetic"):
    ref_dir = os.path.join(ref_table, "runs", f"{name}_db0_r0")
    if not os.path.isdir(ref_dir):
        continue
    ref = load(ref_dir)
    for tab in tables:
        for db in ("0", "10"):
            cells = []
            for d in sorted(glob.glob(os.path.join(tab, "runs", f"{name}_db{db}_r*"))):
                if d.endswith(".log") or os.path.samefile(d, ref_dir):
                    continue
                cells.append(f"{err(ref, load(d)):.1f}")
            print(f"{name:12s} {os.path.basename(tab.rstrip('/')):16s} {db:>2s} %: device F err "
                  + ", ".join(cells) + " %")
