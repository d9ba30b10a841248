#!/usr/bin/env bash
# The web view's figures, into OUT (default out/web_figures): frame_bench (JPEG encode time and size per
# resolution and quality, the render loop's share), rt_bench's 1 kHz floor just before the live runs, then
# web_figures.py (the haptic node's missed deadlines without the web view, with it, and with a browser showing the
# page, side by side; the delay render -> page). About 4 minutes at 20 s. Run it alone on the machine, under the build lock:
#   flock /tmp/surgsim_build.lock scripts/web_figures.sh [OUT] [SECONDS]
# /usr/bin/python3 scripts/report/web.py OUT turns the CSV files into the report's section.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
build=${SURGSIM_BUILD_DIR:-$root/build}
out=${1:-$root/out/web_figures}
seconds=${2:-20}
export SURGSIM_CACHE_DIR=${SURGSIM_CACHE_DIR:-$build/cache}
export SURGSIM_CONFIG_DIR=${SURGSIM_CONFIG_DIR:-$root/config}
for p in bench/frame_bench bench/rt_bench bin/haptic_node bin/visual_node bin/surgsim-web; do
  [ -x "$build/$p" ] || { echo "web_figures: $build/$p not found: build it first (scripts/build.sh)" >&2; exit 1; }
done
mkdir -p "$out"
rm -f "$out/rt_floor.csv"
echo "web_figures: frame_bench" >&2
"$build/bench/frame_bench" --out "$out" | tee "$out/frame_bench.txt"
echo "web_figures: rt_bench floor (${seconds} s)" >&2
"$build/bench/rt_bench" --seconds "$seconds" --label floor --out "$out" | tee "$out/rt_bench.txt"
/usr/bin/python3 "$root/scripts/web_figures.py" "$out" --seconds "$seconds" --build "$build" | tee "$out/web_figures.txt"
{
  echo "machine: $(nproc) cores, $(uname -sr), commit $(git -C "$root" rev-parse --short HEAD)"
  echo "command: scripts/web_figures.sh $out $seconds"
} > "$out/provenance.txt"
echo "web_figures: wrote $out (web_live.csv, web_delay.csv, frame_encode.csv, frame_render_loop.csv, rt_floor.csv)"
