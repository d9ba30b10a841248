#!/usr/bin/env bash
# The main job: installs missing Debian packages, builds, then runs both nodes on one host on the default liver
# scene replaying the shipped poke trajectory. Frames and JSON summaries go to out/liver/ (SURGSIM_OUT overrides).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
"$root/scripts/setup.sh"
"$root/scripts/build.sh"
exec "$root/scripts/run_local.sh" liver "$root/config/trajectories/liver_poke.csv"
