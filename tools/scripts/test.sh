#!/usr/bin/env bash
# The README's test command: installs dependencies, builds (Release, warnings as errors) and runs
# the whole ctest suite, then the ASan+UBSan build of the suite. Exit status is ctest's.
set -euo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
cd "$root"
bash tools/scripts/deps.sh
jobs=$(nproc)

echo "== [1/2] Release build, -Werror =="
cmake -S . -B build/release -G Ninja -DCMAKE_BUILD_TYPE=Release -DPEDALWAVE_WERROR=ON >/dev/null
cmake --build build/release -j"$jobs"
(cd build/release && ctest --output-on-failure -j"$jobs" --timeout 600)

echo "== [2/2] ASan+UBSan build (RelWithDebInfo), -Werror =="
cmake -S . -B build/asan -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DPEDALWAVE_WERROR=ON \
      -DPEDALWAVE_SANITIZE=ON -DPEDALWAVE_BENCH=OFF -DPEDALWAVE_TOOLS=OFF >/dev/null
cmake --build build/asan -j"$jobs"
(cd build/asan && ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1 \
   ctest --output-on-failure -j"$jobs" --timeout 900 -LE "slow|vm")
