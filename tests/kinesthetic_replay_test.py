#!/usr/bin/python3
"""deploy/kinesthetic-replay and the pure parts of deploy/deadband-table (issue 18), without a
loopback run:
  - the WAM leader recording (../shared/data/kinesthetic/wam_leader_fm_reach_dc_1; skipped when
    absent) becomes a replay CSV with the documented header, rows, times and ranges, and
    master_station --device replay loads it (it then waits for a remote node that is not there);
  - a missing input, a folder without kinematics.txt, a dynamics.txt, a non-number, a time that
    does not increase and a one-row file each give one error line naming the file, exit 2, and no
    output file;
  - deadband-table's force error: 0 for identical traces, the formula on a known pair, rows
    paired on t_s when a tick came late; its argument errors exit 2.
Usage: tests/kinesthetic_replay_test.py SOURCE_DIR [BUILD_DIR]
"""
import csv
import importlib.machinery
import importlib.util
import math
import os
import shutil
import subprocess
import sys
import tempfile

failures = []


def check(cond, what):
    if not cond:
        failures.append(what)
        print("FAIL:", what)
    else:
        print("ok:  ", what)


def run(cmd, **kw):
    return subprocess.run(cmd, capture_output=True, text=True, timeout=120, **kw)


def main():
    if len(sys.argv) < 2:
        print(__doc__)
        return 2
    src = os.path.abspath(sys.argv[1])
    build = os.path.abspath(sys.argv[2]) if len(sys.argv) > 2 else os.path.join(src, "build")
    tool = os.path.join(src, "deploy", "kinesthetic-replay")
    table = os.path.join(src, "deploy", "deadband-table")
    data = os.path.join(src, "..", "shared", "data", "kinesthetic", "wam_leader_fm_reach_dc_1")
    tmp = tempfile.mkdtemp(prefix="kinesthetic_replay_test_")

    # --help
    r = run([tool, "--help"])
    check(r.returncode == 0 and "--out FILE" in r.stdout and "joint 1" in r.stdout,
          "kinesthetic-replay --help exits 0 and describes the mapping")

    # The real recording.
    if os.path.isfile(os.path.join(data, "kinematics.txt")):
        out = os.path.join(tmp, "wam.csv")
        r = run([tool, data, "--out", out])
        check(r.returncode == 0, f"converts the WAM recording (exit {r.returncode}: {r.stderr})")
        with open(out, newline="") as f:
            rows = list(csv.reader(f))
        check(rows[0] == ["t_s", "x", "y", "z"], "header t_s,x,y,z")
        body = [[float(c) for c in row] for row in rows[1:]]
        check(len(body) == 6926 + 250, f"6926 recorded rows + 250 approach rows ({len(body)})")
        t = [b[0] for b in body]
        check(all(b > a for a, b in zip(t, t[1:])), "t_s strictly increasing")
        check(abs(t[0]) < 1e-12 and abs(t[-1] - 14.35) < 1e-6, f"t_s from 0 to 14.35 ({t[-1]})")
        check(body[0][1:] == [0.0, 0.0, 0.002], "starts 2 mm above the workspace centre")
        rec = [b for b in body if b[0] >= 0.5]
        xs, ys, zs = ([b[i] for b in rec] for i in (1, 2, 3))
        check(abs(max(xs) - 0.0152047) < 1e-6 and abs(min(xs) + 0.0152047) < 1e-6,
              "x: joint 1 x 10 mm/rad, centred (+-15.2 mm)")
        check(abs(max(ys) - 0.0091967) < 1e-6 and abs(min(ys) + 0.0091967) < 1e-6,
              "y: joint 3 x 10 mm/rad, centred (+-9.2 mm)")
        check(abs(max(zs) + 0.001) < 1e-9 and abs(min(zs) + 0.0027606) < 1e-6,
              "z: 1.0 to 2.76 mm below the centre (joint 2)")
        speeds = [math.dist(a[1:], b[1:]) / (b[0] - a[0]) for a, b in zip(rec, rec[1:])]
        check(max(speeds) < 0.02, f"handle speed below 2 cm/s ({max(speeds):.4f} m/s)")
        # The options change what they say.
        out2 = os.path.join(tmp, "wam2.csv")
        r = run([tool, data, "--out", out2, "--scale", "5", "--depth", "2", "--approach", "0",
                 "--use", "desired", "--start", "3", "--end", "12"])
        with open(out2, newline="") as f:
            rows2 = [[float(c) for c in row] for row in list(csv.reader(f))[1:]]
        check(r.returncode == 0 and abs(rows2[0][0]) < 1e-12 and
              max(b[3] for b in rows2) <= -0.002 + 1e-12 and
              abs(rows2[-1][0] - (12.0 - 3.0)) < 0.003,
              "--scale/--depth/--approach 0/--use desired/--start/--end")
        # master_station reads it as a replay trace (no remote node: it stops after the load).
        master = os.path.join(build, "master_station", "master_station")
        if os.access(master, os.X_OK):
            key = os.path.join(tmp, "k.key")
            run([os.path.join(build, "slave_sim", "slave_sim"), "keygen", key])
            r = run([master, "--key", key, "--remote", "127.0.0.1:9", "--device", "replay",
                     "--replay", out, "--connect-timeout", "0.2"])  # the start-up line says it
            text = r.stdout + r.stderr
            check("replay trace" not in text and "(14.35 s)" in text,
                  "master_station --device replay loads it (14.35 s)")
        else:
            print("skip: no master_station in", build)
    else:
        print("skip: no recording at", data)

    # Malformed inputs: one error line naming the file, exit 2, no output.
    def bad(name, content, expect):
        path = os.path.join(tmp, name)
        if content is not None:
            with open(path, "w") as f:
                f.write(content)
        out = os.path.join(tmp, name + ".csv")
        r = run([tool, path, "--out", out])
        lines = r.stderr.strip().splitlines()
        check(r.returncode == 2 and len(lines) == 1 and path in lines[0] and expect in lines[0]
              and not os.path.exists(out),
              f"{name}: exit 2, one line naming the file with '{expect}' ({r.stderr.strip()})")

    good = "0.002," + ",".join(["0.1"] * 18) + "\n"
    bad("missing.txt", None, "no such file")
    os.makedirs(os.path.join(tmp, "emptydir"), exist_ok=True)
    bad("emptydir", None, "without kinematics.txt")
    bad("dynamics.txt", "0.002," + ",".join(["1"] * 12) + "\n", "line 1: 13 column(s)")
    bad("nonnumber.txt", good + "0.004,0.1,0.1,0.1,0.1,abc" + ",0.1" * 13 + "\n",
        "line 2: feedback joint 2 position is not a number")
    bad("notincreasing.txt", good + good, "line 2: time 0.002 does not increase")
    bad("onerow.txt", good, "1 sample(s)")
    bad("nan.txt", good + "0.004" + ",nan" * 18 + "\n", "line 2")
    r = run([tool, os.path.join(tmp, "x")])
    check(r.returncode == 2 and "--out" in r.stderr, "no --out: exit 2")

    # deadband-table's pure parts.
    loader = importlib.machinery.SourceFileLoader("deadband_table", table)
    spec = importlib.util.spec_from_loader("deadband_table", loader)
    dt = importlib.util.module_from_spec(spec)
    loader.exec_module(dt)
    ref = {"t": [0.001 * k for k in range(100)],
           "contact": [(0.0, 0.0, 1.0 + 0.1 * (k % 3)) for k in range(100)]}
    same_pairs, by_row = dt.align(ref, ref)
    check(len(same_pairs) == 100 and by_row == 0.0 and
          dt.rms_error_pct(ref["contact"], ref["contact"], same_pairs) == 0.0,
          "identical traces: error 0")
    other = {"t": ref["t"], "contact": [(0.0, 0.0, 2 * c[2]) for c in ref["contact"]]}
    e = dt.rms_error_pct(other["contact"], ref["contact"], dt.align(other, ref)[0])
    check(abs(e - 100.0) < 1e-9, f"F = 2 F_ref: error 100 % ({e})")
    # A tick 5 ms late at row 50: the run's rows after it pair with the reference's by time.
    late = {"t": ref["t"][:50] + [t + 0.005 for t in ref["t"][50:95]],
            "contact": ref["contact"][:50] + ref["contact"][55:100]}
    pairs, by_row = dt.align(late, ref)
    after = [(i, k) for i, k in pairs if k >= 55]
    e = dt.rms_error_pct(late["contact"], ref["contact"], after)
    check(abs(by_row - 0.005) < 1e-9 and len(pairs) == 100 and len(after) == 45 and
          all(abs(late["t"][i] - ref["t"][k]) < 1e-12 for i, k in after) and e == 0.0,
          f"late tick: rows after it paired on t_s, error 0 there ({e})")
    m = dt.moving_mean([(0, 0, 1), (0, 0, 3), (0, 0, 5)], 2)
    check(m == [(0, 0, 1), (0, 0, 2), (0, 0, 4)], "trailing mean")
    for args, what in ((["--deadbands", "5,x"], "a non-number deadband"),
                       (["--deadbands", "150"], "a deadband of 150 %"),
                       (["--repeats", "0"], "--repeats 0"),
                       (["--inputs", "fig99"], "an unknown input"),
                       (["--build-dir", os.path.join(tmp, "nobuild")], "a missing build")):
        r = run([table, "--out", os.path.join(tmp, "dbt")] + args)
        check(r.returncode == 2 and "deadband-table: error:" in r.stderr, f"deadband-table: {what}"
              f" exits 2 ({r.stderr.strip()})")
    r = run([table, "--help"])
    check(r.returncode == 0 and "noise floor" in r.stdout, "deadband-table --help exits 0")

    shutil.rmtree(tmp, ignore_errors=True)
    print(f"{len(failures)} failure(s)")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
