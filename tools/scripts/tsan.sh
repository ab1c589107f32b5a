#!/usr/bin/env bash
# ThreadSanitizer on the threaded parts: the SPSC rings, the runtime cycle with its telemetry
# consumer thread, the run events, and the telemetry layer (DDS writer/reader threads, the
# recorder, processes). Builds those test programs only (build/tsan, gcc -fsanitize=thread) and
# runs each under ctest; any data race reported fails the step (halt_on_error). Exit status
# non-zero on any failure. Usage: tools/scripts/tsan.sh   (JOBS=n for the build)
set -euo pipefail
jobs=${JOBS:-$(nproc)}
root=$(cd "$(dirname "$0")/../.." && pwd)
cd "$root"
build=build/tsan
targets=(test_runtime_ring test_runtime_cycle test_runtime_events test_runtime_modes
         pedalwave_telemetry_tests pedalwave_telemetry_test_peer)
cmake -S . -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=None -DCMAKE_CXX_FLAGS="-O1 -DNDEBUG" \
      -DPEDALWAVE_WERROR=ON -DPEDALWAVE_TSAN=ON -DPEDALWAVE_BENCH=OFF -DPEDALWAVE_TOOLS=OFF >/dev/null
cmake --build "$build" -j"$jobs" --target "${targets[@]}"
# Only the programs built above: every discovered test of theirs, nothing of the other targets
# (whose test lists do not exist in this tree: ctest names them <target>_NOT_BUILT).
regex=$(cd "$build" && ctest -N -L "runtime|telemetry" | sed -n 's/^ *Test *#[0-9]*: \([^ ]*\).*/\1/p' |
        grep -v "_NOT_BUILT$" | sed 's/[][().*+?^$\\|]/\\&/g; s/^/^/; s/$/$/' | paste -sd'|')
[ -n "$regex" ] || { echo "tsan: no tests discovered in $build" >&2; exit 1; }
cd "$build"
TSAN_OPTIONS="halt_on_error=1 second_deadlock_stack=1 suppressions=$root/tools/scripts/tsan.supp" \
  ctest --output-on-failure -j"$jobs" --timeout 600 -R "$regex"
