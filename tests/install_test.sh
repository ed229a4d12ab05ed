#!/usr/bin/env bash
# The "Install as a service" steps, end to end into a staging root (issue 17): tools/install.sh
# --destdir R over a stock Debian 12 /etc/passwd and /etc/group (base-passwd's masters), then:
#   - binaries, unit, sysusers.d file, udev rule, docs and example configs where README.md says;
#   - every user and group the installed unit names (User=, Group=, SupplementaryGroups=) exists in
#     R/etc/passwd, R/etc/group after systemd-sysusers (a missing one is status 216/GROUP);
#   - ExecStart= is the installed contourd, every Documentation= file:// is an installed file;
#   - `systemd-analyze verify` accepts the installed unit;
#   - /etc/contourd/contourd.yaml is root:contourd 0640 and passes `contourd --check-config`.
# Exit 77 = skipped (no systemd-analyze / systemd-sysusers / base-passwd here), reported by ctest.
set -u
src=$1
build=$2
for t in systemd-analyze systemd-sysusers; do
  if ! command -v $t >/dev/null 2>&1; then
    echo "install_test: SKIPPED: $t not installed (package systemd)"
    exit 77
  fi
done
if [ ! -f /usr/share/base-passwd/group.master ]; then
  echo "install_test: SKIPPED: no /usr/share/base-passwd (stock Debian passwd/group templates)"
  exit 77
fi
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
root=$tmp/root
mkdir -p "$root/etc"
cp /usr/share/base-passwd/group.master "$root/etc/group"
cp /usr/share/base-passwd/passwd.master "$root/etc/passwd"
fail=0
bad() { echo "install_test: FAIL: $*"; fail=1; }

if ! "$src/tools/install.sh" --build-dir "$build" --destdir "$root" >"$tmp/install.log" 2>&1; then
  cat "$tmp/install.log"
  echo "install_test: FAILED: tools/install.sh exited non-zero"
  exit 1
fi
cat "$tmp/install.log"
p=$root/usr/local
for f in bin/contourd bin/contourctl bin/contour-sim bin/contour-machine-sim; do
  [ -x "$p/$f" ] || bad "$p/$f missing or not executable"
done
for f in lib/systemd/system/contourd.service lib/sysusers.d/contourd.conf \
         lib/udev/rules.d/60-contourd-gpio.rules share/doc/contourd/README.md \
         share/doc/contourd/daemon.md share/doc/contourd/config.md \
         share/doc/contourd/examples/hil.yaml share/doc/contourd/examples/sim.yaml \
         share/doc/contourd/examples/plc/toolchanger.st share/doc/contourd/examples/sim.tbl; do
  [ -f "$p/$f" ] || bad "$p/$f missing"
done
# The installed example loads as it is (its machine logic's .st files beside it).
"$p/bin/contourd" --config "$p/share/doc/contourd/examples/sim.yaml" --check-config >"$tmp/check.log" 2>&1 ||
  { cat "$tmp/check.log"; bad "examples/sim.yaml does not pass --check-config where it is installed"; }
unit=$p/lib/systemd/system/contourd.service
[ -f "$unit" ] || { echo "install_test: FAILED (no unit)"; exit 1; }

# Users and groups the unit names must exist after systemd-sysusers.
val() { sed -n "s/^$1=//p" "$unit"; }
for u in $(val User); do
  grep -q "^$u:" "$root/etc/passwd" || bad "User=$u: not in the staged /etc/passwd"
done
for g in $(val Group) $(val SupplementaryGroups); do
  grep -q "^$g:" "$root/etc/group" || bad "group $g (Group=/SupplementaryGroups=): not in the staged /etc/group (status 216/GROUP)"
done
# udev rule's group too.
for g in $(sed -n 's/.*GROUP="\([^"]*\)".*/\1/p' "$p/lib/udev/rules.d/60-contourd-gpio.rules"); do
  grep -q "^$g:" "$root/etc/group" || bad "udev GROUP=\"$g\": not in the staged /etc/group"
done

exe=$(val ExecStart | awk '{print $1}')
[ "$exe" = /usr/local/bin/contourd ] || bad "ExecStart= runs '$exe', not the installed /usr/local/bin/contourd"
[ -x "$root$exe" ] || bad "ExecStart= $exe: not installed"
docs=$(val Documentation)
[ -n "$docs" ] || bad "no Documentation="
for d in $docs; do
  case "$d" in
    file://*) [ -f "$root${d#file://}" ] || bad "Documentation=$d: not an installed file" ;;
    man:*) bad "Documentation=$d: no man page is installed" ;;
  esac
done

# systemd-analyze verify on the installed unit, ExecStart= pointed at the staged binary (verify
# checks that the executable exists on this machine).
sed "s|^ExecStart=$exe|ExecStart=$root$exe|" "$unit" >"$tmp/contourd.service"
out=$(systemd-analyze verify "$tmp/contourd.service" 2>&1)
rc=$?
echo "$out"
if [ $rc -ne 0 ] || grep -qi "contourd.service" <<<"$out"; then bad "systemd-analyze verify"; fi

cfg=$root/etc/contourd/contourd.yaml
gid=$(awk -F: '$1 == "contourd" { print $3 }' "$root/etc/group")
[ "$(stat -c '%a %u %g' "$cfg" 2>/dev/null)" = "640 0 $gid" ] ||
  bad "$cfg: $(stat -c '%a %u:%g' "$cfg" 2>&1), expected 640 0:$gid (root:contourd)"
[ "$(stat -c '%a %u %g' "$root/etc/contourd" 2>/dev/null)" = "750 0 $gid" ] ||
  bad "$root/etc/contourd: $(stat -c '%a %u:%g' "$root/etc/contourd" 2>&1), expected 750 0:$gid"
"$root$exe" --config "$cfg" --check-config || bad "contourd --check-config $cfg"

if [ $fail -ne 0 ]; then
  echo "install_test: FAILED"
  exit 1
fi
echo "install_test: OK"
