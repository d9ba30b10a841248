#!/usr/bin/env bash
# SURGSIM_HAPTIC_CPU=N scripts/run_local.sh: the haptic node gets --cpu N and the visual node the other
# CPUs, also when HAPTIC_ARGS carries another option that starts with --cpu (--cpu-latency-us used to be taken for
# --cpu, and then nothing was pinned). Usage: run_local_placement_test.sh SOURCE_DIR BUILD_DIR OUT_DIR
set -euo pipefail
src=$1 build=$2 out=$3
cpus=$(taskset -cp $$ | sed 's/.*: *//')
if [ "$(/usr/bin/python3 -c "import os; print(len(os.sched_getaffinity(0)))")" -lt 2 ]; then
  echo "run_local_placement_test: needs 2 CPUs (this process may use $cpus)"; exit 77
fi
rm -rf "$out"
source "$(dirname "$0")/domain.sh"
surgsim_reserve_domain 29
export SURGSIM_BUILD_DIR=$build SURGSIM_OUT=$out
log=$(mktemp)
trap 'rm -f "$log"' EXIT
SURGSIM_HAPTIC_CPU=0 HAPTIC_ARGS="--cpu-latency-us -1 --duration 0.5" \
  "$src/scripts/run_local.sh" intestine "$src/config/trajectories/intestine_push.csv" >"$log" 2>&1 || {
  cat "$log"; echo "run_local_placement_test: run_local.sh failed" >&2; exit 1; }
grep -q '^run_local: the haptic loop on CPU 0; ' "$log" || {
  cat "$log"; echo "run_local_placement_test: SURGSIM_HAPTIC_CPU=0 did not pin the haptic loop" >&2; exit 1; }
/usr/bin/python3 - "$out/haptic_stats.json" <<'PY'
import json, sys
h = json.load(open(sys.argv[1]))
p = h['cpu_placement']
assert p['loop_cpu'] == 0, p
assert p['other_threads_on_loop_cpu'] == 0, p
print('run_local_placement_test: loop on CPU 0, %s' % p['others'])
PY
