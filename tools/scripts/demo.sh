#!/usr/bin/env bash
# The README's main command: installs dependencies, builds Release and runs the default job.
set -euo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
cd "$root"
bash tools/scripts/deps.sh
cmake -S . -B build/release -G Ninja -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build build/release -j"$(nproc)"
exec build/release/tools/runtime/pedalwave_runtime --config config/runtime/demo.yaml --plots out/demo "$@"
