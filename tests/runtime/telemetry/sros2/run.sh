#!/usr/bin/env bash
# SROS2 interop: keystores made by the official sros2 implementation (ros2/sros2's Python
# keystore API, the code behind `ros2 security`) secure pedalwave, and pedalwave's keystore.sh
# keystores pass sros2's own checks. sros2 is an independent peer here, as the npm readers are
# for MCAP: its source is given to the test (Debian 12 does not package sros2, it is on neither
# registry this project may use, so the test cannot download it), copied into the build folder
# and run with Debian's python3-cryptography and python3-lxml. sros2 imports three ROS modules
# (ament_index_python for its share folder, rclpy's namespace validator and rmw name): small
# stand-ins of our own in ros_stand_in/ replace them; everything else is sros2's code.
#
#   PEDALWAVE_SROS2_SOURCE=<a checkout of ros2/sros2, e.g. tag 0.13.0> ctest -L sros2
#   (or cmake -DPEDALWAVE_SROS2_SOURCE=...; the folder holding sros2/sros2/__init__.py)
#
# Checks, on a DDS domain of its own (ROS_DOMAIN_ID for sros2):
#  1. sros2: create_keystore, then create_enclave + create_permission (policy.xml: pedalwave's
#     permission table as an SROS2 policy) for the robot /pedalwave/demo, an operator, an e-stop
#     and a monitor identity.
#  2. keystore.sh makes the same four; sros2 checks that keystore: is_valid_keystore,
#     get_enclaves, governance.xml and every permissions.xml against sros2's governance.xsd /
#     permissions.xsd (and a governance with a required element removed is rejected by them,
#     so the check can fail); the grants in both keystores allow exactly the same topics.
#  3. The daemon and monitors on sros2's keystore: on another domain than sros2's documents the
#     daemon refuses to start naming governance.p7s; on the right one the start line says DDS Security ON with
#     sros2's robot enclave; the monitor-only identity gets the robot's telemetry but Cyclone's
#     access control refuses its command writer (exit 5); a participant without identity sees
#     nothing; the operator's stop is EXECUTED; the e-stop identity's e-stop is EXECUTED and ends
#     the daemon (exit 5); the daemon executed exactly those two commands.
#  4. Mixed, as a ROS 2 user would: `ros2 security create_enclave` / `create_permission` (sros2's
#     API) adds an operator to a keystore.sh keystore; its stop reaches a robot secured by that
#     keystore and is EXECUTED.
# Exit 0 pass, 1 fail, 77 SKIPPED (printed loudly: no sros2 source given, no python3-lxml /
# python3-cryptography, no Cyclone security plugins).
#   run.sh RUNTIME_EXE MONITOR_EXE CONFIG_DIR KEYSTORE_SH WORK_DIR [SROS2_SOURCE]
set -u
rt=$1 mon=$2 cfgdir=$(cd "$3" && pwd) keystore=$4 work=$(mkdir -p "$5" && cd "$5" && pwd)
src=${PEDALWAVE_SROS2_SOURCE:-${6:-}}
here=$(cd "$(dirname "$0")" && pwd)
. "$here/../secured_run.sh"   # check/contains/lacks/skip, the domain lease, config, monitor

# The peer: sros2's Python package from the given source, copied into the build folder.
[ -n "$src" ] || skip "no sros2 source: set PEDALWAVE_SROS2_SOURCE to a checkout of ros2/sros2 (Debian 12 does not package sros2 and this project's registries do not carry it)"
if [ -f "$src/sros2/sros2/__init__.py" ]; then pkg=$src/sros2
elif [ -f "$src/sros2/__init__.py" ]; then pkg=$src
else skip "PEDALWAVE_SROS2_SOURCE=$src: no sros2/sros2/__init__.py there (expected a checkout of ros2/sros2)"; fi
/usr/bin/python3 -c 'import cryptography, lxml.etree' 2>/dev/null ||
  skip "sros2 needs /usr/bin/python3 with cryptography and lxml (packages python3-cryptography python3-lxml)"
