#!/usr/bin/env bash
# The scene file changes on disk while both processes run (issue 17): the remote node rebuilds it,
# switches its pipeline between two steps and streams the changed objects; the operator receives
# the new version and its display shows it. A copy of a real glTF (Box) gets a node scale.
# Usage: scene_reload_loopback.sh BUILD_DIR BOX_GLTF_DIR OUT_DIR   (exit 77 = skipped: no data)
set -euo pipefail
build=$1 data=$2 out=$3
if [ ! -f "$data/Box.gltf" ]; then
  echo "skipped: $data/Box.gltf not found (the team's ../shared/data is not here)"
  exit 77
fi
rm -rf "$out" && mkdir -p "$out"
cp "$data"/* "$out/"
"$build/slave_sim/slave_sim" keygen "$out/k.key" >/dev/null
"$build/slave_sim/slave_sim" --key "$out/k.key" --listen 127.0.0.1:0 --port-file "$out/port" \
  --scene "$out/Box.gltf" --cache-dir "$out/cache" --out "$out/s" >"$out/slave.log" 2>&1 &
slave=$!
trap 'kill $slave 2>/dev/null || true' EXIT
for _ in $(seq 1 240); do [ -s "$out/port" ] && break; sleep 0.25; done
[ -s "$out/port" ] || { echo "remote node did not start"; cat "$out/slave.log"; exit 1; }
"$build/master_station/master_station" --key "$out/k.key" --remote "127.0.0.1:$(cat "$out/port")" \
  --experiment explore --duration 7 --out "$out/m" --display headless --frame-rate 4 --quiet \
  >"$out/master.log" 2>&1 &
master=$!
sleep 2.5
# The edit: the box node three times wider in x (written to a temporary name, then renamed).
/usr/bin/python3 - "$out/Box.gltf" <<'PY'
import json, os, sys
path = sys.argv[1]
d = json.load(open(path))
d["nodes"][1]["scale"] = [3.0, 1.0, 1.0]
json.dump(d, open(path + ".tmp", "w"))
os.replace(path + ".tmp", path)
PY
wait $master || { echo "master_station failed"; cat "$out/master.log"; exit 1; }
wait $slave || true
cat "$out/slave.log" | grep -E "rebuil|switched" || true
grep -q "scene updated" "$out/master.log" || { echo "the operator got no new scene version"; cat "$out/master.log"; exit 1; }
/usr/bin/python3 - "$out/m/summary.json" "$out/s/remote_summary.json" <<'PY'
import json, sys
m = json.load(open(sys.argv[1]))
r = json.load(open(sys.argv[2]))
assert r["scene_file"]["reloads"] == 1 and r["scene_file"]["builds_failed"] == 0, r["scene_file"]
assert r["transport"]["scene"]["reloads_switched"] == 1, r["transport"]["scene"]
assert r["transport"]["scene"]["reload_bytes_queued"] > 0
sc = m["transport"]["scene"]
assert sc["versions_published"] >= 2, sc
graph = [o for o in sc["decoded"] if o.get("kind") == "scene_graph"]
assert graph and graph[0]["version"] == 2, f"the operator holds graph version 2: {graph}"
d = m["display"]
assert d["scene_versions_shown"] >= 2 and not d["error"], d
assert m["nonfinite_count"] == 0
print(f'scene reload: change to ready {r["scene_file"]["last_change_to_ready_s"]:.2f} s '
      f'(build {r["scene_file"]["last_build_s"]:.2f} s), '
      f'{r["transport"]["scene"]["reload_bytes_queued"]} bytes streamed')
PY
echo "scene reload loopback: ok"
