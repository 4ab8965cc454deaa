#!/usr/bin/env bash
# Installs what is missing, builds, and runs every test:
#   1. the Release build and its full Catch2 suite (ctest);
#   2. the same suite built with clang-14, AddressSanitizer + UBSan
#      (./build-asan, scripts/build-sanitize.sh);
#   3. tiny consumer projects built against the installed package config
#      (the engine and deformer without Ceres; the reference component; in a
#      build with MPI, qpreduce::distributed under mpirun -np 2), and
#      the Python tests of the solver, deformer and refine run against the
#      Python package as installed;
#   4. the readers' libFuzzer binary (from the same ./build-asan): the
#      corpus of tests/fuzz replayed, then each reader fuzzed for
#      QPR_FUZZ_SECONDS (default 6) seconds (scripts/fuzz.sh,
#      docs/robustness.md).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
jobs="$(nproc 2>/dev/null || echo 2)"
bash "$root/scripts/build.sh"
echo "   (the Release build done at ${SECONDS}s)"

echo "== tests (Release) (${SECONDS}s since the start)"
ctest --test-dir "$root/build" --output-on-failure -j "$jobs"

echo "== tests (ASan + UBSan, clang-14) (${SECONDS}s since the start)"
# One clang sanitizer build (scripts/build-sanitize.sh) serves this suite
# and the readers' fuzz binary (step 4).
bash "$root/scripts/build-sanitize.sh"
echo "   (the sanitizer build done at ${SECONDS}s)"
# OMP_WAIT_POLICY=passive: LLVM's libomp lets a finished team spin for 200 ms
# by default, and with a test on each core that spinning takes the other
# test's core (qpr deform --refine: 101 s spinning, 32 s passive).
ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1 OMP_WAIT_POLICY=passive \
  ctest --test-dir "$root/build-asan" --output-on-failure -j "$jobs"

echo "== installed package consumers (${SECONDS}s since the start)"
# consumer: the engine and the deformer, with Ceres hidden from find_package
# (they must not need it); reference_consumer: the optional reference component.
prefix="$root/build/install-test"
rm -rf "$prefix" "$root/build/consumer" "$root/build/reference_consumer" "$root/build/distributed_consumer"
cmake --install "$root/build" --prefix "$prefix" >/dev/null
cmake -S "$root/tests/packaging/consumer" -B "$root/build/consumer" -DCMAKE_PREFIX_PATH="$prefix" \
  -DCMAKE_DISABLE_FIND_PACKAGE_Ceres=ON >/dev/null
cmake --build "$root/build/consumer" -j "$jobs"
"$root/build/consumer/consumer"
cmake -S "$root/tests/packaging/reference_consumer" -B "$root/build/reference_consumer" \
  -DCMAKE_PREFIX_PATH="$prefix" >/dev/null
cmake --build "$root/build/reference_consumer" -j "$jobs"
"$root/build/reference_consumer/reference_consumer"
# distributed_consumer: qpreduce::distributed, in a package built with MPI only.
if grep -q '^QPREDUCE_WITH_MPI:BOOL=ON$' "$root/build/CMakeCache.txt"; then
  mpiexec="$(sed -n 's/^MPIEXEC_EXECUTABLE:[A-Z]*=//p' "$root/build/CMakeCache.txt")"
  cmake -S "$root/tests/packaging/distributed_consumer" -B "$root/build/distributed_consumer" \
    -DCMAKE_PREFIX_PATH="$prefix" >/dev/null
  cmake --build "$root/build/distributed_consumer" -j "$jobs"
  OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMP_NUM_THREADS=1 \
    "$mpiexec" --oversubscribe -np 2 "$root/build/distributed_consumer/distributed_consumer"
fi

echo "== installed Python package (${SECONDS}s since the start)"
# The package `cmake --install` put under the prefix (the interpreter's
# site-packages layout), imported from outside the checkout with nothing of
# the build tree on the path: the solver, deformer and refine tests and the
# examples run against it.
python="$(sed -n 's/^_Python3_EXECUTABLE:INTERNAL=//p' "$root/build/CMakeCache.txt")"
module="$(find "$prefix" -name '_qpreduce*.so' -print -quit)"
if [ -z "$module" ]; then
  echo "the Python package was not installed under $prefix" >&2
  exit 1
fi
site="$(dirname "$(dirname "$module")")"
(cd "$prefix" && PYTHONPATH="$site" QPREDUCE_EXPECT_PACKAGE_DIR="$site" OMP_NUM_THREADS="$jobs" \
  "$python" -m pytest -q -p no:cacheprovider "$root/tests/python/test_solver.py" \
  "$root/tests/python/test_deform.py" "$root/tests/python/test_refine.py" "$root/tests/python/test_examples.py")

echo "== fuzzing the readers (libFuzzer, ASan + UBSan) (${SECONDS}s since the start)"
bash "$root/scripts/fuzz.sh"
echo "== scripts/test.sh done in ${SECONDS}s"
