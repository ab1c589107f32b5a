#!/usr/bin/env bash
# The campaign layer's Slurm backend on a real (one-node) Slurm cluster started here
# (cluster.sh: munged, slurmctld, slurmd, all files under the build folder), with pedalwave_paper:
#   1. a k_c sweep through sbatch job arrays (options from a YAML file, chunk 2, throttle 3; its runs
#      in lockstep groups of 2, the local ones in groups of 8) gives bit for bit the local backend's
#      results (sweep.csv without its cpu_s column, the printed best and accuracy-check lines); each
#      group ran exactly once;
#   2. an array task cancelled while it runs (scancel JOB_TASK) is detected and rerun, and the
#      results are still the local ones (one run per group, --group 1, from here on);
#   3. the submitting process killed (SIGKILL) mid-campaign: the same command again resumes —
#      finished runs are not rerun, the running task is followed, not resubmitted (runs.log holds
#      every run exactly once), results the local ones;
#   4. sbatch refusing the job (a bogus --sbatch-opt) is one clear error, exit ≠ 0;
#   5. (with FAULTBENCH_EXE) pedalwave_faultbench's injection trials through sbatch print the same
#      table and per-trial lines as the local backend;
#   6. (with WORKPREC_EXE) pedalwave_workprec's work-precision and fidelity runs through sbatch
#      write the same CSV files (all but the timing columns) as the local backend;
#   7. (with IDENTIFY_EXE) pedalwave_identify fit's evaluations through sbatch give the same
#      fit.json as the local backend (all but the work counters).
# Usage: run_slurm_tests.sh PAPER_EXE WORK_DIR [FAULTBENCH_EXE [WORKPREC_EXE [IDENTIFY_EXE]]] (an
# empty argument skips that tool). Exit 0 pass, 1 fail, 77 SKIPPED (no slurm-wlm /
# munge packages, not root, or the daemons do not come up).
set -uo pipefail
PAPER=$1
W=$2
FAULTBENCH=${3:-}
WORKPREC=${4:-}
IDENTIFY=${5:-}
HERE=$(cd "$(dirname "$0")" && pwd)
source "$HERE/cluster.sh"

rm -rf "$W"; mkdir -p "$W"
if ! cluster_start "$W/cluster"; then
  echo "*****************************************************************"
  echo "SKIPPED: no one-node Slurm cluster: $CLUSTER_WHY"
  echo "*****************************************************************"
  exit 77
fi
trap cluster_stop EXIT
echo "cluster up: SLURM_CONF=$SLURM_CONF, daemons ${CLUSTER_PIDS[*]}"

failures=0
fail() { echo "FAIL: $*"; failures=$((failures + 1)); }
pass() { echo "ok: $*"; }

# sweep.csv without its cpu_s column (the one field that is a measurement, not a result).
results_of() { cut -d, -f1-7 "$1/sweep.csv"; }
# The printed lines that are results: best k_c and the accuracy checks.
printed_of() { grep -E '^  (best k_c|check k_c|whole body)' "$1"; }
same_as_local() {  # $1 local out, $2 slurm out, $3 local log, $4 slurm log, $5 what
  if ! cmp -s <(results_of "$1") <(results_of "$2"); then
    fail "$5: sweep.csv differs from the local backend's"; diff <(results_of "$1") <(results_of "$2") | head -5
  elif ! cmp -s <(printed_of "$3") <(printed_of "$4"); then
    fail "$5: printed results differ"; diff <(printed_of "$3") <(printed_of "$4") | head -5
  else
    pass "$5: bit-identical to the local backend ($(($(results_of "$1" | wc -l) - 2)) runs)"
  fi
}
once_each() {  # $1 campaign folder, $2 runs: runs.log names every run exactly once
  local got; got=$(awk '{print $2}' "$1/runs.log" | sort -n | uniq -c | awk '$1 != 1' | wc -l)
  local n; n=$(awk '{print $2}' "$1/runs.log" | sort -nu | wc -l)
  [ "$got" -eq 0 ] && [ "$n" -eq "$2" ]
}

