#!/usr/bin/env bash
# Issue 32's thirty-first stop: the continuous split's fade width in the closed loop on one clock
# (fig76, striped blocks turned in contact, 12 s, one seed), both deadbands off and at the
# product's 10 %. "default" is the default before this stop (the setting no_split since).
# Usage: run.sh OUT_DIR   (from the repository root, after a Release build)
set -euo pipefail
out=${1:?usage: run.sh OUT_DIR}
B="build/benchmarks/deadband_lockstep --reference-setting no_split"
mkdir -p "$out"
$B --scene striped-blocks --seeds 1 --duration 12 --arm default:setting=no_split,deadband=0 \
  --arm c100:setting=split_continuous_100um,deadband=0 --arm c200:setting=split_continuous_200um,deadband=0 \
  --arm c400:setting=split_continuous_400um,deadband=0 --out "$out/nodb" > "$out/fig76_nodb_fades.md"
$B --scene striped-blocks --seeds 1 --duration 12 --arm default:setting=no_split \
  --arm c100:setting=split_continuous_100um --arm c200:setting=split_continuous_200um \
  --arm c400:setting=split_continuous_400um --out "$out/db" > "$out/fig76_deadbands_fades.md"
F=docs/frontier/issue32/twenty_sixth_stop/lockstep/force_steps.py
specs=()
for d in nodb db; do for a in default c100 c200 c400; do specs+=("$out/$d/$a.csv=${a}_$d"); done; done
/usr/bin/python3 "$F" "$out/fig76_fades.png" "${specs[@]}" > "$out/fig76_force_steps.txt"
# The other scenes, deadbands at the product's 10 % (5 s): the unsplit window against the split.
for sc in hammer-on-torus block-on-gear file-on-cad-part; do
  $B --scene "$sc" --seeds 1 --duration 5 --arm default:setting=no_split \
    --arm c400:setting=split_continuous_400um --out "$out/$sc" > "$out/${sc}_deadbands.md"
done
