#!/usr/bin/env python3
"""A trace for speed_error_frontier --trace: the pose of row 1000 (t = 0.998 s) of a
deadband_lockstep block-on-gear trace (the resting block on fig75's x slide), tilted about y from
-0.6 to +0.6 mrad in 0.01 mrad steps (121 rows). Usage: through_level_trace.py LOCKSTEP.csv OUT.csv"""
import csv
import sys

rows = list(csv.DictReader(open(sys.argv[1])))
r = rows[999]
with open(sys.argv[2], "w") as f:
    f.write("t_s,tool_x,tool_y,tool_z,tool_rx,tool_ry,tool_rz,contacts\n")
    for i in range(121):
        f.write(f"{i * 0.001},{r['tool_x']},{r['tool_y']},{r['tool_z']},{r['tool_rx']},"
                f"{(i - 60) * 1e-5},{r['tool_rz']},1\n")
