#!/usr/bin/env bash
# The picture of pedalwave's CMake targets in the README (tools/scripts/targets.svg): CMake's own
# dependency graph (`cmake --graphviz`) of the project's libraries, drawn by Graphviz (Debian:
# graphviz). Executables, tests and external packages are left out so the layers can be read.
#   bash tools/scripts/targets-graph.sh [BUILD_DIR]     (default build/release, configured)
set -euo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
build=${1:-$root/build/release}
[ -f "$build/CMakeCache.txt" ] || { echo "targets-graph.sh: $build is not a configured build folder" >&2; exit 2; }
command -v dot >/dev/null || { echo "targets-graph.sh: no 'dot': apt-get install graphviz" >&2; exit 2; }
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cat > "$work/CMakeGraphVizOptions.cmake" <<'OPT'
set(GRAPHVIZ_EXECUTABLES FALSE)
set(GRAPHVIZ_EXTERNAL_LIBS FALSE)
set(GRAPHVIZ_GENERATE_PER_TARGET FALSE)
set(GRAPHVIZ_GENERATE_DEPENDERS FALSE)
set(GRAPHVIZ_IGNORE_TARGETS "pedalwave_warnings;.*_test.*;test_.*;.*fakes.*;.*_idl;.*gmock.*;.*gtest.*")
OPT
cp "$work/CMakeGraphVizOptions.cmake" "$build/CMakeGraphVizOptions.cmake"
(cd "$build" && cmake --graphviz="$work/targets.dot" . > /dev/null)
rm -f "$build/CMakeGraphVizOptions.cmake"
# Only the pedalwave libraries, by their alias names.
sed -i 's/"pedalwave_\([a-z_]*\)"/"pedalwave::\1"/g' "$work/targets.dot"
dot -Tsvg -Grankdir=BT "$work/targets.dot" -o "$root/tools/scripts/targets.svg"
echo "wrote tools/scripts/targets.svg"
