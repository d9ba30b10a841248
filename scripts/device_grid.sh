#!/usr/bin/env bash
# The haptic loop closed through a simulated device over DDS: for each (mass, damping, hand force)
# the real haptic_node on the shipped liver (--input device) and surgsim-device-sim --physical, one run after another;
# then a Markdown table of settling time, overshoot, what is left moving in the final window and the resting force.
# A scene with several instruments gets one simulated device per instrument, each with the point's mass,
# damping and hand force, and the table one row per instrument.
#
#   scripts/device_grid.sh [--out DIR] [--rate HZ] [--scene NAME|FILE] [--no-stage] [--points "M,B,F M,B,F ..."]
#
#   --out DIR     where the per-run JSON/CSV go (default: a new temporary folder, printed)
#   --rate HZ     haptic rate (default 1000)
#   --scene S     shipped scene name or YAML file (default liver)
#   --no-stage    the scene with haptic: {coupling_damping: 0, passivity: false} (the force stage off)
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
scene=liver
while [ $# -gt 0 ]; do
  case "$1" in
    --out) out=${2:?--out needs a folder}; shift ;;
    --rate) rate=${2:?--rate needs a value in Hz}; shift ;;
    --scene) scene=${2:?--scene needs a shipped scene name or a YAML file}; shift ;;
    --no-stage) no_stage=1 ;;
    --points) points=${2:?--points needs "M,B,F ..."}; shift ;;
    -h|--help) sed -n '2,15p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
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

if [ $no_stage = 1 ]; then
  # A copy of the scene with the force stage off, its relative file paths made absolute so that it loads from $out.
  src=$scene
  [ -f "$src" ] || src=$root/config/$scene.yaml
  [ -f "$src" ] || { echo "device_grid: --scene '$scene' is neither a file nor a shipped scene (config/*.yaml)" >&2; exit 1; }
  scene=$out/$(basename "${src%.yaml}")_no_stage.yaml
  /usr/bin/python3 - "$src" "$scene" <<'PY'
import os, re, sys
src, dst = sys.argv[1], sys.argv[2]
base = os.path.dirname(os.path.abspath(src))
# "key: value" (block or inside a flow map) whose value is a relative path to a file beside the scene
pair = re.compile(r"(\b[A-Za-z_]+:[ \t]*)([^\s#{}\[\],'\"]+)")
def absolute(m):
    v = m.group(2)
    f = os.path.join(base, v)
    return m.group(1) + (f if not os.path.isabs(v) and os.path.isfile(f) else v)
stage = [("coupling_damping", "0"), ("passivity", "false")]
keys = [k for k, _ in stage]
out, in_haptic, done = [], False, False
for line in open(src):
    line = pair.sub(absolute, line.rstrip("\n"))
    flow = re.match(r"^haptic:\s*\{(.*)\}\s*(#.*)?$", line)
    if flow:  # haptic: {rate_hz: 300, ...}
        kept = [e.strip() for e in flow.group(1).split(",") if e.strip() and e.split(":")[0].strip() not in keys]
        line = "haptic: {" + ", ".join(kept + ["%s: %s" % kv for kv in stage]) + "}"
        done = True
    elif re.match(r"^haptic:\s*(#.*)?$", line):
        out.append(line)
        out += ["  %s: %s" % kv for kv in stage]
        in_haptic = done = True
        continue
    elif in_haptic and re.match(r"^\S", line):
        in_haptic = False
    if in_haptic and line.split(":")[0].strip() in keys:
        continue
    out.append(line)
if not done:
    out += ["haptic:"] + ["  %s: %s" % kv for kv in stage]
open(dst, "w").write("\n".join(out) + "\n")
PY
fi

for point in $points; do
  IFS=, read -r m b f <<<"$point"
  tag="m${m}_b${b}_f${f}"
  echo "device_grid: $scene, mass $m kg, damping $b N s/m, hand $f N at $rate Hz$([ $no_stage = 1 ] && echo ', no force stage')" >&2
  "$bin/haptic_node" --scene "$scene" --input device --rate "$rate" --duration 600 --quiet \
    --stats "$out/${tag}_haptic.json" &
  hpid=$!
  "$bin/surgsim-device-sim" --physical --scene "$scene" --mass "$m" --damping "$b" --hand-force "$f" --duration 6 \
    --window 1 --settle-band 0.001 --rate 1000 --rt-priority 70 --wait-for-haptic 120 \
    --out "$out/${tag}_device.csv" --stats "$out/${tag}_device.json" >"$out/${tag}_device.txt" 2>&1 || true
  kill -INT $hpid 2>/dev/null || true
  wait $hpid || true
done

/usr/bin/python3 - "$out" $points <<'PY'
import json, os, sys
out = sys.argv[1]
runs = []
for point in sys.argv[2:]:
    m, b, f = point.split(",")
    tag = "m%s_b%s_f%s" % (m, b, f)
    try:
        runs.append((m, b, f, tag, json.load(open(os.path.join(out, tag + "_device.json"))),
                     json.load(open(os.path.join(out, tag + "_haptic.json"))), None))
    except (OSError, ValueError) as e:
        runs.append((m, b, f, tag, None, None, e))
# Several instruments: a row per instrument (its device's summary under "instruments"), named in a column of its own.
multi = any(d is not None and len(d.get("instruments", [])) > 1 for _, _, _, _, d, _, _ in runs)
name_col = "instrument | " if multi else ""
print("| mass kg | damping N s/m | hand N | %ssettled | settling s | overshoot mm | p2p last 1 s mm | "
      "velocity reversals last 1 s | resting force N | device / haptic missed deadlines |" % name_col)
print("|---|---|---|%s---|---|---|---|---|---|---|" % ("---|" if multi else ""))
for m, b, f, tag, d, h, e in runs:
    if d is None:
        print("| %s | %s | %s | %srun failed: %s (see %s) | | | | | | |" % (
            m, b, f, "| " if multi else "", e, os.path.join(out, tag + "_device.txt")))
        continue
    for s in (d["instruments"] if multi else [d]):
        print("| %s | %s | %s | %s%s | %.3f | %.1f | %.2f | %d | %.3f | %d / %d |" % (
            m, b, f, (s["name"] + " | ") if multi else "", s["settled"], s["settling_time_s"], 1e3 * s["overshoot_m"],
            1e3 * s["position_p2p_window_m"], s["velocity_sign_changes_window"], s["force_final_n"],
            d.get("deadline_misses", 0), h.get("deadline_misses", 0)))
print("\nrun files: %s" % out)
PY
