#!/usr/bin/env python3
"""One-tick force dropouts and steps in runs of deploy/run-loopback (issue 33).

Usage: dropouts.py RUN_DIR [RUN_DIR ...] [--phase NAME]

Per run, over the trace's ticks (of one phase if given): the device force's one-tick changes
above 0.2 N, the single-tick dropouts (|F| below 30 % of both neighbours, which exceed 0.15 N),
the dips (|F| falls by more than 0.2 N and is back within half of that in one or two ticks),
the contact force's one-tick changes above 0.2 N, and summary.json's passivity figures
(scaled_ticks, force_scaled_away_Ns, dissipated_J, active_ticks) with the device force's impulse,
and the energy reserve's refill (force_refilled_Ns, refill_ticks; counted apart since issue 32's
eleventh stop, in the damping's figures before).
"""
import csv
import json
import math
import os
import sys


def main(argv):
    phase = None
    if "--phase" in argv:
        i = argv.index("--phase")
        phase = argv[i + 1]
        argv = argv[:i] + argv[i + 2:]
    for d in argv:
        with open(os.path.join(d, "trace.csv")) as f:
            rows = [r for r in csv.DictReader(f) if phase is None or r["phase"] == phase]
        dev = [math.sqrt(sum(float(r["device_f" + a]) ** 2 for a in "xyz")) for r in rows]
        con = [math.sqrt(sum(float(r["f" + a]) ** 2 for a in "xyz")) for r in rows]
        t = [float(r["t_s"]) for r in rows]
        steps = sum(1 for i in range(1, len(dev)) if abs(dev[i] - dev[i - 1]) > 0.2)
        csteps = sum(1 for i in range(1, len(con)) if abs(con[i] - con[i - 1]) > 0.2)
        drops = sum(1 for i in range(1, len(dev) - 1)
                    if min(dev[i - 1], dev[i + 1]) > 0.15 and dev[i] < 0.3 * min(dev[i - 1], dev[i + 1]))
        # A dip: |F| falls by more than 0.2 N and is back within half of that after one or two
        # ticks (the 30 % dropout rule misses a 0.9 -> 0.3 N dip).
        dips = sum(1 for i in range(1, len(dev) - 2)
                   if dev[i - 1] - dev[i] > 0.2 and
                   min(abs(dev[i + 1] - dev[i - 1]), abs(dev[i + 2] - dev[i - 1])) <
                   0.5 * (dev[i - 1] - dev[i]))
        impulse = sum(dev[i] * (t[i] - t[i - 1]) for i in range(1, len(dev)))
        s = json.load(open(os.path.join(d, "summary.json"))).get("passivity", {})
        print(f"{d}: {len(rows)} ticks; device steps > 0.2 N {steps}, one-tick dropouts {drops}, "
              f"dips > 0.2 N {dips}; "
              f"contact steps > 0.2 N {csteps}; passivity scaled_ticks {s.get('scaled_ticks')}, "
              f"active_ticks {s.get('active_ticks')}, force scaled away "
              f"{s.get('force_scaled_away_Ns', 0):.4f} N·s of {impulse:.3f} N·s "
              f"({100 * s.get('force_scaled_away_Ns', 0) / max(impulse, 1e-12):.1f} %), "
              f"damped away {s.get('force_damped_away_Ns', float('nan')):.4f} N·s "
              f"({100 * s.get('force_damped_away_Ns', float('nan')) / max(impulse, 1e-12):.1f} %), "
              f"dissipated {s.get('dissipated_J', 0) * 1e3:.3f} mJ; reserve refill "
              f"{s.get('force_refilled_Ns', 0):.4f} N·s "
              f"({100 * s.get('force_refilled_Ns', 0) / max(impulse, 1e-12):.1f} %) on "
              f"{s.get('refill_ticks', 0)} ticks")


if __name__ == "__main__":
    main(sys.argv[1:])
