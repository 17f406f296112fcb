#!/usr/bin/env bash
# Both processes on a scene FILE (a real glTF with animations): the remote node builds it through
# the model cache and plays its animation, the operator runs 3 s. Checks: a session, the operator's
# workspace centred on the home position the node prints (received in the Welcome), the scene
# streamed and verified as a scene (a graph, its meshes), no non-finite value; the animated nodes'
# poses (the milk truck's wheels) reach the operator and change over time; the headless display
# writes frames of the received scene.
# Usage: scene_file_loopback.sh BUILD_DIR SCENE_FILE OUT_DIR   (exit 77 = skipped: no data)
set -euo pipefail
build=$1 scene=$2 out=$3
if [ ! -f "$scene" ]; then
  echo "skipped: $scene not found (the team's ../shared/data is not here)"
  exit 77
fi
rm -rf "$out" && mkdir -p "$out"
"$build/slave_sim/slave_sim" keygen "$out/k.key" >/dev/null
"$build/slave_sim/slave_sim" --key "$out/k.key" --listen 127.0.0.1:0 --port-file "$out/port" \
  --scene "$scene" --cache-dir "$out/cache" --out "$out" >"$out/slave.log" 2>&1 &
slave=$!
trap 'kill $slave 2>/dev/null || true' EXIT
for _ in $(seq 1 240); do [ -s "$out/port" ] && break; sleep 0.5; done
[ -s "$out/port" ] || { echo "remote node did not start"; cat "$out/slave.log"; exit 1; }
origin=$(grep -o 'tool home position in W [-0-9.,]*' "$out/slave.log" | head -1 | cut -d' ' -f6)
[ -n "$origin" ] || { echo "no home position printed"; cat "$out/slave.log"; exit 1; }
"$build/master_station/master_station" --key "$out/k.key" --remote "127.0.0.1:$(cat "$out/port")" \
  --duration 3 --out "$out/m" --display headless --frame-rate 2 | tee "$out/master.log"
grep -q "workspace centre in W $origin (the remote node's home pose)" "$out/master.log" || {
  echo "the operator's workspace is not at the node's home position $origin"; exit 1; }
wait $slave
grep -q '"nonfinite_count": 0' "$out/m/summary.json" || { echo "non-finite values"; exit 1; }
grep -q '"complete": true' "$out/m/summary.json" || { echo "scene not complete"; exit 1; }
/usr/bin/python3 - "$out/m/summary.json" <<'PY'
import json, math, sys
s = json.load(open(sys.argv[1]))
t = s["transport"]
kinds = [o.get("kind") for o in t["scene"]["decoded"]]
assert kinds.count("scene_graph") == 1, f"one scene graph expected, got {kinds}"
assert "draco_mesh" in kinds and not any("error" in o for o in t["scene"]["decoded"]), kinds
poses = t["node_poses"]
assert poses["entries_applied"] > 0, f"no node pose reached the operator: {poses}"
moved = []
for n in poses["nodes"]:
    q0, q1 = n["first_rotation_wxyz"], n["last_rotation_wxyz"]
    angle = 2 * math.acos(min(1.0, abs(sum(a * b for a, b in zip(q0, q1)))))
    if n["last_time_s"] > n["first_time_s"] and n["updates"] > 10 and angle > 1e-3:
        moved.append(f'{n["name"]} ({n["updates"]} updates, turned {math.degrees(angle):.0f} deg)')
print("moving nodes seen by the operator:", "; ".join(moved))
assert moved, f"no node's pose changed over time at the operator: {poses['nodes']}"
d = s["display"]
assert d["frames"] >= 2 and not d["error"], f"display: {d}"
PY
echo "scene file loopback: ok ($(grep -o '"contacts_max": [0-9]*' "$out/m/summary.json"))"
