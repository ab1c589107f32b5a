#!/usr/bin/env bash
# Runs the suite's SocketCAN tests (ctest label "vcan") inside the test VM, building the VM first
# if needed (cached in build/vm/). For CI.
#
# Usage: tools/scripts/vm/test-vcan.sh BUILD_DIR [EXTRA_CTEST_ARGS...]
#
# Exit status: ctest's (0 = all vcan tests passed inside the VM); 77 = SKIPPED (the VM cannot be
# built or qemu cannot run here; a loud SKIPPED banner has been printed: report a skip, never a
# pass); anything else = failure (see run.sh for 124/125). A test that reports itself skipped
# inside the VM counts as a failure (the VM provides vcan0, vcan1 and can-utils).
set -uo pipefail
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
[ $# -ge 1 ] || { echo "usage: $0 BUILD_DIR [EXTRA_CTEST_ARGS...]" >&2; exit 2; }
build_dir=$1
shift

t0=$(date +%s.%N)
bash "$here/build.sh"
rc=$?
if [ $rc -ne 0 ]; then
  [ $rc -eq 77 ] && exit 77
  echo "[test-vcan] FAILED: building the VM failed (exit $rc)" >&2
  exit $rc
fi
t1=$(date +%s.%N)
out=$(mktemp)
trap 'rm -f "$out"' EXIT
# --no-tests=error: an empty label selection (tests not built?) must not pass.
# -j1: every vcan test shares vcan0 and sees the others' frames.
bash "$here/run.sh" "$build_dir" -L vcan --no-tests=error -j1 "$@" 2>&1 | tee "$out"
rc=${PIPESTATUS[0]}
# Inside the VM a vcan test has everything it needs: a skip there is a failure.
if [ $rc -eq 0 ] && grep -qE '^[[:space:]]*[0-9]+ - .*\(Skipped\)$' "$out"; then
  echo "[test-vcan] FAILED: tests skipped inside the VM, where vcan0 and can-utils exist:" >&2
  grep -E '^[[:space:]]*[0-9]+ - .*\(Skipped\)$' "$out" >&2
  rc=1
fi
t2=$(date +%s.%N)
awk -v a="$t0" -v b="$t1" -v c="$t2" -v rc="$rc" \
  'BEGIN{printf "[test-vcan] exit %d; VM build/check %.1f s, boot+test+poweroff %.1f s\n", rc, b-a, c-b}'
exit $rc
