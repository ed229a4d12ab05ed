#!/usr/bin/env bash
# Installs exactly the Debian 12 packages contourd needs to build, test and run its demo.
# Idempotent: when everything is present it does nothing; otherwise it runs `apt-get update` once
# and installs what is missing. Runs apt as root, or through sudo when not root.
set -euo pipefail

PACKAGES=(
  # build
  build-essential cmake ninja-build pkg-config g++ clang-14 libclang-rt-14-dev
  # libraries (Debian packages only)
  libeigen3-dev libyaml-cpp-dev libspdlog-dev libfmt-dev libmodbus-dev libgpiod-dev
  libsystemd-dev libcli11-dev nlohmann-json3-dev libmuparser-dev
  # tests and benchmarks
  googletest libgtest-dev libgmock-dev libbenchmark-dev
  # vcan harness (tools/with-vcan): User-Mode Linux kernel + its CAN modules, insmod, ip
  user-mode-linux kmod iproute2 can-utils
  # plots, latency comparison, independent Modbus client, systemd unit check
  gnuplot-nox rt-tests mbpoll systemd time
)

# Each part of the project that needs more Debian packages lists them in tools/deps.d/NAME.list
# (one package per line, '#' comments); tools/deps.d/NAME.sh scripts run afterwards (npm tooling for
# the browser tests, for instance), each idempotent.
shopt -s nullglob
here=$(cd "$(dirname "$0")" && pwd)
for list in "$here"/deps.d/*.list; do
  while read -r pkg _; do
    case "$pkg" in ''|'#'*) continue ;; esac
    PACKAGES+=("$pkg")
  done < "$list"
done

run_hooks() {
  for hook in "$here"/deps.d/*.sh; do
    bash "$hook"
  done
}

missing=()
for p in "${PACKAGES[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if [ ${#missing[@]} -eq 0 ]; then
  echo "deps: all ${#PACKAGES[@]} packages present"
  run_hooks
  exit 0
fi

SUDO=()
if [ "$(id -u)" -ne 0 ]; then
  if command -v sudo >/dev/null 2>&1; then
    SUDO=(sudo)
  else
    echo "deps: missing packages (${missing[*]}) and not root, and sudo is not available" >&2
    exit 1
  fi
fi

echo "deps: installing ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
"${SUDO[@]}" apt-get update -qq
"${SUDO[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}"
echo "deps: done"
run_hooks
