#!/usr/bin/env python3
"""Per-call overhead of SubspaceSolver.solve_in_D from Python over the C++ call.

Usage: PYTHONPATH=build/python python3 bench/python_overhead.py build/bin/bench_qp_families [--size N]

Runs the C++ BM_QpSolve (bench_qp_families: gmrf family, same constraint set,
b and Y of 16 seeded demands in turn) for the C++ median, then the same loop
from Python on the same family, demands and constraints, with and without a
preallocated out= array. Each Python repetition times a batch of calls with
time.perf_counter; the figure is the median over repetitions of the per-call
time. Prints a Markdown table.
"""
import argparse
import json
import statistics
import subprocess
import time

import numpy as np

import qpreduce
from qpreduce import families

DEMANDS = 16  # as bench_qp_families.cpp (kDemands)


def cpp_median(binary, size, repetitions):
    name = f"BM_QpSolve/family:0/size:{size}/design:0/explicit:0/real_time"
    output = subprocess.run(
        [binary, f"--benchmark_filter=^{name}$", f"--benchmark_repetitions={repetitions}",
         "--benchmark_report_aggregates_only=true", "--benchmark_format=json"],
        check=True, capture_output=True, text=True).stdout
    for run in json.loads(output)["benchmarks"]:
        if run.get("aggregate_name") == "median":
            assert run["time_unit"] == "us"
            return run["real_time"] * 1e-6
    raise RuntimeError(f"no median for {name}")


def gmrf_as_in_the_benchmark(size):
    side = round(size ** 0.5)
    return families.make_gmrf(families.GmrfOptions(nx=side, ny=side, candidates=300, observed=60))


def python_median(solver, demands, use_out, repetitions, batch):
    d0 = demands[0]
    inputs = [(d.b if d.b.shape == d0.b.shape else d0.b, d.Y) for d in demands]
    out = np.empty(solver.p) if use_out else None
    times = []
    for _ in range(repetitions):
        start = time.perf_counter()
        for i in range(batch):
            b, Y = inputs[i % DEMANDS]
            solver.solve_in_D(b, Y, out)
        times.append((time.perf_counter() - start) / batch)
    return statistics.median(times)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("binary", help="build/bin/bench_qp_families")
    parser.add_argument("--size", type=int, default=10000)
    parser.add_argument("--repetitions", type=int, default=15)
    parser.add_argument("--batch", type=int, default=20000)
    args = parser.parse_args()

    family = gmrf_as_in_the_benchmark(args.size)
    demands = [families.make_demand(family, i) for i in range(DEMANDS)]
    solver = qpreduce.SubspaceSolver()
    solver.precompute(family.H, family.C, family.D, families.recommended_options(family)).raise_if_failed()
    summary = solver.set_constraints(demands[0].A).raise_if_failed()

    cpp = cpp_median(args.binary, args.size, args.repetitions)
    fresh = python_median(solver, demands, False, args.repetitions, args.batch)
    into = python_median(solver, demands, True, args.repetitions, args.batch)
    print(f"gmrf n = {family.n}, p = {solver.p}, m = {solver.m}, factored = {summary.factored}, "
          f"median of {args.repetitions} repetitions\n")
    print("| call | median per call | overhead over C++ |")
    print("|---|---|---|")
    print(f"| C++ `solve_in_D(b, Y, w)` (BM_QpSolve) | {cpp * 1e6:.2f} µs | — |")
    print(f"| Python `solve_in_D(b, Y)` (new w) | {fresh * 1e6:.2f} µs | {(fresh - cpp) * 1e6:+.2f} µs |")
    print(f"| Python `solve_in_D(b, Y, out=w)` | {into * 1e6:.2f} µs | {(into - cpp) * 1e6:+.2f} µs |")


if __name__ == "__main__":
    main()
