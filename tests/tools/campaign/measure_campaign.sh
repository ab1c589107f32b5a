#!/usr/bin/env bash
# The README's measured campaign: the paper's k_c sweep (151 runs of 60 s, no accuracy re-runs,
# no figures) with the local backend (2 threads) and through sbatch on the one-node cluster of
# cluster.sh (2 CPUs, 1 per array task) at the given chunk sizes; prints wall times, the tasks and
# the overhead per task, and checks the results are bit-identical. Stops the daemons it started.
# Usage: measure_campaign.sh PAPER_EXE WORK_DIR [CHUNK ...]   (default chunks: 10 1)
set -uo pipefail
PAPER=$1; W=$2; shift 2
CHUNKS=("$@"); [ ${#CHUNKS[@]} -eq 0 ] && CHUNKS=(10 1)
HERE=$(cd "$(dirname "$0")" && pwd)
source "$HERE/cluster.sh"
rm -rf "$W"; mkdir -p "$W"
cluster_start "$W/cluster" || { echo "no cluster: $CLUSTER_WHY"; exit 77; }
trap cluster_stop EXIT
SWEEP=(sweep --checks 0 --no-plots --quiet)
ms() { echo $(( $(date +%s%N) / 1000000 )); }
t0=$(ms); "$PAPER" "${SWEEP[@]}" --jobs 2 --out "$W/local" >"$W/local.log" 2>&1 || { echo "local failed"; exit 1; }
local_ms=$(( $(ms) - t0 ))
runs=$(( $(wc -l <"$W/local/sweep.csv") - 2 ))
echo "| backend | runs | array tasks | wall [s] | overhead per task [s] | results |"
echo "|---|---|---|---|---|---|"
echo "| local, 2 threads | $runs | — | $(awk "BEGIN{printf \"%.1f\", $local_ms/1000}") | — | — |"
for c in "${CHUNKS[@]}"; do
  t0=$(ms)
  "$PAPER" "${SWEEP[@]}" --backend slurm --chunk "$c" --poll 0.5 --out "$W/slurm$c" >"$W/slurm$c.log" 2>&1 ||
    { echo "slurm chunk $c failed: $(tail -2 "$W/slurm$c.log")"; exit 1; }
  s_ms=$(( $(ms) - t0 ))
  tasks=$(( (runs + c - 1) / c ))
  same=$(cmp -s <(cut -d, -f1-7 "$W/local/sweep.csv") <(cut -d, -f1-7 "$W/slurm$c/sweep.csv") && echo "bit-identical" || echo "DIFFER")
  # 2 tasks run at once on the 2-CPU node: each task's share of the extra wall time × 2.
  echo "| slurm, chunk $c | $runs | $tasks | $(awk "BEGIN{printf \"%.1f\", $s_ms/1000}") | $(awk "BEGIN{printf \"%.2f\", 2*($s_ms-$local_ms)/1000/$tasks}") | $same |"
done
# From slurmctld's log (less sensitive to the machine's other load than the wall times): per job,
# the mean time from a task's start to its end, and from a task's end to the next task's start.
# The runs' own CPU time (sweep.csv's cpu_s) for scale.
echo
echo "runs' CPU time: $(awk -F, 'NR > 2 {s += $8} END {printf "%.1f s in all, %.3f s per run", s, s / (NR - 2)}' "$W/local/sweep.csv") (local backend)"
/usr/bin/python3 - "$W/cluster/log/slurmctld.log" "${CHUNKS[@]}" <<'PY'
import datetime, re, sys
alloc, done = {}, {}
for l in open(sys.argv[1]):
    m = re.match(r"\[(.*?)\] (?:sched: Allocate JobId=(\S+)\(|sched/backfill: _start_job: Started JobId=(\S+)\(|"
                 r"_job_complete: JobId=(\S+)\(\d+\) done)", l)
    if not m: continue
    t = datetime.datetime.fromisoformat(m.group(1))
    if m.group(4): done[m.group(4)] = t
    else: alloc[m.group(2) or m.group(3)] = t
jobs = sorted({k.split("_")[0] for k in alloc}, key=int)
for job, chunk in zip(jobs, sys.argv[2:]):
    a = {k: t for k, t in alloc.items() if k.split("_")[0] == job}
    d = {k: t for k, t in done.items() if k.split("_")[0] == job}
    run = [(d[k] - a[k]).total_seconds() for k in a if k in d]
    ends = sorted(d.values())
    gaps = []
    for t in sorted(a.values())[2:]:  # the first two start at once
        before = [e for e in ends if e <= t]
        if before: gaps.append((t - before[-1]).total_seconds())
    print(f"chunk {chunk}: {len(a)} tasks, task start to end {sum(run)/len(run):.2f} s (mean), "
          f"a task's end to the next start {sum(gaps)/max(len(gaps),1):.2f} s (mean), {max(gaps or [0]):.2f} s (max)")
PY
