#!/usr/bin/env bash
# Installed as users expect (issue 16): `cmake --install` into a fresh prefix, then a project
# outside the tree (examples/contact_force) finds the haptic core with find_package and runs a
# remote step with it; and `cpack -G DEB` makes a Debian package holding the binaries, units and
# rules.
# Usage: tests/install_consumer_test.sh SOURCE_DIR BUILD_DIR OUT_DIR
set -euo pipefail
src="${1:?source dir}"; build="${2:?build dir}"; out="${3:?out dir}"
rm -rf "$out"; mkdir -p "$out"
cmake --install "$build" --prefix "$out/prefix" > "$out/install.log"
for f in bin/slave_sim bin/master_station bin/ht_relay bin/speed_error_frontier \
         lib/libhaptic_core.a lib/libhaptic_demo_models.a include/haptic_core/remote_step.h \
         include/haptic_core/demo/demo_scenes.h \
         lib/cmake/haptic_teleop/haptic_teleopConfig.cmake \
         lib/systemd/system/haptic-slave-sim.service lib/udev/rules.d/70-haptic-falcon.rules \
         share/haptic_teleop/config/remote.toml; do
  [ -e "$out/prefix/$f" ] || { echo "install: $f missing"; exit 1; }
done
"$out/prefix/bin/slave_sim" --help > /dev/null
# The installed units (issue 35): ExecStart names the installed binaries (not /usr/local/bin),
# and systemd-analyze finds nothing to say about them: no unknown key, no missing executable.
for unit in haptic-slave-sim haptic-master-station; do
  file="$out/prefix/lib/systemd/system/$unit.service"
  grep -q "^ExecStart=$out/prefix/bin/" "$file" || {
    echo "install: $unit.service does not start $out/prefix/bin/..."; grep ExecStart "$file"; exit 1; }
  if command -v systemd-analyze > /dev/null; then
    said="$(systemd-analyze verify "$file" 2>&1)" || { echo "$said"; exit 1; }
    [ -z "$said" ] || { echo "systemd-analyze verify $unit.service: $said"; exit 1; }
  else
    echo "install_consumer_test: systemd-analyze not found; unit files not verified"
  fi
done
# examples/contact_force: built against the prefix, run at the default pose and at a given one
# (it exits 1 when the block is not pushed up).
cmake -S "$src/examples/contact_force" -B "$out/consumer" \
  -DCMAKE_PREFIX_PATH="$out/prefix" > "$out/consumer.log"
cmake --build "$out/consumer" -j2 >> "$out/consumer.log"
"$out/consumer/contact_force"
"$out/consumer/contact_force" 0.3 1.5 10
( cd "$build" && cpack -G DEB -B "$out/deb" > "$out/cpack.log" 2>&1 ) || { tail "$out/cpack.log"; exit 1; }
deb="$(ls "$out"/deb/haptic-teleop_*.deb)"
contents="$(dpkg-deb -c "$deb")"
for f in ./usr/bin/slave_sim ./usr/bin/master_station ./usr/lib/systemd/system/haptic-slave-sim.service \
         ./usr/lib/udev/rules.d/70-haptic-spacemouse.rules; do
  grep -qF "$f" <<< "$contents" || { echo "deb: $f missing"; exit 1; }
done
echo "install_consumer_test: installed, consumed through find_package, packaged as $(basename "$deb")"
