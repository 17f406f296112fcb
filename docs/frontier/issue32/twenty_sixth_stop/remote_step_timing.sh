#!/bin/sh
# The remote step before (95bdf74) and after (this stop's HEAD), alternated, default and parallax.
OLD=${OLD:-/tmp/s26/wt/build/benchmarks/remote_step_benchmark}  # a build of 95bdf74 (git worktree)
NEW=${NEW:-build/benchmarks/remote_step_benchmark}
for round in 1 2; do
  for b in OLD NEW; do
    eval bin=\$$b
    echo "== round $round $b default"; $bin --scenes fig75,fig76,fig77,hammer_torus --poses 40 --repeats 5 2>&1 | grep -E "^(scene|fig7|hammer)|evaluations" 
  done
done
for b in OLD NEW; do
  eval bin=\$$b
  echo "== $b parallax"; $bin --scenes fig75,fig76,fig77,hammer_torus --poses 40 --repeats 5 --parallax 2>&1 | grep -E "^(scene|fig7|hammer)|evaluations"
done
