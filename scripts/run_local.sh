#!/usr/bin/env bash
# Runs both nodes on one host: the visual node first, then the haptic node replaying a trajectory; stops the visual
# node once the haptic node is done, and prints where the frames and stats went.
#   scripts/run_local.sh [SCENE] [TRAJECTORY]     (SCENE: a shipped name like liver, or a YAML path)
#   scripts/run_local.sh SCENE --web [TRAJECTORY] (issue 18: also surgsim-web; prints the URL to open. Without a
#       trajectory the haptic node takes the browser's virtual device (--input device) until Ctrl-C; with one it
#       replays it and the page watches.)
# Environment: SURGSIM_OUT (default out/<scene>), SURGSIM_BUILD_DIR, SURGSIM_DOMAIN, HAPTIC_ARGS, VISUAL_ARGS;
# with --web: WEB_PORT (8080), WEB_FPS (frames streamed per second, 20), WEB_ARGS (e.g. "--bind 0.0.0.0").
set -euo pipefail
web=0
args=()
for a in "$@"; do
  if [ "$a" = --web ]; then web=1; else args+=("$a"); fi
done
set -- "${args[@]+"${args[@]}"}"
root=$(cd "$(dirname "$0")/.." && pwd)
build=${SURGSIM_BUILD_DIR:-$root/build}
bin=$build/bin
scene=${1:-liver}
trajectory=${2:-}
name=$(basename "$scene" .yaml)
out=${SURGSIM_OUT:-$root/out/$name}
export SURGSIM_CACHE_DIR=${SURGSIM_CACHE_DIR:-$build/cache}
export SURGSIM_CONFIG_DIR=${SURGSIM_CONFIG_DIR:-$root/config}

programs=(haptic_node visual_node)
[ "$web" = 1 ] && programs+=(surgsim-web)
for p in "${programs[@]}"; do
  [ -x "$bin/$p" ] || { echo "run_local: $bin/$p not found: run scripts/build.sh first" >&2; exit 1; }
done
rm -rf "$out"
mkdir -p "$out/frames"


replay=()
[ -n "$trajectory" ] && replay=(--replay "$trajectory")
stream=()
if [ "$web" = 1 ]; then
  stream=(--stream-fps "${WEB_FPS:-20}")
  [ -z "$trajectory" ] && replay=(--input device)
fi

"$bin/visual_node" --scene "$scene" --out "$out/frames" --stats "$out/visual_stats.json" "${stream[@]+"${stream[@]}"}" \
  ${VISUAL_ARGS:-} >"$out/visual.log" 2>&1 &
visual=$!
web_pid=
trap 'kill -INT $visual ${web_pid} 2>/dev/null || true' EXIT
if [ "$web" = 1 ]; then
  "$bin/surgsim-web" --scene "$scene" --port "${WEB_PORT:-8080}" --stats "$out/web_stats.json" ${WEB_ARGS:-} \
    >"$out/web.url" 2>"$out/web.log" &
  web_pid=$!
  for _ in $(seq 100); do
    grep -q 'open http' "$out/web.url" 2>/dev/null && break
    kill -0 $web_pid 2>/dev/null || { cat "$out/web.log" >&2; exit 1; }
    sleep 0.1
  done
  url=$(grep -o 'http://[^ ]*' "$out/web.url")
  echo
  echo "run_local: open $url"
  port=$(echo "$url" | sed 's|^http://[^:]*:\([0-9]*\)/.*|\1|')
  echo "  (from another machine: ssh -L $port:127.0.0.1:$port $(hostname), then the same URL)"
  [ -z "$trajectory" ] && echo "  the page drives the tool; Ctrl-C stops all three processes"
  echo
fi

start=$(date +%s%N)
if ! "$bin/haptic_node" --scene "$scene" "${replay[@]}" --wait-for-visual 20 --stats "$out/haptic_stats.json" \
     --log "$out/haptic_log.csv" ${HAPTIC_ARGS:-} 2>&1 | tee "$out/haptic.log"; then
  echo "run_local: haptic_node failed (see $out/haptic.log)" >&2
  exit 1
fi
# Let the last frames arrive and render, then stop the visual node cleanly.
sleep 0.5
kill -INT $visual ${web_pid} 2>/dev/null || true
[ -n "$web_pid" ] && { wait $web_pid || true; }
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
[ -n "$web_pid" ] && echo "  web stats:     $out/web_stats.json"
exit 0
