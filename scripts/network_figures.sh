#!/usr/bin/env bash
# The network figures as one markdown table: round trip (haptic -> visual -> haptic, on the haptic clock)
# p50/p99/max, haptic rate and missed deadlines, for one host (shared memory and UDP), two hosts (network namespaces,
# veth, UDP) and two hosts through surgsim-netem (no impairment, then 5 ms +- 2 ms and 5 % loss each way).
#   scripts/network_figures.sh [SECONDS] [RATE_HZ]      (default 10 s at 1000 Hz; needs root for the two-host rows)
# Runs with the visual node headless. Environment: SURGSIM_BUILD_DIR (default build).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
export SURGSIM_BUILD_DIR=${SURGSIM_BUILD_DIR:-$root/build}
seconds=${1:-10}
rate=${2:-1000}
out=$root/out/network_figures
rm -rf "$out"
mkdir -p "$out"

row() {  # label summary.json-or-dir
  python3 - "$1" "$2" <<'EOF'
import json, os, sys
label, where = sys.argv[1:3]
if os.path.isdir(where):
    h = json.load(open(os.path.join(where, "haptic_stats.json")))
    v = json.load(open(os.path.join(where, "visual_stats.json")))
else:
    s = json.load(open(where))
    d = os.path.dirname(where)
    h = json.load(open(os.path.join(d, "haptic_stats.json")))
    v = json.load(open(os.path.join(d, "visual_stats.json")))
rt = h["round_trip_us"]
print(f"| {label} | {rt['p50']/1000:.3f} | {rt['p99']/1000:.3f} | {rt['max']/1000:.2f} | {rt['count']} | "
      f"{v['frames_received']} / {h['ticks']} | {h['achieved_hz']:.1f} | {h['deadline_misses']} | "
      f"{h['tick_us']['p99']:.0f} |")
EOF
}

echo "| setup | RTT p50 ms | RTT p99 ms | RTT max ms | echoes | frames received / sent | haptic Hz | missed deadlines | tick p99 us |"
echo "|---|---|---|---|---|---|---|---|---|"
for profile in surgsim_shm surgsim_default; do
  SURGSIM_OUT=$out/one_host_$profile SURGSIM_DOMAIN=${SURGSIM_DOMAIN:-0} \
    HAPTIC_ARGS="--rate $rate --duration $seconds --dds-participant $profile" \
    VISUAL_ARGS="--headless --dds-participant $profile" "$root/scripts/run_local.sh" liver >/dev/null 2>&1
  row "one host, $profile" "$out/one_host_$profile"
done
HAPTIC_ARGS="" "$root/scripts/run_two_hosts.sh" --rate "$rate" --duration "$seconds" --out "$out/two_hosts" >/dev/null
row "two hosts, veth, surgsim_udp" "$out/two_hosts/summary.json"
"$root/scripts/run_two_hosts.sh" --rate "$rate" --duration "$seconds" --impair "delay=0ms" --out "$out/two_hosts_tap" >/dev/null
row "two hosts, TAP + surgsim-netem, no impairment" "$out/two_hosts_tap/summary.json"
"$root/scripts/run_two_hosts.sh" --rate "$rate" --duration "$seconds" --impair "delay=5ms,jitter=2ms,loss=5%" \
  --seed 1 --out "$out/two_hosts_impaired" >/dev/null
row "two hosts, 5 ms +- 2 ms, 5 % loss" "$out/two_hosts_impaired/summary.json"
echo
echo "($rate Hz haptic loop, $seconds s each, visual node headless; files in $out)"
