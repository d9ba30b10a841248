#!/usr/bin/env bash
# The test command: installs missing Debian packages, builds, runs the whole GoogleTest/CTest suite.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
build=${SURGSIM_BUILD_DIR:-$root/build}
start=$(date +%s)
SURGSIM_WITH_REPORT=1 "$root/scripts/setup.sh"   # numpy/matplotlib: scripts/report/ is tested too
"$root/scripts/build.sh"
built=$(date +%s)
cd "$build"
ctest --output-on-failure -j "${SURGSIM_TEST_JOBS:-2}" --timeout 600 "$@"
end=$(date +%s)
echo "test: build $((built - start)) s, tests $((end - built)) s"
