#!/usr/bin/env python3
"""beamctl's PLC against ExprTk (ECMC's engine) and muparser, in one run of bench_plc.

Runs every expression and scan benchmark REPS times in random order on one pinned CPU and prints
a Markdown table of medians and minima, with ExprTk's bit-equality verdict. The ExprTk column
needs bench_plc built with -DBEAMCTL_EXPRTK_DIR (see bench/CMakeLists.txt).

    /usr/bin/python3 bench/plc_engines.py [build/release/bench/bench_plc] [REPS=9] [CPU=1]
"""
import json
import re
import statistics
import subprocess
import sys

binary = sys.argv[1] if len(sys.argv) > 1 else "build/release/bench/bench_plc"
reps = int(sys.argv[2]) if len(sys.argv) > 2 else 9
cpu = sys.argv[3] if len(sys.argv) > 3 else "1"

out = subprocess.run(
    ["taskset", "-c", cpu, binary, "--benchmark_filter=Expr|Scan", f"--benchmark_repetitions={reps}",
     "--benchmark_enable_random_interleaving=true", "--benchmark_format=json"],
    check=True, capture_output=True, text=True)
if "ExprTk reference was not measured" in out.stderr:
    print("note: bench_plc was built without ExprTk; its column stays empty", file=sys.stderr)
runs = [b for b in json.loads(out.stdout)["benchmarks"] if b.get("run_type") == "iteration"]

times, labels, equal = {}, {}, {}
for b in runs:
    name = b["run_name"]
    times.setdefault(name, []).append(b["cpu_time"])
    if b.get("label"):
        labels[name] = b["label"]
    if "bit_equal" in b:
        equal[name] = min(equal.get(name, 1), b["bit_equal"])

def row_key(name):
    """(workload, engine) of a benchmark name."""
    m = re.match(r"BM_Expr_(beamctl|muparser|exprtk)/(\d+)", name)
    if m:
        return labels.get(name, m.group(2)), m.group(1)
    m = re.match(r"BM_Scan_(.*?)(_exprtk)?$", name)
    return "scan " + m.group(1), "exprtk" if m.group(2) else "beamctl"

table = {}
for name, t in times.items():
    workload, engine = row_key(name)
    table.setdefault(workload, {})[engine] = (statistics.median(t), min(t), equal.get(name))

def cell(v):
    return f"{v[0]:.0f} ({v[1]:.0f})" if v else "-"

print(f"| workload | beamctl ns | ExprTk ns | muparser ns | ExprTk / beamctl | ExprTk bit-equal |")
print("|---|---|---|---|---|---|")
for workload, e in table.items():
    b, x, m = e.get("beamctl"), e.get("exprtk"), e.get("muparser")
    ratio = f"{x[0] / b[0]:.2f}" if b and x else "-"
    eq = "-" if not x or x[2] is None else ("yes" if x[2] == 1 else "NO")
    print(f"| {workload} | {cell(b)} | {cell(x)} | {cell(m)} | {ratio} | {eq} |")
print(f"\nmedian (min) of {reps} interleaved repetitions, CPU {cpu}")
