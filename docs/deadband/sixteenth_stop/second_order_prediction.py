#!/usr/bin/python3
"""Would a second-order predictor send fewer tool states? Replays the tool-state deadband offline
on one run's trace.csv (the tool's pose every tick): the Weber rule at k = 0.1 with the floors of
transport/deadband.h (position 0.2 mm near contact, 2 mm away; rotation 20 mrad; near contact =
a contact in the trace within the last 0.5 s; keep-alive 100 ms), predicting from the last sent
state at constant twist (what the remote node does) or with the last sent acceleration as well
(the velocity's backward difference, low-passed with time constant tau; "far only": the
acceleration used away from contact only). The twist is the pose's backward difference.
Prints the states per second each way.
Usage: second_order_prediction.py RUN_DIR  (needs numpy and scipy)"""
import csv
import sys

import numpy as np
from scipy.spatial.transform import Rotation

K = 0.1


def main(run):
    rows = list(csv.DictReader(open(f"{run}/trace.csv")))
    t = np.array([float(r["t_s"]) for r in rows])
    p = np.array([[float(r[k]) for k in ("tool_x", "tool_y", "tool_z")] for r in rows])
    rv = np.array([[float(r[k]) for k in ("tool_rx", "tool_ry", "tool_rz")] for r in rows])
    contact = np.array([int(float(r["contacts"])) > 0 for r in rows])
    dt = np.diff(t, prepend=t[0] - 1e-3)
    dt[dt <= 0] = 1e-3
    v = np.zeros_like(p)
    v[1:] = (p[1:] - p[:-1]) / dt[1:, None]
    R = Rotation.from_rotvec(rv)
    w = np.zeros_like(p)
    w[1:] = (R[1:] * R[:-1].inv()).as_rotvec() / dt[1:, None]
    acc_raw = np.zeros_like(v)
    acc_raw[1:] = (v[1:] - v[:-1]) / dt[1:, None]
    near = np.zeros(len(t), bool)
    last = -1e9
    for i in range(len(t)):
        if contact[i]:
            last = t[i]
        near[i] = t[i] - last < 0.5

    def low_pass(x, tau):
        y = np.zeros_like(x)
        a = x[0]
        for i in range(len(x)):
            a = a + (x[i] - a) * min(1.0, dt[i] / tau)
            y[i] = a
        return y

    def states_per_s(order, tau=0.02, far_only=False):
        acc = low_pass(acc_raw, tau) if order == 2 else None
        sent = 0
        ps, vs, a_s, ts, Rs, ws = p[0], v[0], np.zeros(3), t[0], R[0], w[0]
        for i in range(1, len(t)):
            d = t[i] - ts
            use_a = order == 2 and not (far_only and near[i])
            predicted = ps + vs * d + (0.5 * a_s * d * d if use_a else 0.0)
            error = np.linalg.norm(p[i] - predicted)
            moved = np.linalg.norm(p[i] - ps)
            floor_p = 0.2e-3 if near[i] else 2e-3
            R_pred = Rotation.from_rotvec(ws * d) * Rs
            error_r = np.linalg.norm((R[i] * R_pred.inv()).as_rotvec())
            moved_r = np.linalg.norm((R[i] * Rs.inv()).as_rotvec())
            if d >= 0.1 or error > max(K * moved, K * floor_p) or error_r > max(K * moved_r,
                                                                                 K * 20e-3):
                sent += 1
                ps, vs, ts, Rs, ws = p[i], v[i], t[i], R[i], w[i]
                if order == 2:
                    a_s = acc[i]
        return sent / (t[-1] - t[0])

    print(f"{run}: near contact on {100 * near.mean():.1f} % of the ticks")
    print(f"constant twist: {states_per_s(1):.1f} states/s")
    for tau in (0.005, 0.02, 0.05):
        print(f"with acceleration, tau {tau * 1e3:.0f} ms: {states_per_s(2, tau):.1f} states/s; "
              f"far only: {states_per_s(2, tau, True):.1f}")


if __name__ == "__main__":
    main(sys.argv[1])
