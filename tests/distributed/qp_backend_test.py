#!/usr/bin/env python3
"""`mpirun -np 2 qpr qp --backend mumps` solves the demands as `qpr qp` does.

    qp_backend_test.py QPR_BINARY MPIRUN WORK_DIR

Writes a small QP as Matrix Market files (a 1-D smoothing chain, PD:
H = tridiag(−1, 2 + 10⁻², −1), C selects 6 stations, D = [1, t]; three
demands pinning some stations with q = D·Y, one with a general q), solves it
with the single-process backend and with MUMPS on 2 ranks — each rank
keeping its rows of the basis, A_r and q_r summed over the ranks, X gathered
to rank 0 (`--out` writes X_<name>.mtx; `--check-full` and the report on
rank 0) — and checks that every solution agrees to 1e-8 relative; again on
3 ranks without --check-full, where every rank reads only its rows of H and
D; a NaN in the last rank's rows of H fails the job naming the file. Then `--backend nonsense` is refused with a message naming the option.
"""
import json
import os
import subprocess
import sys

N = 300
STATIONS = [10, 60, 120, 180, 240, 290]


def write_coo(path, rows, cols, entries, symmetric=False):
    with open(path, "w") as f:
        f.write(f"%%MatrixMarket matrix coordinate real {'symmetric' if symmetric else 'general'}\n")
        f.write(f"{rows} {cols} {len(entries)}\n")
        for i, j, v in entries:
            f.write(f"{i + 1} {j + 1} {v!r}\n")


def write_dense(path, values):
    with open(path, "w") as f:
        f.write(f"%%MatrixMarket matrix array real general\n{len(values)} 1\n")
        for v in values:
            f.write(f"{v!r}\n")


def read_dense(path):
    with open(path) as f:
        lines = [l for l in f if not l.startswith("%")]
    rows, cols = (int(x) for x in lines[0].split()[:2])
    return [float(l.split()[-1]) for l in lines[1:1 + rows * cols]]


def run(cmd, expect=0):
    """expect: the exit code, or None for any failure."""
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    if (p.returncode == 0) if expect is None else (p.returncode != expect):
        sys.exit(f"FAILED (exit {p.returncode}, expected {expect}): {' '.join(cmd)}\n{p.stdout}\n{p.stderr}")
    return p


def main():
    qpr, mpirun, work = sys.argv[1:4]
    demands = os.path.join(work, "demands")
    os.makedirs(demands, exist_ok=True)
    H = [(i, i, 2.01) for i in range(N)] + [(i + 1, i, -1.0) for i in range(N - 1)]
    write_coo(os.path.join(work, "H.mtx"), N, N, H, symmetric=True)
    write_coo(os.path.join(work, "C.mtx"), N, len(STATIONS), [(s, j, 1.0) for j, s in enumerate(STATIONS)])
    write_coo(os.path.join(work, "D.mtx"), N, 2, [(i, 0, 1.0) for i in range(N)] + [(i, 1, i / N) for i in range(N)])
    for name, pinned in {"a": [0, 2], "b": [1, 3, 5], "c": [4]}.items():
        write_coo(os.path.join(demands, f"A_{name}.mtx"), N, len(pinned),
                  [(STATIONS[s], j, 1.0) for j, s in enumerate(pinned)])
        write_dense(os.path.join(demands, f"b_{name}.mtx"), [0.5 + 0.25 * s for s in pinned])
        write_dense(os.path.join(demands, f"Y_{name}.mtx"), [0.01, -0.02 * len(pinned)])
    # A demand with a general linear term q (n entries): q_r = Bᵀq summed over the ranks.
    write_coo(os.path.join(demands, "A_d.mtx"), N, 2, [(STATIONS[0], 0, 1.0), (STATIONS[5], 1, 1.0)])
    write_dense(os.path.join(demands, "b_d.mtx"), [0.3, -0.2])
    write_dense(os.path.join(demands, "q_d.mtx"), [0.01 * ((i * 37) % 11 - 5) for i in range(N)])
    common = ["qp", "--H", os.path.join(work, "H.mtx"), "--C", os.path.join(work, "C.mtx"),
              "--D", os.path.join(work, "D.mtx"), "--demands", demands]
    run([qpr, *common, "--out", os.path.join(work, "auto")])
    report = os.path.join(work, "mumps_report.json")
    run([mpirun, "--oversubscribe", "-np", "2", qpr, *common, "--backend", "mumps", "--out", os.path.join(work, "mumps"),
         "--check-full", "--report", report])
    with open(report) as f:
        doc = json.load(f)
    if doc["failures"] or len(doc["demands"]) != 4 or any(r["status"] != "success" for r in doc["demands"]):
        sys.exit(f"FAILED: the 2-rank report: {json.dumps(doc)[:2000]}")
    # Without --check-full every rank, rank 0 too, reads only its rows of H and D; 3 ranks, uneven rows.
    run([mpirun, "--oversubscribe", "-np", "3", qpr, *common, "--backend", "mumps",
         "--out", os.path.join(work, "mumps_rows")])
    for out in ["mumps", "mumps_rows"]:
        for name in ["a", "b", "c", "d"]:
            x = read_dense(os.path.join(work, "auto", f"X_{name}.mtx"))
            y = read_dense(os.path.join(work, out, f"X_{name}.mtx"))
            diff = sum((u - v) ** 2 for u, v in zip(x, y)) ** 0.5
            ref = sum(u * u for u in x) ** 0.5
            print(f"{out}, demand {name}: relative difference {diff / ref:.2e}")
            if len(x) != N or len(y) != N or not diff <= 1e-8 * ref:
                sys.exit(f"FAILED: {out}, demand {name}: {len(x)}, {len(y)} entries, "
                         f"relative difference {diff / ref:.2e}")
    # A broken entry in the last rank's rows of H: every rank reads the whole file, so the job
    # fails with the file and line, whichever rank owns them.
    bad = os.path.join(work, "H_bad.mtx")
    write_coo(bad, N, N, H[:-1] + [(N - 1, N - 2, float("nan"))], symmetric=True)
    p = run([mpirun, "--oversubscribe", "-np", "2", qpr, *[bad if a.endswith("H.mtx") else a for a in common],
             "--backend", "mumps"], expect=None)
    if "H_bad.mtx" not in p.stderr or "not finite" not in p.stderr:
        sys.exit(f"FAILED: the broken H is not named:\n{p.stderr}")
    p = run([qpr, *common, "--backend", "nonsense"], expect=None)
    if "backend" not in p.stderr:
        sys.exit(f"FAILED: the refusal does not name --backend:\n{p.stderr}")
    print("ok")
    return 0


if __name__ == "__main__":
    sys.exit(main())
