#!/usr/bin/env python3
"""The device force's one-tick changes above THR N in deploy/run-loopback runs, and what each is
made of: the coupling spring's change (k_c = 1000 N/m times the change of hand - tool) and its
damper's (b_c = 5 N s/m times the tool's change of velocity), the contact force's change, and
'spike' when the force is back within 5 ticks (|F[i+5] - F[i-1]| < half the change), else 'step'.
Usage: slip_steps.py THR RUN_DIR..."""
import csv, math, sys
THR = float(sys.argv[1]); runs = sys.argv[2:]
kc, bc = 1000.0, 5.0
for run in runs:
    rows = list(csv.DictReader(open(f"{run}/trace.csv")))
    t = [float(r["t_s"]) for r in rows]
    P = [[float(r[k]) for k in ("tool_x", "tool_y", "tool_z")] for r in rows]
    H = [[float(r[k]) for k in ("hand_x", "hand_y", "hand_z")] for r in rows]
    D = [[float(r[k]) for k in ("device_fx", "device_fy", "device_fz")] for r in rows]
    C = [[float(r[k]) for k in ("fx", "fy", "fz")] for r in rows]
    age = [float(r["model_age_ms"]) for r in rows]
    n = len(rows); nstep = nspike = 0
    def sub(a, b): return [x - y for x, y in zip(a, b)]
    def nrm(a): return math.sqrt(sum(x * x for x in a))
    for i in range(2, n - 6):
        d = nrm(sub(D[i], D[i - 1]))
        if d <= THR: continue
        h = t[i] - t[i - 1]
        vt0 = [x / h for x in sub(P[i - 1], P[i - 2])]; vt1 = [x / h for x in sub(P[i], P[i - 1])]
        spring = nrm([kc * (x) for x in sub(sub(H[i], P[i]), sub(H[i - 1], P[i - 1]))])
        dv = nrm(sub(vt1, vt0))
        back = nrm(sub(D[i + 5], D[i - 1]))
        kind = "spike" if back < 0.5 * d else "step"
        nstep += kind == "step"; nspike += kind == "spike"
        print(f"{run} t={t[i]:.3f} {rows[i]['phase']} |dF_dev|={d:.3f} {kind} back5={back:.3f} "
              f"spring~{spring:.3f} |dv_tool|={dv*1e3:.1f}mm/s b*dv={bc*dv:.3f} "
              f"|dF_contact|={nrm(sub(C[i], C[i-1])):.2f} |Fc|={nrm(C[i]):.2f} contacts={rows[i]['contacts']}")
    print(f"{run}: {nstep} steps, {nspike} spikes above {THR} N")
