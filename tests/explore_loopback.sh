#!/usr/bin/env bash
# The explore experiment on a real scene file, both processes through deploy/run-loopback, then
# the trace checks of explore_trace_test.
# Usage: explore_loopback.sh SOURCE_DIR BUILD_DIR SCENE_FILE OUT_DIR DURATION_S
# (exit 77 = skipped: the team's ../shared/data is not here)
set -euo pipefail
src=$1 build=$2 scene=$3 out=$4 duration=$5
if [ ! -f "$scene" ]; then
  echo "skipped: $scene not found (the team's ../shared/data is not here)"
  exit 77
fi
rm -rf "$out" && mkdir -p "$out"
"$src/deploy/run-loopback" --build-dir "$build" --scene "$scene" --experiment explore \
  --duration "$duration" --out "$out" --slave-args "--cache-dir $build/explore_model_cache --quiet" \
  --master-args --quiet
HT_LOOPBACK_OUT="$out" "$build/tests/explore_trace_test"
