#!/usr/bin/env bash
# Benchmarks of issue 11: builds the release benchmark programs, runs them with repetitions and
# prints a table of MEDIANS (Google Benchmark's median aggregate over the repetitions), then the
# planner throughput on a generated 100,000-block CAM-style program, and on a generated
# 1,000,000-line arc-heavy CAM program (issue 19: G2/G3 in G17/G18/G19, helices, full circles,
# short lines and rapids; --arc-lines N to change its size).
#
# Usage: tools/bench.sh [--json] [--reps N] [--blocks N] [--build-dir DIR] [--no-build]
#   --json        end with one JSON object line: cycle_ns_median, contour_model_ns_median,
#                 planner_realtime_factor, planner_peak_rss_mb (+ machine and the other medians)
#   --reps N      benchmark repetitions (default 5)
#   --blocks N    G01 blocks of the generated program (default 100000)
#   --arc-lines N lines of the generated arc-heavy program (default 1000000; 0 skips it)
#   --build-dir   where the bench programs are (default build/release, built by tools/build.sh)
#   --no-build    do not build (use what is in --build-dir)
#
# Times are CPU-time medians (cpu_time of the median aggregate): on this shared 2-core VM the wall
# time of a benchmark includes other processes' time slices and steal time. Compare ratios within
# one run, not absolute numbers across runs or machines.
set -euo pipefail
cd "$(dirname "$0")/.."

json=0
reps=5
blocks=100000
arc_lines=1000000
build_dir=build/release
do_build=1
while [ $# -gt 0 ]; do
  case "$1" in
    --json) json=1 ;;
    --reps) reps=$2; shift ;;
    --blocks) blocks=$2; shift ;;
    --arc-lines) arc_lines=$2; shift ;;
    --build-dir) build_dir=$2; shift ;;
    --no-build) do_build=0 ;;
    -h|--help) sed -n 2,17p "$0"; exit 0 ;;
    *) echo "bench.sh: unknown option $1" >&2; exit 2 ;;
  esac
  shift
done

benches=(bench_cycle bench_loop bench_control bench_planner bench_force bench_canopen)
if [ "$do_build" = 1 ]; then
  tools/build.sh release "${benches[@]}" >&2
  build_dir=build/release
fi
for b in "${benches[@]}"; do
  [ -x "$build_dir/tools/$b" ] || { echo "bench.sh: $build_dir/tools/$b not built" >&2; exit 1; }
done

tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

cpu_model=$(lscpu | awk -F: '/Model name/ {sub(/^[ \t]+/, "", $2); print $2; exit}')
ncpu=$(nproc)
kernel=$(uname -r)
echo "machine: $cpu_model, $ncpu CPUs, Linux $kernel"
echo "repetitions: $reps (median of each)"
echo

# CSV rows of the median aggregates: name,iterations,real_time,cpu_time,time_unit,...
for b in "${benches[@]}"; do
  "$build_dir/tools/$b" --benchmark_repetitions="$reps" --benchmark_report_aggregates_only=true \
    --benchmark_format=csv 2>/dev/null | awk -F, -v prog="$b" '
      $1 ~ /_median"$/ { n = $1; gsub(/"/, "", n); sub(/_median$/, "", n); print prog "," n "," $3 "," $4 "," $5 }' \
    >>"$tmp/medians.csv"
done

to_ns() {  # value unit -> ns
  awk -v v="$1" -v u="$2" 'BEGIN { f = (u == "us") ? 1e3 : (u == "ms") ? 1e6 : (u == "s") ? 1e9 : 1; printf "%.1f", v * f }'
}
median_ns() {  # prog benchmark -> cpu ns (empty if missing)
  local row
  # The name may carry Google Benchmark's suffixes (BM_ServoLoopCycle/min_time:2.000).
  row=$(awk -F, -v p="$1" -v n="$2" '$1 == p && ($2 == n || index($2, n "/") == 1) { print $4 " " $5; exit }' "$tmp/medians.csv")
  if [ -n "$row" ]; then to_ns $row; fi
}

printf '%-14s %-34s %14s %14s\n' program benchmark "cpu median" "wall median"
awk -F, '{ printf "%-14s %-34s %11.1f %-2s %11.1f %-2s\n", $1, $2, $4, $5, $3, $5 }' "$tmp/medians.csv"
echo

