#!/usr/bin/env bash
# DDS Security end to end, with real Cyclone plugins and real certificates made here by
# tools/scripts/keystore.sh: the daemon (demo.yaml + a security: section, localhost only) and
# pedalwave_monitor processes with different identities.
#   - the daemon's start line says DDS Security is on;
#   - an operator's stop is EXECUTED; an e-stop-only identity may e-stop (EXECUTED, the daemon
#     ends with its e-stop status 5) but not change the gait (refused, exit 5);
#   - a monitor-only identity sees the telemetry but cannot command (exit 5);
#   - an unauthenticated participant (no security) sees no telemetry and its command reaches no
#     robot (exit 4); a participant of another CA (its own valid keystore) likewise;
#   - misconfigured keystores are refused at start (exit 2) naming the file and what is wrong:
#     expired certificate, certificate of another CA, unsigned permissions, permissions signed by
#     another CA, permissions for another domain, a missing enclave;
#   - a keystore whose governance signs rather than encrypts (--protection SIGN) works, and the
#     daemon's start line says so.
# Exit 0 pass, 1 fail, 77 SKIPPED (no Cyclone security plugins / no openssl: printed loudly).
#   security_test.sh RUNTIME_EXE MONITOR_EXE CONFIG_DIR KEYSTORE_SH WORK_DIR
set -u
rt=$1 mon=$2 cfgdir=$(cd "$3" && pwd) keystore=$4 work=$5
. "$(dirname "$0")/secured_run.sh"   # check/contains/lacks/skip, the domain lease, config, monitor
need_security
lease_domain
rm -rf "$work"
mkdir -p "$work"
ks=$work/keystore other=$work/other_keystore
{
  "$keystore" init "$ks" &&
  "$keystore" robot "$ks" demo --domain "$domain" &&
  "$keystore" operator "$ks" /pedalwave/alice --domain "$domain" &&
  "$keystore" estop "$ks" /pedalwave/bob --domain "$domain" &&
  "$keystore" monitor "$ks" /pedalwave/screen --domain "$domain" &&
  # Another CA's keystore, valid in itself: its participants must not join ours.
  "$keystore" init "$other" &&
  "$keystore" operator "$other" /pedalwave/mallory --domain "$domain" &&
  # Misconfigured robot enclaves (refused at start).
  "$keystore" robot "$ks" demo --enclave /bad/expired --days -1 --domain "$domain" &&
  "$keystore" robot "$ks" demo --enclave /bad/wrong_ca --ca-dir "$other" --domain "$domain" &&
  "$keystore" robot "$ks" demo --enclave /bad/unsigned --domain "$domain" &&
  "$keystore" robot "$ks" demo --enclave /bad/resigned --domain "$domain" &&
  "$keystore" robot "$ks" demo --enclave /bad/domain --domain "$((domain == 0 ? 1 : domain - 1))"
} >"$work/keystore.log" 2>&1
check "keystore.sh made the keystore (exit status)" 0 $? "$work/keystore.log"
cp "$ks/enclaves/bad/unsigned/permissions.xml" "$ks/enclaves/bad/unsigned/permissions.p7s"
openssl smime -sign -text -in "$ks/enclaves/bad/resigned/permissions.xml" \
  -out "$ks/enclaves/bad/resigned/permissions.p7s" \
  -signer "$other/public/ca.cert.pem" -inkey "$other/private/ca.key.pem"
# SROS2 layout.
for f in public/ca.cert.pem public/identity_ca.cert.pem public/permissions_ca.cert.pem \
         private/ca.key.pem enclaves/governance.p7s enclaves/pedalwave/demo/cert.pem \
         enclaves/pedalwave/demo/key.pem enclaves/pedalwave/demo/permissions.p7s \
         enclaves/pedalwave/demo/governance.p7s enclaves/pedalwave/demo/identity_ca.cert.pem \
         enclaves/pedalwave/demo/permissions_ca.cert.pem; do
  [ -r "$ks/$f" ] || { echo "FAIL  keystore layout: no $f"; fail=1; }
done

config() { secured_config "$1" "$ks" "${2:-}"; }  # config FILE [ENCLAVE]
monitor() {  # monitor ENCLAVE|none|other ARGS...
  local who=$1; shift
  case "$who" in
    other) secured_monitor "$other" /pedalwave/mallory "$@" ;;
    *) secured_monitor "$ks" "$who" "$@" ;;
  esac
}

