#!/usr/bin/env bash
# A one-node Slurm cluster on this machine, for the tests of `kodama-dag submit` (tests/slurm.rs)
# and for trying submissions before a real cluster. Needs Debian's slurm-wlm and munge
# (`apt-get install slurm-wlm munge`) and root, as munged and slurmd do.
#
#   scripts/slurm_local.sh start DIR   # writes DIR/slurm.conf, starts munged, slurmctld, slurmd;
#                                      # prints `export SLURM_CONF=DIR/slurm.conf`
#   scripts/slurm_local.sh stop DIR    # stops the three daemons by their PIDs
#
# The configuration is the minimal one that runs without cgroups or accounting (so `squeue --json
# -t all` is the only record of finished jobs, kept an hour by MinJobAge).
set -euo pipefail

usage() { echo "usage: $0 start|stop DIR" >&2; exit 2; }
[ $# = 2 ] || usage
cmd=$1
mkdir -p "$2"
dir=$(cd "$2" && pwd)

stop() {
    for pidfile in "$dir/slurmd.pid" "$dir/slurmctld.pid" "$dir/munged.pid"; do
        if [ -s "$pidfile" ]; then
            kill "$(cat "$pidfile")" 2>/dev/null || true
            rm -f "$pidfile"
        fi
    done
}

start() {
    for tool in munged slurmctld slurmd sinfo; do
        command -v "$tool" >/dev/null 2>&1 || [ -x "/usr/sbin/$tool" ] \
            || { echo "slurm_local: $tool not found (apt-get install slurm-wlm munge)" >&2; exit 1; }
    done
    mkdir -p "$dir/state" "$dir/spool" "$dir/log" /run/munge
    chown munge:munge /run/munge 2>/dev/null || true
    if ! munge -n 2>/dev/null | unmunge >/dev/null 2>&1; then
        [ -s /etc/munge/munge.key ] || { echo "slurm_local: /etc/munge/munge.key is missing" >&2; exit 1; }
        runuser -u munge -- /usr/sbin/munged \
            || { echo "slurm_local: munged did not start" >&2; exit 1; }
        # munged writes its PID where its own user may: copied here so that stop ends only the
        # munged this script started.
        for _ in $(seq 1 50); do [ -s /run/munge/munged.pid ] && break; sleep 0.1; done
        cp /run/munge/munged.pid "$dir/munged.pid"
    fi
    local host cpus mem
    host=$(hostname -s)
    cpus=$(nproc)
    # RealMemory must not exceed what slurmd measures, or the node is drained: 90 % of it.
    mem=$(/usr/sbin/slurmd -C 2>/dev/null | sed -n 's/.*RealMemory=\([0-9]*\).*/\1/p' | head -1)
    mem=$(( ${mem:-4000} * 9 / 10 ))
    cat > "$dir/slurm.conf" <<CONF
ClusterName=kodama
SlurmctldHost=$host(127.0.0.1)
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
SlurmctldPort=6817
SlurmdPort=6818
MpiDefault=none
StateSaveLocation=$dir/state
SlurmdSpoolDir=$dir/spool
SlurmctldPidFile=$dir/slurmctld.pid
SlurmdPidFile=$dir/slurmd.pid
SlurmctldLogFile=$dir/log/slurmctld.log
SlurmdLogFile=$dir/log/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
ReturnToService=2
MinJobAge=3600
SchedulerParameters=sched_interval=2
NodeName=$host NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=$mem State=UNKNOWN
PartitionName=debug Nodes=ALL Default=YES MaxTime=INFINITE State=UP
CONF
    export SLURM_CONF="$dir/slurm.conf"
    /usr/sbin/slurmctld || { echo "slurm_local: slurmctld did not start (see $dir/log)" >&2; stop; exit 1; }
    /usr/sbin/slurmd || { echo "slurm_local: slurmd did not start (see $dir/log)" >&2; stop; exit 1; }
    for _ in $(seq 1 150); do
        if sinfo -h -o %T 2>/dev/null | grep -q idle; then
            echo "export SLURM_CONF=$dir/slurm.conf"
            return 0
        fi
        sleep 0.2
    done
    echo "slurm_local: the node did not become idle in 30 s (see $dir/log)" >&2
    stop
    exit 1
}

case $cmd in
    start) start ;;
    stop) stop ;;
    *) usage ;;
esac
