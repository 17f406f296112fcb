#!/usr/bin/env bash
# A scripted experiment with its trace and plots: the seed's Fig. 75 run (the block pressed on
# the gear and slid along and across its ridges by the simulated operator) twice, without and
# with a 50 ms one-way network delay (the impairment relay between the two processes); each
# run's plots (deploy/report), then what the operator felt under delay against without it
# (deploy/compare-traces). Copy it and change the conditions in CONDITIONS.
#
# Usage: examples/scripted_experiment/run.sh [OUT_DIR [BUILD_DIR]]
#   OUT_DIR   default out/scripted_experiment: one folder per condition with trace.csv (one row
#             per operator tick: SI units, the scene's world frame W), summary.json,
#             remote_steps.csv, the plots (*.png) and index.html
#   BUILD_DIR default build (slave_sim, master_station and ht_relay built there)
#   DURATION  (environment) seconds per run, default 3
# Prints per run its trace rows, the largest force on the device |F| (N) and the median round
# trip (ms), then compare-traces' force and torque error (RMS, % of the undelayed run's).
# Exits 1 when a run fails or its trace or plots are missing. ctest runs it
# (example_scripted_experiment); the plots need matplotlib (/usr/bin/python3, Debian's).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
out="${1:-out/scripted_experiment}"; build="${2:-$root/build}"; duration="${DURATION:-3}"
CONDITIONS=("nodelay:" "delay50ms:delay=50ms")  # NAME:IMPAIRMENT (empty: direct)
mkdir -p "$out"

for condition in "${CONDITIONS[@]}"; do
  name="${condition%%:*}"; impair="${condition#*:}"
  args=(--build-dir "$build" --out "$out/$name" --experiment fig75 --duration "$duration"
        --display none --no-report --master-args --quiet --slave-args --quiet)
  [ -z "$impair" ] || args+=(--impair "$impair")
  "$root/deploy/run-loopback" "${args[@]}" > "$out/$name.log" 2>&1 ||
    { cat "$out/$name.log"; echo "scripted_experiment: run $name failed" >&2; exit 1; }
  /usr/bin/python3 "$root/deploy/report" "$out/$name" > "$out/$name/report.log" ||
    { cat "$out/$name/report.log"; exit 1; }
  for f in trace.csv summary.json position_force.png loop_period.png network.png index.html; do
    [ -s "$out/$name/$f" ] || { echo "scripted_experiment: $out/$name/$f missing" >&2; exit 1; }
  done
  /usr/bin/python3 - "$out/$name" <<'PY'
import csv, json, math, os, sys
run = sys.argv[1]
with open(os.path.join(run, "trace.csv"), newline="") as f:
    rows = list(csv.DictReader(f))
peak = max(math.dist((0, 0, 0), [float(r[k]) for k in ("device_fx", "device_fy", "device_fz")])
           for r in rows)
summary = json.load(open(os.path.join(run, "summary.json")))
print(f"{os.path.basename(run)}: {len(rows)} ticks, largest device force {peak:.2f} N, "
      f"round trip p50 {summary['rtt_ms_p50']:.1f} ms; plots in {run}/index.html")
PY
done
/usr/bin/python3 "$root/deploy/compare-traces" "$out/nodelay" "$out/delay50ms"
