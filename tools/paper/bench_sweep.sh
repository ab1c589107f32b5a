#!/bin/sh
# The paper's k_c sweep (151 k_c × 60 s over the stair, `pedalwave_paper sweep`) timed with two
# plant integrators in one run, and both checked against a tight reference (issue 19, point 4):
#   before  --integrator $BEFORE_METHOD --h $BEFORE_H (default semi_implicit_euler 2.5e-4 s, the stair
#           scene's integrator before issue 19's implicit_contact)
#   after   --integrator $AFTER_METHOD --h $AFTER_H (default implicit_contact 1e-3 s) --rate
#           $AFTER_RATE (default 1000 Hz, the paper's; 500 with AFTER_H=2e-3 is a 2-ms step, the
#           controller's references then held for 2 ms: a different experiment, checked here
#           against the same 1-kHz reference), its runs 8 at a time in lockstep SIMD lanes where
#           the machine has AVX2 or AVX-512 (the tool's default)
#   after, one by one   the same with --no-lanes (each run on the scalar plant)
#   ref     dopri45 (rtol 1e-6) at k_c = 0, 5, 10, 15
# Prints CPU (user + sys of the whole process, /usr/bin/time) and wall time of each sweep, their
# ratio, and each sweep's largest COM difference from the reference over those four k_c:
# |v − v_ref| · (60 s − 2 s), the average-speed window of the sweep (tools/paper/README.md).
# Usage: tools/paper/bench_sweep.sh [out_dir]
#        (env: PAPER, JOBS, BEFORE_METHOD, BEFORE_H, AFTER_METHOD, AFTER_H, AFTER_RATE, DURATION)
set -eu
PAPER=${PAPER:-build/release/tools/paper/pedalwave_paper}
OUT=${1:-out/sweep_bench}
JOBS=${JOBS:-2}
BEFORE_METHOD=${BEFORE_METHOD:-semi_implicit_euler}
BEFORE_H=${BEFORE_H:-2.5e-4}
AFTER_METHOD=${AFTER_METHOD:-implicit_contact}
AFTER_H=${AFTER_H:-1e-3}
AFTER_RATE=${AFTER_RATE:-1000}
DURATION=${DURATION:-60}
[ -x "$PAPER" ] || { echo "bench_sweep.sh: $PAPER not found (build the pedalwave_paper target)" >&2; exit 2; }
mkdir -p "$OUT"

run() {
  name=$1
  shift
  /usr/bin/time -f "%U %S %e" -o "$OUT/$name.time" \
    "$PAPER" sweep --checks 0 --no-plots --quiet --jobs "$JOBS" --duration "$DURATION" \
    --out "$OUT/$name" "$@" > "$OUT/$name.log"
}

run before --integrator "$BEFORE_METHOD" --h "$BEFORE_H"
run after --integrator "$AFTER_METHOD" --h "$AFTER_H" --rate "$AFTER_RATE"
run after_scalar --integrator "$AFTER_METHOD" --h "$AFTER_H" --rate "$AFTER_RATE" --no-lanes
run ref --from 0 --to 15 --step 5 --integrator dopri45 --h 1e-4

/usr/bin/python3 - "$OUT" "$DURATION" "$AFTER_METHOD" "$AFTER_H" "$BEFORE_METHOD" "$BEFORE_H" "$AFTER_RATE" <<'EOF'
import csv, sys
out, duration, method, h, bmethod, bh = sys.argv[1], float(sys.argv[2]), sys.argv[3], sys.argv[4], sys.argv[5], sys.argv[6]
rate = float(sys.argv[7])
def times(name):
    u, s, e = open(f"{out}/{name}.time").read().split()[:3]
    return float(u) + float(s), float(e)
def speeds(name):
    rows = [r for r in csv.reader(l for l in open(f"{out}/{name}/sweep.csv") if not l.startswith("#"))]
    head = rows[0]
    return {round(float(r[0]), 6): float(r[head.index("speed_m_s")]) for r in rows[1:]}
ref = speeds("ref")
window = duration - 2.0
print("| sweep | integrator | CPU [s] | wall [s] | CPU ratio to before | max COM difference from dopri45 at k_c = 0, 5, 10, 15 [mm] |")
print("|---|---|---:|---:|---:|---:|")
cpu0, _ = times("before")
after = f"{method}, h = {h} s" + ("" if rate == 1000 else f", control rate {rate:g} Hz")
lanes = next((l.rsplit(", runs ", 1)[1].strip() for l in open(f"{out}/after.log") if l.startswith("== k_c sweep")), "?")
for name, integ in (("before", f"{bmethod}, h = {bh} s"), ("after", after + f"; runs {lanes}"),
                    ("after_scalar", after + "; runs one by one (--no-lanes)")):
    cpu, wall = times(name)
    v = speeds(name)
    diff = max(abs(v[k] - ref[k]) * window for k in ref) * 1e3
    print(f"| {name} | {integ} | {cpu:.1f} | {wall:.1f} | {cpu / cpu0:.2f} | {diff:.2f} |")
cpu, wall = times("ref")
print(f"\nreference (4 k_c, dopri45 rtol 1e-6): {cpu:.1f} s CPU, {wall:.1f} s wall")
EOF
