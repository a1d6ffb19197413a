#!/usr/bin/env bash
# End-to-end test of `sysid cluster` against a real Slurm (docs/cluster.md).
#
# Installs Slurm and munge from Debian's packages when they are missing, starts a single-node
# cluster on localhost (munged, slurmctld, slurmd with two CPUs; tests/cluster/slurm-local.sh),
# and then:
#   1. submits the paper reproduction's quick form as 4 array tasks and checks that the merged
#      records and the report equal, timings aside, those of `sysid reproduce --quick` run here;
#   2. submits a study file (MPF-EKF2, 8 runs on the paper's structure) as 2 array tasks,
#      cancels one task while it runs (`scancel`), checks that the finish job names the failed
#      shard and writes no report, resubmits the missing shard, and checks that the resubmitted
#      task reused the records its cancelled instance had finished and that the merged result
#      equals `sysid study` run here.
# Every wait has a time limit. The daemons it started are stopped on exit, whatever happens.
# Run as root (CI does); without root, or when the packages cannot be installed, it says SKIP
# and exits 0.
set -euo pipefail
cd "$(dirname "$0")/../.."
ROOT=$(pwd)

skip() {
    echo "SKIP tests/cluster: $*"
    exit 0
}
fail() {
    echo "FAIL tests/cluster: $*" >&2
    exit 1
}
step() { echo "== $*"; }

[ "$(id -u)" = 0 ] || skip "needs root to install Slurm and munge and to start their daemons"
if ! command -v slurmctld >/dev/null || ! command -v slurmd >/dev/null ||
    ! command -v munged >/dev/null || ! command -v sbatch >/dev/null; then
    command -v apt-get >/dev/null || skip "Slurm is not installed and there is no apt-get"
    step "installing slurm-wlm and munge"
    if ! { timeout 600 apt-get update -qq &&
        DEBIAN_FRONTEND=noninteractive timeout 900 apt-get install -y -qq slurm-wlm munge; } \
        >/tmp/sysid-cluster-apt.log 2>&1; then
        tail -n 5 /tmp/sysid-cluster-apt.log
        skip "could not install slurm-wlm and munge from Debian's packages"
    fi
fi

# The binary under test: $SYSID if given, else this checkout's release build (a no-op build
# after `cargo test --release`).
if [ -z "${SYSID:-}" ]; then
    step "building sysid"
    cargo build --release -p experiments --bin sysid
    SYSID=$ROOT/target/release/sysid
fi

WORK=$(mktemp -d /tmp/sysid-cluster-test.XXXXXX)
chmod 0755 "$WORK"
# shellcheck source=tests/cluster/slurm-local.sh
source "$ROOT/tests/cluster/slurm-local.sh"
cleanup() {
    local rc=$?
    if [ -n "${SLURM_CONF:-}" ]; then
        local jobs i
        jobs=$(squeue -h -o %A 2>/dev/null || true)
        if [ -n "$jobs" ]; then
            # shellcheck disable=SC2086
            scancel $jobs 2>/dev/null || true
            for i in $(seq 1 30); do
                squeue -h 2>/dev/null | grep -q . || break
                sleep 1
            done
        fi
    fi
    slurm_local_stop
    if [ "$rc" = 0 ]; then
        rm -rf "$WORK"
    else
        echo "tests/cluster: kept $WORK (logs of the daemons in $WORK/slurm)" >&2
    fi
}
trap cleanup EXIT
trap 'exit 130' INT TERM

# Ports of our own, so that a Slurm the machine may run is not disturbed.
port=$((20000 + RANDOM % 20000))
while ss -ltn 2>/dev/null | grep -q ":$port \|:$((port + 1)) "; do
    port=$((port + 2))
done
step "starting slurmctld and slurmd on localhost (ports $port, $((port + 1)))"
slurm_local_start "$WORK/slurm" "$port" "$((port + 1))" || fail "Slurm did not start"
sinfo

# Waits until squeue no longer lists job $1 (at most $2 seconds).
wait_gone() {
    local job=$1 limit=$2 t=0
    while squeue -h -j "$job" 2>/dev/null | grep -q .; do
        sleep 1
        t=$((t + 1))
        [ "$t" -lt "$limit" ] || fail "job $job still queued after $limit s: $(squeue)"
    done
}
# A job id `sysid cluster` recorded in OUT/cluster/submissions.json: job_id OUT FIELD N, the
# FIELD (array_job or finish_job) of the N-th submission (0-based).
job_id() {
    grep -o "\"$2\": \"[0-9]*\"" "$1/cluster/submissions.json" | sed -n "$(($3 + 1))p" |
        grep -o '[0-9][0-9]*'
}

