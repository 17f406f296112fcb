#!/bin/bash
# Usage: OUT=DIR bash scrape_run.sh (about 12 minutes; OUT must exist)
set -e
cd "$(git rev-parse --show-toplevel)"
deploy/run-loopback --out ${OUT:-/tmp/s29}/l77 --scene file-on-cad-part --experiment fig77 --duration 10 --display none --no-report --pd-backend cpu > ${OUT:-/tmp/s29}/l77.log 2>&1
for T in 3.0 5.5 7.5; do
  build/slave_sim/speed_error_frontier --out ${OUT:-/tmp/s29}/st_$T --no-gpu --no-model-prediction --scene fig77 --on-product-models \
    --trace fig77=${OUT:-/tmp/s29}/l77/trace.csv --trace-from $T --poses 500 --threads 1 \
    --setting default --setting no_parallax > ${OUT:-/tmp/s29}/st_$T.log 2>&1
done
echo done
