#!/usr/bin/env bash
# Builds the haptic models of scenes into a model cache, so that the runs through both processes
# (which run one at a time) start from the cache instead of building them (up to a minute a scene
# when cold); this runs beside other tests. A built-in scene's node is started and stopped once
# its port file appears (slave_sim writes it only after the scene is built); a scene file goes
# through `slave_sim inspect`, and one that is absent (the team's ../shared/data is not here) is
# skipped.
# Usage: tests/prebuild_scene_models.sh BUILD_DIR CACHE_DIR OUT_DIR SCENE...
set -euo pipefail
build="${1:?build dir}"; cache="${2:?cache dir}"; out="${3:?out dir}"; shift 3
slave="$build/slave_sim/slave_sim"
rm -rf "$out"; mkdir -p "$out"
"$slave" keygen "$out/psk.key" > /dev/null
for scene in "$@"; do
  case "$scene" in
    */*|*.gltf|*.glb|*.json)
      if [ ! -f "$scene" ]; then echo "prebuild: $scene absent: nothing built"; continue; fi
      "$slave" inspect "$scene" --cache-dir "$cache" --quiet > /dev/null
      echo "prebuild: $scene built into $cache"
      continue ;;
  esac
  port_file="$out/$scene.port"
  "$slave" --listen 127.0.0.1:0 --port-file "$port_file" --key "$out/psk.key" --quiet \
    --pd-backend cpu --scene "$scene" --cache-dir "$cache" > "$out/$scene.log" 2>&1 &
  pid=$!
  for _ in $(seq 1 3000); do
    [ -s "$port_file" ] && break
    kill -0 "$pid" 2>/dev/null || break
    sleep 0.1
  done
  kill "$pid" 2>/dev/null || true
  wait "$pid" 2>/dev/null || true
  if [ ! -s "$port_file" ]; then
    echo "prebuild: $scene: the node did not start"; cat "$out/$scene.log"; exit 1
  fi
  echo "prebuild: $scene built into $cache"
done
echo "prebuild: ok"
