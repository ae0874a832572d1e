#!/usr/bin/env bash
# A one-node SLURM cluster (munged + slurmctld + slurmd) on this machine, for the tests marked
# `slurm` and for trying `execution.cluster: {kind: slurm}` by hand. Debian/Ubuntu (SLURM from
# the distribution's packages), run as root, no systemd needed.
#
#   scripts/slurm_local.sh start    install the packages if missing, write slurm.conf, start the
#                                   daemons (those already running are left alone), check that
#                                   `sbatch` runs a job; prints each step, exits non-zero on failure
#   scripts/slurm_local.sh stop     cancel every job, stop the daemons by the PIDs in their pid
#                                   files (nothing else is touched); --purge also deletes $SLURM_STATE
#   scripts/slurm_local.sh status   exit 0 if slurmctld answers and the node takes jobs
#
#   SLURM_STATE (default /tmp/nematic-slurm): pid files, logs, state and spool folders.
#   SLURM_CPUS  (default: every core) CPUs the node offers.
# The configuration is written to /etc/slurm/slurm.conf (where the SLURM commands look for it).
set -euo pipefail
STATE=${SLURM_STATE:-/tmp/nematic-slurm}
NODE=localhost
step() { printf '[slurm_local %(%H:%M:%S)T] %s\n' -1 "$*"; }
die() { printf '[slurm_local] FAILED: %s\n' "$*" >&2; exit 1; }
alive() { [ -s "$1" ] && kill -0 "$(cat "$1")" 2>/dev/null; }

node_ready() {
    scontrol ping 2>/dev/null | grep -q UP || return 1
    case "$(sinfo -h -N -n "$NODE" -o %T 2>/dev/null)" in
        idle*|mixed*|allocated*|completing*) return 0 ;;
        *) return 1 ;;
    esac
}

stop_pid() {  # name pidfile
    local name=$1 pf=$2 pid
    if [ -s "$pf" ] && pid=$(cat "$pf") && kill -0 "$pid" 2>/dev/null; then
        step "stopping $name (pid $pid)"
        kill -TERM "$pid"
        for _ in $(seq 50); do kill -0 "$pid" 2>/dev/null || break; sleep 0.2; done
        if kill -0 "$pid" 2>/dev/null; then step "$name still alive: SIGKILL"; kill -KILL "$pid"; fi
    else
        step "$name not running"
    fi
    rm -f "$pf"
}

