#!/usr/bin/env bash
# Installs what is missing, then configures and builds qpreduce (Release) in ./build.
# Usage: scripts/build.sh [extra cmake -D options]
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$root/scripts/install-deps.sh"
jobs="$(nproc 2>/dev/null || echo 2)"
# A unity build (CMake's CMAKE_UNITY_BUILD: batches of 8 sources per
# compiler run) parses Eigen and instantiates its kernels once a batch, not
# once a file (the build times: docs/performance.md, "Build time").
cmake -S "$root" -B "$root/build" -DCMAKE_BUILD_TYPE=Release -DCMAKE_UNITY_BUILD=ON "$@" >/dev/null
cmake --build "$root/build" -j "$jobs"
