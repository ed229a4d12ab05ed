#!/usr/bin/env bash
# Fleet benchmark (issue 22): builds contourd, contour-bridge and contour-bridge-fleet in the
# given preset (default release) and runs N machines x P programs against one local mosquitto.
#   tools/contour-bridge/bench/fleet.sh [--preset P] [--machines 20] [--programs 3] [--position-rate 10]
# The table and the JSON line it prints are what tools/contour-bridge/README.md "Fleet benchmark"
# quotes. Everything runs on loopback and stops by itself.
set -euo pipefail
cd "$(dirname "$0")/../../.."
preset=release
args=()
while [ $# -gt 0 ]; do
  case "$1" in
    --preset) preset=$2; shift 2 ;;
    *) args+=("$1"); shift ;;
  esac
done
tools/build.sh "$preset" contourd contour-bridge contour-bridge-fleet >/dev/null
exec "build/$preset/tools/contour-bridge/contour-bridge-fleet" "${args[@]}"
