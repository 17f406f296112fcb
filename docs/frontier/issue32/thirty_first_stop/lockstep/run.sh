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
# The fade in proportion to the region's depth (split_fade_per_depth<C>x), against the unsplit
# window ("default" here is no_split), fig76 without and with the deadbands.
$B --scene striped-blocks --seeds 1 --duration 12 --arm default:deadband=0 \
  --arm r15:setting=split_fade_per_depth1.5x,deadband=0 --arm r2:setting=split_fade_per_depth2x,deadband=0 \
  --arm r3:setting=split_fade_per_depth3x,deadband=0 --out "$out/rel_nodb" > "$out/fig76_nodb_fade_per_depth.md"
$B --scene striped-blocks --seeds 1 --duration 12 --arm default --arm r15:setting=split_fade_per_depth1.5x \
  --arm r2:setting=split_fade_per_depth2x --arm r3:setting=split_fade_per_depth3x --out "$out/rel_db" \
  > "$out/fig76_deadbands_fade_per_depth.md"
