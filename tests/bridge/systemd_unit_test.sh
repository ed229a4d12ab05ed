#!/usr/bin/env bash
# contour-bridge.service passes `systemd-analyze verify` (ExecStart pointed at the built binary),
# and contour-bridge.sysusers creates the user it names over a stock Debian 12 passwd/group;
# the group contourd it joins comes from contourd.sysusers. Exit 77 = skipped (no systemd tools).
set -u
src=$1
bin=$2
for t in systemd-analyze systemd-sysusers; do
  if ! command -v $t >/dev/null 2>&1; then
    echo "bridge_systemd_unit: SKIPPED: $t not installed (package systemd)"
    exit 77
  fi
done
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail=0
sed "s|/usr/local/bin/contour-bridge|$bin|" "$src/systemd/contour-bridge.service" >"$tmp/contour-bridge.service"
out=$(systemd-analyze verify "$tmp/contour-bridge.service" 2>&1)
rc=$?
echo "$out"
if [ $rc -ne 0 ] || grep -qi "contour-bridge.service" <<<"$out"; then
  echo "bridge_systemd_unit: FAIL: systemd-analyze verify"
  fail=1
fi
if [ -f /usr/share/base-passwd/group.master ]; then
  mkdir -p "$tmp/root/etc"
  cp /usr/share/base-passwd/group.master "$tmp/root/etc/group"
  cp /usr/share/base-passwd/passwd.master "$tmp/root/etc/passwd"
  systemd-sysusers --root="$tmp/root" "$src/systemd/contour-bridge.sysusers" "$src/systemd/contourd.sysusers"
  unit=$src/systemd/contour-bridge.service
  for u in $(sed -n 's/^User=//p' "$unit"); do
    grep -q "^$u:" "$tmp/root/etc/passwd" || { echo "bridge_systemd_unit: FAIL: User=$u not created"; fail=1; }
  done
  for g in $(sed -n 's/^Group=//p; s/^SupplementaryGroups=//p' "$unit"); do
    grep -q "^$g:" "$tmp/root/etc/group" || { echo "bridge_systemd_unit: FAIL: group $g not created"; fail=1; }
  done
else
  echo "note: no /usr/share/base-passwd: sysusers check skipped"
fi
[ $fail -eq 0 ] && echo "bridge_systemd_unit: OK"
exit $fail
