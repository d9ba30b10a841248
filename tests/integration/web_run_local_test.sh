#!/usr/bin/env bash
# scripts/run_local.sh liver --web TRAJECTORY: the three processes start, the URL is printed with its token,
# surgsim-web receives the visual node's frames and the haptic node's contact frames while the trajectory replays, and
# everything stops cleanly at the end. Usage: web_run_local_test.sh SOURCE_DIR BUILD_DIR OUT_DIR
set -euo pipefail
src=$1 build=$2 out=$3
rm -rf "$out"
source "$(dirname "$0")/domain.sh"
surgsim_reserve_domain 43
export SURGSIM_BUILD_DIR=$build SURGSIM_OUT=$out WEB_PORT=0
log=$(mktemp)
trap 'rm -f "$log"' EXIT
"$src/scripts/run_local.sh" liver --web "$src/config/trajectories/liver_poke.csv" >"$log" 2>&1 || {
  cat "$log"; echo "web_run_local_test: run_local.sh failed" >&2; exit 1; }
grep -q '^run_local: open http://127.0.0.1:[0-9]*/?token=[0-9a-f]\{32\}$' "$log" || {
  cat "$log"; echo "web_run_local_test: no URL with a 32-digit token printed" >&2; exit 1; }
/usr/bin/python3 - "$out/web_stats.json" <<'PY'
import json, sys
w = json.load(open(sys.argv[1]))
assert w['frames_received'] > 10, w['frames_received']
assert w['contact_frames'] > 100, w['contact_frames']
assert w['scene']['name'] == 'liver', w.get('scene')
print('web_run_local_test: %d frames, %d contact frames through surgsim-web' % (w['frames_received'], w['contact_frames']))
PY
