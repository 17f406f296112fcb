#!/usr/bin/env bash
# examples/custom_device against a remote node: slave_sim (block on gear) on 127.0.0.1, the
# example's device in the operator station for 3 s; the device must feel the contact (the
# example exits 1 otherwise) and the run must leave its trace.
# Usage: tests/example_custom_device_test.sh BUILD_DIR OUT_DIR
set -euo pipefail
build="${1:?build dir}"; out="${2:?out dir}"
rm -rf "$out"; mkdir -p "$out"
"$build/slave_sim/slave_sim" keygen "$out/psk.key" > /dev/null
"$build/slave_sim/slave_sim" --listen 127.0.0.1:0 --port-file "$out/slave.port" \
  --key "$out/psk.key" --pd-backend cpu --quiet > "$out/slave.log" 2>&1 &
slave=$!
trap 'kill "$slave" 2>/dev/null || true' EXIT
for _ in $(seq 1 1200); do
  [ -s "$out/slave.port" ] && break
  kill -0 "$slave" 2>/dev/null || { echo "slave_sim did not start:"; cat "$out/slave.log"; exit 1; }
  sleep 0.05
done
"$build/examples/custom_device/custom_device" "127.0.0.1:$(cat "$out/slave.port")" \
  "$out/psk.key" 3 "$out"
[ -s "$out/trace.csv" ] || { echo "no $out/trace.csv"; exit 1; }
# The station said goodbye: slave_sim ends its session and exits.
for _ in $(seq 1 100); do kill -0 "$slave" 2>/dev/null || break; sleep 0.05; done
echo "example_custom_device: ok ($(($(wc -l < "$out/trace.csv") - 1)) trace rows)"
