#!/usr/bin/env bash
# The whole servo cycle (bench_loop: ServoLoop::cycle on the simulated machine running Table 2)
# built from several commits with the SAME benchmark source (this checkout's
# tools/bench/bench_loop.cpp), compared in two ways (issue 15: what a change of the loop costs):
#   - instructions per cycle, from callgrind (deterministic: the same binary gives the same count
#     on every run and every machine load);
#   - CPU time per cycle, the median of alternated rounds (each binary once per round).
# Usage: tools/bench/loop_history.sh [--rounds N] [--no-callgrind] REV...
#   REV: any commit (the first is the reference of the ratios). Each is checked out as a git
#   worktree under build/loop_history/REV and built with the ci preset (-O2), target
#   bench_loop_hist (added to that tree's tools/CMakeLists.txt; its own config/sim.yaml is used).
#   --rounds N      alternated wall-time rounds (default 5)
#   --no-callgrind  skip the instruction counts (valgrind takes ~2 min per commit)
# The instruction counts need valgrind (Debian package valgrind); without it they are skipped.
set -euo pipefail
cd "$(dirname "$0")/../.."
root=$PWD
rounds=5
callgrind=1
revs=()
while [ $# -gt 0 ]; do
  case "$1" in
    --rounds) rounds=$2; shift 2 ;;
    --no-callgrind) callgrind=0; shift ;;
    -h|--help) sed -n 2,15p "$0"; exit 0 ;;
    -*) echo "loop_history.sh: unknown option $1" >&2; exit 2 ;;
    *) revs+=("$1"); shift ;;
  esac
done
if [ "$callgrind" = 1 ] && ! command -v valgrind >/dev/null; then
  echo "loop_history.sh: valgrind not installed (apt-get install valgrind): no instruction counts" >&2
  callgrind=0
fi
[ ${#revs[@]} -ge 1 ] || { echo "loop_history.sh: give at least one commit" >&2; exit 2; }

out=build/loop_history
mkdir -p "$out"
bins=()
shas=()
for rev in "${revs[@]}"; do
  sha=$(git rev-parse --short=12 "$rev^{commit}")
  wt="$out/$sha"
  if [ ! -d "$wt" ]; then
    git worktree add --detach "$wt" "$sha" >/dev/null
  fi
  # The same benchmark source in every tree, as its own target (old trees have no bench_loop, or
  # an older one; their tools/bench/*.cpp glob is left alone).
  mkdir -p "$wt/tools/bench_hist"
  cp tools/bench/bench_loop.cpp "$wt/tools/bench_hist/bench_loop.cpp"
  if ! grep -q bench_loop_hist "$wt/tools/CMakeLists.txt"; then
    cat >>"$wt/tools/CMakeLists.txt" <<'EOF'

# Added by tools/bench/loop_history.sh (not part of this commit).
add_executable(bench_loop_hist ${CMAKE_CURRENT_SOURCE_DIR}/bench_hist/bench_loop.cpp)
target_include_directories(bench_loop_hist PRIVATE ${PROJECT_SOURCE_DIR})
target_link_libraries(bench_loop_hist PRIVATE contour::daemon contour::control contour::config
                      contour::drivers benchmark::benchmark Threads::Threads)
target_compile_definitions(bench_loop_hist PRIVATE CONTOUR_SOURCE_DIR="${PROJECT_SOURCE_DIR}")
EOF
  fi
  echo "loop_history: building $rev ($sha) in $wt" >&2
  (cd "$wt" && cmake --preset ci >/dev/null && cmake --build build/ci -j "$(nproc)" --target bench_loop_hist >/dev/null)
  bins+=("$root/$wt/build/ci/tools/bench_loop_hist")
  shas+=("$sha")
done

tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

# Instructions per cycle: callgrind counts only inside ServoLoop::cycle(); the cycles are the calls
# of that function (every benchmark run, the warm-up ones included).
declare -A ipc
if [ "$callgrind" = 1 ]; then
  for i in "${!revs[@]}"; do
    (cd "$(dirname "${bins[$i]}")/../../.." &&
       valgrind --tool=callgrind --callgrind-out-file="$tmp/cg.$i" \
         --toggle-collect='contour::daemon::ServoLoop::cycle()' \
         "${bins[$i]}" --benchmark_min_time=0.05 >/dev/null 2>"$tmp/cg.$i.log") &
  done
  wait
  for i in "${!revs[@]}"; do
    ipc[$i]=$(python3 - "$tmp/cg.$i" <<'EOF'
import re, sys
names = {}
def name(s):
    m = re.match(r'\((\d+)\)(?: (.*))?', s)
    if not m:
        return s
    if m.group(2):
        names[m.group(1)] = m.group(2)
    return names.get(m.group(1), '')
calls = 0
total = 0
cfn = None
for line in open(sys.argv[1]):
    if line.startswith('fn='):
        name(line[3:].strip())
    elif line.startswith('cfn='):
        cfn = name(line[4:].strip())
    elif line.startswith('calls=') and cfn and cfn.startswith('contour::daemon::ServoLoop::cycle()'):
        calls += int(line[6:].split()[0])
    elif line.startswith('totals:') or line.startswith('summary:'):
        total = int(line.split()[1])
print('%.1f' % (total / calls) if calls else 'nan')
EOF
)
  done
fi

# CPU time: alternated rounds, the median per commit.
for r in $(seq 1 "$rounds"); do
  for i in "${!revs[@]}"; do
    (cd "$(dirname "${bins[$i]}")/../../.." && "${bins[$i]}" --benchmark_format=csv 2>/dev/null) |
      awk -F, -v i="$i" '$1 ~ /BM_ServoLoopCycle/ { print i, $4 }' >>"$tmp/wall"
  done
done

echo "whole servo cycle (bench_loop source of this checkout), reference ${revs[0]}:"
printf '%-14s %-12s %12s %8s %14s %8s\n' commit sha "instr/cycle" ratio "CPU ns (med)" ratio
ref_ipc=${ipc[0]:-}
median_ns() {  # commit index -> median of its rounds
  awk -v i="$1" '$1 == i { print $2 }' "$tmp/wall" | sort -g |
    awk '{ a[NR] = $1 } END { print (NR % 2) ? a[(NR + 1) / 2] : (a[NR / 2] + a[NR / 2 + 1]) / 2 }'
}
ref_ns=$(median_ns 0)
for i in "${!revs[@]}"; do
  ns=$(median_ns "$i")
  all=$(awk -v i="$i" '$1 == i { printf "%s%.0f", (n++ ? " " : ""), $2 }' "$tmp/wall")
  ic=${ipc[$i]:-}
  ir=$([ -n "$ic" ] && awk -v a="$ic" -v b="$ref_ipc" 'BEGIN { printf "%.3f", a / b }' || echo -)
  nr=$(awk -v a="$ns" -v b="$ref_ns" 'BEGIN { printf "%.3f", a / b }')
  printf '%-14s %-12s %12s %8s %14.1f %8s   (%s)\n' "${revs[$i]}" "${shas[$i]}" \
    "${ic:--}" "$ir" "$ns" "$nr" "$all"
done
