#!/bin/bash
# The twenty-third stop's lockstep tables (docs/deadband.md, "the deadband on one clock";
# docs/passivity/README.md, "The pulse train under delay"). Deterministic: the same binary gives the same
# figures on any machine. About 15 minutes on one core.
# Usage: docs/deadband/twenty_third_stop/run.sh OUT_DIR [BUILD_DIR]
set -euo pipefail
out=${1:?usage: run.sh OUT_DIR [BUILD_DIR]}
build=${2:-build}
repo=$(cd "$(dirname "$0")/../../.." && pwd)
B=$build/benchmarks/deadband_lockstep
mkdir -p "$out"
kin=$out/kinesthetic.csv
"$repo/deploy/kinesthetic-replay" "$repo/../shared/data/kinesthetic/wam_leader_fm_reach_dc_1" --out "$kin" >/dev/null
FO="torque_floor=100,stiffness_floor=2e6,rotational_stiffness_floor=2000"
ARMS=(--arm d5:deadband=5 --arm d10:deadband=10 --arm d15:deadband=15 --arm d20:deadband=20
      --arm "fo10:deadband=10,$FO" --arm "t10_m20:tool_deadband=10,model_deadband=20"
      --arm "t20_m10:tool_deadband=20,model_deadband=10" --arm "fo5:deadband=5,$FO"
      --arm "t10_fo5:tool_deadband=10,model_deadband=5,$FO"
      --arm "t10_fo7:tool_deadband=10,model_deadband=7,$FO" --arm "fo7:deadband=7,$FO")
for inp in fig75 kinesthetic; do
  X=(); [ $inp = kinesthetic ] && X=(--replay "$kin")
  "$B" "${X[@]}" --seeds 4 "${ARMS[@]}" --out "$out/deadband_$inp" > "$out/deadband_$inp.md"
done
# The passivity grid on one clock: the default (energy-bounded onsets, 20 ms release) against
# both off. (docs/passivity/twenty_third_stop/passivity_*.md were made with commit 36ff2f2's
# build, whose energy-bounded switch bounded every switch; its arms there are the forms measured
# on the way.)
P=(--arm "before:deadband=10,energy_bounded_switch=0,release_ticks=0" --arm default:deadband=10)
for c in "25 0" "75 0" "150 0" "25 10" "75 10" "150 10" "150 20"; do
  set -- $c
  for inp in fig75 kinesthetic; do
    X=(); [ $inp = kinesthetic ] && X=(--replay "$kin")
    echo "## $inp, $1 ms one way, $2 % loss" >> "$out/passivity_$inp.md"
    "$B" "${X[@]}" --seeds 3 --delay-ms "$1" --loss-pct "$2" --reference-delay-ms 0.1 "${P[@]}" \
      --out "$out/passivity_${inp}_$1_$2" >> "$out/passivity_$inp.md"
  done
done
for c in "50 10" "150 10"; do
  set -- $c
  echo "## stiff wall, $1 ms one way, $2 % loss" >> "$out/passivity_wall.md"
  "$B" --scene stiff-wall --seeds 3 --delay-ms "$1" --loss-pct "$2" --reference-delay-ms 0.1 \
    "${P[@]}" --out "$out/passivity_wall_$1_$2" >> "$out/passivity_wall.md"
done
