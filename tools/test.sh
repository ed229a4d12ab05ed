#!/usr/bin/env bash
# Builds contourd and runs every test: unit, sim and HIL (HIL under tools/with-vcan, through
# User-Mode Linux where the host kernel has no vcan). Installs what it needs first.
#   tools/test.sh [--preset release|ci|dev] [--no-hil] [--with-slow] [--dev-unit] [--o3-unit]
# --dev-unit also builds the unit tests in the ASan+UBSan preset (dev; ci-dev with --preset ci)
# and runs them there.
# --o3-unit also builds the unit tests in CMake's Release build type (-O3: preset ci-o3 with
# --preset ci, else release-o3) and runs them there: g++ 12 -O3 once miscompiled code that
# passed at -O2 (issue 17). Both build only the unit-test programs (target tests_unit).
set -euo pipefail
cd "$(dirname "$0")/.."
preset=release
hil=1
slow=0
dev_unit=0
o3_unit=0
while [ $# -gt 0 ]; do
  case "$1" in
    --preset) preset=$2; shift 2 ;;
    --no-hil) hil=0; shift ;;
    --with-slow) slow=1; shift ;;
    --dev-unit) dev_unit=1; shift ;;
    --o3-unit) o3_unit=1; shift ;;
    *) echo "test.sh: unknown option $1" >&2; exit 2 ;;
  esac
done

# CI keeps only the tail of this output: every step's time and every failed test are repeated at
# the end, so a red run always says what failed.
summary=()
note() { summary+=("$1"); echo "test.sh: $1"; }
tools/deps.sh
start=$(date +%s)
tools/build.sh "$preset"
note "build ($preset) took $(( $(date +%s) - start )) s"

status=0
# run_step STEP BUILD_DIR COMMAND...: runs a ctest command (maybe under with-vcan); on failure
# records the failed tests' names (ctest's LastTestsFailed.log), or that the run itself failed,
# and keeps what ctest printed of each failed test (--output-on-failure) for the summary.
failure_logs=()
run_step() {
  local step=$1 dir=$2; shift 2
  local failed="$dir/Testing/Temporary/LastTestsFailed.log" rc=0 t log
  t=$(date +%s)
  log=$(mktemp "${TMPDIR:-/tmp}/contour-test-step.XXXXXX")
  rm -f "$failed"
  set +e
  "$@" 2>&1 | tee "$log"
  rc=${PIPESTATUS[0]}
  set -e
  if [ "$rc" != 0 ]; then
    status=1
    if [ -s "$failed" ]; then
      note "FAILED in $step: $(cut -d: -f2- "$failed" | tr '\n' ' ')"
    else
      note "FAILED in $step: exit $rc (no failed-test list: the run itself failed or was killed)"
    fi
    # Each failed test's result line and the output ctest printed after it (the last 60 lines).
    local excerpt="$log.failed"
    awk '/Test +#[0-9]+: .*\*\*\*/ && !/Skipped/ {f = 1; print; next}
         f && (/^ *Start +[0-9]+:/ || /^ *[0-9]+\/[0-9]+ Test +#/) {f = 0}
         f {print}' "$log" | tail -n 60 > "$excerpt"
    [ -s "$excerpt" ] && failure_logs+=("$step|$excerpt")
  fi
  rm -f "$log"
  note "$step took $(( $(date +%s) - t )) s"
}
exclude="hil|soak"
[ "$slow" = 1 ] || exclude="hil|soak|slow"
echo "== unit + sim tests ($preset) =="
run_step "unit + sim tests ($preset)" "build/$preset" \
  ctest --test-dir "build/$preset" -LE "$exclude" --output-on-failure -j "$(nproc)"

if [ "$hil" = 1 ]; then
  echo "== HIL tests ($preset) under tools/with-vcan =="
  hil_label="hil"
  # The HIL suite takes ~5 min on a quiet 2-core machine; with-vcan's default bound (600 s) left
  # too little room on a loaded one (seen: killed at test 37 of 46 while a build ran beside it).
  run_step "HIL tests ($preset)" "build/$preset" \
    tools/with-vcan --ifaces vcan0,vcan1 --timeout 1500 -- \
    ctest --test-dir "build/$preset" -L "$hil_label" -LE "$([ "$slow" = 1 ] && echo '^$' || echo slow)" \
    --output-on-failure
  if [ "$slow" = 1 ]; then
    echo "== soak / fault storm ($preset, CONTOUR_SOAK_S=${CONTOUR_SOAK_S:-600} simulated s) =="
    run_step "soak ($preset)" "build/$preset" \
      tools/with-vcan --ifaces vcan0,vcan1 --timeout 7200 -- \
      ctest --test-dir "build/$preset" -L soak --output-on-failure -V
  fi
fi

if [ "$dev_unit" = 1 ]; then
  # With --preset ci: the ci-dev preset (dev with line tables only, -g1: enough for ASan's
  # reports and a quarter less compile time than dev's full -g).
  dev=dev
  [ "$preset" = ci ] && dev=ci-dev
  echo "== unit tests, ASan + UBSan ($dev preset) =="
  t=$(date +%s)
  tools/build.sh "$dev" tests_unit
  note "$dev unit-test build took $(( $(date +%s) - t )) s"
  run_step "$dev unit tests (ASan + UBSan)" "build/$dev" \
    env ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1 \
    ctest --test-dir "build/$dev" -L unit --output-on-failure -j "$(nproc)"
fi

if [ "$o3_unit" = 1 ]; then
  o3=release-o3
  [ "$preset" = ci ] && o3=ci-o3
  echo "== unit tests, Release -O3 ($o3 preset) =="
  t=$(date +%s)
  tools/build.sh "$o3" tests_unit
  note "$o3 unit-test build took $(( $(date +%s) - t )) s"
  run_step "$o3 unit tests" "build/$o3" ctest --test-dir "build/$o3" -L unit --output-on-failure -j "$(nproc)"
fi

for entry in "${failure_logs[@]}"; do
  echo "== what the failed tests of ${entry%%|*} printed (last 60 lines) =="
  cat "${entry#*|}"
  rm -f "${entry#*|}"
done
echo "== summary =="
printf 'test.sh: %s\n' "${summary[@]}"
echo "test.sh: total $(( $(date +%s) - start )) s, status $status"
exit $status
