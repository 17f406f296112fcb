#!/usr/bin/python3
"""fig76 loopback runs against one reference run (deadband 0): device force and torque RMS error
(trace.csv device_f*, device_t*, rows paired by index: every run has one row a tick), tool states
and contact models per second (summary.json), and which way the block swayed: the tool's mean y
over 4.0-4.6 s and 10.0-10.6 s of the run, where the branches part (one sways to +y while the
other sways to -y).

Usage: f76_loopback.py REFERENCE_RUN RUN [RUN ...]
"""
import json
import sys

import numpy as np


def load(d):
    return np.genfromtxt(d + "/trace.csv", delimiter=",", names=True)


def err(a, b, keys):
    n = min(len(a), len(b))
    A = np.stack([a[k][:n] for k in keys], 1)
    B = np.stack([b[k][:n] for k in keys], 1)
    return 100 * np.sqrt(np.mean(np.sum((A - B) ** 2, 1)) / np.mean(np.sum(B ** 2, 1)))


def sway_mm(r):
    t = r["t_s"]
    m = ((t >= 4.0) & (t < 4.6)) | ((t >= 10.0) & (t < 10.6))
    return 1e3 * np.mean(r["tool_y"][m])


ref = load(sys.argv[1])
F = ["device_fx", "device_fy", "device_fz"]
T = ["device_tx", "device_ty", "device_tz"]
print("reference %s: tool y over the parting windows %.3f mm" % (sys.argv[1], sway_mm(ref)))
for name in sys.argv[2:]:
    r = load(name)
    s = json.load(open(name + "/summary.json"))
    st = s["transport"]["streams"]
    ts = sum(v.get("sent", 0) for k, v in st.items() if "tool_state" in k)
    cm = sum(v.get("remote", {}).get("sent", 0) for k, v in st.items() if "contact_model" in k)
    dur = s.get("duration_s", 12.0)
    print("%-28s device F %5.1f %%  torque %5.1f %%  tool states %4.0f/s  models %4.0f/s  "
          "tool y %.3f mm" % (name, err(r, ref, F), err(r, ref, T), ts / dur, cm / dur, sway_mm(r)))
