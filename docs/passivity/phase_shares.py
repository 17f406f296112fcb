#!/usr/bin/env python3
"""Where in a run the passivity stage took its force (issue 33: attribute it), per phase.

Usage: phase_shares.py RUN_DIR [RUN_DIR ...]

Per run of deploy/run-loopback (trace.csv with the passivity_removed_n column, master_station
from issue 33's twenty-second stop on): per phase of the experiment, in the order the phases
come, the device force's impulse (Σ |device_f|·Δt, N·s), the force the passivity stage took
(Σ passivity_removed_n·Δt, N·s) and its share of the run's whole impulse and of the phase's own,
the ticks it acted on, the contact force's peak and the model age p50. The whole run's share is
close to delay_grid.py's guard + damping + refill (those come from summary.json's sums; this
from the per-tick column).
"""
import csv
import math
import os
import sys


def main(argv):
    if not argv:
        print(__doc__.strip())
        return 2
    for d in argv:
        with open(os.path.join(d, "trace.csv")) as f:
            rows = list(csv.DictReader(f))
        if not rows or "passivity_removed_n" not in rows[0]:
            print(f"{d}: no passivity_removed_n column (a trace from before issue 33's "
                  "twenty-second stop)")
            continue
        t = [float(r["t_s"]) for r in rows]
        order, per = [], {}
        total_impulse = 0.0
        for i in range(1, len(rows)):
            r = rows[i]
            dt = t[i] - t[i - 1]
            dev = math.sqrt(sum(float(r["device_f" + a]) ** 2 for a in "xyz"))
            removed = float(r["passivity_removed_n"])
            contact = math.sqrt(sum(float(r["f" + a]) ** 2 for a in "xyz"))
            p = r["phase"]
            if p not in per:
                order.append(p)
                per[p] = {"impulse": 0.0, "removed": 0.0, "ticks": 0, "acted": 0,
                          "contact_max": 0.0, "ages": []}
            q = per[p]
            q["impulse"] += dev * dt
            q["removed"] += removed * dt
            q["ticks"] += 1
            q["acted"] += removed > 1e-9
            q["contact_max"] = max(q["contact_max"], contact)
            age = float(r["model_age_ms"])
            if age >= 0:
                q["ages"].append(age)
            total_impulse += dev * dt
        print(f"== {d}: device impulse {total_impulse:.3f} N·s")
        removed_all = sum(q["removed"] for q in per.values())
        print(f"   taken in all: {removed_all:.4f} N·s = "
              f"{100 * removed_all / max(total_impulse, 1e-12):.1f} % of the impulse")
        for p in order:
            q = per[p]
            ages = sorted(q["ages"])
            age50 = ages[len(ages) // 2] if ages else float("nan")
            print(f"   {p:12s} ticks {q['ticks']:5d}, acted on {q['acted']:5d}, impulse "
                  f"{q['impulse']:.3f} N·s, taken {q['removed']:.4f} N·s = "
                  f"{100 * q['removed'] / max(total_impulse, 1e-12):.2f} % of the run's, "
                  f"{100 * q['removed'] / max(q['impulse'], 1e-12):.1f} % of the phase's; "
                  f"contact |F| max {q['contact_max']:.2f} N, model age p50 {age50:.0f} ms")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