# ---- 1. sweep through sbatch = local ------------------------------------------------------------
SWEEP=(sweep --from 0 --to 2 --step 0.25 --duration 4 --checks 2 --no-plots --quiet)
"$PAPER" "${SWEEP[@]}" --jobs 2 --out "$W/local1" >"$W/local1.log" 2>&1 || fail "local sweep: exit $?"
cat >"$W/slurm.yaml" <<EOF
partition: pw
time: "00:05:00"
chunk: 2
throttle: 3
poll_s: 0.2
sbatch_options: ["--job-name=pw-test"]
EOF
t0=$(date +%s%N)
# In lockstep groups of 2 (5 campaign items; the local run's groups are 8: a run's result does not
# depend on its group).
"$PAPER" "${SWEEP[@]}" --group 2 --backend slurm --slurm-config "$W/slurm.yaml" --out "$W/slurm1" >"$W/slurm1.log" 2>&1 ||
  { fail "slurm sweep: exit $?"; tail -5 "$W/slurm1.log"; }
echo "slurm sweep: $((($(date +%s%N) - t0) / 1000000)) ms wall"
same_as_local "$W/local1" "$W/slurm1" "$W/local1.log" "$W/slurm1.log" "sweep through sbatch"
C1="$W/slurm1/campaign/sweep"
grep -q '^#SBATCH --partition=pw$' "$C1/job.sh" && grep -q '^#SBATCH --time=00:05:00$' "$C1/job.sh" &&
  grep -q '^#SBATCH --job-name=pw-test$' "$C1/job.sh" && pass "job.sh has the YAML file's options" ||
  fail "job.sh lacks the YAML file's options: $(grep SBATCH "$C1/job.sh" | tr '\n' ' ')"
grep -q "array 0-2" "$W/slurm1.log" && pass "9 runs in groups of 2 (5 items) in chunks of 2 = array 0-2" ||
  fail "expected array 0-2: $(grep submitted "$W/slurm1.log")"
once_each "$C1" 5 && pass "each group ran once" || fail "runs.log: $(cat "$C1/runs.log" | tr '\n' ';')"

# ---- 2. a cancelled task is rerun ---------------------------------------------------------------
LONG=(sweep --from 0 --to 3 --step 1 --duration 300 --checks 0 --no-plots --quiet)
"$PAPER" "${LONG[@]}" --jobs 2 --out "$W/local2" >"$W/local2.log" 2>&1 || fail "local long sweep: exit $?"
"$PAPER" "${LONG[@]}" --group 1 --backend slurm --chunk 1 --throttle 2 --poll 0.2 --max-retries 2 --out "$W/slurm2" \
  >"$W/slurm2.log" 2>&1 &
submitter=$!
victim=""
for _ in $(seq 150); do
  victim=$(squeue -h -r -t RUNNING -o "%F_%K" 2>/dev/null | head -1)
  [ -n "$victim" ] && break
  sleep 0.1
done
if [ -z "$victim" ]; then
  fail "no array task ever ran"
else
  # At once: a run takes ~1 s here, it must still be running when cancelled.
  scancel "$victim" && echo "cancelled array task $victim ($(ls "$W/slurm2/campaign/sweep/results" | wc -l) results then)"
fi
wait "$submitter"; rc=$?
[ "$rc" -eq 0 ] || { fail "slurm sweep with a cancelled task: exit $rc"; tail -5 "$W/slurm2.log"; }
if grep -q "ended without its results.*resubmitting" "$W/slurm2.log"; then
  pass "the cancelled task was seen: $(grep -m1 'ended without' "$W/slurm2.log")"
else
  fail "no resubmission in the log: $(cat "$W/slurm2.log" | tr '\n' ';')"
fi
same_as_local "$W/local2" "$W/slurm2" "$W/local2.log" "$W/slurm2.log" "after a cancelled task"

