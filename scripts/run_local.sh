#!/usr/bin/env bash
# Runs both nodes on one host: the visual node first, then the haptic node replaying a trajectory; stops the visual
# node once the haptic node is done, and prints where the frames and stats went.
#   scripts/run_local.sh [SCENE] [TRAJECTORY]     (SCENE: a shipped name like liver, or a YAML path)
# Environment: SURGSIM_OUT (default out/<scene>), SURGSIM_BUILD_DIR, SURGSIM_DOMAIN, HAPTIC_ARGS, VISUAL_ARGS.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
build=${SURGSIM_BUILD_DIR:-$root/build}
bin=$build/bin
scene=${1:-liver}
trajectory=${2:-}
name=$(basename "$scene" .yaml)
out=${SURGSIM_OUT:-$root/out/$name}
export SURGSIM_CACHE_DIR=${SURGSIM_CACHE_DIR:-$build/cache}
export SURGSIM_CONFIG_DIR=${SURGSIM_CONFIG_DIR:-$root/config}

for p in haptic_node visual_node; do
  [ -x "$bin/$p" ] || { echo "run_local: $bin/$p not found: run scripts/build.sh first" >&2; exit 1; }
done
rm -rf "$out"
mkdir -p "$out/frames"


replay=()
[ -n "$trajectory" ] && replay=(--replay "$trajectory")

"$bin/visual_node" --scene "$scene" --out "$out/frames" --stats "$out/visual_stats.json" ${VISUAL_ARGS:-} \
  >"$out/visual.log" 2>&1 &
visual=$!
trap 'kill -INT $visual 2>/dev/null || true' EXIT

start=$(date +%s%N)
if ! "$bin/haptic_node" --scene "$scene" "${replay[@]}" --wait-for-visual 20 --stats "$out/haptic_stats.json" \
     --log "$out/haptic_log.csv" ${HAPTIC_ARGS:-} 2>&1 | tee "$out/haptic.log"; then
  echo "run_local: haptic_node failed (see $out/haptic.log)" >&2
  exit 1
fi
# Let the last frames arrive and render, then stop the visual node cleanly.
sleep 0.5
kill -INT $visual 2>/dev/null || true
wait $visual || { echo "run_local: visual_node failed (see $out/visual.log)" >&2; cat "$out/visual.log" >&2; exit 1; }
trap - EXIT
cat "$out/visual.log" | grep -v '^mesh:' || true
end=$(date +%s%N)

frames=$(ls "$out/frames" 2>/dev/null | grep -c '\.png$' || true)
echo
echo "run_local: scene $name done in $(( (end - start) / 1000000 )) ms"
echo "  frames:        $out/frames ($frames PNG)"
echo "  haptic stats:  $out/haptic_stats.json"
echo "  visual stats:  $out/visual_stats.json"
echo "  haptic log:    $out/haptic_log.csv"
