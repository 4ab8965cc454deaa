"""GMRF interpolation on a grid with changing observations, from scipy.sparse.

A Gaussian Markov random field on an nx × ny grid has the precision
H = (κ²I + L)ᵀ(κ²I + L) (L the 5-point grid Laplacian, n = nx·ny unknowns).
Interpolating observed values b at m sites is

    min_X ½XᵀHX   s.t.  X[site_i] = b_i   (i.e. AᵀX = b, A = [e_site_1 … e_site_m])

The observation sites change on site, so each demand has its own A. All sites
are drawn from a fixed set of `candidates` grid points, the columns of C
(A = C·A_c), which makes every demand lie in the design space: the reduced
answer is then the exact one (Theorem 4.10 with zero bound). We check that
against scipy.sparse.linalg.spsolve of the full KKT system

    [[H, A], [Aᵀ, 0]]·[X; Λ] = [0; b],

and time both.

    PYTHONPATH=build/python python3 python/examples/gmrf_interpolation.py [--nx 120 --ny 120]
"""

import argparse
import time

import numpy as np
import scipy.sparse
import scipy.sparse.linalg

import qpreduce


def grid_laplacian(nx, ny):
    """5-point Laplacian (n × n, n = nx·ny, vertex (i, j) at i + nx·j) as CSC."""
    def path(k):
        return scipy.sparse.diags([-np.ones(k - 1), 2 * np.ones(k), -np.ones(k - 1)], [-1, 0, 1])
    return (scipy.sparse.kron(scipy.sparse.identity(ny), path(nx)) +
            scipy.sparse.kron(path(ny), scipy.sparse.identity(nx))).tocsc()


def selection(n, sites):
    """n × len(sites) sparse matrix whose column j is e_{sites[j]}."""
    return scipy.sparse.csc_matrix((np.ones(len(sites)), (sites, np.arange(len(sites)))), shape=(n, len(sites)))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--nx", type=int, default=120)
    parser.add_argument("--ny", type=int, default=120)
    parser.add_argument("--candidates", type=int, default=200, help="candidate observation sites (d)")
    parser.add_argument("--observed", type=int, default=40, help="sites observed per demand (m)")
    parser.add_argument("--demands", type=int, default=5)
    parser.add_argument("--kappa2", type=float, default=0.05)
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args(argv)

    rng = np.random.default_rng(args.seed)
    n = args.nx * args.ny
    K = args.kappa2 * scipy.sparse.identity(n, format="csc") + grid_laplacian(args.nx, args.ny)
    H = (K.T @ K).tocsc()
    candidates = np.sort(rng.choice(n, args.candidates, replace=False))
    C = selection(n, candidates)

    solver = qpreduce.SubspaceSolver()
    t = time.perf_counter()
    summary = solver.precompute(H, C).raise_if_failed()
    print(f"n = {n}, d = {solver.d}: precompute {time.perf_counter() - t:.3f} s ({summary.brief_report()})")

    worst = 0.0
    for demand in range(args.demands):
        sites = np.sort(rng.choice(candidates, args.observed, replace=False))
        A = selection(n, sites)
        b = rng.standard_normal(args.observed)

        t = time.perf_counter()
        solver.set_constraints(A).raise_if_failed()  # the on-site step
        w = solver.solve_in_D(b, np.zeros(0))
        X = solver.reconstruct(w)
        reduced = time.perf_counter() - t

        t = time.perf_counter()
        KKT = scipy.sparse.bmat([[H, A], [A.T, None]], format="csc")
        # MMD on AᵀA + A: the KKT matrix is symmetric (the default COLAMD fills far more).
        X_full = scipy.sparse.linalg.spsolve(KKT, np.concatenate([np.zeros(n), b]), permc_spec="MMD_AT_PLUS_A")[:n]
        full = time.perf_counter() - t

        error = np.linalg.norm(X - X_full) / np.linalg.norm(X_full)
        worst = max(worst, error)
        print(f"demand {demand}: m = {args.observed}, reduced {1e3 * reduced:.2f} ms "
              f"(constraints + solve + reconstruct), spsolve {1e3 * full:.1f} ms, "
              f"relative difference {error:.2e}, max |X[sites] − b| {np.abs(X[sites] - b).max():.1e}")
    return worst


if __name__ == "__main__":
    main()
