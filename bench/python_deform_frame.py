#!/usr/bin/env python3
"""Deformer.frame(out=V) from Python against the C++ frame time, Bumpy Plane.

Usage: PYTHONPATH=build/python python3 bench/python_deform_frame.py [--model bumpy_plane] [--frames 200]
       [--cache /tmp/bumpy_plane.qpr] [--data ../shared/data] [--cylinder AROUND,RINGS]

Precomputes the Botsch–Sorkine model (.off/.sel/.def, the deformer's default
options; --cache saves the precomputed model and loads it on later runs),
sets the handle patch, then runs frames alternating between two poses of
the .def (t = 0.5 and 1, interpolated as `qpr deform` does), each into one
preallocated (n, 3) array. Per frame it records the Python wall time of the
call (time.perf_counter around deformer.frame) and the C++ frame time the
deformer measures itself (FrameSummary.total_seconds: the rounds and the
reconstruction into the caller's array), and the time of a trivial call
right after it (the property handle_rows). Prints the medians and the ratio
(target ≤ 1.1) as a Markdown table. --cylinder runs the built-in capped
cylinder of `qpr demo` (AROUND vertices per ring, RINGS rings; base fixed,
top cap moved sideways) instead of a shared model.
"""
import argparse
import os
import statistics
import time

import numpy as np

from qpreduce import deform

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", default="bumpy_plane")
    parser.add_argument("--data", default=os.path.join(os.path.dirname(ROOT), "shared", "data"))
    parser.add_argument("--frames", type=int, default=200)
    parser.add_argument("--warm-up", type=int, default=10)
    parser.add_argument("--cache", default=None, help="precomputed model: loaded when it exists, else saved")
    parser.add_argument("--cylinder", default=None, help="AROUND,RINGS: the built-in cylinder instead")
    args = parser.parse_args()

    if args.cylinder:
        around, rings = (int(x) for x in args.cylinder.split(","))
        V, F = deform.shapes.capped_cylinder(1.0, 12.0, around, rings)
        sel = np.ones(len(V), dtype=np.int32)
        sel[V[:, 2] < 0.6] = 0
        sel[V[:, 2] > 11.4] = 2
        M = np.eye(4)
        M[0, 3] = 1.0
        args.model = f"cylinder {around}x{rings}"
        scenario = deform.sel_def_scenario(V, F, sel, M, frames=2)
    else:
        base = os.path.join(args.data, "meshes", "botsch-sorkine", args.model)
        V, F = deform.read_mesh(base + ".off")
        scenario = deform.sel_def_scenario(V, F, base + ".sel", base + ".def", frames=2)
    deformer = deform.Deformer(scenario.model, deform.DeformerOptions())
    t = time.perf_counter()
    if args.cache and os.path.exists(args.cache):
        summary = deformer.load(args.cache)
        how = "loaded"
    else:
        summary = deformer.precompute()
        how = "precomputed"
        if args.cache:
            deformer.save(args.cache)
    print(f"{args.model}: n = {len(V)}, p = {summary.reduced_size}, {how} in {time.perf_counter() - t:.2f} s")
    deformer.set_handles(scenario.handles)

    out = np.empty_like(V)
    poses = [np.ascontiguousarray(f.patch_transforms[0])[None] for f in scenario.frames]
    points = np.zeros((0, 3))
    python, cpp, trivial = [], [], []
    for i in range(args.warm_up + args.frames):
        pose = poses[i % 2]
        t = time.perf_counter()
        deformer.frame(points, out=out, patch_transforms=pose)
        elapsed = time.perf_counter() - t
        t = time.perf_counter()
        deformer.handle_rows  # a trivial call right after the frame
        after = time.perf_counter() - t
        if i >= args.warm_up:
            python.append(elapsed)
            cpp.append(deformer.last_frame.total_seconds)
            trivial.append(after)
    py_median, cpp_median = statistics.median(python), statistics.median(cpp)
    ratios = [p / c for p, c in zip(python, cpp)]
    print(f"{args.frames} frames (after {args.warm_up} warm-up), OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS', 'unset')}, "
          f"load average {os.getloadavg()[0]:.2f}\n")
    print("| | median per frame |")
    print("|---|---|")
    print(f"| C++ frame (FrameSummary.total_seconds) | {1e3 * cpp_median:.3f} ms |")
    print(f"| Python `frame(out=V)` call | {1e3 * py_median:.3f} ms |")
    print(f"| ratio of the medians | {py_median / cpp_median:.3f} |")
    print(f"| median of the per-frame ratios | {statistics.median(ratios):.3f} |")
    print(f"| median overhead per call | {1e6 * statistics.median(p - c for p, c in zip(python, cpp)):.1f} µs |")
    print(f"| a trivial call (handle_rows) right after | {1e6 * statistics.median(trivial):.2f} µs |")


if __name__ == "__main__":
    main()
