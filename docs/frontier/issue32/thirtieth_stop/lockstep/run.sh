#!/usr/bin/env bash
# Issue 32's thirtieth stop: the continuous split in the closed loop on one clock, against the
# default, on the four scenes (one seed; deadbands at the product's default and, on fig76, off).
# Usage: run.sh OUT_DIR   (from the repository root, after a Release build in build/)
set -euo pipefail
out=${1:?usage: run.sh OUT_DIR}
B=build/benchmarks/deadband_lockstep
mkdir -p "$out"
arms=(--arm default --arm c50:setting=split_continuous_50um --arm c100:setting=split_continuous_100um)
"$B" --scene striped-blocks --seeds 1 --duration 12 "${arms[@]}" --out "$out/fig76" > "$out/fig76.md"
"$B" --scene striped-blocks --seeds 1 --duration 12 --arm default:deadband=0 \
  --arm old_split:setting=split_windows_at_separated_overlap_link10mm,deadband=0 \
  --arm ramp:setting=split_link10mm_ramp50um,deadband=0 \
  --arm parent_step:setting=split_link10mm_ramp50um_parent_step,deadband=0 \
  --arm bridge:setting=split_link10mm_ramp50um_parent_step_bridge50um,deadband=0 \
  --arm c50:setting=split_continuous_50um,deadband=0 --arm c100:setting=split_continuous_100um,deadband=0 \
  --out "$out/fig76_nodb" > "$out/fig76_nodb.md"
"$B" --scene block-on-gear --seeds 1 --duration 5 "${arms[@]}" --out "$out/fig75" > "$out/fig75.md"
"$B" --scene file-on-cad-part --seeds 1 --duration 5 "${arms[@]}" --out "$out/fig77" > "$out/fig77.md"
"$B" --scene hammer-on-torus --seeds 1 --duration 5 "${arms[@]}" --out "$out/hammer" > "$out/hammer.md"
