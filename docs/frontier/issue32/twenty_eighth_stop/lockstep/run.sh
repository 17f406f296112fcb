#!/bin/sh
# Issue 32, twenty-eighth stop: parallax (the default now) against the render's form (no_parallax)
# in the closed loop on one clock (deadband_lockstep, deadbands off, one seed).
# Usage: lockstep.sh OUT_DIR [BUILD_DIR]; OUT_DIR/SCENE.md are the tables, OUT_DIR/SCENE/ the traces.
B=${2:-build}
for sc in block-on-gear striped-blocks file-on-cad-part hammer-on-torus; do
  d=5; [ $sc = striped-blocks ] && d=12
  mkdir -p $1/$sc
  $B/benchmarks/deadband_lockstep --scene $sc --duration $d --seeds 1 \
    --arm default:deadband=0 \
    --arm no_parallax:deadband=0,setting=no_parallax \
    --out $1/$sc > $1/$sc.md 2>&1
done
