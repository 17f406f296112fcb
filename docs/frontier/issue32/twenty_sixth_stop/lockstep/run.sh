#!/bin/sh
# Issue 32, twenty-sixth stop: the kink planes' other arm hung by the arms' gap
# (kink_hang_other_arm) against the default (through its own sample), with and without parallax,
# in the closed loop on one clock (deadband_lockstep, deadbands off, three seeds).
# Usage: run.sh OUT_DIR [BUILD_DIR]; OUT_DIR/SCENE.md are the tables, OUT_DIR/SCENE/ the traces.
B=${2:-build}
for sc in block-on-gear striped-blocks file-on-cad-part hammer-on-torus; do
  d=5; [ $sc = striped-blocks ] && d=12
  mkdir -p $1/$sc
  $B/benchmarks/deadband_lockstep --scene $sc --duration $d --seeds 3 \
    --arm default:deadband=0 \
    --arm hung:deadband=0,setting=kink_hang_other_arm \
    --arm parallax:deadband=0,setting=parallax \
    --arm parallax_hung:deadband=0,setting=parallax_kink_hang_other_arm \
    --out $1/$sc > $1/$sc.md 2>&1
done
