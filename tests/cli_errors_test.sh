#!/usr/bin/env bash
# Command-line errors: every program answers a bad argument with one line
# "program: error: ..." on stderr and exit status 2, before it starts anything; a missing key file
# says how to make one. Usage: tests/cli_errors_test.sh SOURCE_DIR BUILD_DIR
set -uo pipefail
src="${1:?source dir}"; build="${2:?build dir}"
tmp="$(mktemp -d)"; trap 'rm -rf "$tmp"' EXIT
fail=0
# expect NAME EXPECTED_SUBSTRING COMMAND...
expect() {
  local name="$1" want="$2"; shift 2
  "$@" > "$tmp/out" 2> "$tmp/err"; local rc=$?
  local lines; lines=$(grep -c '' "$tmp/err")
  if [ "$rc" -ne 2 ] || [ "$lines" -ne 1 ] || ! grep -q "^$name: error: " "$tmp/err" ||
     ! grep -qF -- "$want" "$tmp/err"; then
    echo "FAIL: $* -> exit $rc, $lines line(s) on stderr (want 2, 1 line '$name: error: ...$want...'):"
    cat "$tmp/err"; fail=1
  else
    echo "ok: $* -> $(cat "$tmp/err")"
  fi
}
expect slave_sim "--grid" "$build/slave_sim/slave_sim" --grid 0
expect slave_sim "--speculative-lead-ms" "$build/slave_sim/slave_sim" --speculative-lead-ms -1
"$build/slave_sim/slave_sim" keygen "$tmp/k.key" > /dev/null 2>&1
expect slave_sim "--model-deadband-torque-floor" "$build/slave_sim/slave_sim" --model-deadband-torque-floor 0
expect slave_sim "keygen" "$build/slave_sim/slave_sim" --key "$tmp/no_such.key"
expect master_station "keygen" "$build/master_station/master_station" --key "$tmp/no_such.key"
expect master_station "--rate" "$build/master_station/master_station" --rate 5
expect ht_relay "--listen" "$build/transport/ht_relay" --listen
expect speed_error_frontier "--poses" "$build/slave_sim/speed_error_frontier" --poses 0
# run-loopback checks its own numbers before it starts slave_sim (no slave.log is written).
expect run-loopback "--duration" "$src/deploy/run-loopback" --build-dir "$build" --out "$tmp/lb" --duration abc
[ ! -e "$tmp/lb/slave.log" ] || { echo "FAIL: run-loopback started slave_sim before checking --duration"; fail=1; }
expect run-loopback "--experiment" "$src/deploy/run-loopback" --build-dir "$build" --out "$tmp/lb" --experiment nope
# A bad --impair SPEC is refused before the remote node starts (ht_relay --check).
expect run-loopback "--impair: impairment spec" "$src/deploy/run-loopback" --build-dir "$build" --out "$tmp/imp" --impair "delay=5,lossy=3%"
[ ! -e "$tmp/imp/slave.log" ] || { echo "FAIL: run-loopback started slave_sim before checking --impair"; fail=1; }
# An option run-loopback sets itself, given again in --master-args / --slave-args: which of its own
# options to use instead, before anything starts.
expect run-loopback "use run-loopback --duration" "$src/deploy/run-loopback" --build-dir "$build" --out "$tmp/dup" --master-args "--quiet --duration 3"
expect run-loopback "use run-loopback --scene" "$src/deploy/run-loopback" --build-dir "$build" --out "$tmp/dup" --slave-args "--scene=stiff-wall"
[ ! -e "$tmp/dup/slave.log" ] || { echo "FAIL: run-loopback started slave_sim before checking --master-args"; fail=1; }
# A --config file's misspelt key is refused, the known keys listed (a scene description does so).
printf 'grdi = 50\n' > "$tmp/typo.toml"
expect slave_sim "unknown key 'grdi' (known: " "$build/slave_sim/slave_sim" --config "$tmp/typo.toml"
grep -q "known: .*, grid, " "$tmp/err" || { echo "FAIL: the known keys do not list grid"; fail=1; }
printf 'duration = 3\nexperimnet = "fig75"\n' > "$tmp/typo.toml"
expect master_station "unknown key 'experimnet'" "$build/master_station/master_station" --config "$tmp/typo.toml"
grep -q "known: .*, passivity-refill-pct, " "$tmp/err" ||
  { echo "FAIL: the known keys do not list the Advanced group's passivity-refill-pct"; fail=1; }
# The Advanced group's options are --config keys as the main group's: their values reach the
# program (its range checks refuse them).
printf 'max-speculative-floor-mm = 1000\n' > "$tmp/adv.toml"
expect slave_sim "--max-speculative-floor-mm" "$build/slave_sim/slave_sim" --config "$tmp/adv.toml"
printf 'passivity-refill-pct = 100\n' > "$tmp/adv.toml"
expect master_station "--passivity-refill-pct" "$build/master_station/master_station" --config "$tmp/adv.toml"
# The shipped configurations name only known keys. They cannot be run here (CLI11 checks each key's
# value as it reads it, so their absent key file would hide the keys after it; with the key the
# remote node would start), so each key, and each commented-out "# key = value", is looked up in
# the known keys the program lists when it refuses an unknown one.
printf 'no_such_key = 1\n' > "$tmp/unknown.toml"
for config in operator:master_station remote:slave_sim; do
  name="${config%%:*}"; program="${config#*:}"; file="$src/deploy/config/$name.toml"
  "$build/$program/$program" --config "$tmp/unknown.toml" > /dev/null 2> "$tmp/err"
  known="$(sed -n 's/.*unknown key .no_such_key. (known: \([^)]*\)).*/\1/p' "$tmp/err")"
  if [ -z "$known" ]; then
    echo "FAIL: $program did not list its known keys:"; cat "$tmp/err"; fail=1; continue
  fi
  read -ra keys <<< "$(sed -n 's/^#\{0,1\} *\([a-z][a-z0-9-]*\) *= .*/\1/p' "$file" | tr '\n' ' ')"
  unknown=0
  [ "${#keys[@]}" -ge 10 ] || { echo "FAIL: $file: only ${#keys[@]} key(s) found"; unknown=1; }
  for key in "${keys[@]}"; do
    case ", $known, " in
      *", $key, "*) ;;
      *) echo "FAIL: $file: unknown key '$key' (known: $known)"; unknown=1 ;;
    esac
  done
  if [ "$unknown" -eq 0 ]; then echo "ok: $file: ${#keys[@]} keys, all known to $program"; fi
  [ "$unknown" -eq 0 ] || fail=1
done
exit $fail
