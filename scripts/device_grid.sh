#!/usr/bin/env bash
# The haptic loop closed through a simulated device over DDS (issue 14, part 5): for each (mass, damping, hand force)
# the real haptic_node on the shipped liver (--input device) and surgsim-device-sim --physical, one run after another;
# then a Markdown table of settling time, overshoot, what is left moving in the final window and the resting force.
#
#   scripts/device_grid.sh [--out DIR] [--rate HZ] [--no-stage] [--points "M,B,F M,B,F ..."]
#
#   --out DIR     where the per-run JSON/CSV go (default: a new temporary folder, printed)
#   --rate HZ     haptic rate (default 1000)
#   --no-stage    the liver scene with haptic: {coupling_damping: 0, passivity: false} (the force stage off)
#   --points ...  mass kg, damping N s/m, hand force N per run (default: the issue's grid, {0.05, 0.1, 0.2} x
#                 {0.1, 0.5, 1} x {0.5, 1, 2, 3}, 36 runs, about 5 minutes)
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
build=${SURGSIM_BUILD_DIR:-$root/build}
bin=$build/bin
out=""
rate=1000
no_stage=0
points=""
while [ $# -gt 0 ]; do
  case "$1" in
    --out) out=${2:?--out needs a folder}; shift ;;
    --rate) rate=${2:?--rate needs a value in Hz}; shift ;;
    --no-stage) no_stage=1 ;;
    --points) points=${2:?--points needs "M,B,F ..."}; shift ;;
    -h|--help) sed -n '2,13p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "device_grid: unknown option '$1' (see --help)" >&2; exit 2 ;;
  esac
  shift
done
for p in haptic_node surgsim-device-sim; do
  [ -x "$bin/$p" ] || { echo "device_grid: $bin/$p not found: run scripts/build.sh first" >&2; exit 1; }
done
if [ -z "$points" ]; then
  for m in 0.05 0.1 0.2; do for b in 0.1 0.5 1; do for f in 0.5 1 2 3; do points="$points $m,$b,$f"; done; done; done
fi
[ -n "$out" ] || out=$(mktemp -d /tmp/surgsim-device-grid-XXXXXX)
mkdir -p "$out"
export SURGSIM_DOMAIN=${SURGSIM_DOMAIN:-64}
export SURGSIM_CONFIG_DIR=${SURGSIM_CONFIG_DIR:-$root/config}

scene=liver
if [ $no_stage = 1 ]; then
  # The shipped liver with the force stage off; its relative paths made absolute so the copy loads from $out.
  scene=$out/liver_no_stage.yaml
  sed -e "s|: curves/|: $root/config/curves/|" -e "s|^trajectory: |trajectory: $root/config/|" \
      -e "s|^  rate_hz: 300$|  rate_hz: 300\n  coupling_damping: 0\n  passivity: false|" "$root/config/liver.yaml" >"$scene"
fi

for point in $points; do
  IFS=, read -r m b f <<<"$point"
  tag="m${m}_b${b}_f${f}"
  echo "device_grid: mass $m kg, damping $b N s/m, hand $f N at $rate Hz$([ $no_stage = 1 ] && echo ', no force stage')" >&2
  "$bin/haptic_node" --scene "$scene" --input device --rate "$rate" --duration 600 --quiet \
    --stats "$out/${tag}_haptic.json" &
  hpid=$!
  "$bin/surgsim-device-sim" --physical --scene liver --mass "$m" --damping "$b" --hand-force "$f" --duration 6 \
    --window 1 --settle-band 0.001 --rate 1000 --rt-priority 70 --wait-for-haptic 120 \
    --out "$out/${tag}_device.csv" --stats "$out/${tag}_device.json" >"$out/${tag}_device.txt" 2>&1 || true
  kill -INT $hpid 2>/dev/null || true
  wait $hpid || true
done

/usr/bin/python3 - "$out" $points <<'PY'
import json, os, sys
out = sys.argv[1]
print("| mass kg | damping N s/m | hand N | settled | settling s | overshoot mm | p2p last 1 s mm | "
      "velocity reversals last 1 s | resting force N | device / haptic missed deadlines |")
print("|---|---|---|---|---|---|---|---|---|---|")
for point in sys.argv[2:]:
    m, b, f = point.split(",")
    tag = "m%s_b%s_f%s" % (m, b, f)
    try:
        d = json.load(open(os.path.join(out, tag + "_device.json")))
        h = json.load(open(os.path.join(out, tag + "_haptic.json")))
    except (OSError, ValueError) as e:
        print("| %s | %s | %s | run failed: %s (see %s) | | | | | | |" % (m, b, f, e, os.path.join(out, tag + "_device.txt")))
        continue
    print("| %s | %s | %s | %s | %.3f | %.1f | %.2f | %d | %.3f | %d / %d |" % (
        m, b, f, d["settled"], d["settling_time_s"], 1e3 * d["overshoot_m"], 1e3 * d["position_p2p_window_m"],
        d["velocity_sign_changes_window"], d["force_final_n"], d.get("deadline_misses", 0), h.get("deadline_misses", 0)))
print("\nrun files: %s" % out)
PY