# ---------------------------------------------------------------------------------------------
step "1. the paper's quick reproduction: locally, then as 4 array tasks"
"$SYSID" reproduce --quick --out "$WORK/paper-local" --threads 2 >"$WORK/paper-local.log" 2>&1 ||
    fail "local reproduce: $(tail -n 5 "$WORK/paper-local.log")"
"$SYSID" cluster submit paper --quick --out "$WORK/paper" --tasks 4 --time 00:20:00
wait_gone "$(job_id "$WORK/paper" finish_job 0)" 300
ls "$WORK"/paper/cluster/logs/finish-*.log >/dev/null || fail "the finish job wrote no log"
grep -q "finished" "$WORK"/paper/cluster/logs/finish-*.log ||
    fail "finish job: $(tail -n 20 "$WORK"/paper/cluster/logs/finish-*.log)"
"$SYSID" cluster status --out "$WORK/paper" | tee "$WORK/paper-status.txt"
grep -q "46 done (46 merged" "$WORK/paper-status.txt" || fail "not every run merged"
"$SYSID" cluster compare "$WORK/paper-local" "$WORK/paper" ||
    fail "the cluster's paper reproduction differs from the local one"
[ -f "$WORK/paper/REPORT.md" ] && [ -f "$WORK/paper/fig7_theta_val_crosses.svg" ] ||
    fail "no report or figures"

# ---------------------------------------------------------------------------------------------
step "2. a study file as 2 array tasks, one cancelled while it runs, then resubmitted"
cat >"$WORK/study.toml" <<'TOML'
name = "cluster-test"
description = "MPF-EKF2, 8 runs on the paper's structure (each run its own data set)"

[data]
preset = "paper-3dof"

[sweep]
algorithms = ["mpf-ekf2"]
runs = 8
master_seed = 31
particles = [300]

[filter]
trace_every = 0
loop_every = 0
TOML
"$SYSID" study --config "$WORK/study.toml" --out "$WORK/study-local" --threads 2 \
    >"$WORK/study-local.out" 2>&1 || fail "local study: $(tail -n 5 "$WORK/study-local.out")"
"$SYSID" cluster submit study --config "$WORK/study.toml" --out "$WORK/study" --tasks 2
array=$(job_id "$WORK/study" array_job 0)
finish=$(job_id "$WORK/study" finish_job 0)
part1=$WORK/study/cluster/parts/shard-1/records
# Cancel task 1 once it has finished its first run and while it still runs (4 runs of about a
# second or two each).
t=0
until [ "$(ls "$part1"/*.json 2>/dev/null | wc -l)" -ge 1 ]; do
    sleep 0.1
    t=$((t + 1))
    [ "$t" -lt 1800 ] || fail "task 1 wrote no record in 180 s: $(squeue)"
done
state=$(squeue -h -r -j "${array}_1" -o %T 2>/dev/null || true)
[ "$state" = RUNNING ] || fail "task 1 was no longer running when it was to be cancelled ($state)"
scancel "${array}_1"
wait_gone "$finish" 300
kept=$(ls "$part1"/*.json | wc -l)
echo "task 1 cancelled with $kept of 4 records written"
[ "$kept" -lt 4 ] || fail "the cancel came after task 1 had finished"
[ ! -f "$WORK/study/REPORT.md" ] || fail "the finish job wrote a report with runs missing"
flog=$(ls "$WORK"/study/cluster/logs/finish-*.log)
grep -q "shard 1: $kept of 4 runs done" "$flog" || fail "finish log: $(cat "$flog")"
grep -qi "cancelled" "$flog" || fail "the finish log does not say the shard was cancelled: $(cat "$flog")"
"$SYSID" cluster status --out "$WORK/study" | tee "$WORK/study-status.txt"
grep -q "1 failed" "$WORK/study-status.txt" || fail "status does not count the failed shard"
"$SYSID" cluster resubmit --out "$WORK/study" | tee "$WORK/resubmit.txt"
grep -q -- "--array=1 " "$WORK/resubmit.txt" || fail "resubmitted something else than shard 1"
wait_gone "$(job_id "$WORK/study" finish_job 1)" 300
grep -q "$kept reused" "$WORK/study/cluster/logs/shard-1.log" ||
    fail "the resubmitted task did not reuse the $kept records: $(tail -n 5 "$WORK/study/cluster/logs/shard-1.log")"
[ -f "$WORK/study/REPORT.md" ] || fail "no report after the resubmission: $(tail -n 20 "$WORK"/study/cluster/logs/finish-*.log)"
"$SYSID" cluster compare "$WORK/study-local" "$WORK/study" ||
    fail "the cluster's study differs from the local one"

echo "PASS tests/cluster: paper (46 runs, 4 tasks) and study (8 runs, 2 tasks, one cancelled and resubmitted) equal their local runs"
