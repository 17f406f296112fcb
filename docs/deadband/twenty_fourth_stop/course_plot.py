#!/usr/bin/python3
"""fig76's course with and without the deadband (deadband_lockstep traces, one seed): the device's
sideways force F_y and the tool's y over the run, for the reference (both deadbands off), the
default 10 % deadband and the 0.2 mrad contact rotation floor.

Usage: course_plot.py OUT.png REFERENCE.csv DEFAULT.csv ROT02.csv
"""
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

out, *paths = sys.argv[1:]
names = ["both deadbands off", "default 10 %", "10 %, contact rotation floor 0.2 mrad"]
fig, ax = plt.subplots(2, 1, figsize=(10, 6), sharex=True)
for path, name in zip(paths, names):
    d = np.genfromtxt(path, delimiter=",", names=True)
    ax[0].plot(d["t_s"], d["device_fy"], lw=0.8, label=name)
    ax[1].plot(d["t_s"], 1e3 * d["tool_y"], lw=0.8, label=name)
ax[0].set_ylabel("device F_y (N)")
ax[1].set_ylabel("tool y (mm)")
ax[1].set_xlabel("t (s)")
ax[0].legend(loc="upper right", fontsize=8)
ax[0].set_title("fig76 (striped blocks turned in contact), deadband_lockstep --jitter-ms 0.5, seed 0")
fig.tight_layout()
fig.savefig(out, dpi=110)
