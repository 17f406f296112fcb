#!/bin/bash
# The twenty-fourth stop's lockstep tables (docs/deadband.md, "the deadband on fig76, and the
# depth criterion on one clock"; docs/frontier/issue32/README.md, "the split in the loop on one
# clock"). Deterministic: the same binary gives the same figures. About 20 minutes on one core
# (the striped-blocks models are built once into the model cache, a few minutes more the first
# time).
# Usage: docs/deadband/twenty_fourth_stop/run.sh OUT_DIR [BUILD_DIR]
set -euo pipefail
out=${1:?usage: run.sh OUT_DIR [BUILD_DIR]}
build=${2:-build}
repo=$(cd "$(dirname "$0")/../../.." && pwd)
B=$build/benchmarks/deadband_lockstep
mkdir -p "$out"
kin=$out/kinesthetic.csv
"$repo/deploy/kinesthetic-replay" "$repo/../shared/data/kinesthetic/wam_leader_fm_reach_dc_1" --out "$kin" >/dev/null
# fig76 (striped blocks, 12 s): which stream's deadband, and the depth criterion, one seed.
"$B" --scene striped-blocks --seeds 1 --duration 12 --arm default --arm tool_only:model_deadband=0 \
  --arm model_only:tool_deadband=0 --arm rot_floor_0.2mrad:contact_floor_mrad=2 \
  --arm pos_floor_10um:contact_floor_mm=0.1 --arm depth5:contact_depth_floor_um=5 \
  --arm depth50:contact_depth_floor_um=50 --arm depth100:contact_depth_floor_um=100 \
  --out "$out/fig76_streams" > "$out/fig76_streams.md"
# fig76 with seeds that do move it. A start 1 um along x changes nothing; 5 um along y moves
# the deadband's runs but is not the loopback's noise: with it the depth criterion and a 0.5 mrad
# rotation floor look like cures, which the loopback did not confirm.
"$B" --scene striped-blocks --seeds 5 --seed-axis y --seed-step-um 5 --duration 12 \
  --arm default --arm depth5:contact_depth_floor_um=5 --arm rot0.5:contact_floor_mrad=5 \
  --arm rot1:contact_floor_mrad=10 --out "$out/fig76_seeds_y" > "$out/fig76_seeds_y.md"
# ... and each datagram's delay jittered by up to 0.5 ms (seed k: generator k), which agrees with
# the loopback's runs: the course kept without the deadband, lost with it, kept by a 0.2 mrad
# contact rotation floor.
"$B" --scene striped-blocks --seeds 5 --jitter-ms 0.5 --duration 12 --arm default \
  --arm model_only:tool_deadband=0 --arm tool5:tool_deadband=5 \
  --arm depth5:contact_depth_floor_um=5 --arm rot0.5:contact_floor_mrad=5 \
  --arm rot0.2:contact_floor_mrad=2 --out "$out/fig76_jitter" > "$out/fig76_jitter.md"
# What the 0.2 and 0.5 mrad contact rotation floors cost on fig75 and the recorded motion.
R=(--arm default --arm rot0.5:contact_floor_mrad=5 --arm rot0.2:contact_floor_mrad=2)
"$B" --seeds 3 "${R[@]}" --out "$out/rot_fig75" > "$out/rot_fig75.md"
"$B" --seeds 3 --replay "$kin" "${R[@]}" --out "$out/rot_kinesthetic" > "$out/rot_kinesthetic.md"
# The depth criterion's floor on fig75, the recorded motion and the stiff wall (3 seeds).
D=(--arm default)
for d in 5 20 50 100 200; do D+=(--arm "depth$d:contact_depth_floor_um=$d"); done
"$B" --seeds 3 "${D[@]}" --out "$out/depth_fig75" > "$out/depth_fig75.md"
"$B" --seeds 3 --replay "$kin" "${D[@]}" --out "$out/depth_kinesthetic" > "$out/depth_kinesthetic.md"
"$B" --seeds 3 --scene stiff-wall "${D[@]}" --out "$out/depth_wall" > "$out/depth_wall.md"
# ... and under delay on the gear (judged against the undelayed reference).
for dl in 75 150; do
  "$B" --seeds 2 --delay-ms $dl --reference-delay-ms 0.1 --arm default \
    --arm depth5:contact_depth_floor_um=5 --out "$out/depth_gear_$dl" > "$out/depth_gear_$dl.md"
done
# Issue 32's candidate settings in the loop on fig76 and fig75: the split with the texel slope,
# the split alone, with and without the deadbands (2 seeds, 1 um along x).
S=(--arm default --arm default_nodb:deadband=0
   --arm split_texel:setting=split_windows_texel_gradient_link10mm
   --arm split_texel_nodb:setting=split_windows_texel_gradient_link10mm,deadband=0
   --arm split:setting=split_windows_at_separated_overlap_link10mm
   --arm split_nodb:setting=split_windows_at_separated_overlap_link10mm,deadband=0
   --arm texel_translation:setting=refined_texel_translation_gradient
   --arm texel_translation_nodb:setting=refined_texel_translation_gradient,deadband=0)
"$B" --scene striped-blocks --seeds 2 --duration 12 "${S[@]}" --out "$out/split_fig76" > "$out/split_fig76.md"
"$B" --seeds 2 "${S[@]}" --out "$out/split_fig75" > "$out/split_fig75.md"
# The texel translation slope on fig75 with the loopback's timing noise (three seeds, 0.5 ms
# jitter), with and without the deadbands and with a 5 um contact position floor.
T=refined_texel_translation_gradient
"$B" --seeds 3 --jitter-ms 0.5 --arm default --arm default_nodb:deadband=0 --arm tex:setting=$T \
  --arm tex_nodb:setting=$T,deadband=0 --arm tex_floor5um:setting=$T,contact_floor_mm=0.05 \
  --out "$out/texel_fig75_jitter" > "$out/texel_fig75_jitter.md"
# fig76's two courses (course.png): the reference, the default and the 0.2 mrad floor, seed 0.
/usr/bin/python3 "$repo/docs/deadband/twenty_fourth_stop/course_plot.py" "$out/course.png" \
  "$out/fig76_jitter/reference.csv" "$out/fig76_jitter/default.csv" "$out/fig76_jitter/rot0.2.csv"
