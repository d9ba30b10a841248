#!/usr/bin/env bash
# The benchmark report: error against run time (liver and intestine), the stability suite and the speed
# figures behind every claim, all measured in this run on this machine, written to report/ as Markdown tables, CSV
# files and PNG plots (Debian's python3-matplotlib).
#
#   scripts/report.sh [--quick | --smoke] [--out DIR] [--no-build]
#
#   --quick     smaller meshes and shorter runs (about 14 minutes on 2 cores; for trying the pipeline, not for quoting)
#   --smoke     every step at its smallest that still writes what its section reads (4-5 minutes; the figures mean
#               nothing): the pipeline end to end, as the ctest scripts_report_smoke_test runs it
#   --out DIR   where the report goes (default: report/ in the repository; emptied first)
#   --no-build  use the programs already in build/ (default: setup + build first, as on a fresh clone)
#
# Environment: SURGSIM_BUILD_DIR (default build/), SURGSIM_DOMAIN (default 57), SURGSIM_REPORT_INTESTINE_LOAD_STEP.
# Every step runs even when an earlier one failed; the report names the failed steps and their logs, and the script
# then exits non-zero. The whole default run takes about 20 minutes on the 2-core CI machine (build included). The
# report's sections, their order and numbers: scripts/report/sections.py.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
args="$*"
quick=0
smoke=0
out=$root/report
build_first=1
while [ $# -gt 0 ]; do
  case "$1" in
    --quick) quick=1 ;;
    --smoke) quick=1; smoke=1 ;;
    --out) out=${2:?--out needs a folder}; shift ;;
    --no-build) build_first=0 ;;
    -h|--help) awk 'NR > 1 && !/^#/ {exit} NR > 1 {sub(/^# ?/, ""); print}' "$0"; exit 0 ;;
    *) echo "report: unknown option '$1' (see --help)" >&2; exit 2 ;;
  esac
  shift
done
command_line="scripts/report.sh${args:+ $args}"

build=${SURGSIM_BUILD_DIR:-$root/build}
start_all=$(date +%s)
if [ $build_first = 1 ]; then
  SURGSIM_WITH_REPORT=1 "$root/scripts/setup.sh"
  "$root/scripts/build.sh"
fi
/usr/bin/python3 -c 'import numpy, matplotlib' 2>/dev/null || {
  echo "report: /usr/bin/python3 lacks numpy/matplotlib: run SURGSIM_WITH_REPORT=1 scripts/setup.sh" >&2; exit 1; }
for p in bin/haptic_node bin/visual_node bench/liver_bench bench/node_bench bench/intestine_bench \
         bench/liver_error_bench bench/intestine_error_bench bench/tube_skinning_bench bench/stability_report \
         bench/rt_bench bench/two_hands_bench bench/large_deformation_bench bench/multirate_node_bench bench/frame_bench \
         bench/haptic_signal_bench bench/tool_size_bench bench/abdomen_bench bin/surgsim-web bin/surgsim-device-sim; do
  [ -x "$build/$p" ] || { echo "report: $build/$p not found: run scripts/build.sh first" >&2; exit 1; }
done
build_s=$(( $(date +%s) - start_all ))

rm -rf "$out"
# Every folder a step writes into is made here, on a fresh tree too: liver_bench and node_bench write their CSV files
# only into an existing folder (--out), the haptic node its logs only into one (--log, --stats).
mkdir -p "$out/csv" "$out/logs" "$out/raw/rates" "$out/raw/scale" "$out/plots"
# Tensors and meshes are made by this run (their precompute times are part of the report), not taken from a cache.
export SURGSIM_CACHE_DIR=$out/raw/cache
export SURGSIM_CONFIG_DIR=$root/config
# A DDS domain of our own so that a report never talks to a demo running on the same host.
export SURGSIM_DOMAIN=${SURGSIM_DOMAIN:-57}

