#!/usr/bin/env bash
# Refreshes the page's vendored JavaScript libraries from the npm registry, pinned here:
#   tools/contour-web/refresh-vendor.sh            the pinned versions (re-vendor, e.g. after an edit)
#   tools/contour-web/refresh-vendor.sh 1.6.33     another uPlot version (then commit the result)
# Each library lands in www/vendor/NAME/ with its licence, and www/vendor/VERSIONS records name,
# version, the registry's integrity hash and the licence, so the page never needs a build step
# and a review sees exactly what changed. Needs npm and network access to the npm registry.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
uplot=${1:-1.6.32}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
out=$here/www/vendor
mkdir -p "$out/uplot"
(cd "$tmp" && npm pack --silent "uplot@$uplot" >/dev/null)
tar -xzf "$tmp"/uplot-"$uplot".tgz -C "$tmp"
cp "$tmp/package/dist/uPlot.iife.min.js" "$tmp/package/dist/uPlot.min.css" "$out/uplot/"
cp "$tmp/package/LICENSE" "$out/uplot/LICENSE"
integrity=$(cd "$tmp" && npm view "uplot@$uplot" dist.integrity)
license=$(cd "$tmp" && npm view "uplot@$uplot" license)
cat >"$out/VERSIONS" <<VERS
# Vendored by tools/contour-web/refresh-vendor.sh from the npm registry; do not edit by hand.
# name version integrity licence files
uplot $uplot $integrity $license uplot/uPlot.iife.min.js uplot/uPlot.min.css uplot/LICENSE
VERS
echo "vendored uplot@$uplot ($license) into $out/uplot"
