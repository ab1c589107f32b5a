# A one-node Slurm cluster on this machine, for the campaign tests (source it; bash).
#   cluster_start DIR   munged (its own key), slurmctld and slurmd in the foreground of background
#                       jobs, every file (slurm.conf, key, state, spool, logs, sockets) under DIR,
#                       ports picked free; exports SLURM_CONF. Returns 1 (with CLUSTER_WHY) when the
#                       packages are missing or a daemon does not come up.
#   cluster_stop        stops exactly the daemons cluster_start started, by their PIDs.
# Root only (slurmd runs jobs as their user and must switch users): CLUSTER_WHY says so otherwise.
CLUSTER_PIDS=()
CLUSTER_WHY=""
CLUSTER_SOCKDIR=""  # a short folder for munge's socket when DIR's path is too long for one

cluster_free_port() {
  /usr/bin/python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'
}

cluster_start() {
  local d=$1
  for exe in munged mungekey slurmctld slurmd sbatch squeue scontrol; do
    if ! command -v "$exe" >/dev/null 2>&1 && [ ! -x "/usr/sbin/$exe" ]; then
      CLUSTER_WHY="$exe not installed (apt-get install slurm-wlm munge; tools/scripts/deps.sh)"; return 1
    fi
  done
  if [ "$(id -u)" -ne 0 ]; then CLUSTER_WHY="not root: slurmd must run as root"; return 1; fi
  export PATH="$PATH:/usr/sbin"
  rm -rf "$d"; mkdir -p "$d"/{munge,state,spool,log}
  chmod 700 "$d/munge"
  local node; node=$(hostname -s)
  local cpus; cpus=$(nproc)
  local p1 p2; p1=$(cluster_free_port); p2=$(cluster_free_port)
  while [ "$p2" = "$p1" ]; do p2=$(cluster_free_port); done

  # munge: its own key and socket (a Unix socket's path has at most 107 characters).
  local sock="$d/munge/munge.socket"
  if [ ${#sock} -gt 100 ]; then
    CLUSTER_SOCKDIR=$(mktemp -d /tmp/pw-munge.XXXXXX); sock="$CLUSTER_SOCKDIR/munge.socket"
  fi
  mungekey --create --keyfile="$d/munge/munge.key" >/dev/null 2>&1 ||
    { dd if=/dev/urandom of="$d/munge/munge.key" bs=1024 count=1 status=none; }
  chmod 600 "$d/munge/munge.key"
  munged -F --force --key-file="$d/munge/munge.key" --socket="$sock" \
    --pid-file="$d/munge/munged.pid" --log-file="$d/log/munged.log" --seed-file="$d/munge/munged.seed" \
    >"$d/log/munged.out" 2>&1 &
  CLUSTER_PIDS+=($!)
  local i
  for i in $(seq 50); do [ -S "$sock" ] && break; sleep 0.1; done
  if [ ! -S "$sock" ]; then
    CLUSTER_WHY="munged did not start: $(tail -3 "$d/log/munged.out" "$d/log/munged.log" 2>/dev/null | tr '\n' ' ')"
    cluster_stop; return 1
  fi

  cat >"$d/slurm.conf" <<CONF
ClusterName=pwtest
SlurmctldHost=$node(127.0.0.1)
SlurmUser=root
SlurmdUser=root
SlurmctldPort=$p1
SlurmdPort=$p2
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$sock
StateSaveLocation=$d/state
SlurmdSpoolDir=$d/spool
SlurmctldPidFile=$d/slurmctld.pid
SlurmdPidFile=$d/slurmd.pid
SlurmctldLogFile=$d/log/slurmctld.log
SlurmdLogFile=$d/log/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
SchedulerType=sched/backfill
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
MpiDefault=none
SwitchType=switch/none
ReturnToService=2
SlurmdParameters=config_overrides
KillWait=1
MinJobAge=10
InactiveLimit=0
NodeName=$node NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=100 State=UNKNOWN
PartitionName=pw Nodes=ALL Default=YES MaxTime=INFINITE State=UP
CONF
  export SLURM_CONF="$d/slurm.conf"
  slurmctld -D -f "$d/slurm.conf" >"$d/log/slurmctld.out" 2>&1 &
  CLUSTER_PIDS+=($!)
  slurmd -D -f "$d/slurm.conf" -N "$node" >"$d/log/slurmd.out" 2>&1 &
  CLUSTER_PIDS+=($!)
  # Up when the node is idle.
  for i in $(seq 100); do
    if sinfo -h -N -o "%T" 2>/dev/null | grep -qx "idle"; then return 0; fi
    sleep 0.2
  done
  CLUSTER_WHY="the node did not become idle in 20 s: $(sinfo -h -N -o '%T %E' 2>&1 | head -2 | tr '\n' ' ') $(tail -2 "$d/log/slurmctld.log" "$d/log/slurmd.log" 2>/dev/null | tr '\n' ' ')"
  cluster_stop; return 1
}

cluster_stop() {
  local pid
  # slurmd first (it ends its jobs' steps), then the controller, then munge.
  for ((i = ${#CLUSTER_PIDS[@]} - 1; i >= 0; i--)); do
    pid=${CLUSTER_PIDS[$i]}
    kill -TERM "$pid" 2>/dev/null || continue
    for _ in $(seq 50); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
    kill -KILL "$pid" 2>/dev/null || true
    wait "$pid" 2>/dev/null || true
  done
  CLUSTER_PIDS=()
  if [ -n "$CLUSTER_SOCKDIR" ]; then rm -rf "$CLUSTER_SOCKDIR"; CLUSTER_SOCKDIR=""; fi
}
