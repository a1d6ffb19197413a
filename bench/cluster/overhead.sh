#!/usr/bin/env bash
# The CPU time a study split into array tasks spends outside its filters (docs/cluster.md,
# "Sizing"), measured from a finished study's records without computing any run again.
#
#   bench/cluster/overhead.sh [RECORDS_DIR] [TASKS] [STUDY_FILE]
#   (defaults: results/scaling/records, 64, experiments/scaling.toml)
#
# What a task does beside its filters — start up, load the study, generate each run's data set,
# write its records — and what the finish job does — merge the parts, check every record's
# fingerprint, write the report — is measured by running those steps on copies of the records:
#   1. every shard i/TASKS with --resume over the complete records: start-up, job enumeration,
#      every run's data set generated (for its fingerprint) and its record read, no run
#      computed (the script stops if one would be);
#   2. `sysid merge` of the records dealt into TASKS part directories: reads, checks and
#      writes every record (an upper bound for the shards' own record writing too);
#   3. `sysid cluster finish` over the merged records: the finish job's fingerprint check and
#      the report.
# The filters' CPU time is the records' .cpu files (thread CPU of each run, which includes its
# data generation: step 1's total is subtracted from it, so the fraction is an upper bound).
set -euo pipefail
cd "$(dirname "$0")/../.."
ROOT=$(pwd)
RECORDS=${1:-results/scaling/records}
TASKS=${2:-64}
STUDY=${3:-experiments/scaling.toml}
SYSID=${SYSID:-$ROOT/target/release/sysid}
W=$(mktemp -d /tmp/sysid-overhead.XXXXXX)
trap 'rm -rf "$W"' EXIT

# CPU seconds (user + system) of a command, its output to $W/log.
cpu() {
    /usr/bin/time -f "%U %S" -o "$W/time" "$@" >"$W/log" 2>&1 || {
        cat "$W/log" >&2
        exit 1
    }
    awk '{ printf "%.2f", $1 + $2 }' "$W/time"
}

mkdir -p "$W/out/records" "$W/out/cluster"
cp "$RECORDS"/*.json "$RECORDS"/*.cpu "$W/out/records/"
runs=$(ls "$W/out/records"/*.json | wc -l)
filters=$(cat "$W/out/records"/*.cpu | awk '{ s += $1 } END { printf "%.1f", s }')

shards=0
for i in $(seq 0 $((TASKS - 1))); do
    c=$(cpu "$SYSID" scaling --config "$STUDY" --out "$W/out" --shard "$i/$TASKS" --resume \
        --threads 1)
    if ! grep -q " 0 executed" "$W/log"; then
        echo "shard $i would compute runs (records of another study or version):" >&2
        cat "$W/log" >&2
        exit 1
    fi
    shards=$(awk -v a="$shards" -v b="$c" 'BEGIN { printf "%.2f", a + b }')
done

mkdir -p "$W/parts"
n=0
for f in "$W/out/records"/*.json; do
    p=$W/parts/shard-$((n % TASKS))/records
    mkdir -p "$p"
    cp "$f" "${f%.json}.cpu" "$p/"
    n=$((n + 1))
done
mkdir -p "$W/merged"
merge=$(cpu "$SYSID" merge "$W"/parts/shard-* --into "$W/merged")

cat >"$W/out/cluster/plan.json" <<JSON
{ "kind": "scaling", "config": "$ROOT/$STUDY", "out": "$W/out", "quick": false,
  "tasks": $TASKS, "cpus_per_task": 1, "sysid": "$SYSID",
  "slurm": { "partition": null, "time": null, "mem": null, "account": null,
             "max_running": null } }
JSON
finish=$(cpu "$SYSID" cluster finish --out "$W/out")

awk -v runs="$runs" -v tasks="$TASKS" -v f="$filters" -v s="$shards" -v m="$merge" \
    -v fin="$finish" 'BEGIN {
    outside = s + m + m + fin
    filt = f - s
    printf "%d runs in %d tasks\n", runs, tasks
    printf "filters (records .cpu, less data generation): %.1f CPU-s\n", filt
    printf "tasks beside their filters (start-up, data sets, reading): %.2f CPU-s (%.3f per task)\n", s, s / tasks
    printf "record writing (bounded by the merge): %.2f CPU-s\n", m
    printf "merge: %.2f CPU-s; finish (fingerprints, report): %.2f CPU-s\n", m, fin
    printf "outside the filters: %.2f CPU-s = %.3f%% of %.1f CPU-s\n", outside, 100 * outside / (filt + outside), filt + outside
}'
