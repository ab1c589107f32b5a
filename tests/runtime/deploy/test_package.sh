#!/usr/bin/env bash
# The Debian package end to end, on this machine (root, dpkg): cpack -G DEB from the build, then
#   dpkg -i           files in place, conffile, pedalwave user and group, state and log folders,
#                     the unit installed but not enabled, dependencies from dpkg-shlibdeps
#   systemd-analyze verify <unit dir>/pedalwave-runtime.service: nothing about the unit
#   pedalwave_runtime --check-config --config /etc/pedalwave/robot.yaml: accepted, no auto-start
#   as the pedalwave user, with the unit's --state-dir /var/lib/pedalwave: a crash marker keeps an
#                     auto-starting simulated-plant run READY (exit 0, marker cleared); a fault
#                     run exits 4 and leaves no marker
#   dpkg -r           programs and unit gone (the conffile stays, as Debian wants)
#   dpkg -P           conffile, state and logs gone (the system user stays, as Debian does)
# Exit 77 (ctest: skipped) when not root, without dpkg/cpack, or with a pedalwave package already
# installed (it is not ours to remove).
set -euo pipefail
. "${1:?usage: test_package.sh paths.sh}"

skip() {
  echo "######################################################################"
  echo "### SKIPPED: $*"
  echo "### The Debian package was NOT built, installed or removed.       ###"
  echo "######################################################################"
  exit 77
}
[ "$(id -u)" -eq 0 ] || skip "not root (dpkg -i needs root)"
for t in dpkg dpkg-deb dpkg-shlibdeps cpack runuser; do command -v "$t" >/dev/null || skip "$t not installed"; done
if dpkg-query -W -f='${Status}' pedalwave 2>/dev/null | grep -q "ok installed"; then
  skip "a pedalwave package is already installed on this machine"
fi

work=$(mktemp -d /tmp/pedalwave-pkg.XXXXXX)
chmod 0755 "$work"
installed=0
cleanup() {
  if [ "$installed" -eq 1 ]; then dpkg -P pedalwave >/dev/null 2>&1 || true; fi
  rm -rf "$work"
}
trap cleanup EXIT
fails=0
fail() { echo "FAIL: $*"; fails=$((fails + 1)); }
step() { echo "== $*"; }

step "cpack -G DEB"
(cd "$BUILD_DIR" && cpack -G DEB -B "$work/out" >"$work/cpack.log" 2>&1) || { cat "$work/cpack.log"; exit 1; }
deb=$(ls "$work"/out/pedalwave_*.deb)
echo "$deb ($(du -h "$deb" | cut -f1))"
dpkg-deb -f "$deb" Package Version Architecture Depends
depends=$(dpkg-deb -f "$deb" Depends)
for d in adduser libc6 libyaml-cpp; do [[ "$depends" == *"$d"* ]] || fail "Depends lacks $d: $depends"; done
conffiles=$(dpkg-deb -I "$deb" conffiles 2>/dev/null || true)
[[ "$conffiles" == *"$CONF_DIR/robot.yaml"* ]] || fail "$CONF_DIR/robot.yaml is not a conffile (conffiles: '$conffiles')"

step "dpkg -i"
dpkg -i "$deb" >"$work/dpkg.log" 2>&1 || { cat "$work/dpkg.log"; fail "dpkg -i failed"; exit 1; }
installed=1
for p in $PROGRAMS; do [ -x "$BIN_DIR/$p" ] || fail "$BIN_DIR/$p missing"; done
for f in "$CONF_DIR/robot.yaml" "$UNIT_DIR/pedalwave-runtime.service" "$DOC_DIR/DEPLOY.md" \
         "$DOC_DIR/README.md" "$DOC_DIR/PROTOCOL.md" "$DATA_DIR/idl/Telemetry.idl" \
         "$DATA_DIR/examples/runtime/sim_lockstep.yaml" "$DATA_DIR/examples/scenes/flat_high_friction.yaml"; do
  [ -f "$f" ] || fail "$f missing"
done
getent passwd pedalwave >/dev/null || fail "no pedalwave user"
getent group pedalwave >/dev/null || fail "no pedalwave group"
[ "$(getent passwd pedalwave | cut -d: -f7)" != "/bin/bash" ] || fail "the pedalwave user has a login shell"
for d in /var/lib/pedalwave /var/log/pedalwave; do
  [ "$(stat -c %U "$d" 2>/dev/null)" = "pedalwave" ] || fail "$d missing or not owned by pedalwave"
done
if [ -e /etc/systemd/system/multi-user.target.wants/pedalwave-runtime.service ]; then
  fail "the unit is enabled after install (it must not be)"
fi
echo "user: $(getent passwd pedalwave)"

step "systemd-analyze verify $UNIT_DIR/pedalwave-runtime.service"
if command -v systemd-analyze >/dev/null; then
  verify=$(systemd-analyze verify "$UNIT_DIR/pedalwave-runtime.service" 2>&1) || true
  echo "${verify:-(nothing to say)}"
  if grep -q 'pedalwave' <<<"$verify"; then fail "systemd-analyze verify complains about the unit"; fi
