# A single-node Slurm cluster on localhost for the cluster test (sourced by run.sh).
#
# Everything lives under $SLURM_LOCAL (configuration, state, spool, logs, munge key and socket)
# and on ports of its own, so that the test neither reads nor changes a Slurm or munge the
# machine may already run; the client commands find the configuration through SLURM_CONF.
# `slurm_local_stop` stops exactly the daemons `slurm_local_start` started, by the pids it
# recorded.

# Starts munged (as the munge user, with a generated key), slurmctld and slurmd (one node with
# two CPUs). Arguments: the directory to use, and the ports of slurmctld and slurmd.
slurm_local_start() {
    SLURM_LOCAL=$1
    local ctld_port=${2:-16817} d_port=${3:-16818}
    local host
    host=$(hostname -s)
    mkdir -p "$SLURM_LOCAL"/{state,spool,munge-key,munge-run}
    # munged runs as the munge user, which must own its key and socket directories; it refuses
    # a socket directory that others cannot enter or that they can write to, and a key that
    # others can read.
    chmod 0755 "$SLURM_LOCAL"
    chown munge: "$SLURM_LOCAL/munge-key" "$SLURM_LOCAL/munge-run"
    chmod 0700 "$SLURM_LOCAL/munge-key"
    chmod 0755 "$SLURM_LOCAL/munge-run"
    local key=$SLURM_LOCAL/munge-key/munge.key
    dd if=/dev/urandom of="$key" bs=1024 count=1 status=none
    chown munge: "$key"
    chmod 0400 "$key"
    # Every daemon runs in the foreground as a child of this shell: its pid is known, and
    # `wait` reaps it when it is stopped.
    setpriv --reuid=munge --regid=munge --init-groups munged --foreground \
        --key-file="$key" \
        --socket="$SLURM_LOCAL/munge-run/munge.socket" \
        --pid-file="$SLURM_LOCAL/munge-run/munged.pid" \
        --log-file="$SLURM_LOCAL/munge-run/munged.log" \
        --seed-file="$SLURM_LOCAL/munge-run/munged.seed" >>"$SLURM_LOCAL/munged.out" 2>&1 &
    SLURM_LOCAL_PIDS=$!
    local i
    for i in $(seq 1 50); do
        [ -S "$SLURM_LOCAL/munge-run/munge.socket" ] && break
        sleep 0.2
    done
    if [ ! -S "$SLURM_LOCAL/munge-run/munge.socket" ]; then
        echo "munged did not start; its log:" >&2
        cat "$SLURM_LOCAL/munge-run/munged.log" >&2 || true
        return 1
    fi
    local mem
    mem=$(awk '/MemTotal/ { print int($2 / 1024 / 2) }' /proc/meminfo)
    cat >"$SLURM_LOCAL/slurm.conf" <<CONF
ClusterName=sysidtest
SlurmctldHost=$host(127.0.0.1)
SlurmctldPort=$ctld_port
SlurmdPort=$d_port
SlurmUser=root
AuthType=auth/munge
AuthInfo=socket=$SLURM_LOCAL/munge-run/munge.socket
CredType=cred/munge
StateSaveLocation=$SLURM_LOCAL/state
SlurmdSpoolDir=$SLURM_LOCAL/spool
SlurmctldPidFile=$SLURM_LOCAL/slurmctld.pid
SlurmdPidFile=$SLURM_LOCAL/slurmd.pid
SlurmctldLogFile=$SLURM_LOCAL/slurmctld.log
SlurmdLogFile=$SLURM_LOCAL/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/filetxt
JobCompLoc=$SLURM_LOCAL/jobcomp.log
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
ReturnToService=2
MpiDefault=none
NodeName=$host NodeAddr=127.0.0.1 CPUs=2 RealMemory=$mem State=UNKNOWN
PartitionName=test Nodes=ALL Default=YES MaxTime=INFINITE State=UP
CONF
    export SLURM_CONF=$SLURM_LOCAL/slurm.conf
    slurmctld -D -f "$SLURM_CONF" >>"$SLURM_LOCAL/slurmctld.out" 2>&1 &
    SLURM_LOCAL_PIDS="$! $SLURM_LOCAL_PIDS"
    slurmd -D -f "$SLURM_CONF" >>"$SLURM_LOCAL/slurmd.out" 2>&1 &
    SLURM_LOCAL_PIDS="$! $SLURM_LOCAL_PIDS"
    for i in $(seq 1 60); do
        if sinfo -h -o '%T' 2>/dev/null | grep -qx idle; then
            return 0
        fi
        sleep 1
    done
    echo "slurm did not come up within 60 s; logs in $SLURM_LOCAL" >&2
    sinfo >&2 || true
    tail -n 20 "$SLURM_LOCAL/slurmctld.log" "$SLURM_LOCAL/slurmd.log" >&2 || true
    return 1
}

# Stops the daemons slurm_local_start started (by their pids, slurmd first, then slurmctld, then
# munged), waiting for each to end.
slurm_local_stop() {
    local pid i
    for pid in ${SLURM_LOCAL_PIDS:-}; do
        kill "$pid" 2>/dev/null || continue
        for i in $(seq 1 40); do
            [ "$(ps -o stat= -p "$pid" 2>/dev/null | cut -c1)" = "" ] && break
            [ "$(ps -o stat= -p "$pid" 2>/dev/null | cut -c1)" = "Z" ] && break
            sleep 0.25
        done
        kill -9 "$pid" 2>/dev/null || true
        wait "$pid" 2>/dev/null || true
    done
    SLURM_LOCAL_PIDS=
    # A job step whose slurmd ended before it could report its end waits for it forever: such
    # a slurmstepd is one of ours when it holds our slurmd's log open.
    [ -n "${SLURM_LOCAL:-}" ] || return 0
    local p
    for p in /proc/[0-9]*; do
        [ "$(cat "$p/comm" 2>/dev/null)" = slurmstepd ] || continue
        if ls -l "$p/fd" 2>/dev/null | grep -qF "$SLURM_LOCAL/slurmd.log"; then
            kill -9 "${p#/proc/}" 2>/dev/null || true
        fi
    done
}
