#!/usr/bin/env bash
# Two "machines" on one host: two network namespaces joined by a veth pair (or, with --impair, by
# surgsim-netem through TAP devices), the haptic node in one and the visual node in the other, talking over UDPv4
# only. The visual node also gets its own /dev/shm, so shared memory cannot carry anything between them.
# Prints and writes (OUT/summary.json) frames received, round trip, haptic rate and missed deadlines.
#
#   scripts/run_two_hosts.sh [--scene liver] [--duration S] [--rate HZ] [--transport udp|peers|ds]
#                            [--impair "delay=5ms,jitter=2ms,loss=5%[,reorder=1%]"] [--seed N]
#                            [--wire user|kernel] [--render] [--out DIR]
#   --transport udp    surgsim_udp: multicast discovery over the link (default)
#               peers  surgsim_udp_peers: unicast discovery to 192.168.77.1/.2, multicast switched off on the link
#               ds     surgsim_ds_client: `fastdds discovery` runs in the haptic namespace (port 11888, given to the
#                      nodes by SURGSIM_DISCOVERY_SERVER), multicast switched off on the link
#   --wire user        --impair through surgsim-netem and TAP devices (default: seeded, the same on every kernel)
#          kernel      --impair with the kernel's netem qdisc on the veth, where the kernel has it (no seed)
# Needs root (CAP_SYS_ADMIN and CAP_NET_ADMIN: ip netns, veth, TAP, mount). If the machine refuses one of them the
# script says which and exits with status 4. Namespaces, links and every process started in them are removed on
# exit. Environment: SURGSIM_BUILD_DIR (default build), HAPTIC_ARGS, VISUAL_ARGS.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
build=${SURGSIM_BUILD_DIR:-$root/build}
bin=$build/bin
export SURGSIM_CACHE_DIR=${SURGSIM_CACHE_DIR:-$build/cache}
export SURGSIM_CONFIG_DIR=${SURGSIM_CONFIG_DIR:-$root/config}

scene=liver duration="" rate="" transport=udp impair="" seed=1 wire=user render=0 out=""
while [ $# -gt 0 ]; do
  case "$1" in
    --scene) scene=$2; shift 2 ;;
    --duration) duration=$2; shift 2 ;;
    --rate) rate=$2; shift 2 ;;
    --transport) transport=$2; shift 2 ;;
    --impair) impair=$2; shift 2 ;;
    --seed) seed=$2; shift 2 ;;
    --wire) wire=$2; shift 2 ;;
    --render) render=1; shift ;;
    --out) out=$2; shift 2 ;;
    -h|--help) awk 'NR > 1 && /^#/ { sub(/^# ?/, ""); print; next } NR > 1 { exit }' "$0"; exit 0 ;;
    *) echo "run_two_hosts: unknown option '$1' (see --help)" >&2; exit 2 ;;
  esac
done
case "$transport" in
  udp) profile=surgsim_udp ;;
  peers) profile=surgsim_udp_peers ;;
  ds) profile=surgsim_ds_client ;;
  *) echo "run_two_hosts: --transport '$transport' is not udp, peers or ds" >&2; exit 2 ;;
esac
case "$wire" in user|kernel) ;; *) echo "run_two_hosts: --wire '$wire' is not user or kernel" >&2; exit 2 ;; esac
out=${out:-$root/out/two_hosts_$transport${impair:+_impaired}}
need=(haptic_node visual_node)
[ -n "$impair" ] && [ "$wire" = user ] && need+=(surgsim-netem)
for p in "${need[@]}"; do
  [ -x "$bin/$p" ] || { echo "run_two_hosts: $bin/$p not found: build it first (scripts/build.sh)" >&2; exit 1; }
done
[ "$transport" = ds ] && ! command -v fastdds >/dev/null &&
  { echo "run_two_hosts: fastdds not found (Debian package fastdds-tools)" >&2; exit 1; }
rm -rf "$out"
mkdir -p "$out"

# Names unique to this run, so parallel runs never meet: namespaces and the (<= 15 character) link names.
id=$(( $$ % 100000 ))$(( RANDOM % 100 ))
ns_h=surgsim-h-$id
ns_v=surgsim-v-$id
addr_h=192.168.77.1
addr_v=192.168.77.2
dev=surg0
netem_pid=""

refused() {  # a capability the machine refuses: say which, exit 4 (tests fail on it, never skip)
  echo "run_two_hosts: the machine refused: $1" >&2
  exit 4
}
cleanup() {
  set +e
  for ns in "$ns_h" "$ns_v"; do
    if [ -e "/run/netns/$ns" ]; then
      for pid in $(ip netns pids "$ns" 2>/dev/null); do kill -KILL "$pid" 2>/dev/null; done
    fi
  done
  if [ -n "$netem_pid" ]; then kill -TERM "$netem_pid" 2>/dev/null; wait "$netem_pid" 2>/dev/null; fi
  for ns in "$ns_h" "$ns_v"; do ip netns del "$ns" 2>/dev/null; done
}
trap cleanup EXIT
trap 'exit 130' INT TERM

