"""One edit, the way a libigl user writes it, against qpreduce's one-call
solve (docs/performance.md, "Coming from libigl or CGAL: the same edit timed"):
every fixed and handle vertex of a shared Botsch–Sorkine scenario held at
its target, classic (spokes-and-rims) ARAP.

    build/bin/qpreduce-python scripts/libigl_side_by_side.py [--model bumpy_plane] [--data ../shared/data]
        [--harness /tmp/libigl_arap] [--cgal-harness /tmp/cgal_arap] [--max-rounds 20000] [--repeats 3]
        [--work /tmp/qpreduce-libigl]

Writes b.txt, bc.txt and the tightly converged shape (deform.arap to a
distance tolerance of 1e-9, ref.off) into --work; times deform.arap at its
defaults and reports its RMS distance from that shape (/ diagonal). With
--harness (bench/external/libigl_arap.cpp, built against a libigl checkout
outside this project's dependencies), runs libigl's arap_precomputation and
arap_solve from the rest pose until they are within 1 % and 0.1 % of the
same shape (or --max-rounds), in the same run; with --cgal-harness
(bench/external/cgal_arap.cpp, built against Debian's libcgal-dev, also
outside the dependencies) the same for CGAL's Surface_mesh_deformation
(spokes and rims, one deform(1, 0) call a round). The classic ARAP energy
(arap_energy, Eq. 6) of each shape, and of CGAL's reference shape in
../shared/data/references when there is one, says which is nearer a minimum.
"""

import argparse
import os
import statistics
import subprocess
import time

import numpy as np

from qpreduce import deform


def write_off(path, V, F):
    with open(path, "w") as f:
        f.write(f"OFF\n{len(V)} {len(F)} 0\n")
        np.savetxt(f, V, fmt="%.17g")
        np.savetxt(f, np.hstack([np.full((len(F), 1), 3), F]), fmt="%d")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", default="bumpy_plane")
    ap.add_argument("--data", default=os.path.normpath(os.path.join(os.path.abspath(__file__), "..", "..", "..", "shared", "data")))
    ap.add_argument("--harness", default=None, help="the built bench/external/libigl_arap.cpp")
    ap.add_argument("--cgal-harness", default=None, help="the built bench/external/cgal_arap.cpp")
    ap.add_argument("--max-rounds", type=int, default=20000, help="libigl's rounds at most")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--work", default="/tmp/qpreduce-libigl")
    args = ap.parse_args()
    os.makedirs(args.work, exist_ok=True)
    bs = os.path.join(args.data, "meshes", "botsch-sorkine")
    mesh = os.path.join(bs, args.model + ".off")
    V, F = deform.read_mesh(mesh)
    sel = deform.read_sel(os.path.join(bs, args.model + ".sel"))
    M = deform.read_def(os.path.join(bs, args.model + ".def"))
    b = np.flatnonzero(sel != 1)
    bc = V[b].copy()
    handle = sel[b] == 2
    bc[handle] = V[b][handle] @ M[:3, :3].T + M[:3, 3]
    d = float(np.linalg.norm(np.ptp(V, axis=0)))
    np.savetxt(os.path.join(args.work, "b.txt"), b, fmt="%d")
    np.savetxt(os.path.join(args.work, "bc.txt"), bc, fmt="%.17g")

    tight = deform.RefineOptions(distance_tolerance=1e-9)
    t = time.perf_counter()
    R, tight_summary = deform.arap(V, F, b, bc, options=tight, return_summary=True)
    tight_s = time.perf_counter() - t
    ref = os.path.join(args.work, "ref.off")
    write_off(ref, R, F)
    rms = lambda U: float(np.sqrt(((U - R) ** 2).sum(axis=1).mean()) / d)

    times = []
    for _ in range(args.repeats):
        t = time.perf_counter()
        U, summary = deform.arap(V, F, b, bc, return_summary=True)
        times.append(time.perf_counter() - t)
    model = deform.Model(V, F)
    print(f"{args.model}.off: n = {len(V)}, {len(b)} vertices held ({int(handle.sum())} handle, "
          f"{int((~handle).sum())} fixed); RMS / diagonal from deform.arap to a distance tolerance of 1e-9 "
          f"({tight_summary.rounds} rounds, {tight_s:.1f} s)", flush=True)
    rows = [(f"qpreduce `deform.arap(V, F, b, bc)` (median of {args.repeats})", summary.rounds,
             f"{statistics.median(times):.3f}", rms(U), deform.arap_energy(model, U)),
            ("qpreduce `deform.arap`, distance tolerance 1e-9", tight_summary.rounds, f"{tight_s:.3f}", 0.0,
             deform.arap_energy(model, R))]
    harnesses = [("libigl", "libigl `arap_precomputation` + `arap_solve`", args.harness),
                 ("cgal", "CGAL `Surface_mesh_deformation` (`preprocess` + `deform`)", args.cgal_harness)]
    for key, what, harness in harnesses:
        if not harness:
            continue
        last = os.path.join(args.work, key + ".off")
        out = subprocess.run([harness, mesh, os.path.join(args.work, "b.txt"), os.path.join(args.work, "bc.txt"),
                              ref, "--max-rounds", str(args.max_rounds), "--out", last],
                             capture_output=True, text=True, check=True).stdout
        print(f"\n{key} (bench/external/{key}_arap.cpp):\n" + out)
        L, _ = deform.read_mesh(last)
        rounds = [line for line in out.splitlines() if line.startswith(("0.1 %", "not within"))][-1]
        rows.append((f"{what}: {rounds}", "", "", rms(L), deform.arap_energy(model, L)))
    cgal = os.path.join(args.data, "references", f"cgal_sr_{args.model}_it5000.off")
    if not os.path.exists(cgal):
        cgal = cgal.replace("it5000", "it10000")
    if os.path.exists(cgal):
        C, _ = deform.read_mesh(cgal)
        rows.append((f"CGAL reference ({os.path.basename(cgal)})", "", "", rms(C), deform.arap_energy(model, C)))
    print("| solve | rounds | seconds | RMS / diag | classic ARAP energy |")
    print("|---|---|---|---|---|")
    for name, rounds, seconds, distance, energy in rows:
        print(f"| {name} | {rounds} | {seconds} | {distance:.1e} | {energy:.6g} |")


if __name__ == "__main__":
    main()
