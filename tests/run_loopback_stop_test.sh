#!/usr/bin/env bash
# deploy/run-loopback stopped in the middle of a run: SIGINT to its process group (what Ctrl-C
# sends), SIGTERM to its process group, and SIGTERM to run-loopback alone. Each must stop both
# programs through their own stop: exit status 0, summary.json and remote_summary.json written,
# the master's summary saying it was stopped on request, and trace.csv's last row complete.
# Usage: tests/run_loopback_stop_test.sh SOURCE_DIR BUILD_DIR OUT_DIR SIGNAL TARGET
#   SIGNAL: INT or TERM; TARGET: group (the launcher's process group) or launcher (its pid only)
set -uo pipefail
src="${1:?source dir}"; build="${2:?build dir}"; out="${3:?out dir}"
sig="${4:?signal INT or TERM}"; target="${5:?group or launcher}"
rm -rf "$out"; mkdir -p "$out"
run="$out/run"
# Its own process group (job control), as a shell's foreground job has: the group's id is its pid.
set -m
"$src/deploy/run-loopback" --build-dir "$build" --out "$run" --duration 600 --pd-backend cpu \
  --display none --no-report --master-args --quiet --slave-args --quiet > "$out/launcher.log" 2>&1 &
launcher=$!
set +m
# However this script ends (a failed check, or ctest's timeout), nothing of the run outlives it
# (cleared when every check passed).
trap 'kill -KILL -- "-$launcher" 2>/dev/null' EXIT
fail() {
  echo "SIG$sig to the $target: $*"
  echo "--- run-loopback's output:"; cat "$out/launcher.log"
  exit 1
}
# The run is under way once the trace has rows beyond its header (it is written as the run goes);
# polled every 0.05 s while the launcher is alive, at most 1800 times (ctest's TIMEOUT bounds the
# whole test).
under_way=0
for _ in $(seq 1 1800); do
  if [ "$( { wc -l < "$run/trace.csv"; } 2>/dev/null || echo 0)" -ge 500 ]; then
    under_way=1; break
  fi
  kill -0 "$launcher" 2>/dev/null || fail "run-loopback ended before the run was under way"
  sleep 0.05
done
[ "$under_way" -eq 1 ] || fail "the run was not under way after 1800 polls of trace.csv"
if [ "$target" = group ]; then
  kill "-$sig" -- "-$launcher"
else
  kill "-$sig" "$launcher"
fi
# Both programs stop as at the end of a run and write their files: at most 1200 polls.
for _ in $(seq 1 1200); do
  kill -0 "$launcher" 2>/dev/null || break
  sleep 0.05
done
kill -0 "$launcher" 2>/dev/null && fail "run-loopback still running 1200 polls after SIG$sig"
wait "$launcher"; rc=$?
[ "$rc" -eq 0 ] || fail "run-loopback exited $rc (want 0)"
grep -q "stopped by SIG$sig" "$out/launcher.log" || fail "run-loopback did not say it was stopped"
if grep -q "FAILED" "$out/launcher.log"; then fail "run-loopback says FAILED"; fi
for f in summary.json remote_summary.json trace.csv; do
  [ -s "$run/$f" ] || fail "no $f"
done
python3 - "$run" <<'PY' || fail "the files are not those of a run stopped cleanly"
import csv, json, sys
run = sys.argv[1]
s = json.load(open(run + "/summary.json"))
assert s["stopped_by_request"] is True, "summary.json: stopped_by_request is not true"
assert isinstance(s.get("remote"), dict), "summary.json: the remote node's summary was not merged"
r = json.load(open(run + "/remote_summary.json"))
assert r["steps"] > 0, "remote_summary.json: no steps"
text = open(run + "/trace.csv").read()
assert text.endswith("\n"), "trace.csv does not end with a newline"
rows = list(csv.reader(text.splitlines()))
header, last = rows[0], rows[-1]
assert len(rows) > 500, "trace.csv: %d rows" % len(rows)
assert len(last) == len(header), "trace.csv's last row has %d fields, the header %d" % (
    len(last), len(header))
float(last[0])  # t_s
print("trace.csv: %d rows, the last complete (%d fields); %d ticks, %d remote steps" %
      (len(rows) - 1, len(last), s["ticks"], r["steps"]))
PY
trap - EXIT
echo "run-loopback stop: SIG$sig to the $target: exit 0, both summaries, trace complete"
