#!/usr/bin/env bash
# Fuzzes every reader with libFuzzer under AddressSanitizer + UBSan:
#   1. builds tests/fuzz's fuzz_readers (one binary; QPR_FUZZ_TARGET names
#      the reader) in ./build-asan, the clang-14 sanitizer build of
#      scripts/build-sanitize.sh (scripts/test.sh builds it all first);
#   2. replays tests/fuzz/corpus/<target>/ (seeds and the inputs that once
#      crashed: regressions) — any failure stops the script;
#   3. fuzzes each target for QPR_FUZZ_SECONDS seconds (default 6) from that
#      corpus and ../shared/data files of its kind, with allocations capped
#      (a reader must not reserve what its file cannot hold).
# A finding is written to build-asan/fuzz/findings/<target>-crash-*; replay
# it with QPR_FUZZ_TARGET=<target> build-asan/tests/fuzz/fuzz_readers <file>
# and copy it into tests/fuzz/corpus/<target>/ once fixed.
# Usage: scripts/fuzz.sh [target ...]
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
jobs="$(nproc 2>/dev/null || echo 2)"
seconds="${QPR_FUZZ_SECONDS:-6}"
bin="$root/build-asan/tests/fuzz/fuzz_readers"
build="$root/build-asan/fuzz"  # findings, grown corpora, seeds, scratch files
all=(off obj ply medit tetgen sel def id anim scene mtx_sparse mtx_dense manifest cache)
targets=("$@")
[ $# -eq 0 ] && targets=("${all[@]}")

bash "$root/scripts/build-sanitize.sh" fuzz_readers

# Files of ../shared/data a target takes as seeds (by extension).
seeds_of() {
  case "$1" in
    off) echo "off" ;; obj) echo "obj" ;; ply) echo "ply" ;; medit) echo "mesh" ;; tetgen) echo "node" ;;
    sel) echo "sel" ;; def) echo "def" ;; id) echo "id" ;; anim) echo "anim" ;; *) echo "" ;;
  esac
}

mkdir -p "$build/findings"
export QPR_FUZZ_TMP="$build/tmp"  # the targets' scratch files, removed at the end
rm -rf "$QPR_FUZZ_TMP" && mkdir -p "$QPR_FUZZ_TMP"
trap 'kill $(jobs -p) 2>/dev/null || true; rm -rf "$QPR_FUZZ_TMP"' EXIT
export ASAN_OPTIONS="detect_leaks=1:allocator_may_return_null=0"
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1"
# One target: its corpus replayed, then fuzzed; its lines printed together
# when it ends (targets run $jobs at a time, each on one core).
fuzz_target() {
  local t="$1"
  export QPR_FUZZ_TARGET="$t"
  local corpus="$root/tests/fuzz/corpus/$t"
  local work="$build/corpus/$t"
  mkdir -p "$work"
  local head="== fuzz_$t: replay $(ls "$corpus" | wc -l) inputs, then ${seconds} s"
  "$bin" -runs=0 -rss_limit_mb=2048 -malloc_limit_mb=256 "$corpus" >"$build/findings/$t.replay.log" 2>&1 ||
    { echo "$head"; tail -40 "$build/findings/$t.replay.log"; return 1; }
  local ext extra=()
  ext="$(seeds_of "$t")"
  if [ -n "$ext" ] && [ -d "$root/../shared/data" ]; then
    local seed_dir="$build/seeds/$t"
    mkdir -p "$seed_dir"
    find "$root/../shared/data" -iname "*.$ext" -size -4M -exec cp -t "$seed_dir" {} + 2>/dev/null || true
    extra=("$seed_dir")
  fi
  "$bin" -max_total_time="$seconds" -max_len=16384 -timeout=10 -rss_limit_mb=2048 -malloc_limit_mb=256 \
    -print_final_stats=1 -artifact_prefix="$build/findings/$t-" "$work" "$corpus" "${extra[@]}" \
    >"$build/findings/$t.log" 2>&1 || { echo "$head"; tail -60 "$build/findings/$t.log"; return 1; }
  echo "$head: $(grep -E "stat::number_of_executed_units|stat::peak_rss_mb" "$build/findings/$t.log" | tr '\n' ' ')"
}

running=0
for t in "${targets[@]}"; do
  if [ "$running" -ge "$jobs" ]; then
    wait -n  # a failed target ends the script (set -e)
    running=$((running - 1))
  fi
  fuzz_target "$t" &
  running=$((running + 1))
done
while [ "$running" -gt 0 ]; do
  wait -n
  running=$((running - 1))
done
