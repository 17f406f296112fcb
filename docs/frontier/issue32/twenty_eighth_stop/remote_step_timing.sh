#!/bin/sh
# The remote step with parallax (the default now) and without (--no-parallax), alternated, one binary.
B=${B:-build/benchmarks/remote_step_benchmark}
for round in 1 2; do
  for flag in "" --no-parallax; do
    echo "== round $round ${flag:-default (parallax)}"; $B --scenes fig75,fig76,fig77,hammer_torus --poses 40 --repeats 3 $flag 2>&1 | grep -E "^(scene|fig7|hammer)|evaluations"
  done
done
