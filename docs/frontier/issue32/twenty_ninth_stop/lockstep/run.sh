#!/bin/bash
# Usage: OUT=DIR bash run.sh (about 4 minutes; OUT must exist)
cd "$(git rev-parse --show-toplevel)"
for sc in hammer-on-torus file-on-cad-part; do
  build/benchmarks/deadband_lockstep --scene $sc --duration 5 --seeds 1 --arm default:deadband=0 --arm follow:deadband=0,setting=tool_leaves_follow --out ${OUT:-/tmp/s29}/lock_$sc > ${OUT:-/tmp/s29}/lock_$sc.log 2>&1
done
echo done
