#!/usr/bin/env bash
# The MCAP interop test: files written by pedalwave::mcap (through pedalwave_mcap_demo, zstd, lz4
# and uncompressed, several chunks each) read with the official readers from npm (@mcap/core's
# indexed and stream readers, @foxglove/rosmsg + @foxglove/rosmsg2-serialization to decode every
# message from the file's own ros2msg schema), compared with what the writer published.
#
#   run.sh DEMO_BINARY WORK_DIR
#
# The npm packages are installed into WORK_DIR (in the build folder) once, pinned; exit 77 (ctest:
# skipped) with a loud SKIPPED line when node/npm are missing or the registry cannot be reached.
set -euo pipefail
demo=$1
work=$2
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)

skip() {
  echo "SKIPPED: mcap interop test: $*" >&2
  echo "SKIPPED: mcap interop test: $*"
  exit 77
}
command -v node >/dev/null 2>&1 || skip "node not found (the official MCAP readers are npm packages)"
command -v npm >/dev/null 2>&1 || skip "npm not found (the official MCAP readers are npm packages)"
node_major=$(node -p 'process.versions.node.split(".")[0]')
((node_major >= 18)) || skip "node $(node --version) is older than 18"

# Pinned peers: the MCAP reader, its CRC, Foxglove's ROS 2 .msg parser and CDR decoder, and the
# decompressors Foxglove uses (zstd and lz4 as WebAssembly, shipped inside the packages).
pkgs=(@mcap/core@2.2.2 @foxglove/crc@0.0.3 @foxglove/rosmsg@5.0.5 @foxglove/rosmsg2-serialization@3.1.0
      @foxglove/wasm-zstd@1.0.1 @foxglove/wasm-lz4@1.0.2)
mkdir -p "$work"
stamp="$work/node_modules/.pedalwave-interop-packages"
if [[ ! -f "$stamp" || "$(cat "$stamp")" != "${pkgs[*]}" ]]; then
  echo '{"private": true, "type": "module"}' > "$work/package.json"
  if ! npm install --prefix "$work" --no-audit --no-fund --loglevel=error "${pkgs[@]}" >"$work/npm.log" 2>&1; then
    tail -5 "$work/npm.log" >&2
    skip "npm install of ${pkgs[*]} failed (registry unreachable?): see $work/npm.log"
  fi
  echo "${pkgs[*]}" > "$stamp"
fi
cp "$here/read_mcap.mjs" "$work/read_mcap.mjs"  # node resolves the packages from the script's folder

# 3 s at 100 Hz: 334 messages on 4 topics (JointState, String ×2, a custom message), 16 KiB chunks.
for compression in zstd lz4 none; do
  file="$work/demo_$compression.mcap"
  "$demo" --out "$file" --compression "$compression" --chunk-size 16384 --duration 3 \
          --expect "$work/demo_$compression.jsonl"
  node "$work/read_mcap.mjs" "$file" "$work/demo_$compression.jsonl" 4
done
echo "mcap interop: all passed"
