#!/usr/bin/env bash
# Across hosts, for real: two network namespaces (two "hosts" with their own interfaces) joined by
# a veth pair, addresses in 198.18.0.0/15 (RFC 2544 benchmarking range) chosen here and living only
# inside the namespaces. The daemon (demo.yaml: no interface or domain in the file) runs in one,
# the monitor in the other, both with Cyclone's default discovery (multicast on the veth) and
# ROS_DOMAIN_ID. Checks: the monitor gets a complete picture; a stop command is EXECUTED (exit 0);
# set_gait, which this daemon's controller refuses, is REJECTED (exit 3); a command for another
# robot gets no ack (exit 4); the e-stop is EXECUTED and the daemon exits with its e-stop status 5
# and a start line naming ROS_DOMAIN_ID. Everything is removed afterwards (trap).
# Exit 0 pass, 1 fail, 77 SKIPPED (no permission / no netns support: printed loudly).
#   netns_test.sh RUNTIME_EXE MONITOR_EXE CONFIG_DIR
set -u
rt=$1 mon=$2 cfgdir=$3
tag="pw$$"
nsA="${tag}a" nsB="${tag}b" vA="${tag}a0" vB="${tag}b0"
net="198.18.$(( $$ % 250 + 1 ))"
domain=$(( $$ % 200 + 10 ))
tmp=$(mktemp -d)
daemon_pid=
fail=0

cleanup() {
  [ -n "$daemon_pid" ] && kill -KILL "$daemon_pid" 2>/dev/null && wait "$daemon_pid" 2>/dev/null
  ip netns del "$nsA" 2>/dev/null   # deleting a namespace deletes its end of the veth pair, and
  ip netns del "$nsB" 2>/dev/null   # with it the other end
  ip link del "$vA" 2>/dev/null
  rm -rf "$tmp"
}
trap cleanup EXIT
skip() { echo "*** SKIPPED: $* ***"; exit 77; }
check() {  # check DESCRIPTION EXPECTED ACTUAL [LOG]
  if [ "$2" = "$3" ]; then echo "ok    $1"; else
    echo "FAIL  $1: expected $2, got $3"; [ -n "${4:-}" ] && sed 's/^/      | /' "$4"; fail=1; fi
}
contains() {  # contains DESCRIPTION FILE TEXT
  if grep -qF -- "$3" "$2"; then echo "ok    $1"; else
    echo "FAIL  $1: no \"$3\" in"; sed 's/^/      | /' "$2"; fail=1; fi
}

command -v ip >/dev/null || skip "no ip command (iproute2)"
ip netns add "$nsA" 2>"$tmp/err" || skip "cannot create a network namespace: $(cat "$tmp/err") (needs root / CAP_SYS_ADMIN)"
ip netns add "$nsB" 2>"$tmp/err" || skip "cannot create a network namespace: $(cat "$tmp/err")"
ip link add "$vA" type veth peer name "$vB" 2>"$tmp/err" || skip "cannot create a veth pair: $(cat "$tmp/err")"
ip link set "$vA" netns "$nsA" && ip link set "$vB" netns "$nsB" || { echo "FAIL  moving the veth ends"; exit 1; }
ip -n "$nsA" addr add "$net.1/24" dev "$vA" && ip -n "$nsB" addr add "$net.2/24" dev "$vB" || exit 1
for ns in "$nsA" "$nsB"; do ip -n "$ns" link set lo up; done
ip -n "$nsA" link set "$vA" up && ip -n "$nsB" link set "$vB" up || exit 1
echo "hosts: $nsA ($vA $net.1) <-> $nsB ($vB $net.2), ROS_DOMAIN_ID=$domain"

# The robot host: the demo configuration, as shipped (domain and interface from the environment).
ip netns exec "$nsA" env -u CYCLONEDDS_URI -u ROS_LOCALHOST_ONLY ROS_DOMAIN_ID="$domain" \
  "$rt" -c "$cfgdir/runtime/demo.yaml" --duration 60 >"$tmp/daemon.log" 2>&1 &
daemon_pid=$!

# The operator's host.
monitor() { ip netns exec "$nsB" env -u CYCLONEDDS_URI -u ROS_LOCALHOST_ONLY ROS_DOMAIN_ID="$domain" "$mon" "$@"; }
monitor --robot demo --once --duration 30 >"$tmp/once.log" 2>&1
check "monitor on the other host: a complete snapshot (exit status)" 0 $? "$tmp/once.log"
contains "snapshot names the robot" "$tmp/once.log" 'robot "demo"'
contains "snapshot shows it walking" "$tmp/once.log" "mode running"

monitor --robot demo --command stop --ack-timeout 20 >"$tmp/stop.log" 2>&1
check "stop walking across hosts: executed (exit status)" 0 $? "$tmp/stop.log"
contains "stop walking: the robot's final ack" "$tmp/stop.log" "demo: command stop id"

monitor --robot demo --command gait --amplitude 0.5 --omega 3 --eta 0.7 --ack-timeout 20 >"$tmp/gait.log" 2>&1
check "set_gait refused by the daemon's controller: rejected (exit status)" 3 $? "$tmp/gait.log"
contains "set_gait: the runtime's reason" "$tmp/gait.log" "rejected: set gait rejected by the controller's bounds"

monitor --robot nobody --command stop --ack-timeout 3 >"$tmp/other.log" 2>&1
check "a command for another robot: no ack (exit status)" 4 $? "$tmp/other.log"

monitor --robot demo --command estop --ack-timeout 20 >"$tmp/estop.log" 2>&1
check "e-stop across hosts: executed (exit status)" 0 $? "$tmp/estop.log"
wait "$daemon_pid"
st=$?
daemon_pid=
check "daemon ended by the e-stop (its exit status)" 5 "$st" "$tmp/daemon.log"
contains "daemon start line: the domain from ROS_DOMAIN_ID" "$tmp/daemon.log" "DDS domain $domain (ROS_DOMAIN_ID=$domain)"
contains "daemon start line: default discovery" "$tmp/daemon.log" "discovery Cyclone's choice of interface (default"
[ "$fail" = 0 ] && echo "netns test: all checks passed" || echo "netns test: FAILED"
exit "$fail"
