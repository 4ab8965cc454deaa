#!/usr/bin/env python3
"""`qpr view --exact-handles`, headless: point handles the default proxies
cannot follow end far from their targets without the flag and on them (the
float reconstruction's round-off) with it; the GPU and CPU poses agree.

    view_exact_handles.py --qpr QPR --xvfb XVFB_RUN --out DIR

A generated tube (no shared data): its bottom ring a fixed patch, eight
vertices of its top ring point handles pulled apart, more rows than the
six linear proxies can meet.
"""
import argparse
import json
import os
import subprocess
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "apps"))
import bad_input  # noqa: E402  (the tube it writes)

RINGS, AROUND = 10, 12


def tube():
    """The bad-input suite's tube (tests/apps/bad_input.py): its vertices and its OFF text."""
    off, _, n = bad_input.tube(RINGS, AROUND)
    return [tuple(float(x) for x in line.split()) for line in off.splitlines()[2:2 + n]], off


def scene(V):
    top = [(RINGS - 1) * AROUND + a for a in range(8)]
    handles = []
    for k, v in enumerate(top):
        x, y, z = V[v]
        s = 1.3 if k % 2 else 0.8  # pulled apart and pushed together in turn
        handles.append({"vertices": [v], "targets": [[[s * x, s * y, z + 0.6]]]})
    return {"mesh": "tube.off", "proxies": {"linear": 6, "rotational": 4},
            "patches": [{"type": "fixed", "vertices": list(range(AROUND))}], "handles": handles}


def run(args, name, extra):
    stats = os.path.join(args.out, name + ".json")
    cmd = [args.xvfb, "-a", args.qpr, "view", "--scene", os.path.join(args.out, "s.json"), "--frames", "2",
           "--size", "64x64", "--screenshot", os.path.join(args.out, name + ".png"), "--stats", stats] + extra
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=240)
    if p.returncode != 0:
        sys.exit(f"FAILED: {' '.join(cmd)} exited {p.returncode}:\n{p.stdout}\n{p.stderr}")
    with open(stats) as f:
        return json.load(f), p.stderr


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--qpr", required=True)
    ap.add_argument("--xvfb", required=True)
    ap.add_argument("--out", required=True)
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    V, off = tube()
    with open(os.path.join(args.out, "tube.off"), "w") as f:
        f.write(off)
    with open(os.path.join(args.out, "s.json"), "w") as f:
        json.dump(scene(V), f)

    plain, plain_err = run(args, "plain", [])
    exact, exact_err = run(args, "exact", ["--exact-handles"])
    print(f"without --exact-handles: handle residual {plain['handle_residual_max']:.3e}, "
          f"p = {plain['reduced_size']}")
    print(f"with --exact-handles:    handle residual {exact['handle_residual_max']:.3e}, "
          f"p = {exact['reduced_size']}, GPU vs CPU {exact['gpu_cpu_max_deviation']:.2e}")
    failures = []
    if not plain["handle_residual_max"] > 1e-3:
        failures.append("without --exact-handles the handles should end off their targets (the test lost its point)")
    if not exact["handle_residual_max"] <= 1e-5:
        failures.append(f"--exact-handles left the handles {exact['handle_residual_max']:.3e} of the diagonal off")
    if not exact["reduced_size"] > plain["reduced_size"]:
        failures.append("--exact-handles did not add the handle vertices' proxies")
    if exact["reconstruction"] != "gpu":
        failures.append(f"expected the GPU path, got {exact['reconstruction']} ({exact['gpu_unavailable_reason']})")
    elif not 0 <= exact["gpu_cpu_max_deviation"] <= 1e-5:
        failures.append(f"GPU vs CPU deviation {exact['gpu_cpu_max_deviation']}")
    if "least-squares" in exact_err or "cannot meet" in exact_err:
        failures.append("--exact-handles still warned:\n" + exact_err)
    for f in failures:
        print("FAILED: " + f)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
