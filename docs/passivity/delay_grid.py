#!/usr/bin/python3
"""Issue 33's passivity grid, two or more operator settings alternated cell by cell (one session,
one binary, or one binary per arm with --arm-build): one-way delay x loss on the gear
(block-on-gear, fig75) and the stiff wall, each run `deploy/run-loopback --duration D
--pd-backend cpu --impair delay=..,loss=..,seed=..` with the arm's --master-args. Prints per run:
the device force's impulse (trace.csv), the share of it the passivity stage took (the guard's
cut, the damping, the reserve's refill; summary.json passivity), out <= in, the energy the model
switches created and the controller removed (passivity.attribution), model age p50 / p99
(trace.csv model_age_ms) and the device force's one-tick steps above 0.2 N; then a table of
guard + damping per cell and arm. grid.json keeps every figure.

Usage: delay_grid.py OUT_DIR [--delays 0,25,75,150] [--losses 0,10,20] [--wall 50:10,150:10]
         [--duration 4] [--repeats 1] [--build-dir build] --arm NAME="MASTER ARGS[::SLAVE ARGS]"
         [--arm ...] [--arm-build NAME=BUILD_DIR ...]
--arm-build runs that arm's executables from BUILD_DIR instead of --build-dir (a before/after
pair of builds, alternated run by run).
Example (the record in README.md): delay_grid.py /tmp/grid --losses 0,10 --duration 5 \
         --arm base="" --arm reserve20="--passivity-reserve-mj 20"
"""
import argparse
import csv
import json
import math
import os
import subprocess
import sys


def pct(a, b):
    return 100.0 * a / b if b > 0 else float("nan")


def quantile(xs, q):
    xs = sorted(xs)
    if not xs:
        return float("nan")
    return xs[min(len(xs) - 1, int(q * (len(xs) - 1) + 0.5))]


def read_run(d):
    with open(os.path.join(d, "trace.csv")) as f:
        rows = list(csv.DictReader(f))
    t = [float(r["t_s"]) for r in rows]
    dev = [math.sqrt(sum(float(r["device_f" + a]) ** 2 for a in "xyz")) for r in rows]
    impulse = sum(dev[i] * (t[i] - t[i - 1]) for i in range(1, len(dev)))
    ages = [float(r["model_age_ms"]) for r in rows if "model_age_ms" in r and float(r["model_age_ms"]) >= 0]
    s = json.load(open(os.path.join(d, "summary.json")))
    p = s.get("passivity", {})
    a = p.get("attribution", {})
    steps = sum(1 for i in range(1, len(dev)) if abs(dev[i] - dev[i - 1]) > 0.2)
    return {
        "impulse_Ns": impulse,
        "guard_pct": pct(p.get("force_scaled_away_Ns", 0.0), impulse),
        "damping_pct": pct(p.get("force_damped_away_Ns", 0.0), impulse),
        "refill_pct": pct(p.get("force_refilled_Ns", 0.0), impulse),
        "out_le_in": s.get("operator_energy_out_J", 0) <= s.get("operator_energy_in_J", 0) + 1e-12,
        "created_J": a.get("switch_energy_created_J", float("nan")),
        "removed_J": a.get("controller_removed_J", float("nan")),
        "age_p50": quantile(ages, 0.5),
        "age_p99": quantile(ages, 0.99),
        "steps_0.2N": steps,
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out")
    ap.add_argument("--delays", default="0,25,75,150")
    ap.add_argument("--losses", default="0,10,20")
    ap.add_argument("--wall", default="50:10,150:10")
    ap.add_argument("--duration", default="4")
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--build-dir", default="build")
    ap.add_argument("--arm", action="append", required=True)
    ap.add_argument("--arm-build", action="append", default=[])
    o = ap.parse_args()
    arm_build = {}
    for a in o.arm_build:
        if "=" not in a:
            ap.error(f"--arm-build {a!r}: expected NAME=BUILD_DIR")
        name, d = a.split("=", 1)
        if not os.path.isdir(d):
            ap.error(f"--arm-build {a!r}: {d} is not a directory")
        arm_build[name] = d
    # NAME=MASTER_ARGS, or NAME=MASTER_ARGS::SLAVE_ARGS for an arm that changes the remote node.
    arms = []
    for a in o.arm:
        name, args = a.split("=", 1) if "=" in a else (a, "")
        margs, _, sargs = args.partition("::")
        arms.append((name, margs.strip(), sargs.strip()))
    for name in arm_build:
        if name not in [a[0] for a in arms]:
            ap.error(f"--arm-build {name}: no --arm of that name")
    cells = [("block-on-gear", int(d), int(l)) for d in o.delays.split(",") for l in o.losses.split(",")]
    if o.wall:
        cells += [("stiff-wall", int(x.split(":")[0]), int(x.split(":")[1])) for x in o.wall.split(",")]
    repo = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    results = []
    for scene, delay, loss in cells:
        for r in range(o.repeats):
            for name, margs, sargs in arms:
                d = os.path.join(o.out, f"{scene}_d{delay}_l{loss}_r{r}_{name}")
                cmd = [os.path.join(repo, "deploy/run-loopback"), "--build-dir", arm_build.get(name, o.build_dir), "--out", d,
                       "--duration", o.duration, "--pd-backend", "cpu", "--scene", scene,
                       "--display", "none", "--no-report",
                       "--master-args", ("--quiet " + margs).strip(), "--slave-args", ("--quiet " + sargs).strip()]
                if delay or loss:
                    cmd += ["--impair", f"delay={delay}ms,loss={loss}%,seed={delay}{loss}7"]
                rc = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL).returncode
                if rc != 0:
                    print(f"{d}: run-loopback failed ({rc})", flush=True)
                    continue
                m = read_run(d)
                m.update(scene=scene, delay=delay, loss=loss, arm=name)
                results.append(m)
                print(f"{scene} d{delay} l{loss} {name}: impulse {m['impulse_Ns']:.3f} N·s, guard "
                      f"{m['guard_pct']:.1f} %, damping {m['damping_pct']:.1f} %, refill {m['refill_pct']:.1f} %, "
                      f"out<=in {m['out_le_in']}, created {m['created_J']:.4f} J, removed {m['removed_J']:.4f} J, "
                      f"age p50/p99 "
                      f"{m['age_p50']:.1f}/{m['age_p99']:.1f} ms, steps>0.2N {m['steps_0.2N']}", flush=True)
    with open(os.path.join(o.out, "grid.json"), "w") as f:
        json.dump(results, f, indent=1)
    print("\n| scene | delay (ms) | loss | " + " | ".join(f"{n}: guard + damping (%)" for n, _, _ in arms) + " |")
    print("|---|---:|---:|" + "---:|" * len(arms))
    for scene, delay, loss in cells:
        row = f"| {scene} | {delay} | {loss} % |"
        for name, _, _ in arms:
            ms = [m for m in results if (m["scene"], m["delay"], m["loss"], m["arm"]) == (scene, delay, loss, name)]
            row += " " + " / ".join(f"{m['guard_pct'] + m['damping_pct']:.1f}" for m in ms) + " |"
        print(row)


if __name__ == "__main__":
    sys.exit(main())
