#!/usr/bin/env python3
"""Per phase: RMS of the device force's and the contact force's high-passed part (minus a centred
11-tick moving mean), and the device force's spectrum share in 60-200 Hz. Usage: phase_ripple.py RUN_DIR... (needs numpy)"""
import csv, math, sys
import numpy as np
for run in sys.argv[1:]:
    rows = list(csv.DictReader(open(f"{run}/trace.csv")))
    ph = np.array([r["phase"] for r in rows])
    for phase in dict.fromkeys(ph):
        m = ph == phase
        if m.sum() < 100: continue
        out = []
        for keys in (("device_fx", "device_fy", "device_fz"), ("fx", "fy", "fz")):
            F = np.array([[float(r[k]) for k in keys] for r, mm in zip(rows, m) if mm])
            ker = np.ones(11) / 11
            lp = np.stack([np.convolve(F[:, j], ker, mode="same") for j in range(3)], 1)
            hp = (F - lp)[6:-6]
            out.append(math.sqrt((hp ** 2).sum(1).mean()))
            if keys[0] == "device_fx":
                X = np.abs(np.fft.rfft(F - F.mean(0), axis=0)) ** 2
                f = np.fft.rfftfreq(len(F), 1e-3)
                band = X[(f > 60) & (f < 200)].sum() / X[f > 1].sum()
        print(f"{run} {phase:4s} device hp RMS {out[0]*1e3:6.1f} mN, contact hp RMS {out[1]*1e3:7.1f} mN, device 60-200 Hz share {band*100:.2f} %")
