#!/usr/bin/env bash
# MCAP recordings and the Foxglove live view of pedalwave_monitor, read with the official npm
# peers. One synthetic robot (pedalwave_telemetry_synth, 200 Hz, a fault event every 0.5 s) is
# watched by two monitors at once: one records CSV (run.csv → run.<topic>.csv, the reference), the
# other records run.mcap and serves the Foxglove WebSocket protocol, to which a FoxgloveClient
# (@foxglove/ws-protocol over `ws`) connects. Then:
#   foxglove_client.mjs: serverInfo, every channel advertised with its ros2msg schema, subscribing
#     to /demo/joint_states, /demo/pedalwave/joint_state and /diagnostics, every message decoded
#     with @foxglove/rosmsg2-serialization and equal to the CSV rows of the same cycle (pedalwave
#     topics) or to the pedalwave joint_state of the same stamp (joint_states); unsubscribe stops a
#     channel; a bad subscribe gets an error status.
#   check_mcap.mjs: the MCAP file with @mcap/core's indexed reader: every channel (topic, cdr,
#     ros2msg schema, offered_qos_profiles), every message of every channel decoded and equal to
#     the CSV recording (same cycle / event_seq) or consistent with it (standard topics).
#
# And the daemon's own recorder (telemetry.record): the demo configuration (lockstep simulated
# plant, 1 kHz, 100 Hz state topics) for 3 s with `record: daemon.mcap`, watched by a monitor
# recording CSV; check_mcap.mjs then reads daemon.mcap against that CSV the same way (every event
# and the description found, most best-effort samples, all equal).
#
#   run.sh SYNTH MONITOR WORK_DIR [DAEMON CONFIG_DIR]
# exit 77 (ctest: skipped) with a loud SKIPPED line without node/npm or the npm registry.
set -euo pipefail
synth=$(realpath "$1")
monitor=$(realpath "$2")
mkdir -p "$3"
work=$(realpath "$3")
daemon=${4:+$(realpath "$4")}
cfgdir=${5:+$(realpath "$5")}
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)

skip() {
  echo "SKIPPED: foxglove/mcap test: $*" >&2
  echo "SKIPPED: foxglove/mcap test: $*"
  exit 77
}
# shellcheck source=../../../support/npm_peers.sh
source "$here/../../../support/npm_peers.sh"
if why=$(npm_peers_node_problem); then skip "$why"; fi

pkgs=(@mcap/core@2.2.2 @foxglove/rosmsg@5.0.5 @foxglove/rosmsg2-serialization@3.1.0
      @foxglove/wasm-zstd@1.0.1 @foxglove/wasm-lz4@1.0.2 @foxglove/ws-protocol@0.8.0 ws@8.23.1)
why=$(npm_peers_install "$work" foxmcap "${pkgs[@]}") || skip "$why"
cp "$here/common.mjs" "$here/foxglove_client.mjs" "$here/check_mcap.mjs" "$work/"

# A DDS domain of our own (the lease scheme of tests/runtime/telemetry/dds_test_support.hpp).
domain=""
for id in $(seq 100 230); do
  exec {lock}>"/tmp/pedalwave-dds-domain-$id.lock"
  if flock -n "$lock"; then domain=$id; break; fi
  exec {lock}>&-
done
[[ -n "$domain" ]] || { echo "no free DDS domain id in 100..230" >&2; exit 1; }
cd "$work"
rm -f run.mcap run.*.csv monitor_*.log synth.log
pids=()
cleanup() { for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done; }
trap cleanup EXIT

common=(--robot demo --domain "$domain" --localhost-only --no-view --duration 4.5)
"$synth" --robot demo --domain "$domain" --interface lo --rate 200 --fault-every 0.5 --duration 6 >synth.log 2>&1 &
synth_pid=$!
pids+=($synth_pid)
"$monitor" "${common[@]}" --record run.csv >monitor_csv.log 2>&1 &
csv_pid=$!
pids+=($csv_pid)
"$monitor" "${common[@]}" --record run.mcap --foxglove 0 >monitor_mcap.log 2>&1 &
mcap_pid=$!
pids+=($mcap_pid)
port=""
for _ in $(seq 100); do
  port=$(sed -n 's|.*Foxglove WebSocket server on ws://127.0.0.1:\([0-9]*\).*|\1|p' monitor_mcap.log)
  [[ -n "$port" ]] && break
  sleep 0.05
done
[[ -n "$port" ]] || { cat monitor_mcap.log >&2; echo "FAILED: the monitor did not start its Foxglove server" >&2; exit 1; }
sleep 1  # the robot found, its description received
node foxglove_client.mjs "ws://127.0.0.1:$port" fox.json
wait "$csv_pid" || { cat monitor_csv.log >&2; echo "FAILED: the CSV monitor exited with $?" >&2; exit 1; }
wait "$mcap_pid" || { cat monitor_mcap.log >&2; echo "FAILED: the MCAP monitor exited with $?" >&2; exit 1; }
cat monitor_mcap.log
node foxglove_client.mjs --check fox.json run
node check_mcap.mjs run.mcap run

if [[ -n "$daemon" ]]; then
  wait "$synth_pid" || true  # the stand-in robot "demo" gone before the daemon's "demo" starts
  rm -f daemon.mcap daemon_run.*.csv
  sed -e "s|^duration: .*|duration: 3|" -e "s|\.\./scenes/|$cfgdir/scenes/|" \
      -e "s|^  enabled: true|  enabled: true\n  localhost_only: true\n  domain_id: $domain\n  record: $work/daemon.mcap|" \
      "$cfgdir/runtime/demo.yaml" > daemon.yaml
  "$monitor" --robot demo --domain "$domain" --localhost-only --no-view --duration 5 --record daemon_run.csv \
      >monitor_daemon.log 2>&1 &
  mon_pid=$!
  pids+=($mon_pid)
  sleep 0.5
  rc=0
  "$daemon" -c daemon.yaml >daemon.log 2>&1 || rc=$?
  ((rc == 0)) || { cat daemon.log >&2; echo "FAILED: the daemon exited with $rc" >&2; exit 1; }
  wait "$mon_pid" || { cat monitor_daemon.log >&2; echo "FAILED: the daemon's monitor exited with $?" >&2; exit 1; }
  grep -E "recording" daemon.log
  node check_mcap.mjs daemon.mcap daemon_run
fi
echo "foxglove/mcap: all passed"
