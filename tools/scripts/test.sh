#!/usr/bin/env bash
# The README's test command. Installs dependencies (apt-get), then:
#   1. Release build with warnings as errors; the whole ctest suite (host), with the package tests
#      (label package: the unit's policy, an install into a staging root, and the Debian package
#      built with cpack, installed with dpkg -i, checked and removed; that one needs root).
#   2. ASan+UBSan build; the suite without the slow label.
#   3. ThreadSanitizer build of the threaded tests (rings, runtime cycle and its consumer thread,
#      run events, modes, telemetry/DDS): tools/scripts/tsan.sh.
#   4. libFuzzer targets of the protocol decoders and the YAML readers (clang), a few seconds each.
#   5. The real-SocketCAN tests (ctest -L vcan) inside a qemu VM with Debian's kernel and vcan0.
# Exit status: non-zero if any step fails. A step that cannot run here (no qemu) says SKIPPED loudly.
set -euo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
cd "$root"
bash tools/scripts/deps.sh
jobs=$(nproc)
start=$(date +%s)
step() { echo; echo "== $* ($(( $(date +%s) - start )) s) =="; }

step "[1/5] Release build, -Werror"
cmake -S . -B build/release -G Ninja -DCMAKE_BUILD_TYPE=Release -DPEDALWAVE_WERROR=ON \
      -DCMAKE_INSTALL_PREFIX=/usr >/dev/null  # the Debian package's prefix (DEPLOY.md)
cmake --build build/release -j"$jobs"
step "[1/5] ctest (host; vcan tests run in step 5)"
(cd build/release && ctest --output-on-failure -j"$jobs" --timeout 900 -LE vcan) ||
  { bash tools/scripts/ctest-digest.sh build/release; exit 1; }

step "[2/5] ASan+UBSan build (-O2, no debug info: debug info doubles the Eigen-heavy compile time), -Werror"
cmake -S . -B build/asan -G Ninja -DCMAKE_BUILD_TYPE=None -DCMAKE_CXX_FLAGS="-O2 -DNDEBUG" \
      -DPEDALWAVE_WERROR=ON -DPEDALWAVE_SANITIZE=ON -DPEDALWAVE_BENCH=OFF -DPEDALWAVE_TOOLS=OFF >/dev/null
cmake --build build/asan -j"$jobs"
step "[2/5] ctest under ASan+UBSan (without label slow)"
(cd build/asan && ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
   ctest --output-on-failure -j"$jobs" --timeout 900 -LE "slow|vcan") ||
  { bash tools/scripts/ctest-digest.sh build/asan; exit 1; }

step "[3/5] ThreadSanitizer: the threaded tests (tools/scripts/tsan.sh)"
bash tools/scripts/tsan.sh || { bash tools/scripts/ctest-digest.sh build/tsan; exit 1; }

step "[4/5] fuzzing the protocol decoders and the YAML readers (libFuzzer, 10 s each)"
bash tools/scripts/fuzz.sh 10

step "[5/5] real SocketCAN: ctest -L vcan inside the qemu VM (vcan0)"
set +e
VM_TIMEOUT=${VM_TIMEOUT:-900} bash tools/scripts/vm/test-vcan.sh build/release
rc=$?
set -e
if [ "$rc" -eq 77 ]; then
  echo "######################################################################"
  echo "### SKIPPED: the vcan VM could not run here (qemu or Debian's kernel ###"
  echo "### package unavailable). The SocketCAN tests did NOT run.           ###"
  echo "######################################################################"
elif [ "$rc" -ne 0 ]; then
  echo "vcan VM tests failed (exit $rc)"
  exit "$rc"
fi
step "all steps done"
