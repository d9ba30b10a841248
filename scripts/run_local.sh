#!/usr/bin/env bash
# Runs both nodes on one host: the visual node first, then the haptic node replaying a trajectory; stops the visual
# node once the haptic node is done, and prints where the frames and stats went.
#   scripts/run_local.sh [SCENE] [TRAJECTORY]     (SCENE: a shipped name like liver, or a YAML path)
#   scripts/run_local.sh SCENE --web [TRAJECTORY] (the web view: also surgsim-web; prints the URL to open. Without a
#       trajectory the haptic node takes the browser's virtual device (--input device) until Ctrl-C; with one it
#       replays it and the page watches.)
# Environment: SURGSIM_OUT (default out/<scene>), SURGSIM_BUILD_DIR, SURGSIM_DOMAIN, HAPTIC_ARGS, VISUAL_ARGS;
# with --web: WEB_PORT (8080), WEB_FPS (frames streamed per second, 20), WEB_ARGS (e.g. "--bind 0.0.0.0").
# CPU placement: SURGSIM_HAPTIC_CPU=N (on a machine with 2 or more CPUs) gives the haptic loop thread CPU N
# to itself: haptic_node --cpu N puts its other threads (DDS, publisher, log writers) on the remaining CPUs, and the
# visual node (and surgsim-web) start there (taskset). The default, none, pins nothing: the haptic node's CPU latency
# request (--cpu-latency-us 0) already brings its missed deadlines to the machine's floor, and the visual node keeps
# both CPUs (level of detail ~2 instead of 0-1 on the intestine). A 1-CPU machine or a --cpu in HAPTIC_ARGS pin nothing.
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


haptic_cpu=${SURGSIM_HAPTIC_CPU:-none}
cpu_args=()
others=()   # the command prefix that starts a program on the other CPUs (empty: not pinned)
if [ "$haptic_cpu" != none ] && [[ " ${HAPTIC_ARGS:-} " != *" --cpu "* && " ${HAPTIC_ARGS:-} " != *" --cpu="* ]] && command -v taskset >/dev/null; then
  allowed=()
  for range in $(taskset -cp $$ | sed 's/.*: *//' | tr ',' ' '); do
    allowed+=($(seq "${range%-*}" "${range#*-}"))
  done
  if [ "${#allowed[@]}" -ge 2 ]; then
    [[ " ${allowed[*]} " == *" $haptic_cpu "* ]] || {
      echo "run_local: SURGSIM_HAPTIC_CPU=$haptic_cpu is not one of this machine's CPUs (${allowed[*]}); give one" \
           "of them, or none not to pin" >&2; exit 2; }
    cpu_args=(--cpu "$haptic_cpu")
    other_cpus=()
    for c in "${allowed[@]}"; do [ "$c" = "$haptic_cpu" ] || other_cpus+=("$c"); done
    others=(taskset -c "$(IFS=,; echo "${other_cpus[*]}")")
    echo "run_local: the haptic loop on CPU $haptic_cpu; its other threads and the visual node on CPUs ${other_cpus[*]}"
  fi
fi

replay=()
[ -n "$trajectory" ] && replay=(--replay "$trajectory")
stream=()
if [ "$web" = 1 ]; then
  stream=(--stream-fps "${WEB_FPS:-20}")
  [ -z "$trajectory" ] && replay=(--input device)
fi

"${others[@]+"${others[@]}"}" "$bin/visual_node" --scene "$scene" --out "$out/frames" --stats "$out/visual_stats.json" \
  "${stream[@]+"${stream[@]}"}" ${VISUAL_ARGS:-} >"$out/visual.log" 2>&1 &
visual=$!
web_pid=
trap 'kill -INT $visual ${web_pid} 2>/dev/null || true' EXIT
if [ "$web" = 1 ]; then
  "${others[@]+"${others[@]}"}" "$bin/surgsim-web" --scene "$scene" --port "${WEB_PORT:-8080}" \
    --stats "$out/web_stats.json" ${WEB_ARGS:-} \
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
     --log "$out/haptic_log.csv" "${cpu_args[@]+"${cpu_args[@]}"}" ${HAPTIC_ARGS:-} 2>&1 | tee "$out/haptic.log"; then
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
