#!/bin/sh
# As run for the search fix's before/after (docs/frontier/issue32/twenty_sixth_stop/README.md),
# with the names of those builds (the working tree of commit f29b2f7, its first form, built
# without the search fix for *_before.md and with it for *_after.md; in today's build the settings
# kink_bearing_by_deepest_cell and parallax_kink_bearing_by_deepest_cell are `default` and
# `parallax`, and the first form's arm_gap arms are gone).
# Issue 32, twenty-sixth stop: the kink's bearing arm by the arms' gap (default) against the
# deepest cell (the form before), with and without parallax, in the closed loop on one clock
# (deadband_lockstep, deadbands off, one seed). Usage: run.sh OUT_DIR [BUILD_DIR].
B=${2:-build}
for sc in block-on-gear striped-blocks file-on-cad-part hammer-on-torus; do
  d=5; [ $sc = striped-blocks ] && d=12
  mkdir -p $1/$sc
  $B/benchmarks/deadband_lockstep --scene $sc --duration $d --seeds 1 \
    --reference-setting kink_bearing_by_deepest_cell \
    --arm deepest_cell:deadband=0,setting=kink_bearing_by_deepest_cell \
    --arm arm_gap:deadband=0,setting=default \
    --arm parallax_deepest_cell:deadband=0,setting=parallax_kink_bearing_by_deepest_cell \
    --arm parallax_arm_gap:deadband=0,setting=parallax \
    --out $1/$sc > $1/$sc.md 2>&1
done
