#!/bin/bash
# BEFORE=<a build of 556f0f9> bash remote_step_timing.sh (about 6 minutes)
cd "$(git rev-parse --show-toplevel)"
for round in 1 2; do
  for b in ${BEFORE:-/tmp/wt556/build} build; do
    echo "== round $round $b"
    $b/benchmarks/remote_step_benchmark --scenes fig75,fig76,fig77,hammer_torus --poses 40 --repeats 3 2>&1 | grep -E "^(fig7|hammer)|evaluations"
  done
done
echo "== HEAD --ab parallax"
build/benchmarks/remote_step_benchmark --scenes fig75,fig76,fig77,hammer_torus --poses 40 --repeats 3 --ab parallax 2>&1 | grep -E "^(fig7|hammer)|evaluations"
