#!/usr/bin/python3
"""fig76's two courses are mirror images (the block sways to +y or to -y at a turn; the scene is
symmetric about the tool's start y). Device force error of each run against a reference run, as
is and mirror-aware: per window of W ticks the smaller of the error against the reference and
against its mirror image in the sway (F_y and tau_x change sign; tau_z, which opposes the hand's
turn, does not: the input is not mirrored), so that a run that
took the other, equivalent course is judged by how it felt along it.

Usage: mirror_error.py [--window-ticks W] REFERENCE_TRACE RUN_TRACE... (trace.csv of
master_station or ARM.csv of deadband_lockstep; rows paired by index, one a tick)
"""
import sys

import numpy as np

args = sys.argv[1:]
window = 500
if args and args[0] == "--window-ticks":
    window = int(args[1])
    args = args[2:]
F = ["device_fx", "device_fy", "device_fz"]
T = ["device_tx", "device_ty", "device_tz"]


def load(path):
    d = np.genfromtxt(path, delimiter=",", names=True)
    return np.stack([d[k] for k in F], 1), np.stack([d[k] for k in T], 1)


rf, rt = load(args[0])
mf = rf * np.array([1, -1, 1])
mt = rt * np.array([-1, 1, 1])
for path in args[1:]:
    f, t = load(path)
    n = min(len(f), len(rf))
    e2 = np.sum((f[:n] - rf[:n]) ** 2, 1)
    m2 = np.sum((f[:n] - mf[:n]) ** 2, 1)
    et2 = np.sum((t[:n] - rt[:n]) ** 2, 1)
    mt2 = np.sum((t[:n] - mt[:n]) ** 2, 1)
    den_f = np.sum(np.sum(rf[:n] ** 2, 1))
    den_t = np.sum(np.sum(rt[:n] ** 2, 1))
    best_f = best_t = 0.0
    mirrored = 0
    for s in range(0, n, window):
        a, b = e2[s:s + window].sum(), m2[s:s + window].sum()
        mirrored += b < a
        best_f += min(a, b)
        best_t += et2[s:s + window].sum() if a <= b else mt2[s:s + window].sum()
    windows = (n + window - 1) // window
    print("%-40s device F %5.1f %% as is, %5.1f %% mirror-aware (%d of %d windows mirrored); "
          "torque %5.1f %% / %5.1f %%" % (
              path, 100 * np.sqrt(e2.sum() / den_f), 100 * np.sqrt(best_f / den_f), mirrored,
              windows, 100 * np.sqrt(et2.sum() / den_t), 100 * np.sqrt(best_t / den_t)))
