#!/usr/bin/env python3
"""Checks a loopback run on the plate scene of tests/make_plate_scene.py (a Y-up glTF, the plate's
top at Y = 0, the probe a 1 cm cube): the device's up is the scene's up (issue 33). Every tick in
contact has the contact force pointing up the scene's +Y (|F_Y| ≥ 0.9 |F|), the probe's centre
stays above the plate's top (Y ≥ 4 mm: the probe's half size less its press), and there are such
ticks. The force the operator feels, in the device's frame (device_f*_M), is the device's force in
the scene's frame turned into M: its up (z) is the scene's +Y (device_fy), two routes to one number.
Usage: device_up_check.py RUN_DIR LABEL"""
import csv
import math
import sys

out, label = sys.argv[1], sys.argv[2]
with open(f"{out}/trace.csv") as f:
    rows = [r for r in csv.DictReader(f) if int(r["contacts"]) > 0]
errors = []
if len(rows) < 200:
    errors.append(f"only {len(rows)} ticks in contact")
sideways = below = 0
worst_side, lowest = 0.0, math.inf
for r in rows:
    fx, fy, fz = float(r["fx"]), float(r["fy"]), float(r["fz"])
    norm = math.sqrt(fx * fx + fy * fy + fz * fz)
    if norm > 0.05 and fy < 0.9 * norm:
        sideways += 1
        worst_side = max(worst_side, math.hypot(fx, fz) / norm)
    y = float(r["tool_y"])
    lowest = min(lowest, y)
    if y < 0.004:
        below += 1
felt_M = ("device_fx_M", "device_fy_M", "device_fz_M")
if rows and not all(c in rows[0] for c in felt_M):
    errors.append("trace.csv has no device-frame columns " + ", ".join(felt_M))
elif rows:
    # M's x, y, z are the scene's X, -Z, Y here (the Welcome's home pose turns z up to +Y).
    worst = max(max(abs(float(r["device_fx_M"]) - float(r["device_fx"])),
                    abs(float(r["device_fy_M"]) + float(r["device_fz"])),
                    abs(float(r["device_fz_M"]) - float(r["device_fy"]))) for r in rows)
    if worst > 1e-4:
        errors.append(f"device_f*_M differs from the device's force turned into M by {worst:.3g} N")
    felt_up = sum(1 for r in rows if float(r["device_fz_M"]) > 0.05)
    if felt_up < len(rows) // 2:
        errors.append(f"the operator feels the plate push up (device_fz_M > 0.05 N) on only "
                      f"{felt_up} of {len(rows)} contact ticks")
if sideways:
    errors.append(f"{sideways} contact ticks push sideways or down (worst |F_XZ|/|F| {worst_side:.2f})")
if below:
    errors.append(f"{below} contact ticks with the probe's centre below the plate's top + 4 mm "
                  f"(lowest Y {lowest * 1e3:.2f} mm): it touched the plate's side")
print(f"device up ({label}): {len(rows)} ticks in contact, lowest probe centre "
      f"{lowest * 1e3:.2f} mm above the top, {sideways} sideways")
if errors:
    for e in errors:
        print(f"device up ({label}): FAILED: {e}")
    sys.exit(1)
print(f"device up ({label}): ok")
