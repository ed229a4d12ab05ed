#!/usr/bin/env bash
# npm tooling of the browser tests (tests/web): puppeteer-core, pinned by tests/web/package.json
# and package-lock.json, installed into tests/web/node_modules. puppeteer-core never downloads a
# browser (the tests drive Debian's /usr/bin/chromium). Idempotent: nothing to do while the
# installed tree matches the lock file.
set -euo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
dir=$root/tests/web
if ! command -v npm >/dev/null 2>&1; then
  SUDO=()
  [ "$(id -u)" -ne 0 ] && SUDO=(sudo)
  echo "deps/web: installing Debian's npm"
  DEBIAN_FRONTEND=noninteractive "${SUDO[@]}" apt-get install -y -qq --no-install-recommends npm
fi
want=$(sha256sum "$dir/package-lock.json" | cut -d' ' -f1)
stamp=$dir/node_modules/.contour-lock.sha256
if [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ] && [ -f "$dir/node_modules/puppeteer-core/package.json" ]; then
  echo "deps/web: puppeteer-core $(node -p "require('$dir/node_modules/puppeteer-core/package.json').version") present"
  exit 0
fi
echo "deps/web: npm ci in tests/web (puppeteer-core, no browser download)"
(cd "$dir" && PUPPETEER_SKIP_DOWNLOAD=1 npm ci --no-audit --no-fund --loglevel=error)
echo "$want" >"$stamp"
