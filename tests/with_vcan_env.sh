#!/usr/bin/env bash
# tools/with-vcan passes the caller's environment to the command unchanged, also through
# User-Mode Linux (whose init is dash): spaces, quotes, $, backslashes, backquotes and newlines.
set -u
root=$1
export CONTOUR_ENV_PROBE=$'a b "q" \'s\' $x \\ `t`\nline2'
out=$("$root/tools/with-vcan" --ifaces vcan0 -- sh -c 'printf %s "$CONTOUR_ENV_PROBE"')
rc=$?
if [ "$rc" = 125 ]; then
  echo "SKIP: tools/with-vcan has no way to get vcan on this host (status 125)"
  exit 77
fi
if [ "$rc" != 0 ]; then
  echo "FAIL: with-vcan exited $rc"
  exit 1
fi
if [ "$out" != "$CONTOUR_ENV_PROBE" ]; then
  printf 'FAIL: the command saw [%s], expected [%s]\n' "$out" "$CONTOUR_ENV_PROBE"
  exit 1
fi
echo "ok: environment passed through with-vcan"
