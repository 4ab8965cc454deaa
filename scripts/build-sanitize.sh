#!/usr/bin/env bash
# Configures and builds ./build-asan: everything (but the benchmarks and
# examples) with clang-14 under AddressSanitizer + UBSan, and with the
# coverage hooks of libFuzzer (-fsanitize=fuzzer-no-link), so that one build
# serves both the sanitizer suite (scripts/test.sh) and the readers' fuzz
# binary tests/fuzz/fuzz_readers (scripts/fuzz.sh).
#   -O1 -g1: line tables for the reports at less compile time than -O2 -g
#   (NDEBUG as in RelWithDebInfo: the sanitizers check, not Eigen's asserts);
#   a unity build, as scripts/build.sh.
# Usage: scripts/build-sanitize.sh [target ...]   (default: all)
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
jobs="$(nproc 2>/dev/null || echo 2)"
build="$root/build-asan"
# A build directory configured with another compiler starts over (CMake
# cannot change the compiler of an existing cache).
if [ -f "$build/CMakeCache.txt" ] && ! grep -q '^CMAKE_CXX_COMPILER:[A-Z]*=.*clang++-14$' "$build/CMakeCache.txt"; then
  rm -rf "$build"
fi
launcher=()
command -v ccache >/dev/null && launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
cmake -S "$root" -B "$build" -DCMAKE_CXX_COMPILER=clang++-14 \
  -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g1 -DNDEBUG" \
  -DQPREDUCE_SANITIZE=ON -DQPREDUCE_FUZZ=ON -DCMAKE_UNITY_BUILD=ON \
  -DQPREDUCE_BUILD_BENCH=OFF -DQPREDUCE_BUILD_EXAMPLES=OFF "${launcher[@]}" >/dev/null
if [ $# -eq 0 ]; then
  cmake --build "$build" -j "$jobs"
else
  cmake --build "$build" -j "$jobs" --target "$@"
fi