else
  fail "systemd-analyze not installed (package systemd; tools/scripts/deps.sh installs it)"
fi

step "$BIN_DIR/pedalwave_runtime --check-config --config $CONF_DIR/robot.yaml"
out=$("$BIN_DIR/pedalwave_runtime" --check-config --config "$CONF_DIR/robot.yaml") || fail "--check-config refused $CONF_DIR/robot.yaml (exit $?)"
echo "$out"
[[ "$out" == *"waits in READY"* ]] || fail "the installed robot.yaml starts walking on its own"
help=$("$BIN_DIR/pedalwave_runtime" --help) || fail "--help exited $?"
[[ "$help" == *"4  a fault ended the run"* ]] || fail "--help has no exit-status table"

# Simulated-plant runs of the installed daemon from the installed examples, as the service user.
mkdir -p "$work/runtime" "$work/scenes"
cp "$DATA_DIR/examples/scenes/flat_high_friction.yaml" "$work/scenes/walk.yaml"
cp "$DATA_DIR/examples/scenes/flat_high_friction.yaml" "$work/scenes/fault.yaml"
printf '\nfaults:\n  - {type: encoder_stuck, joint: 0, t_start: 0.5}\n' >>"$work/scenes/fault.yaml"
sed 's#scene: [^,}]*#scene: ../scenes/walk.yaml#' "$DATA_DIR/examples/runtime/sim_lockstep.yaml" >"$work/runtime/walk.yaml"
sed 's#scene: [^,}]*#scene: ../scenes/fault.yaml#' "$DATA_DIR/examples/runtime/sim_lockstep.yaml" >"$work/runtime/fault.yaml"
chmod -R a+rX "$work"
as_service() { runuser -u pedalwave -- "$BIN_DIR/pedalwave_runtime" --no-telemetry --state-dir /var/lib/pedalwave "$@"; }

step "a crash marker in /var/lib/pedalwave: the auto-starting run stays READY"
runuser -u pedalwave -- sh -c 'echo "pid 1, config robot.yaml, walking since (test)" > /var/lib/pedalwave/running'
set +e
out=$(as_service -c "$work/runtime/walk.yaml" --duration 3 2>&1); rc=$?
set -e
grep -E "previous run|^exit:|forward speed" <<<"$out" || true
[ "$rc" -eq 0 ] || fail "the READY run exited $rc, expected 0"
[[ "$out" == *"previous run did not end in order"* ]] || fail "the daemon did not say why it stays READY"
speed=$(grep -oE 'forward speed: -?[0-9.]+' <<<"$out" | grep -oE -- '-?[0-9.]+$' || echo none)
awk -v v="$speed" 'BEGIN { exit !(v != "none" && v < 0.1 && v > -0.1) }' \
  || fail "forward speed '$speed' cm/s: the robot walked after a crash marker"
[ ! -e /var/lib/pedalwave/running ] || fail "the orderly end left the marker"

step "a fault ends the run: exit 4, no marker left"
set +e
out=$(as_service -c "$work/runtime/fault.yaml" --duration 3 2>&1); rc=$?
set -e
echo "$out" | grep -E "^exit:" || true
[ "$rc" -eq 4 ] || fail "the fault run exited $rc, expected 4"
[ ! -e /var/lib/pedalwave/running ] || fail "the fault end left the marker"

step "dpkg -r pedalwave"
dpkg -r pedalwave >"$work/dpkg.log" 2>&1 || { cat "$work/dpkg.log"; fail "dpkg -r failed"; }
for p in $PROGRAMS; do [ ! -e "$BIN_DIR/$p" ] || fail "$BIN_DIR/$p left after dpkg -r"; done
[ ! -e "$UNIT_DIR/pedalwave-runtime.service" ] || fail "the unit is left after dpkg -r"
[ ! -e "$DOC_DIR/DEPLOY.md" ] || fail "the docs are left after dpkg -r"
[ -f "$CONF_DIR/robot.yaml" ] || fail "dpkg -r removed the conffile (only a purge should)"

step "dpkg -P pedalwave"
dpkg -P pedalwave >"$work/dpkg.log" 2>&1 || { cat "$work/dpkg.log"; fail "dpkg -P failed"; }
installed=0
[ ! -e "$CONF_DIR" ] || fail "$CONF_DIR is left after the purge: $(ls -A "$CONF_DIR")"
for d in /var/lib/pedalwave /var/log/pedalwave "$DATA_DIR"; do [ ! -e "$d" ] || fail "$d left after the purge"; done
dpkg-query -W -f='${Status}' pedalwave 2>/dev/null | grep -q "ok installed" && fail "dpkg still lists pedalwave"

if [ "$fails" -ne 0 ]; then echo "$fails check(s) failed"; exit 1; fi
echo "package: built, installed, checked, removed and purged: OK"
