#!/usr/bin/env bash
# Side-by-side benchmark of contourd's blend planner and LinuxCNC 2.9's trajectory planner (issue 23).
# Same programs, same G64 P tolerance, same per-axis velocity and acceleration limits; LinuxCNC runs
# headless (linuxcnc-uspace, trivkins XYZ, 1 ms servo thread, halsampler records the commanded
# position every period). Reports per program and in sum: traverse time and ratio, path and vertex
# error of both against the programmed path, peak per-axis acceleration (10 ms average) of both.
# A benchmark: it reports, it asserts nothing. See tools/bench/tp_compare/README.md.
#
# Usage: tools/bench/tp_compare.sh [--out DIR] [--contour-sim BIN] [--config YAML]
#          [--tolerance-um UM] [--quick] [--reuse-linuxcnc] [--method M] [PROGRAM...]
#   --out DIR          output folder (default build/tp_compare; never committed)
#   --contour-sim BIN  default build/ci/tools/contour-sim (tools/build.sh ci contour-sim)
#   --config YAML      contourd config whose machine.axes limits both planners get
#                      (default tools/bench/tp/contourd.yaml)
#   --tolerance-um UM  G64 P for LinuxCNC and --tolerance-um for contourd (default 50)
#   --method M         contour-sim blend --method (default true)
#   --quick            three short programs only (smoke run, ~1 min)
#   --reuse-linuxcnc   keep DIR/linuxcnc's samples from an earlier run with the same program list
#   PROGRAM...         programs instead of the default set
# Exit: 0 report written, 77 LinuxCNC (or python3-yaml/matplotlib) missing, 1 other failure.
set -euo pipefail
# Debian's interpreter: the linuxcnc module, numpy, yaml and matplotlib are Debian packages.
py=/usr/bin/python3
root=$(cd "$(dirname "$0")/../.." && pwd)
here="$root/tools/bench/tp_compare"
out="$root/build/tp_compare"
sim="$root/build/ci/tools/contour-sim"
config="$root/tools/bench/tp/contourd.yaml"
tol_um=50
method=true
quick=0
reuse=0
programs=()
while [ $# -gt 0 ]; do
  case "$1" in
    --out) out=$2; shift 2 ;;
    --contour-sim) sim=$2; shift 2 ;;
    --config) config=$2; shift 2 ;;
    --tolerance-um) tol_um=$2; shift 2 ;;
    --method) method=$2; shift 2 ;;
    --quick) quick=1; shift ;;
    --reuse-linuxcnc) reuse=1; shift ;;
    -h|--help) sed -n '2,21p' "$0"; exit 0 ;;
    -*) echo "tp_compare.sh: unknown option $1" >&2; exit 1 ;;
    *) programs+=("$(realpath "$1")"); shift ;;
  esac
done

skip() { echo "tp_compare.sh: SKIP: $*"; exit 77; }
command -v linuxcnc >/dev/null && command -v halsampler >/dev/null ||
  skip "LinuxCNC is not installed (tools/deps.sh installs linuxcnc-uspace from tools/deps.d/linuxcnc.list)"
"$py" -c 'import linuxcnc' 2>/dev/null || skip "python3 module linuxcnc missing (linuxcnc-uspace)"
# Its plotting packages are installed here, not by tools/deps.sh: the benchmark is not part of CI.
if ! "$py" -c 'import yaml, numpy, matplotlib' 2>/dev/null; then
  pkgs=$(grep -v '^#' "$(dirname "$0")/tp_compare/deps.list" | tr '\n' ' ')
  sudo=""; [ "$(id -u)" = 0 ] || sudo="sudo"
  echo "tp_compare.sh: installing $pkgs"
  $sudo apt-get install -y --no-install-recommends $pkgs >/dev/null 2>&1 ||
    { $sudo apt-get update >/dev/null 2>&1 && $sudo apt-get install -y --no-install-recommends $pkgs >/dev/null 2>&1; } || true
fi
"$py" -c 'import yaml, numpy, matplotlib' 2>/dev/null ||
  skip "python3-yaml, python3-numpy or python3-matplotlib missing and not installable (tools/bench/tp_compare/deps.list)"
[ -x "$sim" ] || { echo "tp_compare.sh: $sim not built (tools/build.sh ci contour-sim)" >&2; exit 1; }

