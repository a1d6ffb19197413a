"""CPU time per array task when a structure study is split into T tasks (docs/cluster.md,
"Sizing"), from the CPU seconds its records carry (`<id>.cpu`), dealing the jobs out as
`--shard i/T` does (job j to task j mod T, jobs in `Study::jobs` order: run by run, structure by
structure, algorithm by algorithm).

    python3 bench/cluster/balance.py [STUDY_FILE] [RECORDS_DIR] [T ...]
"""

import sys
import tomllib

study = sys.argv[1] if len(sys.argv) > 1 else "experiments/scaling.toml"
records = sys.argv[2] if len(sys.argv) > 2 else "results/scaling/records"
tasks = [int(t) for t in sys.argv[3:]] or [16, 32, 64, 128]

with open(study, "rb") as f:
    s = tomllib.load(f)
sweep = s["sweep"]
scheme = f"np{sweep['particles'][0]}-systematic-{s['filter'].get('discretisation', 'euler')}"
scheme = scheme.removesuffix("-euler")
jobs = []
for run in range(sweep["runs"]):
    for st in sweep["structures"]:
        if run >= st.get("runs", sweep["runs"]):
            continue
        for a in st.get("algorithms", sweep["algorithms"]):
            jobs.append(f"{st['label']}-{a}-{scheme}-run{run:03d}")
cpu = [float(open(f"{records}/{j}.cpu").read()) for j in jobs]
print(f"{len(jobs)} runs, {sum(cpu) / 3600:.2f} CPU-h, longest run {max(cpu):.0f} s")
for t in tasks:
    per = [sum(cpu[i::t]) for i in range(t)]
    mean = sum(per) / t
    print(
        f"{t:4d} tasks: {len(jobs) / t:5.1f} runs per task, CPU per task mean {mean:5.0f} s, "
        f"longest {max(per):5.0f} s, shortest {min(per):4.0f} s (longest/mean {max(per) / mean:.2f})"
    )
