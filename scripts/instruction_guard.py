#!/usr/bin/env python3
"""Instruction guard: the deformer's on-site step (OP) and one default frame,
counted in instructions by callgrind on two Table 1 models, against the
baseline committed with the code (bench/instruction_baseline.json). Fails when
a count rose more than the baseline's tolerance (30 %) above it.

    scripts/instruction_guard.py --probe build/bin/instruction_probe
    scripts/instruction_guard.py --probe build/bin/instruction_probe --update --why "..."

Each model is precomputed natively into a fresh cache folder (bench_deform's
cache format), then build/bin/instruction_probe runs once under
    valgrind --tool=callgrind --toggle-collect=qpreduce_probe_op
             --toggle-collect=qpreduce_probe_frame
on one thread (OMP_NUM_THREADS=1, OPENBLAS_NUM_THREADS=1), and
callgrind_annotate --inclusive=yes gives each function's count. Counts are
repeatable under load; they do depend on the CPU's vector extensions (the
engine's AVX2 kernels and OpenBLAS pick theirs at run time), so the baseline
names the machine it was taken on.

--update writes the new counts into the baseline, with a note of why (--why,
required) appended to its history: a count is raised only with a reason.

Exit codes: 0 pass (or updated), 1 a count rose past the tolerance or the
probe failed, 2 bad usage, 77 skipped (CTest's SKIP_RETURN_CODE): valgrind or
callgrind_annotate missing, or the shared data absent. docs/performance.md,
"Instruction guard", has the baseline's story.
"""
import argparse
import datetime
import json
import os
import pathlib
import re
import shutil
import subprocess
import sys
import tempfile

SKIP = 77
FUNCTIONS = {"op": "qpreduce_probe_op", "frame": "qpreduce_probe_frame"}
ROOT = pathlib.Path(__file__).resolve().parent.parent


def skip(why):
    print(f"skipped: {why}")
    sys.exit(SKIP)


def run(cmd, env, what):
    result = subprocess.run(cmd, env=env, capture_output=True, text=True)
    if result.returncode != 0:
        print(f"instruction_guard: {what} failed (exit {result.returncode}):\n{result.stdout}\n{result.stderr}")
        sys.exit(1)
    return result


def count(probe, model, env, workdir):
    """Instructions of the OP and of the frame on `model` ({'op': n, 'frame': n})."""
    # Natively first: precomputes and writes the cache the callgrind run loads.
    native = run([probe, model], env, f"{model}: instruction_probe")
    print(f"  {native.stdout.strip()}")
    out = os.path.join(workdir, f"callgrind.{model}.out")
    cmd = ["valgrind", "--tool=callgrind", f"--callgrind-out-file={out}"]
    if "(callgrind client requests)" in native.stdout:
        cmd.append("--instr-atstart=no")  # the probe starts the instrumentation after loading
    cmd += [f"--toggle-collect={f}" for f in FUNCTIONS.values()]
    run(cmd + [probe, model], env, f"{model}: valgrind")
    annotated = run(["callgrind_annotate", "--inclusive=yes", out], env, f"{model}: callgrind_annotate").stdout
    counts = {}
    for key, function in FUNCTIONS.items():
        m = re.search(r"^\s*([\d,]+)\s.*\b" + function + r"\b", annotated, re.MULTILINE)
        if not m:
            print(f"instruction_guard: {model}: no count for {function} in callgrind's output")
            sys.exit(1)
        counts[key] = int(m.group(1).replace(",", ""))
    return counts


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--probe", required=True, help="the instruction_probe program (build/bin/instruction_probe)")
    parser.add_argument("--baseline", default=str(ROOT / "bench" / "instruction_baseline.json"))
    parser.add_argument("--data", help="the shared data folder (default: $QPREDUCE_SHARED_DATA, else ../shared/data)")
    parser.add_argument("--models", help="comma-separated models (default: the baseline's)")
    parser.add_argument("--update", action="store_true", help="write the counts into the baseline (needs --why)")
    parser.add_argument("--why", help="why the counts change (kept in the baseline's history)")
    args = parser.parse_args()
    if args.update and not args.why:
        print("instruction_guard: --update needs --why: the baseline changes only with a note of why")
        return 2

    for tool in ("valgrind", "callgrind_annotate"):
        if shutil.which(tool) is None:
            skip(f"{tool} is not installed (Debian: apt-get install valgrind)")
    data = args.data or os.environ.get("QPREDUCE_SHARED_DATA") or str(ROOT.parent / "shared" / "data")
    if not os.path.isdir(data):
        skip(f"the shared test data is not at {data} (set QPREDUCE_SHARED_DATA to its folder)")
    if not os.access(args.probe, os.X_OK):
        print(f"instruction_guard: no instruction_probe at {args.probe}")
        return 2

    with open(args.baseline) as f:
        baseline = json.load(f)
    tolerance = float(baseline["tolerance"])
    models = args.models.split(",") if args.models else list(baseline["counts"])

    workdir = tempfile.mkdtemp(prefix="qpreduce-instruction-guard-")
    env = dict(os.environ, QPREDUCE_SHARED_DATA=data, QPREDUCE_BENCH_CACHE_DIR=workdir, OMP_NUM_THREADS="1",
               OPENBLAS_NUM_THREADS="1")
    try:
        measured = {}
        for model in models:
            print(f"{model}:")
            measured[model] = count(args.probe, model, env, workdir)
    finally:
        shutil.rmtree(workdir, ignore_errors=True)

    if args.update:
        for model, counts in measured.items():
            baseline["counts"][model] = counts
        baseline.setdefault("history", []).append({
            "date": datetime.date.today().isoformat(),
            "counts": measured,
            "why": args.why,
        })
        with open(args.baseline, "w") as f:
            json.dump(baseline, f, indent=2, ensure_ascii=False)
            f.write("\n")
        print(f"instruction_guard: baseline written to {args.baseline}")
        return 0

    failed = False
    for model, counts in measured.items():
        base = baseline["counts"].get(model)
        if base is None:
            print(f"{model}: no baseline (add one with --update --why)")
            failed = True
            continue
        for key in FUNCTIONS:
            ratio = counts[key] / base[key]
            verdict = "ok"
            if ratio > 1.0 + tolerance:
                verdict = f"FAIL: more than {tolerance:.0%} above the baseline"
                failed = True
            elif ratio < 1.0 / (1.0 + tolerance):
                verdict = "ok, far below the baseline: lower it (--update --why) to keep the guard tight"
            print(f"{model} {key}: {counts[key]:,} instructions, baseline {base[key]:,} ({ratio:.3f}x) {verdict}")
    if failed:
        print("instruction_guard: a count rose past the baseline. Find what took it (callgrind_annotate on the "
              "probe's output), or, when the rise is wanted, raise the baseline with --update --why.")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
