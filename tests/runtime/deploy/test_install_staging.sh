#!/usr/bin/env bash
# The install rules into a staging root (DESTDIR=<tmp> cmake --install <build>): every program,
# the configuration examples, /etc/pedalwave/robot.yaml, the unit, the docs and the IDL are there;
# no program carries an RPATH/RUNPATH; the staged daemon accepts the staged robot.yaml; and
# systemd-analyze verify of the staged unit, run against the staged binary, says nothing.
set -euo pipefail
. "${1:?usage: test_install_staging.sh paths.sh}"
stage=$(mktemp -d /tmp/pedalwave-stage.XXXXXX)
trap 'rm -rf "$stage" "$stage.unit" "$stage.log"' EXIT
fails=0
fail() { echo "FAIL: $*"; fails=$((fails + 1)); }

DESTDIR="$stage" cmake --install "$BUILD_DIR" >"$stage.log" 2>&1 || { cat "$stage.log"; rm -f "$stage.log"; exit 1; }
echo "installed $(grep -c 'Installing:' "$stage.log") files into $stage (prefix $PREFIX)"
rm -f "$stage.log"

[ -n "$PROGRAMS" ] || fail "no programs in the install manifest"
for p in $PROGRAMS; do
  f="$stage$BIN_DIR/$p"
  if [ ! -x "$f" ]; then fail "$BIN_DIR/$p missing"; continue; fi
  if readelf -d "$f" | grep -qE 'RPATH|RUNPATH'; then fail "$p has an RPATH: $(readelf -d "$f" | grep -E 'RPATH|RUNPATH')"; fi
done
for f in "$CONF_DIR/robot.yaml" "$UNIT_DIR/pedalwave-runtime.service" \
         "$DOC_DIR/README.md" "$DOC_DIR/DEPLOY.md" "$DOC_DIR/PROTOCOL.md" "$DOC_DIR/TELEMETRY.md" \
         "$DATA_DIR/idl/Telemetry.idl" "$DATA_DIR/examples/runtime/demo.yaml" \
         "$DATA_DIR/examples/runtime/socketcan.yaml" "$DATA_DIR/examples/runtime/serial.yaml" \
         "$DATA_DIR/examples/scenes/flat_high_friction.yaml" "$DATA_DIR/figures/soak.py" \
         "$DATA_DIR/figures/pwfig.py" "$DATA_DIR/figures/runtime.py" "$DATA_DIR/figures/simulate.py" \
         "$DATA_DIR/figures/recording.py" "$DATA_DIR/figures/workprec.py" "$DATA_DIR/figures/paper.py"; do
  [ -f "$stage$f" ] || fail "$f missing"
done
# The installed figure scripts work on their own (pwfig.py found beside them): the work-precision
# figures of the committed results' CSV.
if /usr/bin/python3 -c 'import matplotlib, numpy' 2>/dev/null; then
  mkdir -p "$stage/wp"
  cp "$(dirname "$0")/../../../tools/workprec/results/work_precision.csv" "$stage/wp/"
  /usr/bin/python3 "$stage$DATA_DIR/figures/workprec.py" "$stage/wp" >/dev/null || fail "the installed workprec.py failed"
  [ -s "$stage/wp/stair_com.png" ] || fail "the installed workprec.py drew no stair_com.png"
fi
grep -q "^ExecStart=$BIN_DIR/pedalwave_runtime --config $CONF_DIR/robot.yaml " "$stage$UNIT_DIR/pedalwave-runtime.service" \
  || fail "the unit's ExecStart does not name $BIN_DIR/pedalwave_runtime and $CONF_DIR/robot.yaml"

out=$("$stage$BIN_DIR/pedalwave_runtime" --check-config --config "$stage$CONF_DIR/robot.yaml") || fail "--check-config refused the staged robot.yaml"
echo "$out"
[[ "$out" == *"waits in READY"* ]] || fail "the shipped robot.yaml starts walking on its own"

# systemd-analyze verify --root=<stage> wants a whole system in the root (sysinit.target, …): verify
# the staged unit with its ExecStart pointed at the staged binary instead (the line above checks
# the real path).
if command -v systemd-analyze >/dev/null; then
  mkdir -p "$stage.unit"
  sed "s#^ExecStart=$BIN_DIR/#ExecStart=$stage$BIN_DIR/#" "$stage$UNIT_DIR/pedalwave-runtime.service" \
    >"$stage.unit/pedalwave-runtime.service"
  verify=$(systemd-analyze verify "$stage.unit/pedalwave-runtime.service" 2>&1) || true
  rm -rf "$stage.unit"
  echo "systemd-analyze verify (ExecStart → the staged binary): ${verify:-(nothing to say)}"
  if grep -q 'pedalwave' <<<"$verify"; then fail "systemd-analyze verify complains about the unit"; fi
else
  echo "(systemd-analyze not installed: the unit's verify runs in package_deb)"
fi

if [ "$fails" -ne 0 ]; then echo "$fails check(s) failed"; exit 1; fi
echo "staging install: OK"