start() {
    local t0; t0=$(date +%s)
    [ "$(id -u)" = 0 ] || die "run as root (it installs packages and starts daemons)"
    # 1. packages (only these: the slurm-wlm metapackage pulls ~40 plugin packages)
    if ! command -v slurmctld >/dev/null || ! command -v slurmd >/dev/null \
       || ! command -v sbatch >/dev/null || ! command -v munged >/dev/null; then
        command -v apt-get >/dev/null || die "SLURM is not installed and there is no apt-get"
        step "apt-get install slurmctld slurmd slurm-client munge"
        export DEBIAN_FRONTEND=noninteractive
        apt-get update -qq || die "apt-get update failed"
        apt-get install -y -qq --no-install-recommends slurmctld slurmd slurm-client munge \
            >/dev/null || die "apt-get install slurmctld slurmd slurm-client munge failed"
    fi
    step "$(slurmctld -V) installed"
    id slurm >/dev/null 2>&1 || die "the package did not create the user 'slurm'"
    mkdir -p "$STATE"/{log,ctld,spool}
    chown -R slurm:slurm "$STATE"/ctld "$STATE"/log
    chmod 755 "$STATE" "$STATE"/log

    # 2. munge: a key (the package's postinst usually made one) and the daemon
    if [ ! -s /etc/munge/munge.key ]; then
        step "creating /etc/munge/munge.key"
        if command -v mungekey >/dev/null; then mungekey --create --force
        else dd if=/dev/urandom bs=1 count=1024 of=/etc/munge/munge.key 2>/dev/null; fi
    fi
    chown munge:munge /etc/munge/munge.key; chmod 400 /etc/munge/munge.key
    install -d -o munge -g munge -m 755 /run/munge
    if alive /run/munge/munged.pid; then
        step "munged already running (pid $(cat /run/munge/munged.pid))"
    else
        step "starting munged"
        runuser -u munge -- /usr/sbin/munged --pid-file=/run/munge/munged.pid \
            || die "munged did not start (see /var/log/munge/munged.log)"
    fi
    for _ in $(seq 50); do munge -n 2>/dev/null | unmunge >/dev/null 2>&1 && break; sleep 0.1; done
    munge -n | unmunge >/dev/null || die "munge round trip failed"
    step "munge round trip ok"

    # 3. slurm.conf (rewritten each time: idempotent)
    # half the memory (MB), rounded down to GB: stable from one start to the next, so that
    # the configuration does not change (and the daemons need no restart) on a second start
    local mem_total realmem cpus changed=0
    mem_total=$(awk '/MemTotal/ {print int($2/1024)}' /proc/meminfo)
    realmem=$(( mem_total / 2 / 1024 * 1024 ))
    [ "$realmem" -ge 1024 ] || realmem=$(( mem_total / 2 ))
    cpus=${SLURM_CPUS:-$(nproc)}
    step "writing /etc/slurm/slurm.conf (CPUs=$cpus RealMemory=$realmem)"
    mkdir -p /etc/slurm
    cat > /etc/slurm/slurm.conf.new <<EOF
# one-node cluster written by scripts/slurm_local.sh (state in $STATE)
ClusterName=nematic
SlurmctldHost=localhost
SlurmUser=slurm
SlurmdUser=root
AuthType=auth/munge
CryptoType=crypto/munge
MpiDefault=none
MailProg=/bin/true
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
ReturnToService=2
StateSaveLocation=$STATE/ctld
SlurmdSpoolDir=$STATE/spool
SlurmctldPidFile=$STATE/slurmctld.pid
SlurmdPidFile=$STATE/slurmd.pid
SlurmctldLogFile=$STATE/log/slurmctld.log
SlurmdLogFile=$STATE/log/slurmd.log
SlurmctldDebug=info
SlurmdDebug=info
SlurmctldTimeout=30
SlurmdTimeout=30
InactiveLimit=0
MinJobAge=60
KillWait=5
NodeName=$NODE NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=$realmem State=UNKNOWN
PartitionName=debug Nodes=$NODE Default=YES MaxTime=INFINITE State=UP
EOF
    if ! cmp -s /etc/slurm/slurm.conf.new /etc/slurm/slurm.conf 2>/dev/null; then
        mv /etc/slurm/slurm.conf.new /etc/slurm/slurm.conf; changed=1
    else
        rm /etc/slurm/slurm.conf.new
    fi
    chmod 644 /etc/slurm/slurm.conf

    # 4. daemons
    if [ "$changed" = 1 ] && { alive "$STATE/slurmctld.pid" || alive "$STATE/slurmd.pid"; }; then
        step "configuration changed: restarting the daemons"
        stop_pid slurmd "$STATE/slurmd.pid"
        stop_pid slurmctld "$STATE/slurmctld.pid"
    fi
    if alive "$STATE/slurmctld.pid"; then
        step "slurmctld already running (pid $(cat "$STATE/slurmctld.pid"))"
    else
        step "starting slurmctld"
        slurmctld -i || die "slurmctld did not start (see $STATE/log/slurmctld.log)"
    fi
    for _ in $(seq 100); do scontrol ping 2>/dev/null | grep -q UP && break; sleep 0.2; done
    scontrol ping | grep -q UP || { tail -20 "$STATE/log/slurmctld.log" >&2; die "slurmctld not responding"; }
    step "slurmctld up"
    if alive "$STATE/slurmd.pid"; then
        step "slurmd already running (pid $(cat "$STATE/slurmd.pid"))"
    else
        step "starting slurmd -N $NODE"
        slurmd -N "$NODE" || die "slurmd did not start (see $STATE/log/slurmd.log)"
    fi

    # 5. the node takes jobs: wait for it, then run one batch job
    for _ in $(seq 150); do node_ready && break; sleep 0.2; done
    if ! node_ready; then
        scontrol show node "$NODE" >&2 || true; tail -20 "$STATE/log/slurmd.log" >&2 || true
        die "node $NODE is '$(sinfo -h -N -n "$NODE" -o %T 2>/dev/null)'"
    fi
    local out=$STATE/sbatch-test.out jid
    rm -f "$out"
    jid=$(sbatch --parsable -o "$out" --mem=10M --wrap hostname) || die "sbatch failed"
    for _ in $(seq 150); do
        [ -s "$out" ] && ! squeue -h -j "$jid" 2>/dev/null | grep -q . && break; sleep 0.2
    done
    [ -s "$out" ] || die "sbatch job $jid wrote nothing to $out"
    step "sbatch --wrap hostname (job $jid) -> $(cat "$out")"
    step "SLURM ready in $(( $(date +%s) - t0 )) s (state and logs in $STATE)"
}

stop() {
    if alive "$STATE/slurmctld.pid"; then
        local jobs
        jobs=$(squeue -h -o %i 2>/dev/null | tr '\n' ' ')
        if [ -n "${jobs// /}" ]; then
            step "scancel $jobs"
            # shellcheck disable=SC2086  # one argument per job id
            scancel $jobs || true
            sleep 2
        fi
    fi
    stop_pid slurmd "$STATE/slurmd.pid"
    stop_pid slurmctld "$STATE/slurmctld.pid"
    stop_pid munged /run/munge/munged.pid
    if [ "${1:-}" = --purge ]; then step "rm -rf $STATE"; rm -rf "$STATE"; fi
    step "stopped"
}

case "${1:-}" in
    start) start ;;
    stop) shift; stop "$@" ;;
    status) node_ready && { step "SLURM is up (node $NODE takes jobs)"; exit 0; }
            step "SLURM is not running"; exit 1 ;;
    *) echo "usage: $0 start | stop [--purge] | status" >&2; exit 2 ;;
esac
