#!/usr/bin/env python3
"""Markdown tables for docs/performance.md from Google Benchmark JSON output.

Usage: bench/perf_tables.py RESULT.json [RESULT.json ...]

Each file must come from a run with --benchmark_repetitions=N
--benchmark_report_aggregates_only=true --benchmark_out=RESULT.json
--benchmark_out_format=json. Prints, per benchmark family, one row per
argument set with the median time, the coefficient of variation over the
repetitions, and the counters of the median repetition's aggregate.
"""
import json
import sys
from collections import OrderedDict

UNITS = {"ns": 1e-9, "us": 1e-6, "ms": 1e-3, "s": 1.0}
SKIP = {"name", "run_name", "run_type", "repetitions", "repetition_index", "threads", "iterations",
        "real_time", "cpu_time", "time_unit", "aggregate_name", "aggregate_unit", "family_index",
        "per_family_instance_index", "label", "error_occurred", "error_message"}


def fmt_time(seconds):
    for unit, scale in (("s", 1.0), ("ms", 1e-3), ("µs", 1e-6), ("ns", 1e-9)):
        if seconds >= scale:
            return f"{seconds / scale:.3g} {unit}"
    return f"{seconds:.3g} s"


def fmt_value(v):
    if isinstance(v, float):
        if v == 0:
            return "0"
        if abs(v) >= 1e4 or abs(v) < 1e-2:
            return f"{v:.2e}"
        return f"{v:.3g}"
    return str(v)


def main(paths):
    for path in paths:
        with open(path) as f:
            data = json.load(f)
        ctx = data["context"]
        print(f"<!-- {path}: {ctx.get('date')} on {ctx.get('host_name')}, "
              f"{ctx.get('num_cpus')} CPUs at {ctx.get('mhz_per_cpu')} MHz, "
              f"load average {ctx.get('load_avg')} -->")
        rows = OrderedDict()
        for b in data["benchmarks"]:
            if b.get("run_type") != "aggregate":
                continue
            rows.setdefault(b["run_name"], {})[b["aggregate_name"]] = b
        families = OrderedDict()
        for run_name, aggs in rows.items():
            families.setdefault(run_name.split("/")[0], []).append((run_name, aggs))
        for family, entries in families.items():
            counters = []
            for _, aggs in entries:
                for key in aggs.get("median", {}):
                    if key not in SKIP and key not in counters:
                        counters.append(key)
            print(f"\n#### {family}\n")
            print("| run | median (wall) | median (CPU, main thread) | CV | " + " | ".join(counters) + " | label |")
            print("|---" * (5 + len(counters)) + "|")
            for run_name, aggs in entries:
                med = aggs.get("median")
                if med is None:
                    continue
                unit = UNITS[med["time_unit"]]
                cv = aggs.get("cv", {}).get("real_time")
                cv_text = f"{100 * cv:.1f}%" if isinstance(cv, (int, float)) else "–"
                cells = [fmt_value(med.get(c, "")) for c in counters]
                name = run_name.split("/", 1)[1] if "/" in run_name else run_name
                print(f"| {name} | {fmt_time(med['real_time'] * unit)} | {fmt_time(med['cpu_time'] * unit)} | "
                      f"{cv_text} | " + " | ".join(cells) + f" | {med.get('label', '')} |")


if __name__ == "__main__":
    main(sys.argv[1:])