# Misconfigured keystores: refused before anything runs.
refused() {  # refused ENCLAVE WHAT FILE
  config "$work/bad.yaml" "$1"
  env -u CYCLONEDDS_URI "$rt" -c "$work/bad.yaml" --duration 2 >"$work/bad.log" 2>&1
  check "daemon with $2 refused at start (exit status)" 2 $? "$work/bad.log"
  contains "... naming the file" "$work/bad.log" "$ks/enclaves$1${3:+/$3}"
  contains "... and what is wrong" "$work/bad.log" "$2"
}
refused /bad/expired "certificate expired" cert.pem
refused /bad/wrong_ca "not issued by the identity CA" cert.pem
refused /bad/unsigned "not an S/MIME signed document" permissions.p7s
refused /bad/resigned "signature does not verify against the permissions CA" permissions.p7s
refused /bad/domain "permissions for another domain" permissions.p7s
refused /bad/missing "enclave folder missing" ""

# The secured robot.
config "$work/demo.yaml"
env -u CYCLONEDDS_URI "$rt" -c "$work/demo.yaml" --duration 60 >"$work/daemon.log" 2>&1 &
daemon_pid=$!
monitor /pedalwave/alice --command stop --ack-timeout 20 >"$work/alice.log" 2>&1
check "operator's stop: EXECUTED (exit status)" 0 $? "$work/alice.log"
contains "... by the robot" "$work/alice.log" "executed: stop walking"
contains "daemon start line: security on" "$work/daemon.log" "DDS Security ON: enclave /pedalwave/demo (CN=/pedalwave/demo"

monitor /pedalwave/screen --once --duration 20 >"$work/screen.log" 2>&1
check "monitor-only identity: a complete snapshot (exit status)" 0 $? "$work/screen.log"
contains "... of the robot" "$work/screen.log" "robot \"demo\"  driver sim"
monitor /pedalwave/screen --command stop --ack-timeout 5 >"$work/screen_cmd.log" 2>&1
check "monitor-only identity: command not permitted (exit status)" 5 $? "$work/screen_cmd.log"
contains "... says why" "$work/screen_cmd.log" "do not allow publishing on /pedalwave/command"

monitor none --once --duration 3 >"$work/none.log" 2>&1
contains "unauthenticated participant: sees no telemetry" "$work/none.log" "no robot description yet"
lacks "... not even the description" "$work/none.log" "driver sim"
monitor none --command start --ack-timeout 3 >"$work/none_cmd.log" 2>&1
check "unauthenticated participant: its command reaches no robot (exit status)" 4 $? "$work/none_cmd.log"

monitor other --once --duration 3 >"$work/other.log" 2>&1
contains "another CA's identity: sees no telemetry" "$work/other.log" "no robot description yet"
monitor other --command start --ack-timeout 3 >"$work/other_cmd.log" 2>&1
check "another CA's identity: its command reaches no robot (exit status)" 4 $? "$work/other_cmd.log"

monitor /pedalwave/bob --command gait --amplitude 0.5 --omega 3 --eta 0.7 --ack-timeout 5 >"$work/bob_gait.log" 2>&1
check "e-stop-only identity: gait change not permitted (exit status)" 5 $? "$work/bob_gait.log"
lacks "daemon: no command from the refused identities" "$work/daemon.log" "start_walking"
monitor /pedalwave/bob --command estop --ack-timeout 20 >"$work/bob.log" 2>&1
check "e-stop-only identity: e-stop EXECUTED (exit status)" 0 $? "$work/bob.log"
wait "$daemon_pid"
st=$?
daemon_pid=
check "daemon ended by the e-stop (its exit status)" 5 "$st" "$work/daemon.log"
contains "daemon: exactly the operator's stop and the e-stop were executed" "$work/daemon.log" \
  "events: 2 faults, warnings, holds and operator commands"

# Signing instead of encryption (keystore.sh init --protection SIGN): the governance says so, the
# daemon's start line reports it and an authorized monitor reads the telemetry.
signed=$work/signed_keystore
{
  "$keystore" init "$signed" --protection SIGN &&
  "$keystore" robot "$signed" demo --domain "$domain" &&
  "$keystore" monitor "$signed" /pedalwave/screen --domain "$domain"
} >"$work/signed_keystore.log" 2>&1
check "keystore.sh made a SIGN keystore (exit status)" 0 $? "$work/signed_keystore.log"
sed "s|^  keystore: $ks\$|  keystore: $signed|" "$work/demo.yaml" >"$work/signed.yaml"
env -u CYCLONEDDS_URI "$rt" -c "$work/signed.yaml" --duration 60 >"$work/signed_daemon.log" 2>&1 &
daemon_pid=$!
secured_monitor "$signed" /pedalwave/screen --once --duration 20 >"$work/signed_screen.log" 2>&1
check "SIGN governance: monitor identity gets a complete snapshot (exit status)" 0 $? "$work/signed_screen.log"
contains "... of the robot" "$work/signed_screen.log" "robot \"demo\"  driver sim"
contains "... whose start line says the data are signed" "$work/signed_daemon.log" "keystore $signed, data protection SIGN"
cleanup
daemon_pid=

[ "$fail" = 0 ] && echo "security test: all checks passed" || echo "security test: FAILED"
exit "$fail"
