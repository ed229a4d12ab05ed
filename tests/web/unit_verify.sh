#!/usr/bin/env bash
# systemd-analyze verify of systemd/contour-web.service with ExecStart pointed at the built
# contour-web, and a syntax check of contour-web.sysusers in a staging root. Exit 77 = skipped.
set -u
src=$1
bin=$2
if ! command -v systemd-analyze >/dev/null 2>&1; then
  echo "contour_web_unit_verify: SKIPPED: systemd-analyze not installed (package systemd)"
  exit 77
fi
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
sed "s|/usr/local/bin/contour-web|$bin|" "$src/systemd/contour-web.service" >"$tmp/contour-web.service"
out=$(systemd-analyze verify "$tmp/contour-web.service" 2>&1)
rc=$?
echo "$out"
if [ $rc -ne 0 ] || grep -qi "contour-web.service" <<<"$out"; then
  echo "contour_web_unit_verify: FAILED (contour-web.service)"
  exit 1
fi
if command -v systemd-sysusers >/dev/null 2>&1; then
  mkdir -p "$tmp/root/etc"
  cp "$src/systemd/contourd.sysusers" "$tmp/contourd.conf"
  cp "$src/systemd/contour-web.sysusers" "$tmp/contour-web.conf"
  : >"$tmp/root/etc/passwd"; : >"$tmp/root/etc/group"
  if ! systemd-sysusers --root="$tmp/root" "$tmp/contourd.conf" "$tmp/contour-web.conf" 2>&1; then
    echo "contour_web_unit_verify: FAILED (sysusers)"
    exit 1
  fi
  if ! grep -q '^contourd:.*:contour-web' "$tmp/root/etc/group" || ! grep -q '^contour-web:' "$tmp/root/etc/passwd"; then
    echo "contour_web_unit_verify: FAILED: user contour-web not created in group contourd"
    cat "$tmp/root/etc/passwd" "$tmp/root/etc/group"
    exit 1
  fi
fi
echo "contour_web_unit_verify: contour-web.service and its sysusers file OK"
