"""One edit the way a libigl user writes it: hold vertices b at targets bc, get the ARAP shape.

`deform.arap(V, F, b, bc)` is the one-call solve (converged classic ARAP in the
full space, no subspace precompute: for a single edit the precompute does
not pay); `deform.ArapSolver(V, F, b)` precomputes once with every vertex of
b in the subspace, so that each `solve(bc)` meets its targets exactly in
milliseconds, and `solve(bc, refine=True)` brings it to the one-call shape.
The same edit in libigl is `igl.arap_precomputation(V, F, 3, b, data)` then
`igl.arap_solve(bc, data, U)` (docs/python.md, "Coming from libigl or CGAL").

The scenario: the shared Botsch–Sorkine cylinder with every fixed and handle
vertex of cylinder.sel in b and the .def pose as their targets; without
../shared (or with --builtin) the built-in capped cylinder, both ends held,
the top one bent sideways. Writes the one-call shape and the solver's two
shapes as OFF files into --out.

    PYTHONPATH=build/python python3 python/examples/arap_one_call.py [--builtin] [--solves 5] [--out arap-one-call]
"""

import argparse
import os
import time

import numpy as np

from qpreduce import deform

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SHARED = os.path.join(os.environ.get("QPREDUCE_SHARED_DATA", os.path.join(os.path.dirname(ROOT), "shared", "data")),
                      "meshes", "botsch-sorkine")


def scenario(builtin, around, rings):
    """V, F, b, bc and a name: the shared cylinder's .sel/.def, or the built-in one bent."""
    if not builtin and os.path.exists(os.path.join(SHARED, "cylinder.off")):
        V, F = deform.read_mesh(os.path.join(SHARED, "cylinder.off"))
        sel = deform.read_sel(os.path.join(SHARED, "cylinder.sel"))
        M = deform.read_def(os.path.join(SHARED, "cylinder.def"))
        b = np.flatnonzero(sel != 1)  # fixed (0) and handle (2) vertices, each its own point handle
        bc = V[b].copy()
        handle = sel[b] == 2
        bc[handle] = V[b][handle] @ M[:3, :3].T + M[:3, 3]
        return V, F, b, bc, "shared cylinder.off with cylinder.sel/.def"
    V, F = deform.shapes.capped_cylinder(1.0, 6.0, around, rings)
    b = np.flatnonzero((V[:, 2] < 0.3) | (V[:, 2] > 5.7))
    bc = V[b].copy()
    top = V[b, 2] > 3.0
    bc[top, 1] += 1.5  # the top end sideways
    return V, F, b, bc, f"built-in capped cylinder ({around} around, {rings} rings), both ends held"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--builtin", action="store_true", help="the built-in cylinder even when ../shared is there")
    ap.add_argument("--around", type=int, default=32)
    ap.add_argument("--rings", type=int, default=48)
    ap.add_argument("--solves", type=int, default=5, help="reduced solves timed (targets moved a little each)")
    ap.add_argument("--out", default="arap-one-call")
    args = ap.parse_args(argv)
    V, F, b, bc, name = scenario(args.builtin, args.around, args.rings)
    d = float(np.linalg.norm(np.ptp(V, axis=0)))
    rms = lambda A, B: float(np.sqrt(((A - B) ** 2).sum(axis=1).mean()) / d)
    print(f"{name}: {len(V)} vertices, {len(b)} held")

    t = time.perf_counter()
    U, summary = deform.arap(V, F, b, bc, return_summary=True)  # libigl: arap_precomputation + arap_solve
    one_call = time.perf_counter() - t
    print(f"deform.arap: {one_call:.3f} s, {summary.rounds} rounds, converged {summary.converged}, "
          f"handles off by {np.abs(U[b] - bc).max() / d:.1e} of the diagonal")

    t = time.perf_counter()
    solver = deform.ArapSolver(V, F, b)  # precompute once for this b
    precompute = time.perf_counter() - t
    R = solver.solve(bc)
    times = []
    out = np.empty_like(V)
    for i in range(args.solves):  # a drag: the targets moved a little each solve, the result in place
        t = time.perf_counter()
        solver.solve(bc + 1e-3 * d * (i + 1) / args.solves, out)
        times.append(time.perf_counter() - t)
    solve = float(np.median(times)) if times else float("nan")
    refined = solver.solve(bc, refine=True)
    handle_error = max(np.abs(R[b] - bc).max(), np.abs(refined[b] - bc).max()) / d
    print(f"ArapSolver: precompute {precompute:.2f} s, solve {1e3 * solve:.2f} ms (median of {args.solves}), "
          f"handles off by {handle_error:.1e} of the diagonal")
    print(f"  reduced shape {rms(R, U):.1e} of the diagonal (RMS) from the one-call shape, "
          f"refined {rms(refined, U):.1e}")
    if np.isfinite(solve) and one_call > solve:
        print(f"  the precompute pays after {precompute / (one_call - solve):.1f} solves")

    os.makedirs(args.out, exist_ok=True)
    for tag, shape in (("one_call", U), ("reduced", R), ("refined", refined)):
        deform.write_mesh(os.path.join(args.out, f"{tag}.off"), shape, F)
    print(f"wrote one_call.off, reduced.off and refined.off to {args.out}/")
    return {"handle_error": handle_error, "reduced_rms": rms(R, U), "refined_rms": rms(refined, U),
            "one_call_handle_error": float(np.abs(U[b] - bc).max() / d), "converged": summary.converged}


if __name__ == "__main__":
    main()
