#!/usr/bin/env python3
"""The force the operator feels under delay against the undelayed run on the same replayed input
(issue 33's "within 10 % RMS of the undelayed run").

Usage: replay_compare.py UNDELAYED_RUN RUN [RUN ...]

Each run is a deploy/run-loopback folder of `master_station --device replay` (the same replay
file, so the hand's input is identical). The device force (trace.csv device_fx..fz) is sampled
on the undelayed run's ticks (nearest tick by t_s) after the first 0.5 s (the approach); printed
per run: RMS |F_run − F_undelayed| / RMS |F_undelayed|, the same for |F| alone (what a delay
shifts in time counts in the first, not in the second), and summary.json's passivity shares.
"""
import bisect
import csv
import json
import math
import os
import sys


def load(d):
    with open(os.path.join(d, "trace.csv")) as f:
        rows = list(csv.DictReader(f))
    t = [float(r["t_s"]) for r in rows]
    F = [tuple(float(r["device_f" + a]) for a in "xyz") for r in rows]
    return t, F


def main(argv):
    t0, F0 = load(argv[0])
    for d in argv[1:]:
        t, F = load(d)
        num = den = num_mag = 0.0
        n = 0
        for ti, fi in zip(t0, F0):
            if ti < 0.5:
                continue
            k = bisect.bisect_left(t, ti)
            if k >= len(t):
                break
            if k > 0 and abs(t[k - 1] - ti) < abs(t[k] - ti):
                k -= 1
            g = F[k]
            num += sum((a - b) ** 2 for a, b in zip(g, fi))
            den += sum(a * a for a in fi)
            num_mag += (math.sqrt(sum(a * a for a in g)) - math.sqrt(sum(a * a for a in fi))) ** 2
            n += 1
        s = json.load(open(os.path.join(d, "summary.json"))).get("passivity", {})
        impulse = sum(math.sqrt(sum(a * a for a in F[i])) * (t[i] - t[i - 1]) for i in range(1, len(t)))
        print(f"{d}: {n} ticks; device force RMS error {100 * math.sqrt(num / max(den, 1e-18)):.1f} %"
              f" (|F| alone {100 * math.sqrt(num_mag / max(den, 1e-18)):.1f} %); passivity: guard cut "
              f"{100 * s.get('force_scaled_away_Ns', 0) / impulse:.1f} %, damping "
              f"{100 * s.get('force_damped_away_Ns', float('nan')) / impulse:.1f} % of the impulse")


if __name__ == "__main__":
    main(sys.argv[1:])
