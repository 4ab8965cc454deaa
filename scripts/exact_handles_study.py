"""Exact handles and the one-call API (docs/performance.md, "Exact handles"):
ArapSolver's precompute and solve against the handle count, the
break-even of ArapSolver against deform.arap on the shared cylinder, and
display-rate frames (8 rounds each) with 100 exact handle vertices on the
shared Bumpy Plane.

    build/bin/qpreduce-python scripts/exact_handles_study.py [--counts 10 30 100 300] [--data ../shared/data]
        [--parts sweep break-even frames shared-sel] [--sweep-mesh SEGMENTS RINGS] [--models cylinder cactus bar]

Prints a Markdown table per part; medians over --repeats runs of each solve.
"""

import argparse
import os
import resource
import statistics
import time

import numpy as np

from qpreduce import deform


def bent(V, b):
    t = (V[b, 2] - V[:, 2].min()) / np.ptp(V[:, 2])
    out = V[b].copy()
    c, s = np.cos(0.8 * t), np.sin(0.8 * t)
    out[:, 1], out[:, 2] = c * V[b, 1] - s * V[b, 2], s * V[b, 1] + c * V[b, 2]
    return out


def timed(f, repeats):
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        result = f()
        times.append(time.perf_counter() - t)
    return result, statistics.median(times)


def peak_rss_mb():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # Linux: KiB


def sweep(counts, repeats, segments=30, rings=60):
    V, F = deform.shapes.capped_cylinder(1.0, 6.0, segments, rings)
    d = np.linalg.norm(np.ptp(V, axis=0))
    rng = np.random.default_rng(19)
    print(f"capped cylinder ({segments} segments, {rings} rings), n = {len(V)}; b random vertices, targets a bend")
    print("| handle vertices | p | precompute s | peak RSS MB (process so far) | basis MB (float) | solve ms (median) "
          "| rounds | handle error / diag |")
    print("|---|---|---|---|---|---|---|---|")
    for h in counts:
        b = rng.choice(len(V), size=h, replace=False)
        bc = bent(V, b)
        t = time.perf_counter()
        solver = deform.ArapSolver(V, F, b)
        pre = time.perf_counter() - t
        solver.solve(bc)  # the cold start
        bc2 = bc + 0.01 * d
        U, ms = timed(lambda: solver.solve(bc2), repeats)
        p = solver.precompute_summary.reduced_size
        print(f"| {h} | {p} | {pre:.2f} | {peak_rss_mb():.0f} | {3 * len(V) * p * 4 / 1e6:.0f} | {1e3 * ms:.2f} | "
              f"{solver.last_solve.rounds} | {np.abs(U[b] - bc2).max() / d:.0e} |", flush=True)


def break_even(data, repeats):
    bs = os.path.join(data, "meshes", "botsch-sorkine")
    V, F = deform.read_mesh(os.path.join(bs, "cylinder.off"))
    sel = deform.read_sel(os.path.join(bs, "cylinder.sel"))
    M = deform.read_def(os.path.join(bs, "cylinder.def"))
    b = np.flatnonzero(sel != 1)
    bc = V[b].copy()
    handle = sel[b] == 2
    bc[handle] = V[b][handle] @ M[:3, :3].T + M[:3, 3]
    d = np.linalg.norm(np.ptp(V, axis=0))
    U, one_call = timed(lambda: deform.arap(V, F, b, bc), repeats)
    t = time.perf_counter()
    solver = deform.ArapSolver(V, F, b)
    pre = time.perf_counter() - t
    R, solve = timed(lambda: solver.solve(bc), repeats)
    F2, refine = timed(lambda: solver.solve(bc, refine=True), repeats)
    rms = lambda A: np.sqrt(((A - U) ** 2).sum(axis=1).mean()) / d
    print(f"\nshared cylinder.off (n = {len(V)}), every fixed and handle vertex of cylinder.sel held ({len(b)})")
    print("| call | seconds (median) | RMS from arap() / diag |")
    print("|---|---|---|")
    print(f"| deform.arap (full space, from rest) | {one_call:.3f} | 0 |")
    print(f"| ArapSolver(V, F, b) precompute | {pre:.2f} | |")
    print(f"| ArapSolver.solve(bc) (reduced, warm) | {solve:.4f} | {rms(R):.1e} |")
    print(f"| ArapSolver.solve(bc, refine=True) | {refine:.3f} | {rms(F2):.1e} |")
    print(f"\nbreak-even: the precompute pays after {pre / max(one_call - solve, 1e-9):.1f} reduced solves "
          f"in place of one-call solves")