need_security
lease_domain
rm -rf "$work"
mkdir -p "$work/peer"
cp -R "$pkg/sros2" "$pkg/xml_cache" "$work/peer/" || { echo "FAIL  copying sros2 from $pkg"; exit 1; }
version=$(sed -n 's:.*<version>\(.*\)</version>.*:\1:p' "$pkg/package.xml" 2>/dev/null)
echo "peer: sros2 ${version:-(version unknown)} from $pkg (Python package copied to $work/peer)"
export PYTHONPATH=$work/peer:$here/ros_stand_in PYTHONDONTWRITEBYTECODE=1
export PEDALWAVE_SROS2_SHARE=$work/peer ROS_DOMAIN_ID=$domain RMW_IMPLEMENTATION=rmw_cyclonedds_cpp
sros2() { /usr/bin/python3 "$here/sros2_peer.py" "$@"; }
enclaves=(/pedalwave/demo /pedalwave/alice /pedalwave/bob /pedalwave/screen)
S=$work/sros2_keystore O=$work/keystore_sh M=$work/mixed_keystore

# 1. sros2's keystore.
{ sros2 keystore "$S" && sros2 enclaves "$S" "$here/policy.xml" "${enclaves[@]}"; } >"$work/sros2.log" 2>&1
check "sros2 made a keystore and the four enclaves (exit status)" 0 $? "$work/sros2.log"

# 2. keystore.sh's keystore, checked by sros2.
{
  "$keystore" init "$O" &&
  "$keystore" robot "$O" demo --domain "$domain" &&
  "$keystore" operator "$O" /pedalwave/alice --domain "$domain" &&
  "$keystore" estop "$O" /pedalwave/bob --domain "$domain" &&
  "$keystore" monitor "$O" /pedalwave/screen --domain "$domain"
} >"$work/keystore_sh.log" 2>&1
check "keystore.sh made the same four (exit status)" 0 $? "$work/keystore_sh.log"
sros2 validate "$O" "${enclaves[@]}" >"$work/validate.log" 2>&1
check "sros2 validates the keystore.sh keystore (exit status)" 0 $? "$work/validate.log"
contains "... governance.xml against sros2's governance.xsd" "$work/validate.log" "governance.xml valid against sros2 governance.xsd"
for e in "${enclaves[@]}"; do
  contains "... $e permissions.xml against sros2's permissions.xsd" "$work/validate.log" \
    "${e#/pedalwave/}/permissions.xml valid against sros2 permissions.xsd"
done
grep -v enable_join_access_control "$O/enclaves/governance.xml" >"$work/broken_governance.xml"
sros2 xsd governance "$work/broken_governance.xml" >"$work/broken.log" 2>&1
check "sros2's governance.xsd rejects a governance without enable_join_access_control (exit status)" 1 $? "$work/broken.log"
sros2 compare "$S" "$O" "${enclaves[@]}" >"$work/compare.log" 2>&1
check "policy.xml through sros2 grants exactly what keystore.sh grants, every role" 0 $? "$work/compare.log"

config() { secured_config "$@"; }     # config FILE KEYSTORE
monitor() { secured_monitor "$@"; }   # monitor KEYSTORE ENCLAVE|none ARGS...

# 3. pedalwave on sros2's keystore. sros2's governance and permissions are for ROS_DOMAIN_ID
# only: on another domain the daemon refuses to start, naming the file.
config "$work/demo.yaml" "$S"
other_domain=$((domain == 230 ? 229 : domain + 1))
sed "s|^  domain_id: $domain\$|  domain_id: $other_domain|" "$work/demo.yaml" >"$work/other_domain.yaml"
env -u CYCLONEDDS_URI "$rt" -c "$work/other_domain.yaml" --duration 2 >"$work/other_domain.log" 2>&1
check "daemon on another domain than sros2's documents: refused at start (exit status)" 2 $? "$work/other_domain.log"
contains "... naming sros2's governance and the domain" "$work/other_domain.log" \
  "$S/enclaves/pedalwave/demo/governance.p7s: no domain_rule for DDS domain $other_domain"
