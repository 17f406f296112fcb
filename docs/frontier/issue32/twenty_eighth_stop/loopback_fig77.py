#!/usr/bin/env python3
"""The hard-cases table's columns for fig77 loopback runs (docs/hard-cases.md, "grazing contacts
throw the file"): the simulated tool's contact |F| max and p99, whether the tool turned more than
0.5 rad from its start, the ticks the contact-force bound engaged (summary.json
force_clamped_ticks), the device force's one-tick steps above 0.2 N, and the remote step's p50.
Usage: loopback_fig77.py RUN_DIR=LABEL [RUN_DIR=LABEL ...] (numpy)."""
import csv, json, sys
import numpy as np

print("| run | contact force max (N) | p99 (N) | turned > 0.5 rad | bounded ticks | device steps > 0.2 N | remote step p50 (µs) |")
print("|---|---:|---:|---|---:|---:|---:|")
for spec in sys.argv[1:]:
    d, label = spec.split("=", 1)
    R = list(csv.DictReader(open(f"{d}/trace.csv")))
    F = np.linalg.norm([[float(r[k]) for k in ("fx", "fy", "fz")] for r in R], axis=1)
    D = np.array([[float(r[k]) for k in ("device_fx", "device_fy", "device_fz")] for r in R])
    rot = np.array([[float(r[k]) for k in ("tool_rx", "tool_ry", "tool_rz")] for r in R])
    turned = np.linalg.norm(rot - rot[0], axis=1).max()
    steps = int(np.sum(np.linalg.norm(np.diff(D, axis=0), axis=1) > 0.2))
    s = json.load(open(f"{d}/summary.json"))
    rs = json.load(open(f"{d}/remote_summary.json"))
    print(f"| {label} | {F.max():.1f} | {np.percentile(F, 99):.1f} | {'yes' if turned > 0.5 else 'no'} "
          f"({turned:.2f}) | {s.get('force_clamped_ticks')} | {steps} | {rs.get('step_p50_us', float('nan')):.0f} |")