[ "$(id -u)" = 0 ] || refused "not root (uid $(id -u)); namespaces, veth and TAP devices need CAP_SYS_ADMIN and CAP_NET_ADMIN"
err=$(ip netns add "$ns_h" 2>&1) || refused "ip netns add $ns_h: $err"
err=$(ip netns add "$ns_v" 2>&1) || refused "ip netns add $ns_v: $err"
for ns in "$ns_h" "$ns_v"; do ip -n "$ns" link set lo up; done

# The link: a veth pair, or two TAP devices bridged by surgsim-netem in user space (these kernels have no netem).
if [ -z "$impair" ] || [ "$wire" = kernel ]; then
  link="veth"
  err=$(ip link add "h$id" netns "$ns_h" type veth peer name "v$id" netns "$ns_v" 2>&1) ||
    refused "ip link add ... type veth: $err"
  ip -n "$ns_h" link set "h$id" name "$dev"
  ip -n "$ns_v" link set "v$id" name "$dev"
else
  link="TAP + surgsim-netem ($impair, seed $seed)"
  "$bin/surgsim-netem" --a "/run/netns/$ns_h:$dev" --b "/run/netns/$ns_v:$dev" --impair "$impair" --seed "$seed" \
    --stats "$out/netem_stats.json" --ready "$out/netem.ready" >"$out/netem.log" 2>&1 &
  netem_pid=$!
  for _ in $(seq 100); do
    [ -e "$out/netem.ready" ] && break
    kill -0 "$netem_pid" 2>/dev/null || refused "surgsim-netem: $(cat "$out/netem.log")"
    sleep 0.05
  done
  [ -e "$out/netem.ready" ] || refused "surgsim-netem did not create its TAP devices: $(cat "$out/netem.log")"
fi
if [ -n "$impair" ] && [ "$wire" = kernel ]; then
  # The same impairment with the kernel's netem on both ends of the veth (each direction delayed once).
  delay=0ms jitter="" loss="" reorder=""
  IFS=, read -ra items <<< "$impair"
  for item in "${items[@]}"; do
    case "$item" in
      delay=*) delay=${item#delay=} ;;
      jitter=*) jitter=${item#jitter=} ;;
      loss=*) loss=${item#loss=} ;;
      reorder=*) reorder=${item#reorder=} ;;
      seed=*|"") ;;
      *) echo "run_two_hosts: --impair: unknown key in '$item' (delay, jitter, loss, reorder)" >&2; exit 2 ;;
    esac
  done
  netem=(delay "$delay" ${jitter:+"$jitter"} ${loss:+loss "$loss"} ${reorder:+reorder "$reorder"})
  link="veth + kernel netem (${netem[*]})"
  for ns in "$ns_h" "$ns_v"; do
    err=$(ip netns exec "$ns" tc qdisc add dev "$dev" root netem "${netem[@]}" 2>&1) ||
      refused "tc qdisc add ... netem ${netem[*]}: $err (use --wire user)"
  done
fi
ip -n "$ns_h" addr add "$addr_h/24" dev "$dev"
ip -n "$ns_v" addr add "$addr_v/24" dev "$dev"
for ns in "$ns_h" "$ns_v"; do
  ip -n "$ns" link set "$dev" up
  if [ "$transport" = udp ]; then
    ip -n "$ns" route add 224.0.0.0/4 dev "$dev"  # SPDP multicast (239.255.0.1) leaves through the link
  else
    ip -n "$ns" link set "$dev" multicast off      # prove the unicast discovery needs no multicast
  fi
done
dds_env=(SURGSIM_DDS_PARTICIPANT=$profile)
if [ "$transport" = ds ]; then
  ds_port=11888
  ip netns exec "$ns_h" fastdds discovery -i 0 -l "$addr_h" -p "$ds_port" >"$out/discovery_server.log" 2>&1 &
  disown  # killed with everything else in the namespace on exit
  dds_env+=(SURGSIM_DISCOVERY_SERVER=$addr_h:$ds_port)
fi

# Visual node ("visual host"): its own /dev/shm (tmpfs in a private mount namespace), headless unless --render.
visual_args=(--scene "$scene" --stats "$out/visual_stats.json" --out "$out/frames")
[ "$render" = 1 ] || visual_args+=(--headless)
mount_probe=$(ip netns exec "$ns_v" unshare --mount sh -c 'mount -t tmpfs tmpfs /dev/shm' 2>&1) ||
  refused "private /dev/shm for the visual host (unshare --mount + tmpfs): $mount_probe"