if [ ${#programs[@]} -eq 0 ]; then
  gen="$root/tests/data/tp/gen"
  cam="$root/tests/data/gcode/corpus/cam"
  if [ "$quick" = 1 ]; then
    programs=("$gen/star_acute.ngc" "$gen/jitter_chords.ngc" "$gen/native_helix.ngc")
  else
    # The generated set, the seed-004 diamond and short-block programs, then the real CAM files of the corpus whose motion is G0/G1 only (shortest
    # first; commercial-cameo.nc is left out: over 3 h of machine time per planner).
    programs=("$gen"/*.ngc "$root/tests/data/fuzz/gcode_fuzz/diamond.ngc"
      "$root/tests/data/fuzz/gcode_fuzz/short_blocks.ngc" "$root/tests/data/gcode/cam_post.ngc"
      "$cam/pcb2gcode-example_board_new_default-drill.ngc" "$cam/cncjs-jsdc.gcode"
      "$cam/pcb2gcode-multivibrator-clockwise-outline.ngc" "$cam/pcb2gcode-D1MiniGSR-front.ngc"
      "$cam/pcb2gcode-multivibrator-clockwise-back.ngc" "$cam/camotics-buildbotics.gcode"
      "$cam/pycam-tiny_cat_outline.ngc" "$cam/openvoronoi-ttt-vcarve.ngc")
  fi
fi

mkdir -p "$out"
out=$(cd "$out" && pwd)
"$py" "$here/make_config.py" "$config" "$tol_um" "$out" "$here/driver.py"
printf '%s\n' "${programs[@]}" > "$out/programs.txt"

lc="$out/linuxcnc"
g64=$(awk -v t="$tol_um" 'BEGIN { printf "G21 G64 P%.6f", t / 1000 }')
if [ "$reuse" = 1 ] && [ -s "$lc/samples.txt" ] && cmp -s "$out/programs.txt" "$lc/programs.txt"; then
  echo "tp_compare.sh: reusing LinuxCNC's samples in $lc"
else
  # rtapi_app refuses to run as root: LinuxCNC runs as nobody in a scratch folder it may write.
  run=$(mktemp -d /tmp/tp_compare.XXXXXX)
  trap 'rm -rf "$run"' EXIT
  cp "$lc"/tp.ini "$lc"/tp.hal "$lc"/tp.tbl "$lc"/tp.var "$run/"
  : > "$run/list"
  i=0
  for p in "${programs[@]}"; do
    # LinuxCNC gets the blend mode from its startup code (G64 P = tolerance), as contour-sim gets it
    # from --mode limited: a program's own G61/G61.1/G64 words are taken out of LinuxCNC's copy.
    f=$(printf '%s/%02d_%s' "$run" "$i" "$(basename "$p")")
    # LinuxCNC 2.9 did not apply RS274NGC_STARTUP_CODE's G64 P here (errors of 0.1-1.2 mm on the
    # chord programs): the copy states it on its first line (after a leading '%').
    perl -pe 's/G\s*6\s*(?:1\.1|1|4)(?![0-9.])(?:\s*[PQ]\s*[-+]?[0-9.]+)*//gi' "$p" |
      awk -v g64="$g64" 'NR == 1 && /^[ \t]*%/ { print; print g64; next } NR == 1 { print g64 } { print }' > "$f"
    echo "$f" >> "$run/list"
    i=$((i + 1))
  done
  chmod -R a+rwX "$run"
  runas=()
  if [ "$(id -u)" = 0 ]; then
    id nobody >/dev/null 2>&1 || { echo "tp_compare.sh: no user 'nobody' to run LinuxCNC as" >&2; exit 1; }
    chown -R nobody "$run"
    runas=(runuser -u nobody --)
  fi
  echo "tp_compare.sh: running ${#programs[@]} programs on LinuxCNC (real time; log $lc/linuxcnc.log)"
  (cd "$run" && "${runas[@]}" env HOME="$run" TPC_LIST="$run/list" TPC_SAMPLES="$run/samples.txt" \
    TPC_STATUS="$run/status.txt" linuxcnc "$run/tp.ini") > "$lc/linuxcnc.log" 2>&1 || true
  [ -s "$run/samples.txt" ] || { echo "tp_compare.sh: LinuxCNC recorded nothing; see $lc/linuxcnc.log" >&2; exit 1; }
  cp "$run/samples.txt" "$run/status.txt" "$lc/"
  cp "$out/programs.txt" "$lc/programs.txt"
fi

"$py" "$here/analyse.py" --out "$out" --contour-sim "$sim" --config "$out/contourd.yaml" \
  --tolerance-um "$tol_um" --method "$method"
