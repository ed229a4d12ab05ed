#!/usr/bin/env bash
# Checks systemd/contourd.service with `systemd-analyze verify`, its ExecStart pointed at the
# built contourd (the installed path does not exist in a build tree). Exit 77 = skipped (no
# systemd-analyze on this machine), reported as such by ctest.
set -u
src=$1
bin=$2
if ! command -v systemd-analyze >/dev/null 2>&1; then
  echo "systemd_verify: SKIPPED: systemd-analyze not installed (package systemd)"
  exit 77
fi
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
sed "s|/usr/local/bin/contourd|$bin|" "$src/systemd/contourd.service" >"$tmp/contourd.service"
out=$(systemd-analyze verify "$tmp/contourd.service" 2>&1)
rc=$?
echo "$out"
if [ $rc -ne 0 ] || grep -qi "contourd.service" <<<"$out"; then
  echo "systemd_verify: FAILED"
  exit 1
fi
echo "systemd_verify: contourd.service OK"
