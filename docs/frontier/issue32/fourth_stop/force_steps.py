#!/usr/bin/env python3
"""Per phase of a run's trace.csv: the mean and largest |F|, the largest one-tick change of F and
the ticks whose change exceeds 0.1 N and 0.2 N, for the contact force on the simulated tool
(fx..fz) and for the force on the device (device_fx..fz, what the operator feels).
Usage: force_steps.py RUN_DIR [RUN_DIR...] (no numpy needed)."""
import csv
import math
import sys

for run in sys.argv[1:]:
    with open(f"{run}/trace.csv") as f:
        rows = list(csv.DictReader(f))
    phases = list(dict.fromkeys(r["phase"] for r in rows))
    for phase in phases:
        part = [r for r in rows if r["phase"] == phase]
        if len(part) < 2:
            continue
        for label, keys in (("contact", ("fx", "fy", "fz")),
                            ("device", ("device_fx", "device_fy", "device_fz"))):
            F = [[float(r[k]) for k in keys] for r in part]
            norm = [math.sqrt(sum(c * c for c in v)) for v in F]
            steps = [math.sqrt(sum((a - b) ** 2 for a, b in zip(F[i + 1], F[i])))
                     for i in range(len(F) - 1)]
            print(f"{run} {phase:12s} {label:8s} |F| mean {sum(norm) / len(norm):.2f} "
                  f"max {max(norm):.2f} N; one-tick change max {max(steps):.3f} N, "
                  f"> 0.1 N {sum(s > 0.1 for s in steps)}, > 0.2 N {sum(s > 0.2 for s in steps)} "
                  f"of {len(steps)} ticks")
