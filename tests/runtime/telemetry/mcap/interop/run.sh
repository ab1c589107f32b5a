#!/usr/bin/env bash
# The MCAP interop test: files written by pedalwave::mcap (through pedalwave_mcap_demo, zstd, lz4
# and uncompressed, several chunks each) read with the official readers from npm (@mcap/core's
# indexed and stream readers, @foxglove/rosmsg + @foxglove/rosmsg2-serialization to decode every
# message from the file's own ros2msg schema), compared with what the writer published.
#
# And the other way: files written by @mcap/core's McapWriter (write_mcap.mjs: zstd chunks,
# uncompressed chunks, no chunks; an attachment and a metadata record among the messages) read by
# pedalwave::mcap::Reader (pedalwave_mcap_dump): every schema, channel and message exactly as the
# writer listed them; and the same file with a chunk's CRC byte flipped, or cut inside a chunk,
# refused with the error naming the file, the chunk's offset and the problem.
#
#   run.sh DEMO_BINARY WORK_DIR [DUMP_BINARY]
#
# The npm packages are installed into WORK_DIR (in the build folder) once, pinned; exit 77 (ctest:
# skipped) with a loud SKIPPED line when node/npm are missing or the registry cannot be reached.
set -euo pipefail
demo=$1
work=$2
dump=${3:-}
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)

skip() {
  echo "SKIPPED: mcap interop test: $*" >&2
  echo "SKIPPED: mcap interop test: $*"
  exit 77
}
# shellcheck source=../../../../support/npm_peers.sh
source "$here/../../../../support/npm_peers.sh"
if why=$(npm_peers_node_problem); then skip "$why"; fi

# Pinned peers: the MCAP reader, its CRC, Foxglove's ROS 2 .msg parser and CDR decoder, and the
# decompressors Foxglove uses (zstd and lz4 as WebAssembly, shipped inside the packages).
pkgs=(@mcap/core@2.2.2 @foxglove/crc@0.0.3 @foxglove/rosmsg@5.0.5 @foxglove/rosmsg2-serialization@3.1.0
      @foxglove/wasm-zstd@1.0.1 @foxglove/wasm-lz4@1.0.2)
why=$(npm_peers_install "$work" interop "${pkgs[@]}") || skip "$why"
cp "$here/read_mcap.mjs" "$work/read_mcap.mjs"  # node resolves the packages from the script's folder

# 3 s at 100 Hz: 334 messages on 4 topics (JointState, String ×2, a custom message), 16 KiB chunks.
for compression in zstd lz4 none; do
  file="$work/demo_$compression.mcap"
  "$demo" --out "$file" --compression "$compression" --chunk-size 16384 --duration 3 \
          --expect "$work/demo_$compression.jsonl"
  node "$work/read_mcap.mjs" "$file" "$work/demo_$compression.jsonl" 4
done
if [[ -n "$dump" ]]; then
  cp "$here/write_mcap.mjs" "$work/write_mcap.mjs"
  for mode in zstd none unchunked; do
    file="$work/peer_$mode.mcap"
    node "$work/write_mcap.mjs" "$file" "$work/peer_$mode.txt" "$mode"
    "$dump" "$file" > "$work/peer_$mode.ours.txt"
    if ! cmp -s "$work/peer_$mode.txt" "$work/peer_$mode.ours.txt"; then
      diff "$work/peer_$mode.txt" "$work/peer_$mode.ours.txt" | head -5 >&2
      echo "FAILED: our reader's listing of $file differs from what @mcap/core wrote" >&2
      exit 1
    fi
    echo "$file: our reader read all $(grep -c '^message' "$work/peer_$mode.ours.txt") messages as written"
  done
  # Corrupted: the first chunk's uncompressed_crc flipped; the file cut 20 bytes into that chunk.
  chunk=$(/usr/bin/python3 -c '
import struct, sys
b = open(sys.argv[1], "rb").read()
pos = 8
while b[pos] != 0x06:
    pos += 9 + struct.unpack_from("<Q", b, pos + 1)[0]
print(pos)' "$work/peer_zstd.mcap")
  /usr/bin/python3 -c '
import sys
b = bytearray(open(sys.argv[1], "rb").read())
at = int(sys.argv[2])
open(sys.argv[4], "wb").write(bytes(b[: at + 20]))
b[at + 9 + 24] ^= 0x01
open(sys.argv[3], "wb").write(b)' "$work/peer_zstd.mcap" "$chunk" "$work/peer_badcrc.mcap" "$work/peer_cut.mcap"
  expect_refused() {  # FILE TEXT
    local rc=0
    "$dump" "$1" >/dev/null 2>"$1.err" || rc=$?
    if ((rc != 1)) || ! grep -qF -- "$2" "$1.err"; then
      cat "$1.err" >&2
      echo "FAILED: $1: expected exit 1 and the error \"$2\", got exit $rc" >&2
      exit 1
    fi
    echo "$1 refused: $(cat "$1.err")"
  }
  expect_refused "$work/peer_badcrc.mcap" "$work/peer_badcrc.mcap: byte $chunk: Chunk CRC mismatch"
  expect_refused "$work/peer_cut.mcap" "$work/peer_cut.mcap: byte $chunk: Chunk record (opcode 0x06) truncated"
fi
echo "mcap interop: all passed"
