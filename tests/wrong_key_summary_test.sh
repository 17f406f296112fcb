#!/usr/bin/env bash
# The two sides with different --key files: the operator station finds no session, exits non-zero
# with an error that names the key, and still writes summary.json saying why; the remote node
# counts the operator's datagrams as failing authentication.
# Usage: tests/wrong_key_summary_test.sh BUILD_DIR OUT_DIR
set -uo pipefail
build="${1:?build dir}"; out="${2:?out dir}"
rm -rf "$out"; mkdir -p "$out"
slave="$build/slave_sim/slave_sim"; master="$build/master_station/master_station"
"$slave" keygen "$out/slave.key" > /dev/null && "$slave" keygen "$out/other.key" > /dev/null || exit 1
"$slave" --listen 127.0.0.1:0 --port-file "$out/slave.port" --key "$out/slave.key" --quiet --stay \
  --pd-backend cpu --out "$out/remote" > "$out/slave.log" 2>&1 &
slave_pid=$!
trap 'kill "$slave_pid" 2>/dev/null' EXIT
while [ ! -s "$out/slave.port" ]; do
  kill -0 "$slave_pid" 2>/dev/null || { echo "slave_sim did not start:"; cat "$out/slave.log"; exit 1; }
  sleep 0.05
done
"$master" --remote "127.0.0.1:$(cat "$out/slave.port")" --key "$out/other.key" --quiet \
  --connect-timeout 1 --out "$out/operator" > "$out/master.log" 2>&1
rc=$?
kill -TERM "$slave_pid"; wait "$slave_pid"; slave_rc=$?
trap - EXIT
cat "$out/master.log"
[ "$rc" -ne 0 ] || { echo "FAIL: master_station exited 0 without a session"; exit 1; }
[ "$slave_rc" -eq 0 ] || { echo "FAIL: slave_sim exited $slave_rc on SIGTERM"; exit 1; }
grep -q "same --key file" "$out/master.log" || { echo "FAIL: the error does not name the key"; exit 1; }
python3 - "$out" <<'PY' || exit 1
import json, sys
out = sys.argv[1]
try:
    s = json.load(open(out + "/operator/summary.json"))
except OSError as e:
    sys.exit("FAIL: no operator summary.json: %s" % e)
assert "same --key file" in s.get("error", ""), "FAIL: summary.json error: %r" % s.get("error")
assert s["session_opened"] is False and s["ticks"] == 0, "FAIL: summary.json: %s" % s
r = json.load(open(out + "/remote/remote_summary.json"))
bad = r["transport"]["rejected_by_reason"].get("bad_mac", 0)
assert bad > 0, "FAIL: the remote node counted no bad MAC: %s" % r["transport"]
print("wrong key: operator summary.json error: %s" % s["error"])
print("wrong key: remote node: %d datagram(s) with a bad MAC" % bad)
PY
echo "wrong key summary: ok"