env -u CYCLONEDDS_URI "$rt" -c "$work/demo.yaml" --duration 60 >"$work/daemon.log" 2>&1 &
daemon_pid=$!
monitor "$S" /pedalwave/screen --once --duration 20 >"$work/screen.log" 2>&1
check "sros2 monitor identity: a complete snapshot of the robot (exit status)" 0 $? "$work/screen.log"
contains "... telemetry of the robot secured by sros2's enclave" "$work/screen.log" "robot \"demo\"  driver sim"
contains "daemon start line: security on, sros2's robot enclave" "$work/daemon.log" \
  "DDS Security ON: enclave /pedalwave/demo (CN=/pedalwave/demo"
contains "... from the sros2 keystore" "$work/daemon.log" "keystore $S"
monitor "$S" /pedalwave/screen --command stop --ack-timeout 5 >"$work/screen_cmd.log" 2>&1
check "sros2 monitor identity: cannot command (exit status)" 5 $? "$work/screen_cmd.log"
contains "... refused by the permissions sros2 signed" "$work/screen_cmd.log" \
  "the permissions of enclave /pedalwave/screen do not allow publishing on /pedalwave/command"
monitor "$S" none --once --duration 3 >"$work/none.log" 2>&1
contains "unauthenticated participant: sees no telemetry" "$work/none.log" "no robot description yet"
lacks "... not even the description" "$work/none.log" "driver sim"
monitor "$S" /pedalwave/alice --command stop --ack-timeout 20 >"$work/alice.log" 2>&1
check "sros2 operator identity: stop EXECUTED (exit status)" 0 $? "$work/alice.log"
contains "... by the robot" "$work/alice.log" "executed: stop walking"
monitor "$S" /pedalwave/bob --command estop --ack-timeout 20 >"$work/bob.log" 2>&1
check "sros2 e-stop identity: e-stop EXECUTED (exit status)" 0 $? "$work/bob.log"
wait "$daemon_pid"
st=$?
daemon_pid=
check "daemon ended by the e-stop (its exit status)" 5 "$st" "$work/daemon.log"
contains "daemon: exactly the operator's stop and the e-stop were executed" "$work/daemon.log" \
  "events: 2 faults, warnings, holds and operator commands"

# 4. An operator made by sros2 inside a keystore.sh keystore.
sed 's|path="/pedalwave/alice"|path="/pedalwave/carol"|' "$here/policy.xml" >"$work/policy_carol.xml"
{
  "$keystore" init "$M" && "$keystore" robot "$M" demo --domain "$domain" &&
  sros2 enclaves "$M" "$work/policy_carol.xml" /pedalwave/carol
} >"$work/mixed.log" 2>&1
check "sros2 create_enclave/create_permission /pedalwave/carol in a keystore.sh keystore (exit status)" 0 $? "$work/mixed.log"
config "$work/mixed.yaml" "$M"
env -u CYCLONEDDS_URI "$rt" -c "$work/mixed.yaml" --duration 60 >"$work/mixed_daemon.log" 2>&1 &
daemon_pid=$!
monitor "$M" /pedalwave/carol --command stop --ack-timeout 20 >"$work/carol.log" 2>&1
check "sros2-made operator on keystore.sh's robot: stop EXECUTED (exit status)" 0 $? "$work/carol.log"
contains "... by the robot" "$work/carol.log" "executed: stop walking"
contains "... whose start line names the keystore.sh enclave" "$work/mixed_daemon.log" \
  "DDS Security ON: enclave /pedalwave/demo (CN=/pedalwave/demo"

[ "$fail" = 0 ] && echo "sros2 interop test: all checks passed" || echo "sros2 interop test: FAILED"
exit "$fail"
