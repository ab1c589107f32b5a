# Sourced by the DDS Security tests (security_test.sh, sros2/run.sh): their common start-up.
# Expects rt (daemon), mon (pedalwave_monitor) and cfgdir (config folder) set by the caller.
#   - fail / daemon_pid and the EXIT trap that kills a daemon still running;
#   - skip (exit 77, printed loudly), check / contains / lacks (one "ok"/"FAIL" line each);
#   - need_security: SKIPPED without Cyclone's security plugins or openssl;
#   - lease_domain: a DDS domain of our own in $domain (the lease the gtest processes and the
#     other DDS tests use: flock on the same files, held by fd 9 until the script ends);
#   - secured_config FILE KEYSTORE [ENCLAVE]: demo.yaml on that domain, localhost only, secured;
#   - secured_monitor KEYSTORE ENCLAVE|none ARGS...: pedalwave_monitor as that identity (none:
#     without security) watching robot "demo".
fail=0
daemon_pid=
cleanup() { [ -n "$daemon_pid" ] && kill -KILL "$daemon_pid" 2>/dev/null && wait "$daemon_pid" 2>/dev/null; }
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
lacks() {  # lacks DESCRIPTION FILE TEXT
  if ! grep -qF -- "$3" "$2"; then echo "ok    $1"; else
    echo "FAIL  $1: unexpected \"$3\" in"; sed 's/^/      | /' "$2"; fail=1; fi
}

need_security() {
  local plugins=/usr/lib/x86_64-linux-gnu/libddsc0debian p
  for p in auth ac crypto; do
    [ -f "$plugins/libdds_security_$p.so" ] ||
      skip "Cyclone DDS security plugin $plugins/libdds_security_$p.so missing (package libddsc0debian)"
  done
  command -v openssl >/dev/null || skip "no openssl (package openssl)"
}

lease_domain() {
  for domain in $(seq 100 230); do
    exec 9>"/tmp/pedalwave-dds-domain-$domain.lock"
    flock -n 9 && break
  done
}

secured_config() {  # secured_config FILE KEYSTORE [ENCLAVE]
  sed "s|scene: \.\./|scene: $cfgdir/|" "$cfgdir/runtime/demo.yaml" >"$1"
  printf '  domain_id: %s\n  localhost_only: true\nsecurity:\n  keystore: %s\n' "$domain" "$2" >>"$1"
  [ -n "${3:-}" ] && printf '  enclave: %s\n' "$3" >>"$1"
  return 0
}

secured_monitor() {  # secured_monitor KEYSTORE ENCLAVE|none ARGS...
  local ks=$1 who=$2; shift 2
  if [ "$who" = none ]; then
    env -u CYCLONEDDS_URI -u ROS_SECURITY_ENABLE "$mon" --robot demo --domain "$domain" --localhost-only "$@"
  else
    env -u CYCLONEDDS_URI "$mon" --robot demo --domain "$domain" --localhost-only \
      --security-keystore "$ks" --security-enclave "$who" "$@"
  fi
}
