#!/usr/bin/env bash
# Installs the Debian packages surgsim needs, only when some are missing (idempotent). Needs root (or sudo).
set -euo pipefail

packages=(
  build-essential cmake pkg-config
  libeigen3-dev                       # linear algebra
  libfastrtps-dev libfastcdr-dev fastddsgen fastdds-tools   # Fast DDS 2.9 + IDL code generator + discovery server
  cyclonedds-tools cyclonedds-dev     # Cyclone DDS's idlc and headers: the ctest idl_cyclone_idlc (another vendor reads the IDL)
  libsuitesparse-dev libopenblas0-pthread                   # CHOLMOD (OpenBLAS makes it ~2x faster than reference BLAS)
  libosmesa6-dev libpng-dev           # off-screen rendering, PNG frames
  libgmsh-dev                         # tetrahedral mesher (C++ API) for the generated organs
  libyaml-cpp-dev libcli11-dev nlohmann-json3-dev           # scenes, command lines, stats JSON
  libgtest-dev libgmock-dev libbenchmark-dev clang-format   # tests and benchmarks (clang-format: scripts/check_format.sh and its test)
  iproute2 procps                     # two-host tests (namespaces), process control in scripts
  openssl                             # test CA and certificates for the DDS Security profile
  libturbojpeg0-dev libboost-dev      # surgsim-web: JPEG frames (libturbojpeg), HTTP + WebSocket (Boost.Beast, headers)
  chromium chromium-driver python3-selenium fonts-liberation  # the web view's tests: a real headless browser
  calculix-ccx                        # CalculiX (ccx): the independent FEM reference of the surgsim-solve tests
)
[ "${SURGSIM_WITH_VIDEO:-0}" = 1 ] && packages+=(ffmpeg)
[ "${SURGSIM_WITH_REPORT:-0}" = 1 ] && packages+=(python3-numpy python3-matplotlib)   # scripts/report.sh plots
[ "${SURGSIM_WITH_FUZZ:-0}" = 1 ] && packages+=(clang libclang-rt-dev)   # scripts/fuzz.sh: libFuzzer + sanitizers

missing=()
for p in "${packages[@]}"; do
  status=$(dpkg-query -W -f='${Status}' "$p" 2>/dev/null || true)
  [ "$status" = "install ok installed" ] || missing+=("$p")
done

if [ ${#missing[@]} -eq 0 ]; then
  echo "setup: all ${#packages[@]} Debian packages present"
  exit 0
fi

echo "setup: installing ${missing[*]}"
sudo=""
[ "$(id -u)" -eq 0 ] || sudo="sudo"
export DEBIAN_FRONTEND=noninteractive
$sudo apt-get update -q
$sudo apt-get install -y -q --no-install-recommends "${missing[@]}"