def shared_sel(data, models, repeats):
    """Every fixed and handle vertex of each shared .sel held vertex by vertex (libigl's habit)."""
    bs = os.path.join(data, "meshes", "botsch-sorkine")
    print("\nshared Botsch–Sorkine models, every fixed and handle vertex of the .sel held, targets from the .def")
    print("| model | n | held | p | precompute s | peak RSS MB (process so far) | solve ms (median) "
          "| reconstruction's handle error / diag | returned handle error / diag |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name in models:
        V, F = deform.read_mesh(os.path.join(bs, name + ".off"))
        sel = deform.read_sel(os.path.join(bs, name + ".sel"))
        M = deform.read_def(os.path.join(bs, name + ".def"))
        b = np.flatnonzero(sel != 1)
        bc = V[b].copy()
        handle = sel[b] == 2
        bc[handle] = V[b][handle] @ M[:3, :3].T + M[:3, 3]
        d = np.linalg.norm(np.ptp(V, axis=0))
        t = time.perf_counter()
        solver = deform.ArapSolver(V, F, b)
        pre = time.perf_counter() - t
        U, ms = timed(lambda: solver.solve(bc), repeats)
        p = solver.precompute_summary.reduced_size
        print(f"| {name} | {len(V)} | {len(b)} | {p} | {pre:.2f} | {peak_rss_mb():.0f} | {1e3 * ms:.2f} | "
              f"{solver.reconstruction_handle_error / d:.1e} | {np.abs(U[b] - bc).max() / d:.1e} |", flush=True)


def frames_on_bumpy_plane(data, handles, repeats):
    V, F = deform.read_mesh(os.path.join(data, "meshes", "botsch-sorkine", "bumpy_plane.off"))
    d = np.linalg.norm(np.ptp(V, axis=0))
    b = np.random.default_rng(3).choice(len(V), size=handles, replace=False)
    options = deform.ArapSolverOptions(max_rounds=8, tolerance=0.0)  # a drag's frame: 8 rounds, as qpr deform
    t = time.perf_counter()
    solver = deform.ArapSolver(V, F, b, options=options)
    pre = time.perf_counter() - t
    out = np.empty_like(V)
    lift = np.zeros_like(V[b])
    solver.solve(V[b], out)  # the cold start
    times = []
    for f in range(1, 4 * repeats + 1):
        lift[:, 2] = 0.05 * d * f / (4 * repeats) * np.sin(V[b, 0] / np.ptp(V[:, 0]) * np.pi)
        t = time.perf_counter()
        solver.solve(V[b] + lift, out)
        times.append(time.perf_counter() - t)
    p = solver.precompute_summary.reduced_size
    print(f"\nshared bumpy_plane.off (n = {len(V)}), {handles} random vertices held exactly, frames of 8 rounds")
    print("| handle vertices | p | precompute s | frame ms (median of %d, Python call) | handle error / diag |"
          % len(times))
    print("|---|---|---|---|---|")
    print(f"| {handles} | {p} | {pre:.1f} | {1e3 * statistics.median(times):.2f} | "
          f"{np.abs(out[b] - (V[b] + lift)).max() / d:.0e} |")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--counts", type=int, nargs="*", default=[10, 30, 100, 300])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--parts", nargs="*", default=["sweep", "break-even", "frames"],
                        choices=["sweep", "break-even", "frames", "shared-sel"],
                        help="which tables (default: the first three)")
    parser.add_argument("--models", nargs="*", default=["cylinder", "cactus", "bar"],
                        help="shared-sel's Botsch–Sorkine models")
    parser.add_argument("--sweep-mesh", type=int, nargs=2, default=[30, 60], metavar=("SEGMENTS", "RINGS"),
                        help="the sweep's capped cylinder (default 30 60: 1,802 vertices)")
    parser.add_argument("--data", default=os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(
        os.path.abspath(__file__)))), "shared", "data"))
    args = parser.parse_args()
    if "sweep" in args.parts:
        sweep(args.counts, args.repeats, *args.sweep_mesh)
    if not os.path.isdir(args.data):
        print(f"\n{args.data} not found: the break-even and frames parts need the shared data")
        return
    if "break-even" in args.parts:
        break_even(args.data, args.repeats)
    if "frames" in args.parts:
        frames_on_bumpy_plane(args.data, 100, args.repeats)
    if "shared-sel" in args.parts:
        shared_sel(args.data, args.models, args.repeats)


if __name__ == "__main__":
    main()