# Machine and commit, stated in every file of the report.
{
  echo "{"
  echo "  \"commit\": \"$(git -C "$root" rev-parse HEAD 2>/dev/null || echo unknown)\","
  echo "  \"dirty\": $( [ -z "$(git -C "$root" status --porcelain --untracked-files=no 2>/dev/null)" ] && echo false || echo true),"
  echo "  \"command\": \"$command_line\","
  echo "  \"cpu\": \"$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ *//' | tr -d '"')\","
  echo "  \"cores\": $(nproc),"
  echo "  \"memory_gib\": $(awk '/MemTotal/ {printf "%.1f", $2 / 1048576}' /proc/meminfo),"
  echo "  \"kernel\": \"$(uname -r)\","
  echo "  \"os\": \"$(. /etc/os-release 2>/dev/null && echo "$PRETTY_NAME")\","
  echo "  \"load_at_start\": \"$(cut -d' ' -f1-3 /proc/loadavg)\","
  echo "  \"date\": \"$(date -u +%Y-%m-%dT%H:%M:%SZ)\","
  echo "  \"quick\": $quick,"
  echo "  \"smoke\": $smoke,"
  echo "  \"build_s\": $build_s"
  echo "}"
} >"$out/meta.json"

failed=()
steps_csv=$out/raw/steps.csv
echo "step,seconds,status,log" >"$steps_csv"
# step NAME COMMAND...: runs one part, its output in logs/NAME.log, its time and status in raw/steps.csv.
step() {
  local name=$1; shift
  local t0 status
  t0=$(date +%s%N)
  echo "report: $name ..." >&2
  if "$@" >"$out/logs/$name.log" 2>&1; then status=ok; else status=failed; failed+=("$name"); fi
  local s
  s=$(awk "BEGIN {printf \"%.1f\", ($(date +%s%N) - $t0) / 1e9}")
  echo "$name,$s,$status,logs/$name.log" >>"$steps_csv"
  echo "report: $name $status in $s s" >&2
}

bench=$build/bench
bin=$build/bin
csv=$out/csv

# What --quick and --smoke change, all in one place; every step below is the same command for the three sizes.
size_flag=()                            # liver_error_bench, intestine_error_bench: --quick or --smoke
rates=(100 300 1000 10000)              # haptic rates replayed, each against the 10 kHz one
tube_frames=60
liver_bench_args=(--sizes 500,1500,5000 --cg-columns 60 --repeats 1000)
node_bench_args=(--sizes 1500,5000 --reps 2000)
intestine_bench_args=()
live_s=60                               # 60 000 ticks at 1 kHz: enough to tell 0.1 % missed deadlines from 0.2 %
intestine_s=20
device_points="0.05,0.1,3 0.05,1,0.5 0.2,0.1,3 0.2,1,0.5 0.1,0.5,2"
two_hands_s=5.5                         # the two-instrument trajectory (5 s), held 0.5 s
abdomen_s=8.5                           # the abdomen trajectory (8 s), held 0.5 s
abdomen_args=()
field_args=(--pairs 3 --seconds 30 --rt-seconds 10)   # field_live.py: the field with a browser open, in pairs
intestine_live_max_s=                   # empty: each intestine trajectory's length + 0.5 s
intestine_load_step=${SURGSIM_REPORT_INTESTINE_LOAD_STEP:-2:2:1.5}
tool_size_args=()                       # tool_size_bench: livers at 1500, 5000, 20000 target nodes (the last the reference)
large_deformation_args=()
multirate_node_args=()
scale_sizes=1500,5000,20000
web_s=20
network_s=5
if [ $quick = 1 ]; then
  size_flag=(--quick)
  liver_bench_args=(--sizes 500,1500 --cg-columns 30 --repeats 300)
  node_bench_args=(--sizes 1500 --reps 500)
  intestine_bench_args=(--quick)
  live_s=6
  intestine_s=6
  large_deformation_args=(--quick)
  scale_sizes=1500,5000
  web_s=6
  network_s=2
  field_args=(--pairs 2 --seconds 10 --rt-seconds 10)
