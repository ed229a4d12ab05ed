#!/usr/bin/env bash
# Loop timing of contourd against the kernel's limit (issue 11): runs
#   contourd --latency-test SECONDS          (the servo loop's RT set-up without drives)
# and
#   cyclictest -m -t1 [-a CPU] -p80 -i1000 -D SECONDS -q -h 20000   (Debian rt-tests; 1 ms period)
# AT THE SAME TIME (both in the background, then wait) so both see the same machine conditions,
# prints both reports and ends with one JSON line:
#   {"contourd_p99_us":..,"cyclictest_p99_us":..,"ratio_p99":..,...}
# ratio_p99 = contourd p99 / cyclictest p99; the issue's bar is <= 1.2.
#
# Usage: tools/latency-compare.sh [--seconds N] [--contourd PATH] [--priority P] [-- extra contourd args]
#   --seconds N     duration of both runs (default 30)
#   --contourd PATH the daemon binary (default build/release/daemon/contourd)
#   --priority P    SCHED_FIFO priority of both (default 80)
#   --cpu N         pin both to CPU N (default: the last CPU; -1: no pinning). On a VM the steal
#                   time differs between vCPUs, so two unpinned runs can see different machines;
#                   on one CPU both see the same one (their 1 ms wake-ups cost each other a few us).
# Needs root (or CAP_SYS_NICE + memlock limits) for SCHED_FIFO and mlockall; without it both
# tools fall back / fail and the numbers are not RT numbers.
#
# On this 2-core VM the absolute numbers are in the MILLISECONDS range (hypervisor steal time:
# the vCPU is not running when the timer fires) and vary run to run; only the ratio of two runs
# taken at the same time means anything. On a PREEMPT_RT host expect tens of microseconds.
set -euo pipefail
cd "$(dirname "$0")/.."

seconds=30
contourd=build/release/daemon/contourd
prio=80
cpu=$(( $(nproc) - 1 ))
extra=()
while [ $# -gt 0 ]; do
  case "$1" in
    --seconds) seconds=$2; shift ;;
    --contourd) contourd=$2; shift ;;
    --priority) prio=$2; shift ;;
    --cpu) cpu=$2; shift ;;
    --) shift; extra=("$@"); break ;;
    -h|--help) sed -n 2,25p "$0"; exit 0 ;;
    *) echo "latency-compare.sh: unknown option $1" >&2; exit 2 ;;
  esac
  shift
done
[ -x "$contourd" ] || { echo "latency-compare.sh: $contourd not built (tools/build.sh release contourd)" >&2; exit 1; }
command -v cyclictest >/dev/null || { echo "latency-compare.sh: cyclictest missing (apt-get install rt-tests)" >&2; exit 1; }

tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

echo "machine: $(lscpu | awk -F: '/Model name/ {sub(/^[ \t]+/, "", $2); print $2; exit}'), $(nproc) CPUs, Linux $(uname -r)"
echo "running contourd --latency-test $seconds and cyclictest -D $seconds side by side..."
c_pin=(--priority "$prio"); k_pin=()
if [ "$cpu" -ge 0 ]; then c_pin+=(--cpu "$cpu"); k_pin=(-a "$cpu"); fi
echo "priority $prio, $([ "$cpu" -ge 0 ] && echo "both pinned to CPU $cpu" || echo "not pinned")"
"$contourd" --latency-test "$seconds" "${c_pin[@]}" "${extra[@]}" >"$tmp/contourd.out" 2>"$tmp/contourd.err" &
pid_c=$!
cyclictest -m -t1 "${k_pin[@]}" -p"$prio" -i1000 -D "$seconds" -q -h 20000 >"$tmp/cyclictest.out" 2>"$tmp/cyclictest.err" &
pid_k=$!
rc_c=0; rc_k=0
wait "$pid_c" || rc_c=$?
wait "$pid_k" || rc_k=$?
if [ "$rc_c" != 0 ]; then
  echo "latency-compare.sh: contourd failed ($rc_c):" >&2; cat "$tmp/contourd.err" "$tmp/contourd.out" >&2; exit 1
fi
if [ "$rc_k" != 0 ]; then
  echo "latency-compare.sh: cyclictest failed ($rc_k):" >&2; cat "$tmp/cyclictest.err" >&2; exit 1
fi

echo
echo "== contourd --latency-test $seconds"
grep -v '^  ' "$tmp/contourd.out" | sed '$d'   # summary without the histogram rows and JSON
cat "$tmp/contourd.err" >&2
c_json=$(tail -n 1 "$tmp/contourd.out")
num() { sed -n "s/.*\"$1\":\([-0-9.eE+]*\).*/\1/p" <<<"$c_json"; }
c_p99=$(num p99_us); c_p999=$(num p999_us); c_max=$(num max_us); c_avg=$(num avg_us)
[ -n "$c_p99" ] || { echo "latency-compare.sh: no p99_us in contourd's last line: $c_json" >&2; exit 1; }

# cyclictest -h: rows "BUCKET_US COUNT" (1 us buckets up to 20000 us), then "# Total", "# Min/Avg/Max
# Latencies", "# Histogram Overflows" (samples >= 20000 us). p99 = first bucket where the
# cumulative count reaches 99 % of the total (overflows count as above every bucket).
k_stats=$(awk '
  /^[0-9]+ +[0-9]+/ { b = $1 + 0; c = $2 + 0; cnt[b] = c; total += c; if (b > maxb) maxb = b; next }
  /^# Min Latencies/ { mn = $4 + 0 } /^# Avg Latencies/ { av = $4 + 0 } /^# Max Latencies/ { mx = $4 + 0 }
  /^# Histogram Overflows/ { ov = $4 + 0 }
  END {
    total += ov
    if (total == 0) { print "nan nan nan nan nan 0 0"; exit }
    split("0.99 0.999", qs, " ")
    for (qi = 1; qi <= 2; ++qi) {
      need = qs[qi] * total; acc = 0; res[qi] = -1
      for (b = 0; b <= maxb; ++b) { acc += cnt[b]; if (acc >= need) { res[qi] = b; break } }
      if (res[qi] < 0) res[qi] = maxb + 1   # in the overflow: a lower bound
    }
    printf "%d %d %d %d %d %d %d\n", mn, av, res[1], res[2], mx, total, ov
  }' "$tmp/cyclictest.out")
read -r k_min k_avg k_p99 k_p999 k_max k_total k_ov <<<"$k_stats"
echo
echo "== cyclictest -m -t1 ${k_pin[*]} -p$prio -i1000 -D $seconds -q -h 20000"
echo "samples $k_total (overflows >= 20000 us: $k_ov)"
echo "wake-up latency us: min $k_min avg $k_avg p99 $k_p99 p99.9 $k_p999 max $k_max"

ratio=$(awk -v a="$c_p99" -v b="$k_p99" 'BEGIN { if (b > 0) printf "%.3f", a / b; else print "null" }')
echo
echo "p99: contourd $c_p99 us, cyclictest $k_p99 us, ratio $ratio (bar: <= 1.2; cyclictest = kernel limit)"
printf '{"seconds":%s,"contourd_p99_us":%s,"cyclictest_p99_us":%s,"ratio_p99":%s,"contourd_p999_us":%s,"cyclictest_p999_us":%s,"contourd_max_us":%s,"cyclictest_max_us":%s,"contourd_avg_us":%s,"cyclictest_avg_us":%s}\n' \
  "$seconds" "$c_p99" "$k_p99" "$ratio" "${c_p999:-null}" "$k_p999" "${c_max:-null}" "$k_max" "${c_avg:-null}" "$k_avg"
