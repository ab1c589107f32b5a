#!/usr/bin/env bash
# Builds the driver decoders' libFuzzer targets (clang++, -fsanitize=fuzzer,address,undefined) in
# build/fuzz and runs each for SECONDS (default 10). Exit status non-zero on any crash, sanitizer
# report or failed property. Usage: tools/scripts/fuzz.sh [SECONDS]   (JOBS=n for the build)
set -euo pipefail
secs=${1:-10}
jobs=${JOBS:-2}
root=$(cd "$(dirname "$0")/../.." && pwd)
cd "$root"
build=build/fuzz
fuzzers=(fuzz_can_feedback fuzz_canfd_command fuzz_dxl_status fuzz_dxl_unstuff)

cmake -S . -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
      -DCMAKE_C_COMPILER=clang -DCMAKE_CXX_COMPILER=clang++ -DPEDALWAVE_FUZZ=ON \
      -DPEDALWAVE_TESTS=OFF -DPEDALWAVE_TOOLS=OFF -DPEDALWAVE_BENCH=OFF -DPEDALWAVE_DDS=OFF >/dev/null
cmake --build "$build" --target pedalwave_fuzzers -j"$jobs"

status=0
for f in "${fuzzers[@]}"; do
  corpus="$build/corpus/$f"
  mkdir -p "$corpus" "$build/artifacts"
  echo "== $f: ${secs} s =="
  if ! "$build/drivers/fuzz/$f" -max_total_time="$secs" -timeout=10 -rss_limit_mb=2048 \
        -print_final_stats=1 -artifact_prefix="$build/artifacts/$f-" "$corpus" \
        > "$build/$f.log" 2>&1; then
    echo "!! $f FAILED (log: $build/$f.log, reproducer in $build/artifacts/)"
    tail -n 40 "$build/$f.log"
    status=1
  else
    grep -E "stat::number_of_executed_units|Done [0-9]+ runs" "$build/$f.log" | tail -n 1 || true
  fi
done
exit $status