# ---- 3. resume after the submitter was killed ---------------------------------------------------
"$PAPER" "${LONG[@]}" --group 1 --backend slurm --chunk 1 --throttle 1 --poll 0.2 --out "$W/slurm3" >"$W/slurm3a.log" 2>&1 &
submitter=$!
C3="$W/slurm3/campaign/sweep"
for _ in $(seq 300); do
  [ -n "$(ls "$C3/results" 2>/dev/null)" ] && break
  sleep 0.1
done
kill -KILL "$submitter"; wait "$submitter" 2>/dev/null
done_before=$(ls "$C3/results" 2>/dev/null | wc -l)
queued=$(squeue -h -r -o "%F_%K %T" | tr '\n' ' ')
echo "submitter killed with $done_before runs done, queue: $queued"
"$PAPER" "${LONG[@]}" --group 1 --backend slurm --chunk 1 --throttle 1 --poll 0.2 --out "$W/slurm3" >"$W/slurm3b.log" 2>&1 ||
  { fail "resumed sweep: exit $?"; tail -5 "$W/slurm3b.log"; }
if grep -q "resuming: $done_before runs done" "$W/slurm3b.log" && [ "$done_before" -ge 1 ]; then
  pass "resumed with $done_before runs done"
else
  fail "expected 'resuming: $done_before runs done': $(head -3 "$W/slurm3b.log" | tr '\n' ';')"
fi
once_each "$C3" 4 && pass "no run ran twice across the interruption" || fail "runs.log: $(cat "$C3/runs.log" | tr '\n' ';')"
[ "$(wc -l <"$C3/state.txt")" -eq 1 ] && pass "the queued tasks were followed, not submitted again" ||
  fail "state.txt: $(cat "$C3/state.txt" | tr '\n' ';')"
same_as_local "$W/local2" "$W/slurm3" "$W/local2.log" "$W/slurm3b.log" "after resuming"

# ---- 4. sbatch refuses -----------------------------------------------------------------------------
"$PAPER" sweep --from 0 --to 0 --step 1 --duration 1 --checks 0 --no-plots --quiet --backend slurm \
  --sbatch-opt=--bogus-option --out "$W/slurm4" >"$W/slurm4.log" 2>&1; rc=$?
if [ "$rc" -ne 0 ] && grep -q "error: sbatch --array=0 .*job.sh failed" "$W/slurm4.log"; then
  pass "sbatch's refusal is one error line (exit $rc)"
else
  fail "expected an sbatch error: exit $rc, $(tail -2 "$W/slurm4.log" | tr '\n' ';')"
fi

# ---- 5. faultbench's trials --------------------------------------------------------------------------
if [ -n "$FAULTBENCH" ]; then
  FB=(--trials 1 --only encoder_offset --seed 11 -v)
  "$FAULTBENCH" "${FB[@]}" --jobs 2 >"$W/fb_local.md" 2>"$W/fb_local.err" || fail "local faultbench: exit $?"
  "$FAULTBENCH" "${FB[@]}" --backend slurm --campaign-dir "$W/fb" --poll 0.2 >"$W/fb_slurm.md" 2>"$W/fb_slurm.err" ||
    { fail "slurm faultbench: exit $?"; tail -3 "$W/fb_slurm.err"; }
  if cmp -s "$W/fb_local.md" "$W/fb_slurm.md" &&
     cmp -s <(grep -- '->' "$W/fb_local.err") <(grep -- '->' "$W/fb_slurm.err") &&
     [ "$(grep -c -- '->' "$W/fb_slurm.err")" -eq 2 ]; then
    pass "faultbench trials through sbatch = local (table and 2 trial lines)"
  else
    fail "faultbench differs: $(diff "$W/fb_local.md" "$W/fb_slurm.md" | head -3 | tr '\n' ';')"
  fi
fi

