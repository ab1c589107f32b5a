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
