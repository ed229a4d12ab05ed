#!/usr/bin/env bash
# Fails if control/ includes an OS, thread, logging, YAML or drivers/daemon header, if
# drivers/ and control/ include each other, or if drivers/ includes anything above it (config/,
# daemon/, tools/: the mapping from config to driver settings is the composition root's, daemon/).
# control/ is Eigen + the C++ standard library only.
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
  echo "layering: drivers/ must not include control/, config/, daemon/ or tools/: $hit"
  bad=1
done < <(grep -rnHE '^[[:space:]]*#[[:space:]]*include[[:space:]]*[<"](control|config|daemon|tools)/' drivers 2>/dev/null)
while IFS= read -r hit; do
  echo "layering: drivers/ must not use YAML (config is mapped by daemon/): $hit"
  bad=1
done < <(grep -rnHE '^[[:space:]]*#[[:space:]]*include[[:space:]]*[<"]yaml-cpp/' drivers 2>/dev/null)
n=$(ls control/*.hpp control/*.cpp 2>/dev/null | wc -l)
m=$(find drivers -name '*.[ch]pp' 2>/dev/null | wc -l)
if [ "$bad" = 0 ]; then echo "layering: OK ($n files in control/, $m in drivers/ checked)"; fi
exit $bad