fi
if [ $smoke = 1 ]; then
  # Each program still runs and writes every file its section reads, on the least work that does: one size, few
  # repeats, 2 s live runs, two cases of the large-deformation study.
  size_flag=(--smoke)
  rates=(1000 10000)
  tube_frames=10
  liver_bench_args=(--sizes 500 --cg-columns 10 --repeats 50)
  node_bench_args=(--sizes 1500 --reps 100)
  intestine_bench_args=(--quick --only 1)
  live_s=2
  intestine_s=2
  device_points="0.1,0.5,2"
  two_hands_s=2
  abdomen_s=2
  abdomen_args=(--quick)
  field_args=(--pairs 1 --seconds 2 --rt-seconds 2)
  intestine_live_max_s=3
  intestine_load_step=${SURGSIM_REPORT_INTESTINE_LOAD_STEP:-1:1:1.5}
  tool_size_args=(--meshes 500,1500)
  large_deformation_args=(--quick --only indent_10 lift_45 --durations 0.5 --motion-samples 10 --repeats 20)
  multirate_node_args=(--sample-ms 1000)
  scale_sizes=1500
  web_s=2
  network_s=1
fi

# Liver: error against time per frame (solvers, precision, far-field dropping, meshes, non-linear reference).
step liver_error "$bench/liver_error_bench" "${size_flag[@]}" --out "$csv"

# Liver: haptic rate against a 10 kHz reference on replayed trajectories (the real haptic node, tick-exact).
haptic_rates() {
  local trajs=(liver_press_slide liver_fast_stab)
  for t in "${trajs[@]}"; do
    for r in "${rates[@]}"; do
      echo "== $t at $r Hz"
      "$bin/haptic_node" --scene liver --replay "$root/config/trajectories/$t.csv" --speed max --rate "$r" \
        --rt-priority 0 --log "$out/raw/rates/${t}_${r}.csv" --stats "$out/raw/rates/${t}_${r}.json"
    done
  done
}
step haptic_rates haptic_rates

# Intestine: time step, random pairs, level of detail.
step intestine_error "$bench/intestine_error_bench" "${size_flag[@]}" --out "$csv"

# The intestine tube drawn with GPU (vertex-shader) against CPU two-matrix skinning, per level of detail.
step tube_skinning "$bench/tube_skinning_bench" --frames "$tube_frames"

# Stability on stiff and extreme cases.
step stability "$bench/stability_report" --out "$csv"

# Benchmarks: precompute and Table 1, node costs, intestine step, live runs of both nodes.
step liver_bench "$bench/liver_bench" "${liver_bench_args[@]}" --out "$csv"
step node_bench "$bench/node_bench" "${node_bench_args[@]}" --out "$csv"
step intestine_bench "$bench/intestine_bench" "${intestine_bench_args[@]}"

