#!/usr/bin/env bash
# Fuzzes every reader of outside input (tests/fuzz/fuzz_<reader>.cpp) with libFuzzer under AddressSanitizer (with
# LeakSanitizer) and UndefinedBehaviorSanitizer: builds the targets with clang in a folder of their own, runs each in
# turn on one core from a copy of its committed seeds (tests/fuzz/corpus/<target>/ and regressions/<target>/; the
# committed folders never grow) and prints a table: executions, coverage (libFuzzer's cov: edges and ft: features at
# the end) and findings (crash-*, leak-*, timeout-*, oom-* files, with their paths). Exit 1 when any target has a
# finding. A finding is a crash, a leak, undefined behaviour, an input running over 10 s (a hang), more than 2 GB,
# or an exception other than the project's surgsim::core::Error escaping a reader (tests/fuzz/fuzz_support.h).
# Each finding, once fixed, goes to tests/fuzz/regressions/<target>/ (ctest fuzz_replay_<reader> replays it).
#
# Usage: scripts/fuzz.sh [SECONDS] [TARGET...]
#   SECONDS  per target (default 60)
#   TARGET   e.g. fuzz_scene fuzz_msh (default: every tests/fuzz/fuzz_*.cpp)
# It builds: run it when no other build loads the machine (two cores).
# Environment:
#   SURGSIM_FUZZ_DIR  build folder (default build-fuzz beside build/); a run's files: <dir>/runs/<target>/
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)

usage() { sed -n '2,18p' "$0" | sed 's/^# \{0,1\}//'; }
seconds=60
if [[ ${1:-} =~ ^[0-9]+$ ]]; then
  seconds=$1
  shift
elif [[ ${1:-} == -h || ${1:-} == --help ]]; then
  usage
  exit 0
fi
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
  for f in "$root"/tests/fuzz/fuzz_*.cpp; do targets+=("$(basename "$f" .cpp)"); done
fi
for t in "${targets[@]}"; do
  if [ ! -f "$root/tests/fuzz/$t.cpp" ]; then
    echo "fuzz.sh: no target $t (tests/fuzz/$t.cpp); the targets are:" $(cd "$root/tests/fuzz" && ls fuzz_*.cpp | sed 's/\.cpp$//') >&2
    exit 2
  fi
done
build=${SURGSIM_FUZZ_DIR:-$root/build-fuzz}

SURGSIM_WITH_FUZZ=1 "$root/scripts/setup.sh"
# RelWithDebInfo: -O2 for executions per second, -g for the lines of a report. ccache when the machine has it.
launcher=()
if command -v ccache >/dev/null; then launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache -DCMAKE_C_COMPILER_LAUNCHER=ccache); fi
CC=clang CXX=clang++ cmake -S "$root" -B "$build" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DSURGSIM_FUZZ=ON \
  -DSURGSIM_BUILD_BENCHMARKS=OFF "${launcher[@]}" >/dev/null
build_targets=()
for t in "${targets[@]}"; do build_targets+=(--target "$t"); done
cmake --build "$build" -j "${SURGSIM_JOBS:-$(nproc)}" "${build_targets[@]}"

export ASAN_OPTIONS="detect_leaks=1:halt_on_error=1:allocator_may_return_null=0"
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1"
export OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1

rows=()
any=0
for t in "${targets[@]}"; do
  run=$build/runs/$t
  rm -rf "$run"
  mkdir -p "$run/corpus" "$run/findings"
  # A copy of the seeds and the kept findings: what the run adds stays in build-fuzz/.
  for d in corpus regressions; do
    if [ -d "$root/tests/fuzz/$d/$t" ]; then find "$root/tests/fuzz/$d/$t" -type f ! -name '.*' -exec cp {} "$run/corpus/" \;; fi
  done
  dict=()
  if [ -f "$root/tests/fuzz/dict/$t.dict" ]; then dict=(-dict="$root/tests/fuzz/dict/$t.dict"); fi
  echo "fuzz.sh: $t for $seconds s (log: $run/log)"
  status=0
  # taskset -c 0: one core for the target, the other for the machine.
  (cd "$run" && taskset -c 0 "$build/fuzz/$t" -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 \
    -print_final_stats=1 -artifact_prefix="$run/findings/" "${dict[@]}" corpus) >"$run/log" 2>&1 || status=$?
  execs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$run/log" | grep -o '[0-9]*$' | tail -1)
  cov=$(grep -o 'cov: [0-9]* ft: [0-9]*' "$run/log" | tail -1)
  findings=$(find "$run/findings" -type f \( -name 'crash-*' -o -name 'leak-*' -o -name 'timeout-*' -o -name 'oom-*' \) | sort)
  if [ -n "$findings" ] || [ "$status" -ne 0 ]; then
    any=1
    [ -n "$findings" ] || findings="(exit $status, no input saved: see $run/log)"
  fi
  rows+=("$t|${execs:-?}|${cov:-?}|${findings:-none}")
done

echo
printf '%-20s %12s  %-22s %s\n' target executions coverage findings
for r in "${rows[@]}"; do
  IFS='|' read -r t e c f <<<"$r"
  printf '%-20s %12s  %-22s %s\n' "$t" "$e" "$c" "$(echo "$f" | head -1)"
  echo "$f" | tail -n +2 | sed 's/^/                                                    /'
done
echo "fuzz.sh: ${#targets[@]} targets, $seconds s each, $([ $any -eq 0 ] && echo 'no finding' || echo 'FINDINGS (see above)')"
exit $any
