#!/usr/bin/env bash
# The generated systemd unit's service policy (DEPLOY.md "Service policy"), read by a parser of
# our own (sections and keys, as systemd reads them: the last assignment wins):
#   [Service] Restart=on-failure (a crash restarts), RestartPreventExitStatus holds 2 4 5 (bad
#   input, fault, e-stop never restart), RestartSec set; [Unit] holds StartLimitIntervalSec and
#   StartLimitBurst and [Service] does not (systemd ignores them there); ExecStart is absolute,
#   passes --config and --state-dir /var/lib/pedalwave with StateDirectory=pedalwave; the RT
#   limits LimitRTPRIO and LimitMEMLOCK are set.
set -uo pipefail
unit=${1:?usage: test_unit_policy.sh UNIT_FILE}
fails=0
fail() { echo "FAIL: $*"; fails=$((fails + 1)); }

# value SECTION KEY: the last assignment of KEY in [SECTION], or empty.
value() {
  awk -v want="$1" -v key="$2" '
    /^[ \t]*[#;]/ || /^[ \t]*$/ { next }
    /^\[/ { sec = $0; gsub(/^\[|\][ \t]*$/, "", sec); next }
    sec == want { k = $0; sub(/=.*/, "", k); gsub(/[ \t]/, "", k)
                  if (k == key) { v = $0; sub(/^[^=]*=[ \t]*/, "", v); found = v } }
    END { print found }' "$unit"
}
has() { [ -n "$(value "$1" "$2")" ]; }

[ -f "$unit" ] || { echo "FAIL: no unit at $unit"; exit 1; }
echo "unit: $unit"
[ "$(value Service Restart)" = "on-failure" ] || fail "[Service] Restart is '$(value Service Restart)', expected on-failure"
prevent=" $(value Service RestartPreventExitStatus) "
for code in 2 4 5; do
  [[ "$prevent" == *" $code "* ]] || fail "[Service] RestartPreventExitStatus='${prevent# }' lacks $code"
done
for code in 0 1; do
  [[ "$prevent" != *" $code "* ]] || fail "[Service] RestartPreventExitStatus holds $code (a crash must restart)"
done
has Service RestartSec || fail "[Service] RestartSec missing"
for k in StartLimitIntervalSec StartLimitBurst; do
  has Unit "$k" || fail "[Unit] $k missing"
  has Service "$k" && fail "[Service] $k: systemd ignores it there (it belongs to [Unit])"
done
burst=$(value Unit StartLimitBurst)
[[ "$burst" =~ ^[0-9]+$ ]] && [ "$burst" -ge 1 ] && [ "$burst" -le 5 ] || fail "[Unit] StartLimitBurst='$burst', expected 1..5"
exec_start=$(value Service ExecStart)
[[ "$exec_start" == /*/pedalwave_runtime\ * ]] || fail "ExecStart '$exec_start' is not an absolute pedalwave_runtime"
[[ "$exec_start" == *"--config "* ]] || fail "ExecStart passes no --config"
[[ "$exec_start" == *"--state-dir /var/lib/pedalwave"* ]] || fail "ExecStart passes no --state-dir /var/lib/pedalwave"
[ "$(value Service StateDirectory)" = "pedalwave" ] || fail "[Service] StateDirectory is not pedalwave"
[ "$(value Service LimitRTPRIO)" = "99" ] || fail "[Service] LimitRTPRIO is not 99"
[ "$(value Service LimitMEMLOCK)" = "infinity" ] || fail "[Service] LimitMEMLOCK is not infinity"
[ "$(value Service KillSignal)" = "SIGTERM" ] || fail "[Service] KillSignal is not SIGTERM"
has Install WantedBy || fail "[Install] WantedBy missing"

# The parser itself, on a unit with the start limit in the wrong section.
bad=$(mktemp)
printf '[Unit]\nDescription=x\n[Service]\nStartLimitBurst=3\nRestart=always\n' >"$bad"
unit_saved=$unit; unit=$bad
has Unit StartLimitBurst && fail "parser: found StartLimitBurst in [Unit] of a unit that has it in [Service]"
has Service StartLimitBurst || fail "parser: missed StartLimitBurst in [Service]"
unit=$unit_saved; rm -f "$bad"

if [ "$fails" -ne 0 ]; then echo "$fails check(s) failed"; exit 1; fi
echo "unit policy: Restart=on-failure, RestartPreventExitStatus=$(value Service RestartPreventExitStatus), StartLimitIntervalSec=$(value Unit StartLimitIntervalSec) StartLimitBurst=$burst in [Unit]: OK"
