#!/usr/bin/env bash
# Installs contourd as a systemd service from a build tree (README.md "Install as a service"):
#   1. cmake --install: binaries to PREFIX/bin, the unit to PREFIX/lib/systemd/system, the
#      sysusers.d file to PREFIX/lib/sysusers.d, the gpiochip udev rule to PREFIX/lib/udev/rules.d,
#      README.md + module docs + example configs to PREFIX/share/doc/contourd.
#   2. systemd-sysusers: user `contourd`, groups `contourd` and `gpio` (what the unit names).
#   3. /etc/contourd (root:contourd 0750) and, when absent, /etc/contourd/contourd.yaml
#      (root:contourd 0640) from --config (default config/hil.yaml: edit it for your machine).
#   4. Without --destdir: udev rules reloaded, gpiochips re-triggered, systemctl daemon-reload.
#      The service is not enabled or started: `systemctl enable --now contourd` does that.
# Usage: tools/install.sh [--build-dir DIR] [--prefix DIR] [--destdir DIR] [--config FILE]
#   --destdir stages everything under DIR (DIR/etc/passwd and DIR/etc/group get the user and
#   groups; nothing on this machine changes); tests/install_test.sh uses it.
set -euo pipefail
cd "$(dirname "$0")/.."
build=build/release
prefix=/usr/local
destdir=""
config=config/hil.yaml
while [ $# -gt 0 ]; do
  case "$1" in
    --build-dir) build=$2; shift 2 ;;
    --prefix) prefix=$2; shift 2 ;;
    --destdir) destdir=$(realpath -m "$2"); shift 2 ;;
    --config) config=$2; shift 2 ;;
    -h|--help) sed -n '2,16p' "$0"; exit 0 ;;
    *) echo "install.sh: unknown argument '$1' (see --help)" >&2; exit 2 ;;
  esac
done
if [ ! -f "$build/CMakeCache.txt" ]; then
  echo "install.sh: $build is not a build directory: cmake --preset release && cmake --build build/release -j" >&2
  exit 2
fi
if [ ! -f "$config" ]; then
  echo "install.sh: --config $config: no such file" >&2
  exit 2
fi
if [ -z "$destdir" ] && [ "$(id -u)" -ne 0 ]; then
  echo "install.sh: run as root (sudo), or stage with --destdir DIR" >&2
  exit 2
fi
root=${destdir:-}

echo "install.sh: installing $build to ${destdir}${prefix}"
DESTDIR="$destdir" cmake --install "$build" --prefix "$prefix" >/dev/null

conf="$root$prefix/lib/sysusers.d/contourd.conf"
if [ -n "$destdir" ]; then
  mkdir -p "$root/etc"
  systemd-sysusers --root="$root" "$conf"
else
  systemd-sysusers "$conf"
fi
gid=$(awk -F: '$1 == "contourd" { print $3 }' "$root/etc/group")
if [ -z "$gid" ]; then
  echo "install.sh: systemd-sysusers did not create group contourd in $root/etc/group" >&2
  exit 1
fi

install -d -m 0750 "$root/etc/contourd"
chown "0:$gid" "$root/etc/contourd"
if [ -e "$root/etc/contourd/contourd.yaml" ]; then
  echo "install.sh: keeping the existing $root/etc/contourd/contourd.yaml"
else
  install -m 0640 "$config" "$root/etc/contourd/contourd.yaml"
  chown "0:$gid" "$root/etc/contourd/contourd.yaml"
  echo "install.sh: $root/etc/contourd/contourd.yaml from $config: edit it for your machine"
fi

if [ -z "$destdir" ]; then
  if command -v udevadm >/dev/null 2>&1; then
    udevadm control --reload-rules || true
    udevadm trigger --subsystem-match=gpio || true
  fi
  if [ -d /run/systemd/system ]; then systemctl daemon-reload; fi
  cat <<EOT
install.sh: done. Next:
  sudo $prefix/bin/contourd --config /etc/contourd/contourd.yaml --check-config
  sudo usermod -aG contourd \$USER     # socket and records access (log in again)
  sudo systemctl enable --now contourd
EOT
fi