# ---- 6. workprec's runs ------------------------------------------------------------------------------
if [ -n "$WORKPREC" ]; then
  SC=$(cd "$HERE/../../../config/scenes" && pwd)
  WP=("$SC/free_fall.yaml" "$SC/flat_high_friction.yaml" --quick --duration 0.3 --repeats 1 --quiet)
  # work_precision.csv / fidelity.csv without wall_s and cpu_s (columns 6-7): measurements, not results.
  wp_results() { cut -d, -f1-5,8- "$1"; }
  "$WORKPREC" "${WP[@]}" --jobs 2 --out "$W/wp_local" >"$W/wp_local.log" 2>&1 || fail "local workprec: exit $?"
  "$WORKPREC" "${WP[@]}" --backend slurm --chunk 4 --poll 0.2 --out "$W/wp_slurm" >"$W/wp_slurm.log" 2>&1 ||
    { fail "slurm workprec: exit $?"; tail -3 "$W/wp_slurm.log"; }
  n=$(($(grep -vc '^#' "$W/wp_local/work_precision.csv") - 1))
  if [ "$n" -gt 10 ] && cmp -s <(wp_results "$W/wp_local/work_precision.csv") <(wp_results "$W/wp_slurm/work_precision.csv") &&
     [ -s "$W/wp_slurm/campaign/work-precision/job.sh" ]; then
    pass "workprec through sbatch = local ($n runs, work_precision.csv but the timings)"
  else
    fail "workprec differs: $(diff <(wp_results "$W/wp_local/work_precision.csv") <(wp_results "$W/wp_slurm/work_precision.csv") | head -3 | tr '\n' ';')"
  fi
  FID=("$SC/flat_high_friction.yaml" --fidelity --duration 0.2 --quiet)
  "$WORKPREC" "${FID[@]}" --jobs 2 --out "$W/fid_local" >/dev/null 2>&1 || fail "local fidelity: exit $?"
  "$WORKPREC" "${FID[@]}" --backend slurm --chunk 7 --poll 0.2 --out "$W/fid_slurm" >"$W/fid_slurm.log" 2>&1 ||
    { fail "slurm fidelity: exit $?"; tail -3 "$W/fid_slurm.log"; }
  fid_results() { cut -d, -f1-5,8-9 "$1"; }  # all but cpu_s, wall_s
  if cmp -s <(fid_results "$W/fid_local/fidelity.csv") <(fid_results "$W/fid_slurm/fidelity.csv"); then
    pass "workprec --fidelity through sbatch = local ($(($(wc -l <"$W/fid_local/fidelity.csv") - 1)) runs)"
  else
    fail "fidelity differs: $(diff <(fid_results "$W/fid_local/fidelity.csv") <(fid_results "$W/fid_slurm/fidelity.csv") | head -3 | tr '\n' ';')"
  fi
fi

# ---- 7. the identification's evaluations --------------------------------------------------------------
if [ -n "$IDENTIFY" ]; then
  ID=(fit --smoke --starts 2 --max-evals 2 --no-cache --quiet)
  "$IDENTIFY" "${ID[@]}" --jobs 2 --out "$W/id_local" >"$W/id_local.log" 2>&1 || fail "local identify: exit $?"
  "$IDENTIFY" "${ID[@]}" --backend slurm --chunk 5 --poll 0.2 --out "$W/id_slurm" >"$W/id_slurm.log" 2>&1 ||
    { fail "slurm identify: exit $?"; tail -3 "$W/id_slurm.log"; }
  id_results() { grep -v -E '"(evaluations|simulations|cache_hits)"' "$1/fit.json"; }
  if [ -s "$W/id_local/fit.json" ] && cmp -s <(id_results "$W/id_local") <(id_results "$W/id_slurm") &&
     ls "$W/id_slurm/campaign" | grep -q '^eval-'; then
    pass "identify fit through sbatch = local (fit.json, $(ls "$W/id_slurm/campaign" | wc -l) campaigns)"
  else
    fail "identify differs: $(diff <(id_results "$W/id_local") <(id_results "$W/id_slurm") | head -3 | tr '\n' ';')"
  fi
fi

if [ "$failures" -ne 0 ]; then echo "$failures FAILED (logs in $W)"; exit 1; fi
echo "all slurm campaign tests passed"