# ---- planner throughput: generated CAM-style program, streamed through parser + planner.
prog="$tmp/cam_${blocks}.ngc"
awk -v n="$blocks" -v lenfile="$tmp/len" 'BEGIN {
  srand(11);
  print "%"; print "(generated CAM-style program: short G01 chords at 4 m/min, G64 P0.02)";
  print "G17 G21 G90 G94"; print "G64 P0.02"; print "G1 F4000";
  x = 0; y = 0; z = 0; h = 0; len = 0;
  for (i = 0; i < n; i++) {
    h += 0.6 * (rand() - 0.5);
    l = 0.1 + 0.9 * rand();        # 0.1..1.0 mm chords, mean 0.55 mm
    nx = x + l * cos(h); ny = y + l * sin(h); nz = 0.5 * sin(0.001 * i);
    len += sqrt((nx - x) ^ 2 + (ny - y) ^ 2 + (nz - z) ^ 2); x = nx; y = ny; z = nz;
    printf "G1 X%.4f Y%.4f Z%.4f\n", x, y, z;
  }
  print "M2"; print "%";
  printf "%.3f\n", len > lenfile;
}' >"$prog"
plan_json=$(/usr/bin/time -f '%M' -o "$tmp/rss_kb" "$build_dir/tools/bench_cycle" --plan-file "$prog")
rss_kb=$(cat "$tmp/rss_kb")
rtf=$(sed -n 's/.*"realtime_factor":\([0-9.]*\).*/\1/p' <<<"$plan_json")
program_s=$(sed -n 's/.*"program_s":\([0-9.]*\).*/\1/p' <<<"$plan_json")
wall_s=$(sed -n 's/.*"wall_s":\([0-9.]*\).*/\1/p' <<<"$plan_json")
rss_mb=$(awk -v k="$rss_kb" 'BEGIN { printf "%.1f", k / 1024 }')
echo "planner: $blocks blocks ($(wc -c <"$prog") bytes), program time ${program_s} s, planning wall ${wall_s} s"
echo "planner: realtime factor ${rtf}x (target >= 100x), peak RSS ${rss_mb} MB (target <= 64 MB)"
path_mm=$(cat "$tmp/len")
feed_s=$(awk -v l="$path_mm" 'BEGIN { printf "%.1f", l / 4000 * 60 }')
feed_rtf=$(awk -v f="$feed_s" -v w="$wall_s" 'BEGIN { printf "%.1f", f / w }')
echo "planner: path ${path_mm} mm = ${feed_s} s at the programmed 4 m/min -> ${feed_rtf}x on pure feed time (the planned time is longer: tolerance-limited corners slow down)"

# ---- planner throughput, arc-heavy: generated in $tmp (never in git), streamed the same way.
arc_rtf="" arc_rss_mb="" arc_program_s="" arc_wall_s=""
if [ "$arc_lines" -gt 0 ]; then
  aprog="$tmp/cam_arcs_${arc_lines}.ngc"
  awk -v n="$arc_lines" 'BEGIN {
    srand(19);
    print "%"; print "(generated arc-heavy CAM program: arcs in three planes, helices, full circles)";
    print "G17 G21 G90 G94"; print "G64 P0.05"; print "G0 X0 Y0 Z0"; print "G1 F3000";
    x = 0; y = 0; z = 0; plane = 17; k = 5;
    while (k < n - 2) {
      r = rand();
      if (r < 0.02) {              # plane change (LinuxCNC arcs in G18/G19 too)
        p = 17 + int(3 * rand()); if (p != plane) { plane = p; printf "G%d\n", plane; k++ }
        continue;
      }
      rad = 0.5 + 4.5 * rand(); a = 6.2831853 * rand();
      if (r < 0.55) {              # arc of 20..180 degrees, centre rad away, I/J/K format
        sw = (0.35 + 2.8 * rand()) * (rand() < 0.5 ? 1 : -1);
        g = sw > 0 ? 3 : 2;
        if (plane == 17) { cx = x - rad * cos(a); cy = y - rad * sin(a);
          nx = cx + rad * cos(a + sw); ny = cy + rad * sin(a + sw);
          printf "G%d X%.4f Y%.4f I%.4f J%.4f\n", g, nx, ny, cx - x, cy - y; x = nx; y = ny }
        else if (plane == 18) { cz = z - rad * cos(a); cx = x - rad * sin(a);
          nz = cz + rad * cos(a + sw); nx = cx + rad * sin(a + sw);
          printf "G%d X%.4f Z%.4f I%.4f K%.4f\n", g, nx, nz, cx - x, cz - z; x = nx; z = nz }
        else { cy = y - rad * cos(a); cz = z - rad * sin(a);
          ny = cy + rad * cos(a + sw); nz = cz + rad * sin(a + sw);
          printf "G%d Y%.4f Z%.4f J%.4f K%.4f\n", g, ny, nz, cy - y, cz - z; y = ny; z = nz }
      } else if (r < 0.62) {       # helix: one turn and a bit, in the current plane
        if (plane == 17) { printf "G3 X%.4f Y%.4f Z%.4f I%.4f J0 P2\n", x, y, z - 0.5, rad; z -= 0.5 }
        else if (plane == 18) { printf "G3 Z%.4f X%.4f Y%.4f K%.4f I0 P2\n", z, x, y - 0.5, rad; y -= 0.5 }
        else { printf "G3 Y%.4f Z%.4f X%.4f J%.4f K0 P2\n", y, z, x - 0.5, rad; x -= 0.5 }
      } else if (r < 0.66) {       # full circle (start == end)
        if (plane == 17) printf "G2 I%.4f J0\n", rad; else if (plane == 18) printf "G2 K%.4f I0\n", rad;
        else printf "G2 J%.4f K0\n", rad;
      } else if (r < 0.68) {       # rapid
        x += 10 * (rand() - 0.5); y += 10 * (rand() - 0.5);
        printf "G0 X%.4f Y%.4f\nG1\n", x, y; k++;
      } else {                     # short line
        x += 0.4 * (rand() - 0.5); y += 0.4 * (rand() - 0.5); z += 0.1 * (rand() - 0.5);
        printf "G1 X%.4f Y%.4f Z%.4f\n", x, y, z;
      }
      k++;
      if (x > 200 || x < -200 || y > 200 || y < -200 || z > 50 || z < -50) { x = 0; y = 0; z = 0; printf "G0 X0 Y0 Z0\nG1\n"; k += 2 }
    }
    print "M2"; print "%";
  }' >"$aprog"
  arc_json=$(/usr/bin/time -f '%M' -o "$tmp/arc_rss_kb" "$build_dir/tools/bench_cycle" --plan-file "$aprog")
  arc_rss_mb=$(awk -v k="$(cat "$tmp/arc_rss_kb")" 'BEGIN { printf "%.1f", k / 1024 }')
  arc_rtf=$(sed -n 's/.*"realtime_factor":\([0-9.]*\).*/\1/p' <<<"$arc_json")
  arc_program_s=$(sed -n 's/.*"program_s":\([0-9.]*\).*/\1/p' <<<"$arc_json")
  arc_wall_s=$(sed -n 's/.*"wall_s":\([0-9.]*\).*/\1/p' <<<"$arc_json")
  echo "planner (arc-heavy): $(wc -l <"$aprog") lines ($(wc -c <"$aprog") bytes), program time ${arc_program_s} s, planning wall ${arc_wall_s} s"
  echo "planner (arc-heavy): realtime factor ${arc_rtf}x (target >= 100x), peak RSS ${arc_rss_mb} MB"
