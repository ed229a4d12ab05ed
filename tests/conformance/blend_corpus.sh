#!/usr/bin/env bash
# Issue 19: the blend tolerance on every corpus program that both interpreters accept.
# Usage: blend_corpus.sh CONTOUR_SIM CONFIG CORPUS_DIR TOLERANCE_UM PROGRAM...
# (CORPUS_DIR's machine.var, machine.tbl and subroutines/ are used where they exist.)
# Each program runs through `contour-sim blend --mode limited --method M` (M = $BLEND_CORPUS_METHOD,
# default true; the planner, the
# FIR interpolator and the independent path meter: true path error sampled, between samples and
# at vertices <= the tolerance, no NaN, axis accelerations within the config's limits; contour-sim
# exits 1 otherwise). A program both interpreters reject (corpus README, gcode_conformance_*)
# must be listed in REJECTED_BY_BOTH below and must still be refused here; any other refusal,
# error or tolerance violation fails the test. Prints one line per program and a summary.
set -u
sim=$1 cfg=$2 corpus=$3 tol=$4
shift 4
# Refused by LinuxCNC's rs274 and contourd on the same line (gcode_conformance_* checks that).
REJECTED_BY_BOTH=" ${BLEND_CORPUS_REJECTED:-} "
method=${BLEND_CORPUS_METHOD:-true}
# The corpus's machine state (parameters, tool table, subroutines), where CORPUS_DIR has one.
machine=()
[ -f "$corpus/machine.var" ] && machine+=(--var "$corpus/machine.var")
[ -f "$corpus/machine.tbl" ] && machine+=(--tbl "$corpus/machine.tbl")
[ -d "$corpus/subroutines" ] && machine+=(--subroutines "$corpus/subroutines")
fail=0 ok=0 rej=0 worst=0 worst_prog=""
for f in "$@"; do
  name=${f#"$corpus"/}
  out=$("$sim" blend --program "$f" --mode limited --tolerance-um "$tol" --config "$cfg" --method "$method" \
        --max-corners 0 "${machine[@]}" 2>/dev/null)
  rc=$?
  if [[ $REJECTED_BY_BOTH == *" $name "* ]]; then
    if [ $rc -eq 2 ] && [[ $out == *'"error"'* ]]; then
      echo "REJECTED (by both, expected) $name: $out"; rej=$((rej + 1))
    else
      echo "FAIL $name: listed as rejected by both but contour-sim exit $rc: ${out:0:300}"; fail=$((fail + 1))
    fi
    continue
  fi
  figs=$(printf '%s' "$out" | sed -n 's/.*"max_path_error_um":\([^,]*\).*"max_vertex_error_um":\([^,]*\).*"nan":\([a-z]*\).*/path_um=\1 vertex_um=\2 nan=\3/p')
  if [ $rc -ne 0 ]; then
    echo "FAIL $name: exit $rc $figs ${out:0:400}"; fail=$((fail + 1))
  else
    echo "OK $name: $figs"; ok=$((ok + 1))
    p=$(printf '%s' "$out" | sed -n 's/.*"max_path_error_um":\([^,]*\).*/\1/p')
    if awk -v a="$p" -v b="$worst" 'BEGIN{exit !(a > b)}'; then worst=$p worst_prog=$name; fi
  fi
done
[ -n "${BLEND_CORPUS_SLOW:-}" ] && echo "not run here (label slow, ctest -R blend_corpus_slow): ${BLEND_CORPUS_SLOW}"
echo "blend corpus (--method $method): $# programs, $ok within ${tol} um, $rej rejected by both, $fail failed; worst path error ${worst} um ($worst_prog)"
[ $fail -eq 0 ]
