#!/usr/bin/env bash
# Chatter vs contour error for the derivative-filter settings (control/CHATTER.md).
# Usage: control/chatter/tradeoff.sh [BUILD_DIR]   (default build/ci; needs tools/contour-sim)
# Writes control/chatter/tradeoff.dat; plot with: gnuplot control/chatter/tradeoff.gp
# Per setting: the daemon's offline path (`contour-sim run`, config/sim.yaml + the setting) on
# Table 2: command chatter RMS X/Y/Z (mm/s), largest step, max contour error (um); then the
# seed-000 Table 2 and eq 11 runs (`contour-sim contour --compare`, delay 0): CCC max contour
# error (um) and P/CCC ratio; last, the same daemon run replayed through the same control stage
# with the clamped command fed back to the controller (`contour-sim contour --reference-csv
# --command-applied`, the wiring proposed for the daemon): chatter X/Y/Z and worst axis; last, the
# interpolator's second FIR stage (fir2_ms, jerk limit) the daemon run used (the seed-000 runs
# have no interpolator: sharp corners).
set -euo pipefail
cd "$(dirname "$0")/../.."
build=${1:-build/ci}
sim="$build/tools/contour-sim"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
out=control/chatter/tradeoff.dat
settings=(
  "round1 0 never 0 0"
  "lp1 0 never 1 0"
  "lp2 0 never 2 0"
  "lp3 0 never 3 0"
  "blend2 2 ahead 0 0"
  "blend5 5 ahead 0 0"
  "blend10 10 ahead 0 0"
  "blend20 20 ahead 0 0"
  "blend5_never 5 never 0 0"
  "blend5_always 5 always 0 0"
  "blend5+lp1 5 ahead 1 0"
  "blend5+lp2 5 ahead 2 0"
  "round1+fir2_5 0 never 0 5"
  "blend5+fir2_5(default) 5 ahead 0 5"
  "blend5+fir2_10 5 ahead 0 10"
  "blend5+fir2_20 5 ahead 0 20"
)
json() { python3 -c "import json,sys; j=json.loads(sys.stdin.read().strip().splitlines()[-1]); print($1)"; }
{
  echo "# setting blend_ms same_geometry lowpass_ms | daemon Table 2: chatter_x chatter_y chatter_z chatter_max_axis max_step max_contour_um | seed Table 2: ccc_um p/ccc | seed eq11: ccc_um p/ccc | replay with command_applied: chatter_x chatter_y chatter_z chatter_max_axis | interpolator fir2_ms"
  for s in "${settings[@]}"; do
    read -r name blend sg lp f2 <<<"$s"
    cfg="$tmp/sim.yaml"
    sed -e "s/^  delay_compensation: true/  delay_compensation: true\n  derivative: {model_blend_ms: $blend, same_geometry: $sg, lowpass_ms: $lp}/" \
      -e "s/^  fir2_ms: .*/  fir2_ms: $f2/" config/sim.yaml >"$cfg"
    "$sim" run --config "$cfg" --program config/programs/table2.ngc --csv "$tmp/t2.csv" >"$tmp/run.out"
    daemon=$(python3 - "$tmp/t2.csv" "$tmp/run.out" <<'PY'
import csv, json, math, sys
rows = list(csv.DictReader(open(sys.argv[1])))
rms, mx = [], 0.0
for ax in "xyz":
    v = [float(r["v%s_mm_s" % ax]) for r in rows]
    d = [v[i + 1] - v[i] for i in range(len(v) - 1)]
    rms.append(math.sqrt(sum(x * x for x in d) / len(d)))
    mx = max(mx, max(abs(x) for x in d))
j = json.loads(open(sys.argv[2]).read().strip().splitlines()[-1])
print("%.3f %.3f %.3f %.3f %.1f %.3f" % (rms[0], rms[1], rms[2], max(rms), mx, j["max_contour_error_um"]))
PY
)
    args=(--compare --feed-mm-min 4000 --delay-cycles 0 --model-blend-ms "$blend" --same-geometry "$sg" --lowpass-ms "$lp")
    t2=$("$sim" contour --path config/programs/table2.ngc "${args[@]}" | json '"%.3f %.3f" % (j["runs"][2]["max_contour_error_um"], j["ratio_p_ccc"])')
    e11=$("$sim" contour --path config/programs/eq11.yaml "${args[@]}" | json '"%.3f %.3f" % (j["runs"][2]["max_contour_error_um"], j["ratio_p_ccc"])')
    # (exit status 1 = "did not come to rest" within the 50 ms settle: expected, not an error)
    told=$({ "$sim" contour --path config/programs/table2.ngc --reference-csv "$tmp/t2.csv" --controller ccc \
      --settle-s 0.05 --command-applied --model-blend-ms "$blend" --same-geometry "$sg" --lowpass-ms "$lp" || true; } |
      json '"%.3f %.3f %.3f %.3f" % tuple(j["command_chatter_rms_mm_s"] + [max(j["command_chatter_rms_mm_s"])])')
    echo "$name $blend $sg $lp $daemon $t2 $e11 $told $f2"
  done
} >"$out"
cat "$out"
