#!/usr/bin/env bash
# After a failed ctest run: the failed tests' assertion lines (gtest "Failure" and the lines that
# follow it) and the suite's own FINDING / VOID / isolation lines, at the END of the log, so that a
# CI view that keeps only the tail still says why each test failed.
#   usage: ctest-digest.sh BUILD_DIR
set -euo pipefail
log="$1/Testing/Temporary/LastTest.log"
[ -f "$log" ] || { echo "ctest-digest: no $log"; exit 0; }
echo
echo "== why the failed tests failed (from $log) =="
awk '
  /^[0-9]+\/[0-9]+ Testing: / { name = $0; sub(/^[0-9]+\/[0-9]+ Testing: /, "", name); n = 0; after = 0; next }
  /^Test Failed|^Test time.*\*\*\*|^Test Timeout|\*\*\*Exception/ {
    if (name != "") { print "-- " name " --"; for (i = 0; i < n; ++i) print "   " buf[i]; if (n == 0) print "   (no assertion line: crash, timeout or exit code; see the full log)" }
    name = ""; next }
  /^Test Passed/ { name = ""; next }
  /^<end of output>/ { after = 0; next }
  name != "" {
    keep = 0
    if ($0 ~ /Failure$|: error: |FINDING|VOID RUN|isolated as|not detected|deploy-table|Segmentation|Sanitizer|Timeout/) { keep = 1; after = 4 }
    else if (after > 0) { keep = 1; --after }
    if (keep && n < 60) buf[n++] = substr($0, 1, 400)
  }
' "$log"
