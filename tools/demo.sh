#!/usr/bin/env bash
# The main job: install what is missing, build, start contourd on the built-in simulated machine
# (config/sim.yaml: Table 1 drives, one cycle of CANopen transport delay, lockstep), home it,
# run the paper's Table 2 part program (config/programs/table2.ngc, 4 m/min) with contourctl —
# coupled (cross-coupled controller) and then uncoupled, each from the same start point (a rapid
# to the program's origin first) and recorded — stop the daemon, print a table and plot those
# two runs. Leaves no process behind. Output folder: build/demo (override with DEMO_OUT).
set -euo pipefail
cd "$(dirname "$0")/.."
out=${DEMO_OUT:-build/demo}
tools/deps.sh
echo "demo: building (release preset)..."
tools/build.sh release contourd contourctl contour-sim >/dev/null
mkdir -p "$out"
bin=build/release
sock_dir=$(mktemp -d "${TMPDIR:-/tmp}/contourd-demo.XXXXXX")
sock="$sock_dir/contourd.sock"
ctl() { "$bin/tools/contourctl" --socket "$sock" "$@"; }
field() { sed -nE "s/.*\"$1\": ?\"?([-0-9.eE+A-Z_]+|true|false)\"?.*/\1/p" <<<"$2" | head -n 1; }
sfield() { sed -nE "s/.*\"$1\": ?\"([^\"]*)\".*/\1/p" <<<"$2" | head -n 1; }  # a string field

"$bin/daemon/contourd" --config config/sim.yaml --socket "$sock" >"$out/contourd.log" 2>&1 &
pid=$!
cleanup() {
  if kill -0 "$pid" 2>/dev/null; then
    kill -TERM "$pid" 2>/dev/null || true
    wait "$pid" 2>/dev/null || true
  fi
  rm -rf "$sock_dir"
}
trap cleanup EXIT
for _ in $(seq 1 100); do
  ctl status >/dev/null 2>&1 && break
  kill -0 "$pid" 2>/dev/null || { echo "demo: contourd exited; log:"; cat "$out/contourd.log"; exit 1; }
  sleep 0.1
done

echo "demo: contourd running on the simulated machine (socket $sock)"
echo "demo: homing every axis (Z, then X and Y: switch search and latch; $out/home.log)..."
ctl home --all >"$out/home.log" 2>&1 || { echo "demo: homing failed:"; cat "$out/home.log"; exit 1; }
# Each run starts at the program's origin: a rapid there first (the machine is where the last
# run ended), then the program, recorded for the plot.
printf 'G21 G90 G0 X0 Y0 Z0\nM2\n' >"$out/to_start.ngc"
csvs=()
printf '%-22s %12s %12s %10s %9s %s\n' run max_err_um rms_err_um time_s overruns state
for mode in coupled uncoupled; do
  if [ "$mode" = coupled ]; then ctl gains set coupling=true >/dev/null; else ctl gains set coupling=false >/dev/null; fi
  ctl run "$out/to_start.ngc" --wait --quiet >/dev/null
  ctl record start "demo_table2_$mode.csv" >/dev/null
  json=$(ctl --json run config/programs/table2.ngc --wait --quiet | tail -n 1)
  csvs+=("$(sfield path "$(ctl --json record stop | tail -n 1)")")
  echo "$json" >"$out/table2_$mode.json"
  printf '%-22s %12.3f %12.3f %10.3f %9s %s\n' "Table 2, $mode" "$(field max_contour_error_um "$json")" \
    "$(field rms_contour_error_um "$json")" "$(field duration_s "$json")" "$(field overruns "$json")" \
    "$(field state "$json")"
done
# The plot of the two runs in the table: contour error against time, and the coupled run's path.
ctl plot --kind error "${csvs[@]}" --label coupled --label uncoupled -o "$out/table2_runs_error.png" >/dev/null
ctl plot --kind path "${csvs[0]}" --program config/programs/table2.ngc -o "$out/table2_coupled_path.png" >/dev/null
echo "plots of these runs: $out/table2_runs_error.png (contour error), $out/table2_coupled_path.png (path)"
cp "${csvs[@]}" "$out/" 2>/dev/null || true
status=$(ctl --json status | tail -n 1)
echo "$status" >"$out/status.json"
ctl shutdown >/dev/null 2>&1 || true
wait "$pid" 2>/dev/null || true

# The same program offline (paper's reference without acc/dec) and its plot.
"$bin/tools/contour-sim" contour --path config/programs/table2.ngc --compare --feed-mm-min 4000 \
  --plot "$out/table2_compare.png" | tail -n 1 >"$out/table2_offline.json"
echo "offline (contour-sim, paper's no-acc/dec reference): P/CCC $(field ratio_p_ccc "$(cat "$out/table2_offline.json")"), plot $out/table2_compare.png"
echo "daemon log: $out/contourd.log; JSON results and status: $out/"
