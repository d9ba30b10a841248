#!/usr/bin/env bash
# Configures and builds surgsim into build/ (programs in build/bin/). Extra arguments go to CMake's configure step.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
build=${SURGSIM_BUILD_DIR:-$root/build}
jobs=${SURGSIM_JOBS:-$(nproc)}
# ccache when the machine has it, with paths relative to the checkout: a rebuild, or another clone of the same
# sources (CI's fresh clone), compiles only what changed.
launcher=()
if command -v ccache >/dev/null; then
  launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
  export CCACHE_BASEDIR=$root
fi
cmake -S "$root" -B "$build" -DCMAKE_BUILD_TYPE="${SURGSIM_BUILD_TYPE:-Release}" "${launcher[@]}" "$@" >/dev/null
cmake --build "$build" -j "$jobs"
echo "build: programs in $build/bin"