# Live: both nodes on one host, SCHED_FIFO haptic loop at 1 kHz, the liver sweeping for `live_s` seconds; then the
# intestine at its scene rate for `intestine_s` seconds.
live_liver() {
  SURGSIM_OUT=$out/raw/live_liver HAPTIC_ARGS="--rate 1000 --duration $live_s" VISUAL_ARGS="--png-every 50" \
    "$root/scripts/run_local.sh" liver "$root/config/trajectories/liver_sweep.csv"
}
live_intestine() {
  SURGSIM_OUT=$out/raw/live_intestine HAPTIC_ARGS="--duration $intestine_s" VISUAL_ARGS="--png-every 50" \
    "$root/scripts/run_local.sh" intestine "$root/config/trajectories/intestine_push.csv"
}
# The machine's own floor for the same loop: the haptic node's timer with a fixed 50 us busy tick and nothing else,
# for as long as the live run, just before it (misses on a shared VM come and go within minutes).
step rt_floor "$bench/rt_bench" --seconds "$live_s" --label alone --out "$csv"
step live_liver live_liver
# The same live run with the DDS writes back on the loop thread (SURGSIM_HAPTIC_PUBLISHER=inline), right
# after, so the publisher thread's effect on the tick is measured side by side on the same machine state.
live_liver_inline() {
  SURGSIM_HAPTIC_PUBLISHER=inline SURGSIM_OUT=$out/raw/live_liver_inline HAPTIC_ARGS="--rate 1000 --duration $live_s" \
    VISUAL_ARGS="--png-every 50" "$root/scripts/run_local.sh" liver "$root/config/trajectories/liver_sweep.csv"
}
step live_liver_inline live_liver_inline
step live_intestine live_intestine
# What the hand feels. The contact signal (triangle against patch on a slab and the shipped liver), then the
# loop closed through a simulated device over DDS (surgsim-device-sim --physical) at the corners of the grid the
# issue names (mass 0.05-0.2 kg, damping 0.1-1 N s/m, hand force 0.5-3 N): settling, oscillation, resting force.
step haptic_signal "$bench/haptic_signal_bench" --out "$csv"
device_loop() {
  "$root/scripts/device_grid.sh" --out "$out/raw/device" --points "$device_points"
}
step device_loop device_loop
# The instrument's contact (tip size): a 5 mm tip slid at 5 mm depth and pressed 1-10 mm on the shipped liver meshed at
# about 1.4k, 5k and 21k nodes, the footprint contact beside the earlier node patch, and the flat punch on a bonded slab
# against Hayes 1972 (tool_size.csv, tool_size_slide.csv, tool_size_press.csv). Its meshes and tensors go to the run's
# cache ($SURGSIM_CACHE_DIR, as for the other liver benchmarks): liver_error_bench has made the 21k liver's already
# (not with --quick: then this step makes it, about 20 s); the 5k liver is meshed here on first use. --smoke: the livers
# at 500 and 1500 target nodes.
step tool_size "$bench/tool_size_bench" "${tool_size_args[@]}" --out "$csv"
# Both hands. The tick with two instruments x 10 contacts on the shipped two-tool liver and the grasper's
# force while the probe presses, against the grasper alone and a direct solve (two_hands.csv, two_hands_trace.csv);
# then the machine's floor for as long as the live run, just before it (a row of its own in rt_floor.csv: rt_bench
# appends), and both nodes live at 1 kHz on that scene replaying the two-instrument trajectory (5 s, held 0.5 s).
step two_hands "$bench/two_hands_bench" --out "$csv"
step rt_floor_two_hands "$bench/rt_bench" --seconds "$two_hands_s" --label before_live_two_hands --out "$csv"
live_two_hands() {
  SURGSIM_OUT=$out/raw/live_two_hands HAPTIC_ARGS="--rate 1000 --duration $two_hands_s" VISUAL_ARGS="--png-every 50" \
    "$root/scripts/run_local.sh" liver_two_tools "$root/config/trajectories/liver_two_hands.csv"
}
step live_two_hands live_two_hands
# Several organs: the shipped abdomen in abdomen_bench (the tick with both instruments in contact, the wall during the
# trajectory, a simulated device pushed into the floor), the machine's floor just before, both nodes live at 1 kHz.
step abdomen "$bench/abdomen_bench" "${abdomen_args[@]}" --out "$csv"
step rt_floor_abdomen "$bench/rt_bench" --seconds "$abdomen_s" --label before_live_abdomen --out "$csv"
live_abdomen() {
  SURGSIM_OUT=$out/raw/live_abdomen HAPTIC_ARGS="--rate 1000 --duration $abdomen_s" VISUAL_ARGS="--png-every 50" \
    "$root/scripts/run_local.sh" abdomen
}
step live_abdomen live_abdomen
# The field again with surgsim-web and a headless chromium showing the page for the whole run, in pairs after rt_bench.
step field_live /usr/bin/python3 "$root/scripts/field_live.py" "$out/raw/field_live" "${field_args[@]}" --build "$build" \
  --csv "$csv/field_live.csv"
