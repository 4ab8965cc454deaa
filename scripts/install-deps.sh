#!/usr/bin/env bash
# Installs the Debian 12 packages qpreduce builds against, only those missing.
# Run as root (or with sudo available). Safe to run again.
set -euo pipefail
packages=(
  build-essential cmake git pkg-config
  libeigen3-dev libopenblas-dev libsuitesparse-dev libceres-dev libspectra-dev libomp-dev
  libfmt-dev catch2 libbenchmark-dev libcli11-dev nlohmann-json3-dev zlib1g-dev
  libimgui-dev libstb-dev libglfw3-dev libgl-dev libgl1-mesa-dri xvfb xauth mesa-utils
  pybind11-dev python3-dev python3-numpy python3-scipy python3-pytest python3-matplotlib
  clang-14 libclang-rt-14-dev
  valgrind
  libopenmpi-dev openmpi-bin libmumps-dev libmumps-ptscotch-dev
)
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#packages[@]} packages present"
  exit 0
fi
echo "install-deps: installing ${missing[*]}"
SUDO=""
[ "$(id -u)" -eq 0 ] || SUDO="sudo"
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
