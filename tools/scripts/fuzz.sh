#!/usr/bin/env bash
# Builds the driver decoders' and the YAML readers' (config/fuzz) libFuzzer targets (clang++, -fsanitize=fuzzer,address,undefined) in
# build/fuzz and runs each for SECONDS (default 10). Exit status non-zero on any crash, sanitizer
# report or failed property. Usage: tools/scripts/fuzz.sh [SECONDS]   (JOBS=n for the build)
set -euo pipefail
secs=${1:-10}
jobs=${JOBS:-2}
root=$(cd "$(dirname "$0")/../.." && pwd)
cd "$root"
build=build/fuzz
fuzzers=(drivers/fuzz/fuzz_can_feedback drivers/fuzz/fuzz_canfd_command drivers/fuzz/fuzz_dxl_status
         drivers/fuzz/fuzz_dxl_unstuff config/fuzz/fuzz_yaml_config)

cmake -S . -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
      -DCMAKE_C_COMPILER=clang -DCMAKE_CXX_COMPILER=clang++ -DPEDALWAVE_FUZZ=ON \
      -DPEDALWAVE_TESTS=OFF -DPEDALWAVE_TOOLS=OFF -DPEDALWAVE_BENCH=OFF -DPEDALWAVE_DDS=OFF >/dev/null
cmake --build "$build" --target pedalwave_fuzzers fuzz_yaml_config -j"$jobs"

status=0
for path in "${fuzzers[@]}"; do
  f=$(basename "$path")
  corpus="$build/corpus/$f"
  mkdir -p "$corpus" "$build/artifacts"
  seeds=()  # read-only seed folders after the corpus (libFuzzer adds new inputs to the first only)
  [ "$f" = fuzz_yaml_config ] && seeds=(config/scenes config/runtime)
  echo "== $f: ${secs} s =="
  if ! "$build/$path" -max_total_time="$secs" -timeout=10 -rss_limit_mb=2048 \
        -print_final_stats=1 -artifact_prefix="$build/artifacts/$f-" "$corpus" "${seeds[@]}" \
        > "$build/$f.log" 2>&1; then
    echo "!! $f FAILED (log: $build/$f.log, reproducer in $build/artifacts/)"
    tail -n 40 "$build/$f.log"
    status=1
  else
    grep -E "stat::number_of_executed_units|Done [0-9]+ runs" "$build/$f.log" | tail -n 1 || true
  fi
done
exit $status