ip netns exec "$ns_v" env "${dds_env[@]}" unshare --mount sh -c 'mount -t tmpfs tmpfs /dev/shm && exec "$@"' sh \
  "$bin/visual_node" "${visual_args[@]}" ${VISUAL_ARGS:-} >"$out/visual.log" 2>&1 &
visual=$!

# Reachability, checked while the visual node loads (a fresh link takes about a second to carry). No ping here:
# a TCP connect to a closed port is refused only if the other side answered.
ip netns exec "$ns_v" python3 -c "
import socket, sys
s = socket.socket(); s.settimeout(3)
try: s.connect(('$addr_h', 9))
except ConnectionRefusedError: sys.exit(0)
except OSError as e: print(e); sys.exit(1)
" >"$out/link_check.log" 2>&1 ||
  refused "no IPv4 connectivity between the namespaces over the $link link: $(cat "$out/link_check.log")"


# Haptic node ("haptic host"): waits for the visual node to match, then replays the scene's trajectory.
haptic_args=(--scene "$scene" --wait-for-visual 20 --stats "$out/haptic_stats.json" --log "$out/haptic_log.csv")
[ -n "$duration" ] && haptic_args+=(--duration "$duration")
[ -n "$rate" ] && haptic_args+=(--rate "$rate")
start=$(date +%s%N)
if ! ip netns exec "$ns_h" env "${dds_env[@]}" "$bin/haptic_node" "${haptic_args[@]}" ${HAPTIC_ARGS:-} \
     >"$out/haptic.log" 2>&1; then
  echo "run_two_hosts: haptic_node failed:" >&2
  cat "$out/haptic.log" >&2
  exit 1
fi
sleep 0.5  # the last frames and echoes
kill -INT "$visual" 2>/dev/null || true
if ! wait "$visual"; then
  echo "run_two_hosts: visual_node failed:" >&2
  cat "$out/visual.log" >&2
  exit 1
fi
end=$(date +%s%N)
if [ -n "$netem_pid" ]; then kill -TERM "$netem_pid"; wait "$netem_pid" || true; netem_pid=""; fi

# Summary: the figures listed at the top, from the two stats files (and the wire's counters when impaired).
python3 - "$out" "$transport" "$profile" "$link" "$(( (end - start) / 1000000 ))" <<'EOF'
import json, os, sys
out, transport, profile, link, wall_ms = sys.argv[1:6]
h = json.load(open(os.path.join(out, "haptic_stats.json")))
v = json.load(open(os.path.join(out, "visual_stats.json")))
rt = h["round_trip_us"]
s = {
    "transport": transport, "dds_participant": profile, "link": link, "wall_ms": int(wall_ms),
    "frames_received": v["frames_received"], "frames_rendered": v["frames_rendered"],
    "round_trip_us": rt, "round_trips": rt.get("count", 0),
    "rate_hz": h["rate_hz"], "achieved_hz": h["achieved_hz"], "ticks": h["ticks"],
    "deadline_misses": h["deadline_misses"], "tick_us": h["tick_us"],
    "scene_hash_ok": v["scene_hash_ok"], "first_frame_ms": v.get("first_frame_ms"),
    "haptic_dds_participant": h.get("dds_participant"), "visual_dds_participant": v.get("dds_participant"),
}
netem = os.path.join(out, "netem_stats.json")
if os.path.exists(netem):
    s["netem"] = json.load(open(netem))
json.dump(s, open(os.path.join(out, "summary.json"), "w"), indent=2)
print(f"run_two_hosts: {transport} ({profile}) over {link}")
print(f"  frames received   {s['frames_received']} (visual), scene match {s['scene_hash_ok']}")
print(f"  round trip        p50 {rt.get('p50', 0):.0f} us, p99 {rt.get('p99', 0):.0f} us, max {rt.get('max', 0):.0f} us "
      f"({s['round_trips']} echoes)")
print(f"  haptic rate       {s['achieved_hz']:.1f} Hz (target {s['rate_hz']:.0f} Hz), tick p99 {h['tick_us']['p99']:.1f} us")
print(f"  missed deadlines  {s['deadline_misses']} of {s['ticks']} ticks")
if "netem" in s:
    n = s["netem"]
    for d in ("a_to_b", "b_to_a"):
        print(f"  wire {d:7s}      {n[d]['received']} frames, {n[d]['dropped']} dropped, {n[d]['reordered']} reordered")
print(f"  files             {out}/summary.json, haptic_stats.json, visual_stats.json, *.log")
EOF