# The intestine live at 1 kHz with the visual node on one host, for both shipped trajectories, each just
# after the machine's floor for as long as it runs (rt_bench, a row of its own in rt_floor.csv), so the missed
# deadlines are set beside the floor of the same minute. The visual node's frame trace (frames/frame_trace.csv: time,
# LOD, frame work, rate) shows the LOD controller around a synthetic load step: every frame's work x1.5 from 2 s after
# the first frame shown, for 2 s (SURGSIM_VISUAL_LOAD_STEP, visual_app.h).
live_intestine_1khz() {  # NAME DURATION_S
  SURGSIM_VISUAL_LOAD_STEP=$intestine_load_step SURGSIM_OUT=$out/raw/live_intestine_$1 \
    HAPTIC_ARGS="--rate 1000 --duration $2" VISUAL_ARGS="--png-every 50" \
    "$root/scripts/run_local.sh" intestine "$root/config/trajectories/intestine_$1.csv"
}
for traj in push lift; do
  # The trajectory's length + 0.5 s (the haptic node's default), at most intestine_live_max_s; the floor for as long.
  traj_s=$(awk -F, -v max="$intestine_live_max_s" '!/^#/ && NF > 1 {t = $1}
    END {t += 0.5; if (max != "" && t > max) t = max; printf "%.1f", t}' "$root/config/trajectories/intestine_$traj.csv")
  step rt_floor_intestine_$traj "$bench/rt_bench" --seconds "$traj_s" --label before_live_intestine_$traj --out "$csv"
  step live_intestine_$traj live_intestine_1khz "$traj" "$traj_s"
done
# Large deformation. Every method (linear, quasi non-linear with cylinder and organ curves, corotational, both)
# against the neo-Hookean Newton reference at 5-30 % indentation, a lobe lifted 45 and 90 degrees and a rigid turn,
# with the tick p99 of each (csv/liver_large_deformation.csv; the organ curves are computed, not cached, in this run).
step large_deformation "$bench/large_deformation_bench" "${large_deformation_args[@]}" --out "$csv"
# The multirate liver in the haptic node along its grasp-and-lift, against Newton on the same targets (csv/multirate_node.csv).
step multirate_node "$bench/multirate_node_bench" "${multirate_node_args[@]}" --out "$csv"
# Patient-size livers. Precompute time and peak memory, haptic tick, visual deformation and render at 1.5k,
# 5k and (not with --quick) 20k nodes, the tensors stored as the scenes store them (raw/scale/*.csv).
step scale_precompute "$bench/liver_bench" --sizes "$scale_sizes" --no-cg --skip-table --out "$out/raw/scale"
step scale_nodes "$bench/node_bench" --sizes "$scale_sizes" --out "$out/raw/scale"
# The web view. JPEG encode per resolution and quality, the machine's floor, then the haptic node's missed
# deadlines without the web view, with it and with a browser showing the page, side by side, and render -> page delay.
step web_figures "$root/scripts/web_figures.sh" "$out/raw/web" "$web_s"
# The round trips: one host (shared memory, UDP), two hosts over veth and through the user-space impairment.
step network "$root/scripts/network_figures.sh" "$network_s" 1000

echo "{\"load_at_end\": \"$(cut -d' ' -f1-3 /proc/loadavg)\", \"total_s\": $(( $(date +%s) - start_all ))}" \
  >"$out/raw/end.json"

# Tables and plots: the sections of scripts/report/sections.py, numbered in that order.
step render /usr/bin/python3 "$root/scripts/report/build.py" "$out"

echo
echo "report: $out/README.md ($(( $(date +%s) - start_all )) s in all)"
if [ ${#failed[@]} -gt 0 ]; then
  echo "report: failed steps: ${failed[*]} (logs in $out/logs)" >&2
  exit 1
fi
