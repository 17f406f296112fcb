#!/usr/bin/env bash
# The device's up is the scene's up (issue 33), on a Y-up glTF scene whose tool node has no
# rotation, then one whose tool node is turned 90° about X: the explore experiment presses the
# plate's top, and a replayed hand lowered along the device's −z presses the tool onto that top.
# Usage: device_up_loopback.sh SOURCE_DIR BUILD_DIR OUT_DIR
set -euo pipefail
src=$1 build=$2 out=$3
rm -rf "$out" && mkdir -p "$out"
printf 't_s,x,y,z\n0,0,0,0\n1,0,0,0\n3,0,0,-0.0104\n100,0,0,-0.0104\n' > "$out/lower.csv"
for angle in 0 90; do
  python3 "$src/tests/make_plate_scene.py" "$out/scene$angle" --tool-rotation-deg "$angle"
  "$src/deploy/run-loopback" --build-dir "$build" --scene "$out/scene$angle/plate.json" \
    --experiment explore --duration 6 --display none --no-report --out "$out/explore$angle" \
    --slave-args --quiet --master-args --quiet
  python3 "$src/tests/device_up_check.py" "$out/explore$angle" "explore, tool node turned $angle°"
  "$src/deploy/run-loopback" --build-dir "$build" --scene "$out/scene$angle/plate.json" \
    --duration 4 --display none --no-report --out "$out/replay$angle" --slave-args --quiet \
    --master-args "--device replay --replay $out/lower.csv --quiet"
  python3 "$src/tests/device_up_check.py" "$out/replay$angle" "replay lowered, tool node turned $angle°"
done
echo "device up loopback: ok"
