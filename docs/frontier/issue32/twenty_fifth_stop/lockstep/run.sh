#!/bin/sh
# Issue 32, twenty-fifth stop: the last step's seeds and parallax in the closed loop on one clock
# (deadband_lockstep, deadbands off, one seed), against the remote step without the seeds.
# Usage: run.sh OUT_DIR [BUILD_DIR]. The tables here were made before the seeds became the
# default, with the reference at the then default and the arms named by the settings of that
# build (last_step_seeds, parallax, parallax_last_step_seeds); with today's names that is:
B=${2:-build}
for sc in block-on-gear striped-blocks file-on-cad-part hammer-on-torus; do
  d=5; [ $sc = striped-blocks ] && d=12
  $B/benchmarks/deadband_lockstep --scene $sc --duration $d --seeds 1 \
    --reference-setting no_last_step_seeds \
    --arm seeds:deadband=0,setting=default \
    --arm parallax:deadband=0,setting=parallax_no_last_step_seeds \
    --arm parallax_seeds:deadband=0,setting=parallax \
    --arm reference_again:deadband=0 > $1/$sc.md 2>&1
done
