#!/usr/bin/env bash
# Fails if control/ includes an OS, thread, logging, YAML or drivers/daemon header, or if
# drivers/ and control/ include each other. control/ is Eigen + the C++ standard library only.
set -u
root=${1:-$(dirname "$0")/..}
cd "$root" || exit 2
bad=0
forbidden='^[[:space:]]*#[[:space:]]*include[[:space:]]*[<"](unistd\.h|pthread\.h|thread|mutex|condition_variable|shared_mutex|future|semaphore|stop_token|fstream|iostream|cstdio|stdio\.h|filesystem|chrono|sys/[^>"]*|linux/[^>"]*|net/[^>"]*|fcntl\.h|poll\.h|time\.h|ctime|signal\.h|csignal|spdlog/[^>"]*|fmt/[^>"]*|yaml-cpp/[^>"]*|modbus[^>"]*|gpiod[^>"]*|systemd/[^>"]*|drivers/[^>"]*|daemon/[^>"]*|config/[^>"]*|tools/[^>"]*|muParser[^>"]*|nlohmann/[^>"]*|CLI/[^>"]*)[>"]'
while IFS= read -r hit; do
  echo "layering: control/ must stay pure: $hit"
  bad=1
done < <(grep -nHE "$forbidden" control/*.hpp control/*.cpp 2>/dev/null)
while IFS= read -r hit; do
  echo "layering: drivers/ must not include control/: $hit"
  bad=1
done < <(grep -rnHE '^[[:space:]]*#[[:space:]]*include[[:space:]]*"(control|daemon)/' drivers 2>/dev/null)
n=$(ls control/*.hpp control/*.cpp 2>/dev/null | wc -l)
if [ "$bad" = 0 ]; then echo "layering: OK ($n files in control/ checked)"; fi
exit $bad
