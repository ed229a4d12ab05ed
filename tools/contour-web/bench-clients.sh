#!/usr/bin/env bash
# Loop lateness with and without browser clients (issue 21): builds contourd and contour-web (ci
# preset) and runs tools/contour-web/bench/bench_clients.mjs; prints the lateness summaries and
# their ratio (reported, not asserted). Arguments go to the script (--runs N, --clients N,
# --json FILE).
set -euo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
cd "$root"
preset=${PRESET:-ci}
tools/build.sh "$preset" contourd contour-web >/dev/null
CONTOUR_BINARY_DIR=$root/build/$preset node tools/contour-web/bench/bench_clients.mjs "$@"