fi

cycle=$(median_ns bench_cycle BM_Cycle3Axis)
plant=$(median_ns bench_cycle BM_PlantOnly)
model=$(median_ns bench_cycle BM_ContourModel)
model_eq11=$(median_ns bench_control BM_ModelOnly)
window=$(median_ns bench_control BM_WindowUpdate)
pdo_cycle=$(median_ns bench_canopen BM_PdoCycle3Axis)
pdo_pack=$(median_ns bench_canopen BM_PdoPack)
pdo_unpack=$(median_ns bench_canopen BM_PdoUnpack)
loop_cycle=$(median_ns bench_loop BM_ServoLoopCycle)
echo "cycle (3 axes, incl. plant ${plant} ns): ${cycle} ns median (target <= 2000 ns)"
echo "servo loop cycle (every stage, SimBus, Table 2): ${loop_cycle} ns median"

if [ "$json" = 1 ]; then
  printf '{"cycle_ns_median":%s,"contour_model_ns_median":%s,"planner_realtime_factor":%s,"planner_peak_rss_mb":%s,' \
    "${cycle:-null}" "${model:-null}" "${rtf:-null}" "${rss_mb:-null}"
  printf '"plant_ns_median":%s,"contour_model_eq11_ns_median":%s,"window_update_ns_median":%s,' \
    "${plant:-null}" "${model_eq11:-null}" "${window:-null}"
  printf '"servo_loop_cycle_ns_median":%s,' "${loop_cycle:-null}"
  printf '"pdo_cycle_3axis_ns_median":%s,"pdo_pack_ns_median":%s,"pdo_unpack_ns_median":%s,' \
    "${pdo_cycle:-null}" "${pdo_pack:-null}" "${pdo_unpack:-null}"
  printf '"planner_blocks":%s,"planner_program_s":%s,"planner_wall_s":%s,"planner_path_mm":%s,"planner_feed_time_s":%s,"planner_feed_realtime_factor":%s,' "$blocks" "$program_s" "$wall_s" "$path_mm" "$feed_s" "$feed_rtf"
  printf '"planner_arcs_lines":%s,"planner_arcs_realtime_factor":%s,"planner_arcs_peak_rss_mb":%s,"planner_arcs_program_s":%s,"planner_arcs_wall_s":%s,' \
    "$arc_lines" "${arc_rtf:-null}" "${arc_rss_mb:-null}" "${arc_program_s:-null}" "${arc_wall_s:-null}"
  printf '"repetitions":%s,"machine":{"cpu":"%s","nproc":%s,"kernel":"%s"}}\n' \
    "$reps" "$cpu_model" "$ncpu" "$kernel"
fi
